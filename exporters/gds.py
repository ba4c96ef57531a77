"""GDSII and OASIS masks with gdstk.

Units: user unit 1 µm, database unit 1 nm. A dot is a cell (a circle polygon whose
vertex count follows the tolerance; one cell per diameter, ``DOT`` when all dots have the
same size, ``DOT_<diameter in nm>`` otherwise) placed by one reference per dot, so 10⁶ dots stay
~26 MB in GDSII; OASIS stores the same references as one explicit repetition (~8 MB).
``flatten`` writes plain polygons instead. The panel (outline minus holes and keep-outs)
goes on its own layer as filled polygons, holes cut open by zero-width keyholes.
"""

from __future__ import annotations

import contextlib
import datetime
import math
import os
import tempfile
from pathlib import Path

import gdstk
import numpy as np

from optdot.errors import ExportError
from optdot.geometry.morton import spatial_order
from optdot.io.atomic import atomic_path, expect_tail
from optdot.pattern import Pattern

from .options import ExportOptions

#: Fixed GDSII timestamp: identical input gives identical bytes.
TIMESTAMP = datetime.datetime(2000, 1, 1, 0, 0, 0)
#: Largest coordinate a 32-bit GDSII integer holds at 1 nm, mm.
MAX_EXTENT_MM = (2**31 - 1) * 1e-6
#: Fewest vertices of a dot polygon (what ``optdot qa`` reads back as a circle).
MIN_DOT_VERTICES = 8
#: Most vertices one GDSII boundary can hold.
MAX_POINTS = 8190


def circle_vertices(radius_um: float, tolerance_um: float) -> int:
    """Vertices of a polygon within ``tolerance_um`` of a circle of ``radius_um`` (µm)."""
    t = min(tolerance_um, radius_um)
    return max(8, math.ceil(math.pi / math.acos(1.0 - t / radius_um)))


def build_library(pattern: Pattern, opts: ExportOptions, oasis: bool = False) -> gdstk.Library:
    """The gdstk library of a pattern (µm user unit, nm database unit)."""
    lo = min(pattern.box[0], pattern.box[1])
    hi = max(pattern.box[2], pattern.box[3])
    if max(abs(lo), abs(hi)) > MAX_EXTENT_MM:
        raise ExportError(
            f"pattern extent {max(abs(lo), abs(hi)):.1f} mm exceeds the GDSII/OASIS 32-bit "
            f"limit of {MAX_EXTENT_MM:.1f} mm at 1 nm"
        )
    lib = gdstk.Library("OPTDOT", unit=1e-6, precision=1e-9)
    groups = _size_groups(pattern, opts)
    top = gdstk.Cell(opts.top_cell)
    # the panel as filled polygon(s); GDSII has no holes, so gdstk cuts each hole open
    # with a zero-width keyhole, which KLayout and mask tools read as a hole
    rings = pattern.outline_rings()
    shells = [gdstk.Polygon(r * 1e3) for r in rings if _ccw(r)]
    holes = [gdstk.Polygon(r * 1e3) for r in rings if not _ccw(r)]
    lay = {"layer": opts.outline_layer, "datatype": opts.outline_datatype}
    if holes:
        top.add(*gdstk.boolean(shells, holes, "not", precision=1e-3, **lay))
    else:
        top.add(*(gdstk.Polygon(p.points, **lay) for p in shells))
    for dot, sel in groups:
        xy = pattern.xy[sel] * 1e3
        if oasis and len(xy) > 1:
            xy = xy[spatial_order(xy)]  # small deltas: compact OASIS repetition
        ref = gdstk.Reference(dot, origin=(float(xy[0, 0]), float(xy[0, 1])))
        if len(xy) > 1:
            # the origin itself is always an instance: offsets exclude it
            ref.repetition = gdstk.Repetition(offsets=xy[1:] - xy[0])
        top.add(ref)
    if opts.flatten:
        top.flatten()
        lib.add(top)
    else:
        lib.add(*(dot for dot, _ in groups), top)
    return lib


def _size_groups(pattern: Pattern, opts: ExportOptions) -> list[tuple[gdstk.Cell, np.ndarray]]:
    """One dot cell per diameter (rounded to the 1 nm database unit) and the ``[n]`` bool
    mask of its dots, smallest diameter first."""
    if pattern.n == 0:
        raise ExportError("the pattern has no dots")
    d_nm = np.round(pattern.diameter * 1e6).astype(np.int64)
    sizes = np.unique(d_nm)
    groups = []
    for size in sizes:
        r_um = 0.5 * float(size) * 1e-3 if len(sizes) > 1 else float(pattern.radius[0]) * 1e3
        nv = circle_vertices(r_um, opts.tolerance_um)
        if nv > MAX_POINTS:
            raise ExportError(
                f"--tolerance {opts.tolerance_um} µm needs {nv} vertices per dot (max {MAX_POINTS})"
            )
        name = opts.dot_cell if len(sizes) == 1 else f"{opts.dot_cell}_{size}"
        dot = gdstk.Cell(name)
        circle = gdstk.ellipse(
            (0, 0), r_um, tolerance=opts.tolerance_um, layer=opts.layer, datatype=opts.datatype
        )
        if len(circle.points) < MIN_DOT_VERTICES:
            most = r_um * (1 - math.cos(math.pi / MIN_DOT_VERTICES))
            raise ExportError(
                f"--tolerance {opts.tolerance_um} µm draws {2 * r_um:.4g} µm dots as "
                f"{len(circle.points)}-gons; at most {most:.3g} µm keeps them round"
            )
        dot.add(circle)
        groups.append((dot, d_nm == size if len(sizes) > 1 else np.ones(pattern.n, bool)))
    return groups


def _ccw(ring: np.ndarray) -> bool:
    x, y = ring[:, 0], ring[:, 1]
    return float(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1))) > 0


def write_gds(pattern: Pattern, path: str | Path, opts: ExportOptions) -> None:
    """Write a GDSII file atomically, verified before it replaces anything."""
    lib = build_library(pattern, opts)
    with atomic_path(path, _verify_gds(path, lib, opts)) as tmp:
        lib.write_gds(tmp, max_points=MAX_POINTS, timestamp=TIMESTAMP)


def write_oas(pattern: Pattern, path: str | Path, opts: ExportOptions) -> None:
    """Write an OASIS file atomically (cells compressed; circles detected as CIRCLE
    records) with a CRC32 in its END record, checked before it replaces anything."""
    lib = build_library(pattern, opts, oasis=True)
    with atomic_path(path, _verify_oas(path)) as tmp:
        lib.write_oas(
            tmp, compression_level=6, circle_tolerance=opts.tolerance_um, validation="crc32"
        )


#: The GDSII ENDLIB record: length 4, type 0x04, no data.
ENDLIB = b"\x00\x04\x04\x00"


def _verify_gds(path, lib: gdstk.Library, opts: ExportOptions):
    """Check a written GDSII file: it ends with ENDLIB, gdstk reads its whole record
    stream, and it holds the references and polygons the library had.

    gdstk's writer ignores write errors (a full disk gave a truncated file and no error),
    so this is what stands between a full disk and a mask that looks finished."""
    # GDSII has no repetitions: each repeated instance is written as its own record
    refs = sum(max(r.repetition.size, 1) for c in lib.cells for r in c.references)
    polys = sum(max(q.repetition.size, 1) for c in lib.cells for q in c.polygons)
    tail = expect_tail(ENDLIB, str(path))

    def check(tmp: Path) -> None:
        tail(tmp)
        info, err = quietly(gdstk.gds_info, str(tmp))
        if info is None:
            raise ExportError(f"{path}: the written file does not read back ({err})")
        if info["num_references"] != refs or info["num_polygons"] != polys:
            raise ExportError(
                f"{path}: the written file holds {info['num_references']} references and "
                f"{info['num_polygons']} polygons, not {refs} and {polys}"
            )

    return check


def _verify_oas(path):
    """Check a written OASIS file against the CRC32 of its END record (every byte)."""

    def check(tmp: Path) -> None:
        res, err = quietly(gdstk.oas_validate, str(tmp))
        if res is None or res[0] is not True:
            raise ExportError(f"{path}: the written file fails its CRC32 check {err}".rstrip())

    return check


def quietly(fn, *args):
    """Call a gdstk function with the C library's stderr captured: ``(result, text)``;
    ``result`` is None when it raised ``OSError`` (what gdstk raises on bad files).

    gdstk prints ``[GDSTK] ...`` lines to the process's stderr; a command-line tool
    should print one line of its own instead."""
    with tempfile.TemporaryFile() as buf:
        saved = os.dup(2)
        try:
            os.dup2(buf.fileno(), 2)
            try:
                result = fn(*args)
            except OSError:
                result = None
        finally:
            os.dup2(saved, 2)
            os.close(saved)
        buf.seek(0)
        text = buf.read().decode("utf-8", "replace").strip()
    with contextlib.suppress(Exception):
        text = text.splitlines()[0].removeprefix("[GDSTK] ")
    return result, text
