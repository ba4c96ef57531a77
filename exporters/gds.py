"""GDSII and OASIS masks with gdstk.

Units: user unit 1 µm, database unit 1 nm. A dot is a cell (a circle polygon whose
vertex count follows the tolerance; one cell per diameter, ``DOT`` when all dots have the
same size, ``DOT_<diameter in nm>`` otherwise) placed by one reference per dot, so 10⁶ dots stay
~26 MB in GDSII; OASIS stores the same references as one explicit repetition (~8 MB).
A shaped dot's cell holds its footprint at angle 0 (``DOT_<length>x<width>[x<corner
radius>]`` in nm), each dot a reference rotated by its own angle (one repeated
reference when every dot has the same angle).
``flatten`` writes plain polygons instead. The panel (outline minus holes and keep-outs)
goes on its own layer as filled polygons, holes cut open by zero-width keyholes. Caps
over LEDs (:mod:`optdot.geometry.caps`) are circles on the dots' layer in a cell ``CAP``
(``CAP_<diameter in nm>`` when they differ), one reference a cap, flattened or not.
Graded caps print their rings instead: the cell is always ``CAP_<diameter in nm>`` (the
cap's diameter is not drawn when its outer bands are empty) and holds one polygon a ring,
a disc for a ring from the centre, else an annulus cut open by a zero-width keyhole.
"""

from __future__ import annotations

import contextlib
import datetime
import itertools
import math
import os
import tempfile
from pathlib import Path

import gdstk
import numpy as np

from optdot.errors import ExportError
from optdot.geometry.caps import CAP_CELL
from optdot.geometry.morton import spatial_order
from optdot.geometry.shapes import CIRCLE, MIN_VERTICES, Footprints, Kind, polygon_vertices
from optdot.io.atomic import atomic_path, expect_tail
from optdot.pattern import DotSource, caps_of
from optdot.printing.mask import (
    mask_cap_rings,
    mask_polygons,
    mask_ring,
    mask_rings,
    placed_whole,
)
from optdot.printing.sheet import CUT_LAYER, FIDUCIAL_LAYER, LABEL_LAYER, SHEET_CELL

from .options import ExportOptions

#: Fixed GDSII timestamp: identical input gives identical bytes.
TIMESTAMP = datetime.datetime(2000, 1, 1, 0, 0, 0)
#: Largest coordinate a 32-bit GDSII integer holds at 1 nm, mm.
MAX_EXTENT_MM = (2**31 - 1) * 1e-6
#: Fewest vertices of a dot polygon (what ``optdot qa`` reads back as a circle).
MIN_DOT_VERTICES = MIN_VERTICES
#: Most vertices one GDSII boundary can hold.
MAX_POINTS = 8190


def _check_extent(box, xy: np.ndarray | None = None, dots: Footprints | None = None) -> None:
    """Refuse coordinates a 32-bit GDSII integer cannot hold at 1 nm (they would wrap:
    3000 mm reads back as -1294.97 mm): the panel box and, when given, the dots
    themselves (``xy`` ``[n, 2]`` mm, their footprints), whatever box they claim."""
    far = max(abs(float(v)) for v in box)
    if xy is not None and len(xy):
        r = float(np.max(dots.extent()))
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


def dot_cell(name: str, kind: Kind, size_um: np.ndarray, opts: ExportOptions) -> gdstk.Cell:
    """The cell of one dot: its footprint (``kind`` of ``size_um``, µm, at angle 0)
    centred on the origin, a polygon within the tolerance; with a process, the mask's
    polygon that prints as that footprint (:func:`optdot.printing.mask.mask_ring`).

    Raises:
        ExportError: the tolerance needs too many vertices, or too few to read as round.
    """
    if not kind.round or opts.process is not None:
        dot = gdstk.Cell(name)
        size, tol = np.asarray(size_um) * 1e-3, opts.tolerance_um * 1e-3
        if opts.process is None:
            ring = kind.outline(size, 0.0, tol) * 1e3
        else:  # what prints as the footprint: shrunk by the gain, scaled, on the grid
            ring = mask_ring(opts.process, kind, size, tol) * 1e3
        if len(ring) > MAX_POINTS:
            raise ExportError(
                f"--tolerance {opts.tolerance_um} µm needs {len(ring)} vertices per dot "
                f"(max {MAX_POINTS})"
            )
        dot.add(gdstk.Polygon(ring, layer=opts.layer, datatype=opts.datatype))
        return dot
    r_um = 0.5 * float(size_um[0])
    nv = polygon_vertices(r_um, opts.tolerance_um)
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


class _Cells:
    """The cells of a mask as a dot source's chunks come in: one dot cell per footprint
    size (its parameters rounded to the 1 nm database unit), created on first use, and
    the dots of each chunk as references (one per size, an explicit repetition in Morton
    order: small deltas) or, flattened, as plain polygons.

    Args:
        src: the dot source: its kind, and its one diameter, mm, when every dot has it
            (then the one cell is ``opts.dot_cell``, drawn at that diameter exactly).
    """

    def __init__(self, src: DotSource, opts: ExportOptions) -> None:
        self.kind = src.kind
        self.box = src.box
        self.uniform = src.uniform_diameter
        self.opts = opts
        self.dots: dict[tuple[int, ...], gdstk.Cell] = {}
        self.names = {opts.top_cell: "the top cell"}

    def dot(self, key: tuple[int, ...]) -> gdstk.Cell:
        """The cell of the footprint of size ``key`` (nm per parameter)."""
        if key not in self.dots:
            what = "x".join(str(v) for v in key)
            if self.uniform is not None:
                name, size_um = self.opts.dot_cell, np.array([self.uniform * 1e3])
            else:
                name, size_um = f"{self.opts.dot_cell}_{what}", np.array(key) * 1e-3
            name = _unique(name, f"the {what} nm dot", self.names)
            self.dots[key] = dot_cell(name, self.kind, size_um, self.opts)
        return self.dots[key]

    def fill(self, cell: gdstk.Cell, xy: np.ndarray, dots: Footprints) -> tuple[int, int]:
        """Put the dots ``xy`` (``[n, 2]`` mm, their footprints) into ``cell``;
        returns the references and the polygons a GDSII file holds for them. With a process,
        their places and angles on the mask; dots a reference cannot place on the grid
        (:func:`~optdot.printing.mask.placed_whole`) are polygons of their own."""
        process = self.opts.process
        if process is not None and not placed_whole(process, dots.kind, dots.angle):
            return 0, self._polygons(cell, xy, dots)
        if process is not None:
            xy = process.place(xy, self.box)
            if dots.angle is not None:
                dots = Footprints(dots.kind, dots.size, process.turn(dots.angle))
        for key, index in dots.groups(1e6):  # sizes in nm
            sel = xy[index] * 1e3
            order = spatial_order(sel)
            if dots.angle is None:
                cell.add(_placed(self.dot(key), sel[order]))
                continue
            turn = dots.angle[index][order]
            if np.all(turn == turn[0]):  # one angle: one rotated reference, repeated
                ref = _placed(self.dot(key), sel[order])
                ref.rotation = float(turn[0])
                cell.add(ref)
                continue
            dot = self.dot(key)  # a reference per dot, each with its exact rotation
            for (x, y), t in zip(sel[order].tolist(), turn.tolist(), strict=True):
                cell.add(gdstk.Reference(dot, origin=(x, y), rotation=t))
        if self.opts.flatten:
            cell.flatten()
            return 0, len(xy)
        return len(xy), 0

    def _polygons(self, cell: gdstk.Cell, xy: np.ndarray, dots: Footprints) -> int:
        """The dots as the mask's polygons, one each (Morton order per size)."""
        lay = {"layer": self.opts.layer, "datatype": self.opts.datatype}
        tol = self.opts.tolerance_um * 1e-3
        for _, index in dots.groups(1e6):
            order = index[spatial_order(xy[index])]
            size = dots.size[order[0]]
            rings = mask_polygons(
                self.opts.process, dots.kind, size, xy[order], dots.angles[order], self.box, tol
            )
            cell.add(*(gdstk.Polygon(r * 1e3, **lay) for r in rings))
        return len(xy)

    def tile(self, label: tuple[int, int]) -> gdstk.Cell:
        i, j = label
        return gdstk.Cell(_unique(f"T{i}_{j}", f"tile ({i}, {j})", self.names))

    def library_cells(self) -> list[gdstk.Cell]:
        """The dot cells (none when flattened), smallest diameter first."""
        return [] if self.opts.flatten else [self.dots[k] for k in sorted(self.dots)]


def _chunks(src: DotSource):
    """``(label, xy, diameter, alone)`` per chunk of ``src``, ``alone`` when it is the
    only one (its dots then go straight into the top cell), extents checked."""
    if src.n == 0:
        raise ExportError("the pattern has no dots")
    _check_extent(src.box)
    it = iter(src.chunks())
    first = next(it)
    second = next(it, None)
    if second is None:
        _check_extent(src.box, first[1], first[2])
        yield (*first, True)
        return
    for label, xy, d in itertools.chain([first, second], it):
        _check_extent(src.box, xy, d)
        yield label, xy, d, False


def _top(src: DotSource, opts: ExportOptions, oasis: bool) -> gdstk.Cell:
    top = gdstk.Cell(opts.top_cell)
    top.add(*_outline_polygons(_rings(src, opts), opts, oasis))
    return top


def _rings(src: DotSource, opts: ExportOptions) -> list[np.ndarray]:
    """The panel's loops (mm) as the mask draws them."""
    rings = src.outline_rings()
    return rings if opts.process is None else mask_rings(opts.process, rings, src.box)


def _cap_cells(src: DotSource, opts: ExportOptions, names: dict[str, str]):
    """``(cells, refs, polygons)``: a cell per cap diameter (:data:`CAP_CELL`, with
    ``_<nm>`` when there are several or the caps are graded), a circle on the dots'
    layer or the graded caps' rings, the references placing them (one a cap, in Morton
    order), to go into the top cell, and how many polygons the cells hold."""
    caps = caps_of(src)
    graded = src.outline is not None and src.outline.cap_rings is not None
    cells, refs = [], []
    sizes = np.unique(np.round(caps[:, 2] * 1e6).astype(np.int64)) if len(caps) else []
    for nm in sizes:
        name = CAP_CELL if len(sizes) == 1 and not graded else f"{CAP_CELL}_{nm}"
        name = _unique(name, f"the {nm} nm cap", names)
        rings = src.outline.cap_rings if graded else None
        if graded and opts.process is not None:
            rings = mask_cap_rings(opts.process, rings)
        if graded:
            cell = _ring_cell(name, rings * 1e3, opts)
        else:
            cell = dot_cell(name, CIRCLE, np.array([nm * 1e-3]), opts)
        at = caps[np.round(caps[:, 2] * 1e6).astype(np.int64) == nm, :2]
        if opts.process is not None:
            at = opts.process.place(at, src.box)
        at = at * 1e3
        at = at[spatial_order(at)]
        cells.append(cell)
        refs.extend(gdstk.Reference(cell, origin=(float(x), float(y))) for x, y in at.tolist())
    return cells, refs, sum(len(c.polygons) for c in cells)


def _ring_cell(name: str, rings_um: np.ndarray, opts: ExportOptions) -> gdstk.Cell:
    """The cell of a graded cap: one polygon a ring ``(r_in, r_out)`` µm about the
    origin, within the tolerance."""
    cell = gdstk.Cell(name)
    for r_in, r_out in rings_um.tolist():
        nv = polygon_vertices(r_out, opts.tolerance_um)
        if 2 * nv + 2 > MAX_POINTS:
            raise ExportError(
                f"--tolerance {opts.tolerance_um} µm needs {nv} vertices for a cap's ring of "
                f"{2 * r_out:.4g} µm (max {MAX_POINTS // 2 - 1})"
            )
        cell.add(
            gdstk.ellipse(
                (0, 0),
                r_out,
                inner_radius=r_in if r_in > 0 else None,
                tolerance=opts.tolerance_um,
                layer=opts.layer,
                datatype=opts.datatype,
            )
        )
    return cell


def write_gds(src: DotSource, path: str | Path, opts: ExportOptions) -> None:
    """Stream a dot source (a pattern, a dataset) into a GDSII file with
    ``gdstk.GdsWriter``, one chunk in memory at a time: a pattern's dots go into the top
    cell, a tiled dataset's into one cell ``T<i>_<j>`` per tile that the top cell places;
    the top cell also holds the outline. Written atomically, verified before it replaces
    anything (ENDLIB, the whole record stream, the reference and polygon counts)."""
    cells = _Cells(src, opts)
    top = _top(src, opts, oasis=False)
    cap_cells, cap_refs, cap_polys = _cap_cells(src, opts, cells.names)
    counts = {"refs": len(cap_refs), "polys": cap_polys}

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
            for label, xy, d, alone in _chunks(src):
                cell = top if alone else cells.tile(label)
                refs, polys = cells.fill(cell, xy, d)
                counts["refs"] += refs
                counts["polys"] += polys
                if not alone:
                    writer.write(cell)
                    top.add(gdstk.Reference(cell))
                    counts["refs"] += 1
            dots = cells.library_cells()
            top.add(*cap_refs)  # after the dots: a flattened top keeps its caps placed
            writer.write(*dots, *cap_cells, top)
            if opts.sheet is not None:
                sheet = _sheet_cell(top, src, opts, cells.names)
                writer.write(sheet)
                counts["refs"] += 1
                counts["polys"] += len(sheet.polygons)
        finally:
            writer.close()
        counts["polys"] += len(dots) + len(_outline_polygons(_rings(src, opts), opts))


def write_oas(src: DotSource, path: str | Path, opts: ExportOptions) -> None:
    """A dot source as an OASIS file, cells as in :func:`write_gds`, with a CRC32 in its
    END record, checked before it replaces anything (circles stored as CIRCLE records).

    gdstk has no streaming OASIS writer: the library is built whole, each chunk's dots
    one reference per size with an explicit repetition (16 B per dot: 1.9 GB at 1.2·10⁸
    dots). Offsets are relative to the chunk's first dot in Morton order, so the deltas
    gdstk rounds to the 1 nm grid are each exact (no drift across a tile)."""
    cells = _Cells(src, opts)
    top = _top(src, opts, oasis=True)
    cap_cells, cap_refs, _ = _cap_cells(src, opts, cells.names)
    lib = gdstk.Library("OPTDOT", unit=1e-6, precision=1e-9)
    for label, xy, d, alone in _chunks(src):
        cell = top if alone else cells.tile(label)
        cells.fill(cell, xy, d)
        if not alone:
            lib.add(cell)
            top.add(gdstk.Reference(cell))
    top.add(*cap_refs)  # after the dots: a flattened top keeps its caps placed
    lib.add(*cells.library_cells(), *cap_cells, top)
    if opts.sheet is not None:
        lib.add(_sheet_cell(top, src, opts, cells.names))
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


def _sheet_cell(top: gdstk.Cell, src: DotSource, opts: ExportOptions, names) -> gdstk.Cell:
    """The production sheet (:mod:`optdot.printing.sheet`): the panel's cell ``top``
    arrayed once (an AREF), the fiducials, a label per panel (text as polygons) and the
    cut lines, each on its layer; µm."""
    sheet = opts.sheet
    cell = gdstk.Cell(_unique(SHEET_CELL, "the sheet", names))
    px, py = (v * 1e3 for v in sheet.pitch)
    cell.add(gdstk.Reference(top, (0, 0), columns=sheet.columns, rows=sheet.rows, spacing=(px, py)))
    box = opts.process.mask_box(src.box) if opts.process is not None else src.box
    for ring in sheet.fiducial_polygons():
        cell.add(gdstk.Polygon(ring * 1e3, layer=FIDUCIAL_LAYER[0]))
    for ring in sheet.cut_lines(box):
        cell.add(gdstk.Polygon(ring * 1e3, layer=CUT_LAYER[0]))
    if sheet.label_height > 0:
        at = np.asarray(sheet.label_at(box))
        for off, text in zip(sheet.offsets(), opts.labels, strict=True):
            x, y = (at + off) * 1e3
            cell.add(*gdstk.text(text, sheet.label_height * 1e3, (x, y), layer=LABEL_LAYER[0]))
    return cell


def _write_oas_lib(lib: gdstk.Library, path: str | Path, opts: ExportOptions) -> None:
    with atomic_path(path, _verify_oas(path)) as tmp:
        lib.write_oas(
            tmp, compression_level=6, circle_tolerance=opts.tolerance_um, validation="crc32"
        )


#: The GDSII ENDLIB record: length 4, type 0x04, no data.
ENDLIB = b"\x00\x04\x04\x00"


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
