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
from optdot.io.dataset import Dataset
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


def _check_extent(box, xy: np.ndarray | None = None, diameter=None) -> None:
    """Refuse coordinates a 32-bit GDSII integer cannot hold at 1 nm (they would wrap:
    3000 mm reads back as -1294.97 mm): the panel box and, when given, the dots
    themselves (``xy`` ``[n, 2]`` mm, ``diameter`` mm), whatever box they claim."""
    far = max(abs(float(v)) for v in box)
    if xy is not None and len(xy):
        r = 0.5 * float(np.max(diameter))
        far = max(far, float(np.max(np.abs(xy))) + r)
    if not far <= MAX_EXTENT_MM:
        raise ExportError(
            f"pattern extent {far:.1f} mm exceeds the GDSII/OASIS 32-bit "
            f"limit of {MAX_EXTENT_MM:.1f} mm at 1 nm"
        )


def _outline_polygons(
    rings: list[np.ndarray], opts: ExportOptions, oasis: bool = False
) -> list[gdstk.Polygon]:
    """The panel as filled polygon(s); GDSII has no holes, so gdstk cuts each hole open
    with a zero-width keyhole, which KLayout and mask tools read as a hole."""
    shells = [gdstk.Polygon(r * 1e3) for r in rings if _ccw(r)]
    holes = [gdstk.Polygon(r * 1e3) for r in rings if not _ccw(r)]
    lay = {"layer": opts.outline_layer, "datatype": opts.outline_datatype}
    if holes:
        polys = gdstk.boolean(shells, holes, "not", precision=1e-3, **lay)
    else:
        polys = [gdstk.Polygon(p.points, **lay) for p in shells]
    # what made this mask: GDSII holds at most 128 bytes of properties per element, so
    # only the first line (version, seed and the digest of the full record); OASIS all
    lines = opts.provenance if oasis else opts.provenance[:1]
    for i, line in enumerate(lines):
        polys[0].set_gds_property(i + 1, line)
    return polys


def _placed(dot: gdstk.Cell | str, xy_um: np.ndarray) -> gdstk.Reference:
    """One reference placing ``dot`` at every ``[k, 2]`` position (µm): the first as the
    origin, the rest as an explicit repetition (offsets exclude the origin)."""
    ref = gdstk.Reference(dot, origin=(float(xy_um[0, 0]), float(xy_um[0, 1])))
    if len(xy_um) > 1:
        ref.repetition = gdstk.Repetition(offsets=xy_um[1:] - xy_um[0])
    return ref


def build_library(pattern: Pattern, opts: ExportOptions, oasis: bool = False) -> gdstk.Library:
    """The gdstk library of a pattern (µm user unit, nm database unit)."""
    _check_extent(pattern.box, pattern.xy, pattern.diameter)
    lib = gdstk.Library("OPTDOT", unit=1e-6, precision=1e-9)
    groups = _size_groups(pattern, opts)
    top = gdstk.Cell(opts.top_cell)
    top.add(*_outline_polygons(pattern.outline_rings(), opts, oasis))
    for dot, sel in groups:
        xy = pattern.xy[sel] * 1e3
        if oasis and len(xy) > 1:
            xy = xy[spatial_order(xy)]  # small deltas: compact OASIS repetition
        top.add(_placed(dot, xy))
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
    names = {opts.top_cell: "the top cell"}
    for size in sizes:
        r_um = 0.5 * float(size) * 1e-3 if len(sizes) > 1 else float(pattern.radius[0]) * 1e3
        name = opts.dot_cell if len(sizes) == 1 else f"{opts.dot_cell}_{size}"
        dot = dot_cell(_unique(name, f"the {size} nm dot", names), r_um, opts)
        groups.append((dot, d_nm == size if len(sizes) > 1 else np.ones(pattern.n, bool)))
    return groups


def dot_cell(name: str, r_um: float, opts: ExportOptions) -> gdstk.Cell:
    """The cell of one dot: a circle polygon of radius ``r_um`` centred on the origin.

    Raises:
        ExportError: the tolerance needs too many vertices, or too few to read as round.
    """
    nv = circle_vertices(r_um, opts.tolerance_um)
    if nv > MAX_POINTS:
        raise ExportError(
            f"--tolerance {opts.tolerance_um} µm needs {nv} vertices per dot (max {MAX_POINTS})"
        )
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
    return dot


def _ccw(ring: np.ndarray) -> bool:
    x, y = ring[:, 0], ring[:, 1]
    return float(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1))) > 0


def _tile_cells(ds: Dataset, opts: ExportOptions, sizes: dict[int, str]):
    """``(tile cell, dots in it)`` per part of a dataset, one at a time: each tile a cell
    ``T<i>_<j>`` placing the dot cells by name (one reference per size, explicit
    repetition). ``sizes`` collects ``{diameter nm: dot cell name}`` as they appear."""
    uniform = ds.uniform_diameter
    names = {opts.top_cell: "the top cell"}
    for (i, j), xy, d in ds.chunks():
        _check_extent(ds.box, xy, d)
        cell = gdstk.Cell(_unique(f"T{i}_{j}", f"tile ({i}, {j})", names))
        d_nm = np.round(d * 1e6).astype(np.int64)
        for size in np.unique(d_nm):
            name = opts.dot_cell if uniform is not None else f"{opts.dot_cell}_{size}"
            if int(size) not in sizes:
                sizes[int(size)] = _unique(name, f"the {size} nm dot", names)
            sel = xy[d_nm == size] * 1e3
            cell.add(_placed(name, sel[spatial_order(sel)]))
        yield cell, len(xy)


def _unique(name: str, what: str, names: dict[str, str]) -> str:
    """``name``, recorded in ``names`` (cell name -> what it holds), or refuse a second
    cell of that name: a library with two structures of one name is a broken mask."""
    if name in names:
        raise ExportError(
            f"cell name {name!r} is used by {names[name]} and {what}; choose another "
            "--top-cell or dot cell name"
        )
    names[name] = what
    return name


def _dot_cells(ds: Dataset, sizes: dict[int, str], opts: ExportOptions) -> list[gdstk.Cell]:
    uniform = ds.uniform_diameter
    return [
        dot_cell(name, (0.5 * uniform if uniform is not None else 0.5e-6 * size) * 1e3, opts)
        for size, name in sorted(sizes.items())
    ]


def _tiled_top(
    ds: Dataset, tiles: list[str], opts: ExportOptions, oasis: bool = False
) -> gdstk.Cell:
    top = gdstk.Cell(opts.top_cell)
    top.add(*_outline_polygons(ds.outline_rings(), opts, oasis))
    for name in tiles:
        top.add(gdstk.Reference(name))
    return top


def write_gds_tiles(ds: Dataset, path: str | Path, opts: ExportOptions) -> None:
    """Stream a dataset into a hierarchical GDSII file with ``gdstk.GdsWriter``: one cell
    per tile referencing the dot cell, a top cell placing the tiles and the outline.
    Memory: one tile."""
    _check_extent(ds.box)
    if ds.n == 0:
        raise ExportError("the pattern has no dots")
    sizes: dict[int, str] = {}
    tiles: list[str] = []
    counts = {"refs": 0, "polys": 0}

    def check(tmp: Path) -> None:
        _check_counts(path, tmp, counts["refs"], counts["polys"])

    with atomic_path(path, check) as tmp:
        writer = gdstk.GdsWriter(
            str(tmp),
            name="OPTDOT",
            unit=1e-6,
            precision=1e-9,
            max_points=MAX_POINTS,
            timestamp=TIMESTAMP,
        )
        try:
            for cell, n in _tile_cells(ds, opts, sizes):
                writer.write(cell)
                tiles.append(cell.name)
                counts["refs"] += n
            dots = _dot_cells(ds, sizes, opts)
            top = _tiled_top(ds, tiles, opts)
            writer.write(*dots, top)
        finally:
            writer.close()
        counts["refs"] += len(tiles)
        counts["polys"] = len(dots) + len(top.polygons)


def write_oas_tiles(ds: Dataset, path: str | Path, opts: ExportOptions) -> None:
    """A dataset as a hierarchical OASIS file (tile cells as in :func:`write_gds_tiles`).

    gdstk has no streaming OASIS writer: the library is built whole, each tile one
    reference with an explicit repetition (16 B per dot: 1.9 GB at 1.2·10⁸ dots), and
    written with a CRC32. Offsets are relative to the tile's first dot in Morton order, so
    the deltas gdstk rounds to the 1 nm grid are each exact (no drift across a tile)."""
    _check_extent(ds.box)
    if ds.n == 0:
        raise ExportError("the pattern has no dots")
    sizes: dict[int, str] = {}
    lib = gdstk.Library("OPTDOT", unit=1e-6, precision=1e-9)
    tiles = []
    for cell, _ in _tile_cells(ds, opts, sizes):
        lib.add(cell)
        tiles.append(cell.name)
    lib.add(*_dot_cells(ds, sizes, opts), _tiled_top(ds, tiles, opts, oasis=True))
    _write_oas_lib(lib, path, opts)


def _check_counts(path, tmp: Path, refs: int, polys: int) -> None:
    """The written GDSII ends with ENDLIB, reads back whole, and holds ``refs``
    references and ``polys`` polygons."""
    expect_tail(ENDLIB, str(path))(tmp)
    info, err = quietly(gdstk.gds_info, str(tmp))
    if info is None:
        raise ExportError(f"{path}: the written file does not read back ({err})")
    if info["num_references"] != refs or info["num_polygons"] != polys:
        raise ExportError(
            f"{path}: the written file holds {info['num_references']} references and "
            f"{info['num_polygons']} polygons, not {refs} and {polys}"
        )


def write_gds(pattern: Pattern, path: str | Path, opts: ExportOptions) -> None:
    """Write a GDSII file atomically, verified before it replaces anything."""
    if isinstance(pattern, Dataset):
        write_gds_tiles(pattern, path, opts)
        return
    lib = build_library(pattern, opts)
    with atomic_path(path, _verify_gds(path, lib, opts)) as tmp:
        lib.write_gds(tmp, max_points=MAX_POINTS, timestamp=TIMESTAMP)


def write_oas(pattern: Pattern, path: str | Path, opts: ExportOptions) -> None:
    """Write an OASIS file atomically (cells compressed; circles detected as CIRCLE
    records) with a CRC32 in its END record, checked before it replaces anything."""
    if isinstance(pattern, Dataset):
        write_oas_tiles(pattern, path, opts)
        return
    _write_oas_lib(build_library(pattern, opts, oasis=True), path, opts)


def _write_oas_lib(lib: gdstk.Library, path: str | Path, opts: ExportOptions) -> None:
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

    def check(tmp: Path) -> None:
        _check_counts(path, tmp, refs, polys)

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
