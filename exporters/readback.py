"""Read masks written by the exporters back into a :class:`~optdot.pattern.Pattern`.

Used by ``optdot qa`` on GDSII/OASIS/DXF files. Dots are the references to the dot cell
(or, in flattened files, the polygons on the dot layer). A dot must be a circle: a polygon
of at least ``MIN_DOT_VERTICES`` (8) vertices all at one distance from their mean (to
:data:`RADIUS_SPREAD`); anything else on the dot layer (a square, a slot) is refused, as
qa's distances would be wrong for it. The panel box is the outline's bounding box.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from optdot.errors import GeometryError, PatternFileError, one_line
from optdot.geometry.domain import domain_from_rings
from optdot.io.patterns import load_pattern, validate_dots
from optdot.pattern import Pattern
from optdot.runtime.isolate import ChildCrashed, in_child

from .gds import MIN_DOT_VERTICES as MIN_VERTICES
from .gds import quietly
from .options import ExportOptions

#: Largest spread of a dot polygon's vertex radii: 2 nm plus this share of the radius
#: (vertices are snapped to the 1 nm grid).
RADIUS_SPREAD = 1e-3


def read_any(path: str | Path, opts: ExportOptions | None = None, box=None) -> Pattern:
    """Read ``.csv``/``.npz`` (pattern files) or ``.gds``/``.oas``/``.dxf`` (masks)."""
    path = Path(path)
    opts = opts or ExportOptions()
    suffix = path.suffix.lower()
    if not path.exists():
        raise PatternFileError(f"{path}: file not found")
    if suffix in (".csv", ".npz", ".parquet"):
        return load_pattern(path, box)
    try:
        if suffix in (".gds", ".gds2", ".oas"):
            # gdstk's C++ readers can crash on a damaged file: read in a child process
            return in_child(_read_layout, path, opts)
        if suffix == ".dxf":
            return _read_dxf(path)
    except PatternFileError:
        raise
    except ChildCrashed as e:
        raise PatternFileError(f"{path}: damaged {suffix[1:].upper()} file ({e})") from None
    except Exception as e:  # reader libraries raise many types on corrupt files
        raise PatternFileError(f"{path}: cannot read ({one_line(e, True)})") from None
    raise PatternFileError(f"{path}: unknown format {suffix!r} (csv, npz, parquet, gds, oas, dxf)")


def _read_layout(path: Path, opts: ExportOptions) -> Pattern:
    import gdstk

    reader = gdstk.read_oas if path.suffix.lower() == ".oas" else gdstk.read_gds
    lib, why = quietly(reader, str(path))
    if lib is None:
        raise PatternFileError(f"{path}: not a readable {path.suffix[1:].upper()} file ({why})")
    lib_unit = lib.unit  # metres per user unit
    to_mm = lib_unit * 1e3
    tops = lib.top_level()
    if len(tops) != 1:
        raise PatternFileError(f"{path}: expected one top cell, found {len(tops)}")
    top = tops[0]
    centres: list[np.ndarray] = []
    diameters: list[np.ndarray] = []
    _collect(path, top, np.zeros(2), opts, to_mm, centres, diameters, 0)
    for poly in top.polygons:
        if (poly.layer, poly.datatype) != (opts.layer, opts.datatype):
            continue
        c, radius = _circle(path, poly.points, "a polygon", to_mm)
        diameter = round(2 * radius, 6)
        reps = poly.repetition.get_offsets() if poly.repetition.size > 1 else np.zeros((1, 2))
        centres.append((c + reps) * to_mm)
        diameters.append(np.full(len(reps), diameter))
    if not centres:
        raise PatternFileError(f"{path}: no dots on layer {opts.layer}/{opts.datatype}")
    outline = [
        p
        for p in top.polygons
        if (p.layer, p.datatype) == (opts.outline_layer, opts.outline_datatype)
    ]
    rings = [p.points * to_mm for p in outline]
    xy = np.round(np.concatenate(centres), 6)
    return _pattern(path, xy, np.concatenate(diameters), rings, filled=True)


#: Deepest hierarchy read: top -> tile cells -> dot cells is 2.
MAX_DEPTH = 4


def _collect(path, cell, offset, opts, to_mm, centres, diameters, depth) -> None:
    """Dots placed by ``cell``'s references, shifted by ``offset`` (file units): a
    referenced cell with one circle on the dots' layer is a dot cell; one with references
    of its own (a tile of a tiled export) is walked in turn."""
    on_layer = (opts.layer, opts.datatype)
    for ref in cell.references:
        sub = ref.cell
        if isinstance(sub, str):
            raise PatternFileError(f"{path}: reference to a missing cell {sub!r}")
        origins = np.array([ref.origin]) + offset
        if ref.repetition.size > 1:
            origins = ref.repetition.get_offsets() + origins[0]
        pts = [p for p in sub.polygons if (p.layer, p.datatype) == on_layer]
        if sub.references and not pts:
            if depth >= MAX_DEPTH:
                raise PatternFileError(f"{path}: cells nested deeper than {MAX_DEPTH}")
            for o in origins:
                _collect(path, sub, o, opts, to_mm, centres, diameters, depth + 1)
            continue
        if not pts:
            continue
        if len(pts) > 1:
            raise PatternFileError(
                f"{path}: cell {sub.name} holds {len(pts)} shapes on layer "
                f"{opts.layer}/{opts.datatype}; a dot cell holds one circle"
            )
        centre, radius = _circle(path, pts[0].points, f"cell {sub.name}", to_mm)
        if np.hypot(*centre) * to_mm > 1e-6:
            raise PatternFileError(
                f"{path}: the circle of cell {sub.name} is not centred on the cell origin"
            )
        # vertices sit on the circle, snapped to the database grid: their mean radius
        # recovers the diameter to well under 1 nm
        diameter = round(2 * radius, 6)
        centres.append(origins * to_mm)
        diameters.append(np.full(len(origins), diameter))


def _circle(path: Path, pts: np.ndarray, what: str, to_mm: float) -> tuple[np.ndarray, float]:
    """``(centre [2] in the file's units, radius mm)`` of a dot polygon, or refuse it as
    not a circle."""
    c = pts.mean(axis=0)
    rad = np.hypot(*(pts - c).T)
    r = float(rad.mean())
    spread = float(rad.max() - rad.min()) * to_mm
    if len(pts) < MIN_VERTICES or spread > 2e-6 + RADIUS_SPREAD * r * to_mm:
        at = c * to_mm
        lo, hi = rad.min() * to_mm * 1e3, rad.max() * to_mm * 1e3
        raise PatternFileError(
            f"{path}: {what} at ({at[0]:.6g}, {at[1]:.6g}) mm on the dot layer is not a circle "
            f"({len(pts)} vertices, radii {lo:.4g}..{hi:.4g} µm); qa checks round dots only"
        )
    return c, r * to_mm


def _read_dxf(path: Path) -> Pattern:
    import ezdxf

    doc = ezdxf.readfile(str(path))
    msp = doc.modelspace()
    circles = msp.query('CIRCLE[layer=="DOTS"]')
    if not len(circles):
        raise PatternFileError(f"{path}: no CIRCLE entities on layer DOTS")
    xy = np.array([(c.dxf.center.x, c.dxf.center.y) for c in circles], dtype=np.float64)
    radii = np.array([c.dxf.radius for c in circles], dtype=np.float64)
    bad = ~(np.isfinite(radii) & (radii > 0))
    if bad.any():
        i = int(np.argmax(bad))
        raise PatternFileError(
            f"{path}: CIRCLE {circles[i].dxf.handle} on layer DOTS has radius {float(radii[i])!r}; "
            "dots need a radius > 0"
        )
    rings = []
    for e in msp.query('LWPOLYLINE POLYLINE[layer=="OUTLINE"]'):
        rings.append(
            np.array([p[:2] for p in e.get_points()], dtype=np.float64)
            if e.dxftype() == "LWPOLYLINE"
            else np.array([v.dxf.location[:2] for v in e.vertices], dtype=np.float64)
        )
    return _pattern(path, np.round(xy, 6), 2 * radii, rings)


def _pattern(
    path: Path, xy: np.ndarray, diameter: np.ndarray, rings: list[np.ndarray], filled: bool = False
) -> Pattern:
    """A pattern whose panel is the outline read back, else the dots' extent.

    ``rings`` are DXF loops (exteriors counter-clockwise, holes clockwise) or, with
    ``filled``, GDS/OAS polygons whose holes are keyholes."""
    outline = None
    if rings:
        try:
            outline = domain_from_rings(rings, str(path), filled)
        except GeometryError as e:
            raise PatternFileError(str(e)) from None
        pts = np.concatenate(rings)
        lo, hi = pts.min(axis=0), pts.max(axis=0)
    else:
        lo = (xy - diameter[:, None] / 2).min(axis=0)
        hi = (xy + diameter[:, None] / 2).max(axis=0)
    box = (float(lo[0]), float(lo[1]), float(hi[0]), float(hi[1]))
    validate_dots(path, xy, diameter, box)
    return Pattern(
        xy=xy,
        diameter=np.round(diameter, 6),
        box=box,
        meta={"source": str(path)},
        outline=outline,
    )
