"""Read masks written by the exporters back into a :class:`~optdot.pattern.Pattern`.

Used by ``optdot qa`` on GDSII/OASIS/DXF files. Dots are the references to the dot cell
(or, in flattened files, the polygons on the dot layer). A dot must be a circle: a polygon
of at least ``MIN_DOT_VERTICES`` (8) vertices all at one distance from their mean (to
:data:`RADIUS_SPREAD`); anything else on the dot layer (a square, a slot) is refused, as
qa's distances would be wrong for it. The panel box is the outline's bounding box.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from optdot.errors import GeometryError, PatternFileError, ResourceError, one_line
from optdot.files import input_problem
from optdot.formats import FORMATS, READ, format_of
from optdot.geometry.caps import CAP_APPID, CAP_CELL, rings_problem
from optdot.geometry.domain import Domain, domain_from_rings
from optdot.geometry.kinds import drawn_as, kinds_text
from optdot.geometry.limits import validate_dots
from optdot.geometry.orientation import degrees
from optdot.geometry.shapes import CIRCLE, KINDS, Fit, Footprints, Kind
from optdot.pattern import Pattern
from optdot.printing.mask import printed_box, printed_cap_rings, unscaled
from optdot.printing.sheet import PANEL_BLOCK, SHEET_CELL
from optdot.runtime.isolate import ChildCrashed, in_child
from optdot.runtime.memory import max_dots_read

from . import named
from .gds import quietly
from .options import ExportOptions

#: How far a graded cap's ring polygon's area may be off its annulus', as a share (the
#: polygon is drawn within the export tolerance, far under it).
RING_AREA_SHARE = 0.01
#: Largest spread of a dot polygon's vertex radii: 2 nm plus this share of the radius
#: (vertices are snapped to the 1 nm grid).
RADIUS_SPREAD = 1e-3
#: How far a vertex on a process's address grid may lie off its footprint, in grid steps
#: (rounding to the nearest grid point moves it by at most half a step's diagonal, and
#: the spread of radii is the difference of two such moves).
GRID_SLACK = 1.5


def read_any(path: str | Path, opts: ExportOptions | None = None, box=None) -> Pattern:
    """Read a pattern file (``.csv``/``.npz``/``.parquet``) or a mask
    (``.gds``/``.oas``/``.dxf``) with the reader its format's record names
    (:data:`optdot.formats.FORMATS`)."""
    path = Path(path)
    opts = opts or ExportOptions()
    fmt = format_of(path)
    if fmt is None or fmt.reader is None:
        raise PatternFileError(
            f"{path}: unknown format {path.suffix.lower()!r} ({', '.join(READ)})"
        )
    if not fmt.mask:
        return named(fmt.reader)(path, box)
    problem = input_problem(path)
    if problem is not None:
        raise PatternFileError(f"{path}: {problem}")
    try:
        return named(fmt.reader)(path, opts)
    except (PatternFileError, ResourceError):
        raise
    except ChildCrashed as e:
        raise PatternFileError(f"{path}: damaged {fmt.name.upper()} file ({e})") from None
    except Exception as e:  # reader libraries raise many types on corrupt files
        raise PatternFileError(f"{path}: cannot read ({one_line(e, True)})") from None


def read_layout(path: Path, opts: ExportOptions) -> Pattern:
    """A GDSII or OASIS mask's dots, panel and caps, read in a child process: gdstk's C++
    readers can crash on a damaged file."""
    return in_child(_read_layout, path, opts)


def _read_layout(path: Path, opts: ExportOptions) -> Pattern:
    import gdstk

    oas = format_of(path) is FORMATS["oas"]
    reader = gdstk.read_oas if oas else gdstk.read_gds
    lib, why = quietly(reader, str(path))
    if lib is None:
        raise PatternFileError(f"{path}: not a readable {path.suffix[1:].upper()} file ({why})")
    lib_unit = lib.unit  # metres per user unit
    to_mm = lib_unit * 1e3
    tops = lib.top_level()
    if len(tops) != 1:
        raise PatternFileError(f"{path}: expected one top cell, found {len(tops)}")
    top = _panel_of(path, tops[0])
    centres: list[np.ndarray] = []
    diameters: list[Drawn] = []
    budget = [max_dots_read()]
    gds = not oas
    _collect(path, top, _IDENTITY, opts, to_mm, centres, diameters, 0, budget, gds)
    caps, cap_rings = _layout_caps(path, top, opts, to_mm)
    if not centres:
        raise PatternFileError(f"{path}: no dots on layer {opts.layer}/{opts.datatype}")
    outline = [
        p
        for p in top.polygons
        if (p.layer, p.datatype) == (opts.outline_layer, opts.outline_datatype)
    ]
    rings = [p.points * to_mm for p in outline]
    seed = _seed_of([str(p.get_gds_property(1) or "") for p in outline[:1]])
    xy = np.concatenate(centres)
    if opts.process is not None:  # the print the mask makes, on the print's panel
        xy, rings, caps, diameters = _printed(opts.process, xy, rings, caps, diameters)
    xy = np.round(xy, 6)
    kinds = {d.kind for d in diameters}
    if all(k.round for k in kinds):
        d = np.concatenate([d.size[:, 0] for d in diameters])
        return _seeded(_pattern(path, xy, d, rings, True, caps=caps, cap_rings=cap_rings), seed)
    if len(kinds) > 1:
        raise PatternFileError(
            f"{path}: the dot layer holds {' and '.join(sorted(k.name for k in kinds))} dots; "
            "qa measures dots of one kind"
        )
    dots = Footprints(
        diameters[0].kind,
        np.round(np.concatenate([d.size for d in diameters]), 6),
        np.radians(degrees(np.concatenate([d.angle for d in diameters]))),
    )
    return _seeded(_pattern(path, xy, dots.diameter, rings, True, dots, caps, cap_rings), seed)


def _panel_of(path: Path, top):
    """The panel's cell of a mask: the top cell, or on a production sheet
    (:data:`SHEET_CELL`) the one cell it arrays (every panel is that cell: QA judges it
    once)."""
    if top.name != SHEET_CELL:
        return top
    panels = {r.cell.name: r.cell for r in top.references if not isinstance(r.cell, str)}
    if len(panels) != 1:
        raise PatternFileError(
            f"{path}: the sheet places {len(panels)} cells; a production sheet arrays one panel"
        )
    return next(iter(panels.values()))


def _printed(process, xy, rings, caps, drawn):
    """``(xy, rings, caps, drawn)`` of a mask read back (mm, the mask's places) as the
    print makes them: on the print's panel, unmirrored (footprints were already fitted
    as printed, at the print's scale)."""
    if not rings:
        raise PatternFileError("a mask with a process needs its panel outline to be read")
    box = printed_box(process, rings)
    xy = process.unplace(xy, box)
    out = [process.unplace(r, box) for r in rings]
    rings = [r[::-1] for r in out] if process.reflects else out
    if len(caps):
        caps = np.column_stack([np.round(process.unplace(caps[:, :2], box), 6), caps[:, 2]])
    drawn = [Drawn(d.kind, d.size, process.turn(d.angle)) for d in drawn]
    return xy, rings, caps, drawn


def _scale_of(process) -> np.ndarray | float:
    """The mask's scale (per axis when it differs)."""
    return process.scale if not process.isotropic else float(process.scale[0])


def _seed_of(lines: list[str]) -> int | None:
    """The seed a mask's provenance line names (``provenance: optdot X seed N
    sha256:...``), or None."""
    for line in lines:
        m = re.search(r"\bseed (\d+)\b", line)
        if m:
            return int(m.group(1))
    return None


def _dxf_seed(doc) -> int | None:
    """The seed a drawing's provenance (its ``seed`` custom property) names, or None."""
    value = str(doc.header.custom_vars.get("seed", "") or "").strip()
    return int(value) if value.isdigit() else None


def _seeded(pattern: Pattern, seed: int | None) -> Pattern:
    """``pattern`` with the seed its mask's provenance names in its ``meta``."""
    return pattern if seed is None else replace(pattern, meta={**pattern.meta, "seed": seed})


def _is_cap_cell(name: str) -> bool:
    """A cell written for caps (:data:`exporters.gds.CAP_CELL`, or ``CAP_<nm>``)."""
    return name == CAP_CELL or re.fullmatch(f"{CAP_CELL}_[0-9]+", name) is not None


def _layout_caps(
    path: Path, top, opts: ExportOptions, to_mm: float
) -> tuple[np.ndarray, np.ndarray | None]:
    """``(caps, rings)``: ``[m, 3]`` caps ``(x, y, diameter)`` mm, the top cell's plain
    references to cap cells, each a circle on the dots' layer centred on the cell's
    origin; or, graded, a cell ``CAP_<diameter nm>`` of rings about it, whose ``[k, 2]``
    ``(r_in, r_out)`` mm every cap must share (None for solid caps)."""
    rows, tables = [], []
    for ref in top.references:
        sub = ref.cell
        if isinstance(sub, str) or not _is_cap_cell(sub.name):
            continue
        pts = [p for p in sub.polygons if (p.layer, p.datatype) == (opts.layer, opts.datatype)]
        fit = None
        if len(pts) == 1 and opts.process is None:
            fit = CIRCLE.fit(pts[0].points, 2e-6 / to_mm, RADIUS_SPREAD)
        elif len(pts) == 1:  # the cap it prints
            at = unscaled(opts.process, pts[0].points)
            g = opts.process.dot_gain / to_mm
            slack = (2e-6 + GRID_SLACK * opts.process.grid) / to_mm
            fit = CIRCLE.fit_grown(at, g, slack, RADIUS_SPREAD)
        plain = ref.magnification == 1 and ref.repetition.size <= 1 and not ref.x_reflection
        solid = fit is not None and fit.ok and np.hypot(*fit.centre) * to_mm <= 1e-6
        named = re.fullmatch(f"{CAP_CELL}_([0-9]+)", sub.name)
        d = None if fit is None else round(float(fit.size[0]) * to_mm, 6)
        if named and not (solid and abs(d - int(named.group(1)) * 1e-6) <= 1e-6):
            d = int(named.group(1)) * 1e-6  # graded: the cell's name holds the diameter
            rings = _cell_rings(path, sub.name, pts, to_mm, 0.5 * d)
            if opts.process is not None:
                rings = np.round(printed_cap_rings(opts.process, rings), 6)
            tables.append(rings)
        elif not solid:
            d = None
        if d is None or not plain:
            raise PatternFileError(
                f"{path}: cap cell {sub.name} must hold one circle on layer "
                f"{opts.layer}/{opts.datatype} (or, named CAP_<nm>, rings), centred, placed "
                "once a reference unscaled"
            )
        x, y = (float(v) * to_mm for v in ref.origin)
        rows.append((round(x, 6), round(y, 6), d))
    caps = np.array(rows, np.float64).reshape(-1, 3)
    if not tables:
        return caps, None
    return caps, _one_table(path, tables, len(rows))


def _one_table(path: Path, tables: list[np.ndarray], n_caps: int) -> np.ndarray:
    """The ring table every graded cap of a mask prints (one a cap, each ``[k, 2]`` mm,
    equal within 2 nm), or one line saying they differ."""
    if len(tables) != n_caps or any(
        t.shape != tables[0].shape or not np.allclose(t, tables[0], atol=2e-6) for t in tables
    ):
        raise PatternFileError(f"{path}: graded caps must all print the same rings")
    return tables[0]


def _cell_rings(path: Path, name: str, pts: list, to_mm: float, reach: float) -> np.ndarray:
    """``[k, 2]`` ``(r_in, r_out)`` mm of a graded cap cell's polygons about its origin
    (a disc when the polygon holds the origin), sorted outward, within ``reach`` mm."""
    import gdstk

    rows = []
    for p in pts:
        r = np.hypot(p.points[:, 0], p.points[:, 1]) * to_mm
        holds = bool(gdstk.inside([(0.0, 0.0)], p)[0])
        r_out = float(r.max())
        r_in = 0.0 if holds else float(r.min())
        # a ring's vertices lie on its two circles (a disc's on one): a polygon reaching
        # r_in and r_out elsewhere (a triangle, a spoke) prints other ink than a ring
        slack = 2e-6 + RADIUS_SPREAD * r_out
        off = np.minimum(np.abs(r - r_out), np.abs(r - r_in) if not holds else np.inf)
        x, y = p.points[:, 0] * to_mm, p.points[:, 1] * to_mm
        area = 0.5 * abs(float(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1))))
        ring = math.pi * (r_out * r_out - r_in * r_in)
        if float(off.max()) > slack or abs(area - ring) > RING_AREA_SHARE * ring:
            raise PatternFileError(
                f"{path}: cap cell {name}: a polygon on the dots' layer is not a ring about "
                f"the cap's centre (its area {area:.4g} mm² against the ring's {ring:.4g}, "
                f"a vertex {float(off.max()) * 1e3:.3g} µm off its circles)"
            )
        r_out = reach if reach < r_out <= reach + 1e-5 else r_out  # vertices on the nm grid
        rows.append((0.0 if holds else round(r_in, 6), round(r_out, 6)))
    rings = np.array(sorted(rows), np.float64).reshape(-1, 2)
    problem = rings_problem(rings, np.array([[0.0, 0.0, 2 * reach]]))
    if problem is not None:
        raise PatternFileError(f"{path}: cap cell {name}: {problem}")
    return rings


#: A tile's cell (``T<i>_<j>``, :func:`exporters.gds.write_gds`): its dots may be polygons
#: of their own (turned shaped dots on a process's grid).
_TILE = re.compile(r"T[0-9]+_[0-9]+")
#: Deepest hierarchy read: top -> tile cells -> dot cells is 2.
MAX_DEPTH = 4
#: Most columns or rows of a GDSII array reference (COLROW holds signed 16-bit numbers).
GDS_MAX_COLROW = 32767
#: The identity placement: ``(A [2, 2], b [2])`` maps a cell's points p to A p + b.
_IDENTITY = (np.eye(2), np.zeros(2))


def _placement(ref) -> np.ndarray:
    """The linear part of a reference's transform (file units are kept): magnification
    times rotation times, with ``x_reflection``, the mirror about the x axis (applied
    first, as GDSII STRANS defines it)."""
    m = float(ref.magnification)
    c, s = math.cos(ref.rotation), math.sin(ref.rotation)
    a = m * np.array([[c, -s], [s, c]])
    if ref.x_reflection:
        a = a @ np.diag([1.0, -1.0])
    return a


def _origins(path, rep, origin: np.ndarray, budget: list[int], gds: bool) -> np.ndarray:
    """``[k, 2]`` positions of a (repeated) placement, file units, in its parent cell."""
    cols, rows = rep.columns, rep.rows
    # before the size: gdstk reads COLROW 0xFFFF as 2**64 - 1, whose square wraps to 1
    if gds and cols is not None and (cols > GDS_MAX_COLROW or rows > GDS_MAX_COLROW):
        raise PatternFileError(
            f"{path}: an array reference of {cols & 0xFFFF} x {rows & 0xFFFF} (COLROW) "
            f"exceeds GDSII's {GDS_MAX_COLROW} columns/rows (an overflowed AREF)"
        )
    if gds and cols is not None and (cols == 0 or rows == 0):
        raise PatternFileError(
            f"{path}: an array reference of {cols} x {rows} (COLROW) places no dot; "
            "an AREF has at least 1 column and 1 row"
        )
    if rep.size <= 1:
        return origin[None, :]
    budget[0] -= int(rep.size)
    if budget[0] < 0:
        raise ResourceError(
            f"{path}: references place more than {max_dots_read():,} dots, more than "
            "this machine's memory can check"
        )
    return rep.get_offsets() + origin


def _collect(
    path, cell, place, opts, to_mm, centres, diameters, depth, budget, gds, flat=False
) -> None:
    """Dots drawn by ``cell`` placed by ``place`` (``(A, b)`` in file units; see
    :data:`_IDENTITY`): its polygons on the dots' layer, and its references: a referenced
    cell with one circle on the dots' layer is a dot cell (the reference's origin is the
    dot's centre, its magnification scales the diameter; rotation and mirroring move the
    centres of nested cells); one with references of its own (a tile of a tiled export) is
    walked in turn with the composed transform."""
    a, b = place
    on_layer = (opts.layer, opts.datatype)
    scale = math.sqrt(abs(np.linalg.det(a)))
    if depth == 0 or flat:  # deeper, a dot cell's circle is read by the reference placing it
        for poly in cell.polygons:
            if (poly.layer, poly.datatype) != on_layer:
                continue
            fit, seen = _placed_fit(path, poly.points, "a polygon", to_mm, opts, a)
            at = _origins(path, poly.repetition, (seen @ fit[1].centre), budget, gds)
            centres.append((at @ a.T + b) * to_mm)
            diameters.append(Drawn.of(fit, a @ seen, len(at), scale * to_mm))
    for ref in cell.references:
        sub = ref.cell
        if isinstance(sub, str):
            raise PatternFileError(f"{path}: reference to a missing cell {sub!r}")
        if depth == 0 and _is_cap_cell(sub.name):
            continue  # a cap over an LED (:func:`_layout_caps`), not a dot
        m = float(ref.magnification)
        if not (math.isfinite(m) and m > 0 and math.isfinite(ref.rotation)):
            raise PatternFileError(
                f"{path}: a reference to {sub.name} has magnification {m!r}, "
                f"rotation {ref.rotation!r}"
            )
        origins = _origins(path, ref.repetition, np.asarray(ref.origin, float), budget, gds)
        inner = a @ _placement(ref)
        pts = [p for p in sub.polygons if (p.layer, p.datatype) == on_layer]
        tile = _TILE.fullmatch(sub.name) is not None and ref.repetition.size <= 1
        if (sub.references and not pts) or (tile and len(pts) > 1):  # a tile's dots
            if depth >= MAX_DEPTH:
                raise PatternFileError(f"{path}: cells nested deeper than {MAX_DEPTH}")
            for o in origins:
                _collect(
                    path,
                    sub,
                    (inner, a @ o + b),
                    opts,
                    to_mm,
                    centres,
                    diameters,
                    depth + 1,
                    budget,
                    gds,
                    flat=tile,
                )
            continue
        if not pts:
            continue
        if len(pts) > 1 or pts[0].repetition.size > 1:
            raise PatternFileError(
                f"{path}: cell {sub.name} holds {len(pts)} shapes on layer "
                f"{opts.layer}/{opts.datatype}; a dot cell holds one circle"
            )
        what = f"cell {sub.name}"
        fit, seen = _placed_fit(path, pts[0].points, what, to_mm, opts, inner)
        off = 1e-6 + (0.0 if opts.process is None else GRID_SLACK * opts.process.grid)
        if np.hypot(*fit[1].centre) * to_mm > off:
            raise PatternFileError(
                f"{path}: the dot of cell {sub.name} is not centred on the cell origin"
            )
        # vertices sit on the outline, snapped to the database grid: the fit recovers
        # the size to well under 1 nm
        centres.append((origins @ a.T + b) * to_mm)
        scale = math.sqrt(abs(np.linalg.det(inner)))
        diameters.append(Drawn.of(fit, inner @ seen, len(origins), scale * to_mm))


#: A mirror about the x axis.
_MIRROR = np.diag([1.0, -1.0])


def _placed_fit(path, points, what: str, to_mm: float, opts, place: np.ndarray):
    """``((kind, fit), seen)``: the footprint a dot polygon (``points`` in its cell's
    units) draws where ``place`` (``[2, 2]``) puts it, fitted as drawn in the cell and
    ``seen`` (``[2, 2]``) the map from the fit's frame to the cell's: the identity, or a
    mirror where ``place`` mirrors a polygon of the job's made kind (a polygon symmetric
    about no axis is another polygon in a mirror: it is fitted as the mirror shows it).

    Raises:
        PatternFileError: the polygon is none of the kinds, or the mirror image of the
            job's polygon."""
    kind = opts.kind
    if np.linalg.det(place) >= 0 or kind is None or not kind.derived:
        return _footprint(path, points, what, to_mm, opts.process, kind), np.eye(2)
    try:
        fit = _footprint(path, points @ _MIRROR, what, to_mm, opts.process, kind)
    except PatternFileError:
        raise PatternFileError(
            f"{path}: {what} is placed mirrored: it draws the mirror image of the job's "
            f"{kind.name}, not its dots"
        ) from None
    return fit, _MIRROR


@dataclass(frozen=True)
class Drawn:
    """Dots read from one placement: their ``kind``, ``size [k, p]`` (mm) and ``angle
    [k]`` (rad)."""

    kind: Kind
    size: np.ndarray
    angle: np.ndarray

    @classmethod
    def of(cls, fit: tuple[Kind, Fit], place: np.ndarray, k: int, to_mm: float) -> Drawn:
        """``k`` dots of the footprint ``fit`` (file units) placed by the linear map
        ``place`` (``[2, 2]``; its scale already in ``to_mm``, mm per file unit)."""
        kind, f = fit
        size = np.round(f.size * to_mm, 6)
        # the footprint's axis as the placement maps it (a mirror turns it the other way)
        ax = place @ np.array([math.cos(f.angle), math.sin(f.angle)])
        turn = math.atan2(ax[1], ax[0])
        return cls(kind, np.tile(size, (k, 1)), np.full(k, turn))


def _kinds(job_kind: Kind | None) -> list[Kind]:
    """The kinds a dot polygon is tried as: the registry's in order, where a kind made
    per job (:attr:`~optdot.geometry.kinds.base.Kind.derived`, a polygon) recognises
    nothing; the job's own such kind first (a square polygon is the job's, not a
    rectangle; a regular 12-gon the job's, not a circle)."""
    kinds = [k for k in KINDS.values() if not k.derived]
    if job_kind is not None and job_kind.derived:
        kinds.insert(0, job_kind)
    return kinds


def _footprint(path: Path, pts: np.ndarray, what: str, to_mm: float, process=None, job_kind=None):
    """``(kind, fit)`` of a dot polygon (its centre, size and angle in the file's units):
    a circle (:meth:`optdot.geometry.kinds.circle.Circle.fit`: vertex radii within 2 nm
    plus :data:`RADIUS_SPREAD` of the radius), else another kind of the registry to the
    same tolerance (a polygon: the job's, ``job_kind``), or refuse it. With a
    ``process``, the footprint the polygon prints: fitted at the print's scale as the
    dot it grows to (its centre kept on the mask)."""
    slack = (2e-6 + (0.0 if process is None else GRID_SLACK * process.grid)) / to_mm
    kinds = _kinds(job_kind)
    if process is None:
        fits = ((k, k.fit(pts, slack, RADIUS_SPREAD)) for k in kinds)
    else:
        at = unscaled(process, pts)
        g = process.dot_gain / to_mm
        fits = ((k, k.fit_grown(at, g, slack, RADIUS_SPREAD)) for k in kinds)
    fit = None
    for kind, other in fits:  # the circle first: a disc of any kind reads as one (but
        # the job's polygon before it)
        fit = fit or other
        if other.ok:
            if process is not None:
                other = replace(other, centre=other.centre * _scale_of(process))
            return kind, other
    at = np.round(fit.centre * to_mm, 9) + 0.0  # no -0 or 1e-20 noise in the message
    lo, hi = (v * to_mm * 1e3 for v in fit.radii)
    hint = (
        " (a mask drawn for a [process] on a coarser grid, or of polygon dots, reads with its job)"
        if process is None or job_kind is None
        else ""
    )
    tried = kinds_text(kinds) + ("" if job_kind in kinds else ", nor a job's polygon")
    raise PatternFileError(
        f"{path}: {what} at ({at[0]:.6g}, {at[1]:.6g}) mm on the dot layer is not "
        f"{tried} ({len(pts)} vertices, radii {lo:.4g}..{hi:.4g} "
        f"µm); qa checks those dots only{hint}"
    )


def read_dxf(path: Path, opts: ExportOptions | None = None) -> Pattern:
    """Dots are the CIRCLEs on layer ``DOTS``, the panel the closed polylines on
    ``OUTLINE``, everything in the drawing's units converted to mm and block references
    expanded (:mod:`optdot.geometry.dxf_entities`). A circle is placed by its centre in
    world coordinates (an extrusion of -Z mirrors x); anything else on ``DOTS`` (an
    ellipse from a stretched block, a polyline, a circle seen at a slant) is refused,
    as qa's distances would be wrong for it."""
    import ezdxf

    from optdot.geometry.dxf_entities import drawn_entities, mm_per_unit

    opts = opts or ExportOptions()
    doc = ezdxf.readfile(str(path))
    try:
        scale = mm_per_unit(doc, path)
        xy_l, r_l, rings, shaped, caps, graded = [], [], [], [], [], []
        for e in drawn_entities(_dxf_panel(doc), path):
            # DXF layer names are case-insensitive: "dots" is the layer DOTS
            layer, kind = str(e.dxf.get("layer", "0")).upper(), e.dxftype()
            if layer == "DOTS" and kind in ("POINT", "HATCH") and e.has_xdata(CAP_APPID):
                _dxf_graded(path, e, kind, scale, caps, graded)
            elif layer == "DOTS" and kind == "CIRCLE" and e.has_xdata(CAP_APPID):
                x, y = (v * scale for v in _dxf_dot(path, e, kind))
                caps.append((round(x, 6), round(y, 6), round(2 * float(e.dxf.radius) * scale, 6)))
            elif layer == "DOTS" and kind != "CIRCLE":
                shaped.append(_dxf_shape(path, e, kind, scale, opts.process, opts.kind))
            elif layer == "DOTS":
                xy_l.append(_dxf_dot(path, e, kind))
                r_l.append(float(e.dxf.radius))
            elif layer == "OUTLINE" and kind in ("LWPOLYLINE", "POLYLINE"):
                pts = (
                    [p[:2] for p in e.get_points()]
                    if kind == "LWPOLYLINE"
                    else [tuple(v.dxf.location)[:2] for v in e.vertices]
                )
                ocs = e.ocs()
                if ocs.transform:
                    z = float(e.dxf.elevation) if kind == "LWPOLYLINE" else 0.0
                    pts = [ocs.to_wcs((x, y, z))[:2] for x, y in pts]
                rings.append(np.array(pts, dtype=np.float64) * scale)
    except GeometryError as err:
        raise PatternFileError(str(err)) from None
    for _, f in [s for s in shaped if s[0].round]:  # round outlines: discs
        xy_l.append(tuple(f.centre / scale))  # back to drawing units, as the others
        r_l.append(0.5 * float(f.size[0]) / scale)
    shaped = [s for s in shaped if not s[0].round]
    if shaped:
        kinds = {k for k, _ in shaped}
        if xy_l or len(kinds) > 1:
            what = sorted({k.name for k in kinds} | ({"circle"} if xy_l else set()))
            raise PatternFileError(
                f"{path}: layer DOTS holds {' and '.join(what)} dots; qa measures one kind"
            )
        fits = [f for _, f in shaped]
        drawn = Drawn(
            shaped[0][0],
            np.round(np.array([f.size for f in fits]), 6),
            np.array([f.angle for f in fits]),
        )
        xy = np.array([f.centre for f in fits])
        caps, cap_rings = _rows(caps), _dxf_rings(path, _rows(caps), graded)
        if opts.process is not None:
            xy, rings, caps, cap_rings, drawn = _dxf_printed(
                path, opts.process, xy, rings, caps, cap_rings, [drawn]
            )
            drawn = drawn[0]
        dots = Footprints(drawn.kind, drawn.size, np.radians(degrees(drawn.angle)))
        made = _pattern(path, np.round(xy, 6), dots.diameter, rings, False, dots, caps, cap_rings)
        return _seeded(made, _dxf_seed(doc))
    if not xy_l:
        raise PatternFileError(f"{path}: no CIRCLE entities on layer DOTS")
    xy = np.array(xy_l, dtype=np.float64) * scale
    radii = np.array(r_l, dtype=np.float64) * scale
    bad = ~(np.isfinite(radii) & (radii > 0))
    if bad.any():
        i = int(np.argmax(bad))
        raise PatternFileError(
            f"{path}: CIRCLE {i + 1} on layer DOTS has radius {float(radii[i])!r}; "
            "dots need a radius > 0"
        )
    caps, cap_rings = _rows(caps), _dxf_rings(path, _rows(caps), graded)
    if opts.process is not None:
        drawn = [Drawn(CIRCLE, (2 * radii)[:, None], np.zeros(len(radii)))]
        xy, rings, caps, cap_rings, drawn = _dxf_printed(
            path, opts.process, xy, rings, caps, cap_rings, drawn, grow=True
        )
        radii = 0.5 * drawn[0].size[:, 0]
    made = _pattern(path, np.round(xy, 6), 2 * radii, rings, caps=caps, cap_rings=cap_rings)
    return _seeded(made, _dxf_seed(doc))


def _dxf_panel(doc):
    """The layout holding a drawing's panel: the modelspace, or on a production sheet
    the block :data:`PANEL_BLOCK` it inserts (every panel is that block: QA judges it
    once)."""
    msp = doc.modelspace()
    if PANEL_BLOCK in doc.blocks and any(
        e.dxftype() == "INSERT" and e.dxf.name == PANEL_BLOCK for e in msp
    ):
        return doc.blocks.get(PANEL_BLOCK)
    return msp


def _dxf_printed(path, process, xy, rings, caps, cap_rings, drawn, grow=False):
    """A drawing's dots, panel and caps (mm, on the mask) as they print (see
    :func:`_printed`); circles read as drawn are grown here (``grow``), shaped dots were
    fitted as printed; caps and their rings are grown too."""
    if grow:
        g, k = process.dot_gain, float(process.scale[0])
        drawn = [Drawn(d.kind, np.round(d.size / k + 2.0 * g, 6), d.angle) for d in drawn]
    if len(caps):
        caps = caps.copy()
        caps[:, 2] = np.round(caps[:, 2] / float(process.scale[0]) + 2.0 * process.dot_gain, 6)
    if cap_rings is not None:
        cap_rings = np.round(printed_cap_rings(process, cap_rings), 6)
    try:
        xy, rings, caps, drawn = _printed(process, xy, rings, caps, drawn)
    except PatternFileError as e:
        raise PatternFileError(f"{path}: {e}") from None
    return xy, rings, caps, cap_rings, drawn


def _dxf_graded(path: Path, e, kind: str, scale: float, caps: list, graded: list) -> None:
    """A graded cap's POINT (into ``caps``: ``(x, y, diameter)`` mm; None into
    ``graded``) or one of its ring HATCHes (into ``graded``: ``(x, y, r_in, r_out)``
    mm), from their XDATA."""
    if kind == "POINT":
        tags = [v for code, v in e.get_xdata(CAP_APPID) if code == 1040]
        x, y = (float(v) * scale for v in tuple(e.dxf.location)[:2])
        if len(tags) != 1:
            raise PatternFileError(f"{path}: a cap's POINT needs its diameter (XDATA 1040)")
        caps.append((round(x, 6), round(y, 6), round(float(tags[0]), 6)))
        graded.append(None)  # a graded cap, whether or not it prints a ring
        return
    arcs = []
    for p in e.paths:
        edges = getattr(p, "edges", [])
        if len(edges) != 1 or edges[0].type.name != "ARC":
            raise PatternFileError(f"{path}: a cap's ring HATCH must be bounded by circles")
        arcs.append(edges[0])
    if len(arcs) not in (1, 2):
        raise PatternFileError(f"{path}: a cap's ring HATCH must have one or two circles")
    c = np.array([(a.center.x, a.center.y) for a in arcs], np.float64) * scale
    r = sorted(float(a.radius) * scale for a in arcs)
    if np.ptp(c, axis=0).max() > 1e-6:
        raise PatternFileError(f"{path}: a cap's ring HATCH must have concentric circles")
    r_in = r[0] if len(r) == 2 else 0.0
    graded.append((float(c[0, 0]), float(c[0, 1]), round(r_in, 6), round(r[-1], 6)))


def _dxf_rings(path: Path, caps: np.ndarray, graded: list) -> np.ndarray | None:
    """The graded caps' one ring table ``[k, 2]`` mm from their HATCHes, each about a
    cap's centre (None without graded caps)."""
    if not graded:
        return None
    tables: dict[int, list] = {}
    found = [g for g in graded if g is not None]
    if not found:
        return np.zeros((0, 2))
    for x, y, r_in, r_out in found:
        d = np.hypot(caps[:, 0] - x, caps[:, 1] - y) if len(caps) else np.array([np.inf])
        k = int(np.argmin(d))
        if d[k] > 1e-6:
            raise PatternFileError(f"{path}: a cap's ring HATCH at ({x:g}, {y:g}) has no cap")
        tables.setdefault(k, []).append((r_in, r_out))
    one = [np.array(sorted(rows), np.float64) for rows in tables.values()]
    first = _one_table(path, one, len(caps))
    problem = rings_problem(first, caps)
    if problem is not None:
        raise PatternFileError(f"{path}: {problem}")
    return first


def _rows(caps: list) -> np.ndarray:
    return np.array(caps, np.float64).reshape(-1, 3)


#: How finely a DXF dot's arcs are flattened before its footprint is fitted, mm.
DXF_FLATTEN_MM = 1e-5


def _dxf_shape(
    path: Path, e, kind: str, scale: float, process=None, job_kind: Kind | None = None
) -> tuple[Kind, Fit]:
    """``(kind, fit)`` (mm) of a shaped dot drawn in world coordinates: an ELLIPSE read
    from its axes, a closed polyline fitted (:func:`_footprint`) from its outline
    flattened to :data:`DXF_FLATTEN_MM`; anything else on ``DOTS`` is refused."""
    where = f"{kind} {e.dxf.handle or '(in a block)'}"
    ext = e.dxf.get("extrusion", (0.0, 0.0, 1.0))
    if abs(float(ext[0])) > 1e-9 or abs(float(ext[1])) > 1e-9:
        raise PatternFileError(f"{path}: {where} on layer DOTS is tilted (extrusion {tuple(ext)})")
    if kind == "ELLIPSE":
        full = abs(float(e.dxf.end_param) - float(e.dxf.start_param) - 2 * math.pi) < 1e-9
        major, ratio = e.dxf.major_axis, float(e.dxf.ratio)
        if not full or not (0 < ratio <= 1):
            raise PatternFileError(f"{path}: {where} on layer DOTS is not a whole ellipse")
        a = math.hypot(float(major[0]), float(major[1])) * scale
        c = e.dxf.center  # an ELLIPSE's centre and major axis are in world coordinates
        turn = math.atan2(float(major[1]), float(major[0]))
        centre = np.array([float(c[0]), float(c[1])]) * scale
        size = np.array([2 * a, 2 * a * ratio])
        return drawn_as("ellipse"), Fit(True, centre, size, turn, (a, a))
    if kind in ("LWPOLYLINE", "POLYLINE") and e.is_closed:
        from ezdxf import path as dxf_path

        pts = np.array([(v.x, v.y) for v in dxf_path.make_path(e).flattening(1e-5 / scale)])
        if len(pts) > 1 and np.allclose(pts[0], pts[-1]):
            pts = pts[:-1]
        kind_, fit = _footprint(path, pts * scale, where, 1.0, process, job_kind)
        if kind_.arc_param is not None and kind == "LWPOLYLINE":
            fit = _bulge_radius(e, kind_, fit, scale, process)
        return kind_, fit  # a round outline (a disc-shaped block) is read as a disc
    raise PatternFileError(
        f"{path}: {where} on layer DOTS is not a CIRCLE, an ELLIPSE or a closed outline of "
        f"{kinds_text()}; qa checks those dots only"
    )


def _bulge_radius(e, kind: Kind, fit: Fit, scale: float, process=None) -> Fit:
    """``fit`` with the size parameter its LWPOLYLINE's arcs hold exactly (the kind's
    :attr:`~optdot.geometry.kinds.base.Kind.arc_param`, a corner radius: a bulge ``b``
    over a chord ``c`` is an arc of radius ``c (1 + b²) / (4 |b|)``), when they agree."""
    pts = np.array(e.get_points("xyb"), dtype=np.float64)
    nxt = np.roll(pts[:, :2], -1, axis=0)
    b = pts[:, 2]
    arc = np.abs(b) > 1e-12
    if not arc.any():
        return fit
    chord = np.hypot(*(nxt - pts[:, :2])[arc].T)
    r = chord * (1 + b[arc] ** 2) / (4 * np.abs(b[arc])) * scale
    if process is not None:  # the arcs the print's corners grow from
        r = r / float(process.scale[0]) + process.dot_gain
    if float(np.ptp(r)) > 1e-9 or r[0] > 0.5 * fit.size[1] + 1e-9:
        return fit
    size = np.array(fit.size, dtype=np.float64)
    size[kind.arc_param] = float(r.mean())
    return Fit(fit.ok, fit.centre, size, fit.angle, fit.radii)


def _dxf_dot(path: Path, e, kind: str) -> tuple[float, float]:
    """World x-y of a dot CIRCLE, or refuse what is not a round dot seen from above."""
    where = f"{kind} {e.dxf.handle or '(in a block)'}"
    if kind != "CIRCLE":
        raise PatternFileError(
            f"{path}: {where} on layer DOTS is not a CIRCLE; qa checks round dots only"
        )
    ext = e.dxf.get("extrusion", (0.0, 0.0, 1.0))
    if abs(float(ext[0])) > 1e-9 or abs(float(ext[1])) > 1e-9:
        raise PatternFileError(
            f"{path}: {where} on layer DOTS is tilted (extrusion {tuple(ext)}); "
            "seen from above it is an ellipse"
        )
    c = e.dxf.center
    if float(ext[2]) < 0:  # seen from below: the object x axis points the other way
        c = e.ocs().to_wcs(c)
    return float(c[0]), float(c[1])


def _pattern(
    path: Path,
    xy: np.ndarray,
    diameter: np.ndarray,
    rings: list[np.ndarray],
    filled: bool = False,
    dots: Footprints | None = None,
    caps: np.ndarray | None = None,
    cap_rings: np.ndarray | None = None,
) -> Pattern:
    """A pattern whose panel is the outline read back, else the dots' extent; ``caps``
    ``[m, 3]`` read back go with the outline (a mask with caps has one), with their
    ``cap_rings`` when graded.

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
        if caps is not None and len(caps):
            panel = outline or Domain.rect(float(lo[0]), float(lo[1]), float(hi[0]), float(hi[1]))
            outline = replace(panel, caps=caps, cap_rings=cap_rings)
    elif caps is not None and len(caps):
        raise PatternFileError(f"{path}: caps over LEDs but no panel outline to hold them")
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
        dots=dots,
    )
