"""DXF for CAD/CAM: native CIRCLE entities on layer ``DOTS``, the outline on ``OUTLINE``.

Shaped dots are blocks, one per size (``DOT_<length>x<width>[x<corner radius>]`` in nm):
an ELLIPSE, or a closed LWPOLYLINE whose corners are exact arcs (bulges) for a rounded
rectangle (R12, which has neither, gets the outline as a polygon within the tolerance),
each dot an INSERT on layer ``DOTS`` rotated by its angle in degrees.

ezdxf's document model takes ~50 s for 10⁶ circles, so the file is streamed: ezdxf writes
a complete document (header with ``$INSUNITS`` = mm, tables, layers, blocks, objects)
holding the outline and one template circle; the template's entity text is then repeated
once per dot with fresh handles, and ``$HANDSEED`` is moved past the last one. The result
is an ordinary DXF that ezdxf's audit accepts (tests/test_exporters.py).

Caps over LEDs (:mod:`optdot.geometry.caps`) are CIRCLEs on ``DOTS`` too (they are
printed), each marked by XDATA of the application ``OPTDOT_CAP``. A graded cap is a
POINT at its centre (XDATA ``cap``, its diameter in mm) and one solid HATCH a ring on
``DOTS`` (XDATA ``cap ring``): a disc bounded by one circle, an annulus by two; R12,
which has no HATCH, refuses graded caps.
"""

from __future__ import annotations

import io
import logging
import re
from pathlib import Path

import ezdxf
import numpy as np

from optdot.errors import ExportError
from optdot.geometry.caps import CAP_APPID
from optdot.geometry.kinds import Curve
from optdot.geometry.orientation import degrees
from optdot.geometry.shapes import Footprints, Kind
from optdot.io.atomic import atomic_path, expect_tail
from optdot.pattern import DotSource, Pattern, caps_of
from optdot.printing.mask import mask_cap_rings, mask_ring, mask_rings
from optdot.printing.sheet import CUT_LAYER, FIDUCIAL_LAYER, LABEL_LAYER, PANEL_BLOCK

from .options import ExportOptions

_FIXED = {
    "$TDCREATE": "2451544.5",
    "$TDUCREATE": "2451544.5",
    "$TDUPDATE": "2451544.5",
    "$TDUUPDATE": "2451544.5",
    "$TDINDWG": "0.0",
    "$TDUSRTIMER": "0.0",
    "$FINGERPRINTGUID": "{00000000-0000-0000-0000-000000000000}",
    "$VERSIONGUID": "{00000000-0000-0000-0000-000000000000}",
}
_STAMP = re.compile(r"^(\S+) @ \d{4}-\d\d-\d\dT[0-9:.]+[+-]\d\d:\d\d$")
_MARK_X, _MARK_Y = 123456.654321, 654321.123456  # template circle, found by its coordinates
_MARK_R = 0.123456  # its radius when the sizes vary (replaced per dot)
_MARK_A = 12.345678  # a template INSERT's rotation (replaced per dot)


def _new_document(version: str):
    """An empty ezdxf document of ``version``, without ezdxf's warning that R12 has no
    $INSUNITS (it sets the units of every new document; R12 drawings are in mm by
    convention, which the module doc states): a command prints its own lines only."""
    log = logging.getLogger("ezdxf")
    level = log.level
    log.setLevel(logging.ERROR)
    try:
        return ezdxf.new(version, setup=False)
    finally:
        log.setLevel(level)


def _block_name(key: tuple[int, ...]) -> str:
    """The block of a shaped dot of size ``key`` (nm per parameter)."""
    return "DOT_" + "x".join(str(v) for v in key)


def _graded_caps(msp, caps: np.ndarray, rings: np.ndarray) -> None:
    """Graded caps into ``msp``: a POINT a cap, a solid HATCH a ring (see the module
    doc)."""
    for x, y, d in caps.tolist():
        mark = msp.add_point((x, y), dxfattribs={"layer": "DOTS"})
        mark.set_xdata(CAP_APPID, [(1000, "cap"), (1040, float(d))])
        for r_in, r_out in rings.tolist():
            hatch = msp.add_hatch(dxfattribs={"layer": "DOTS"})
            hatch.paths.add_edge_path().add_arc((x, y), r_out, 0.0, 360.0)
            if r_in > 0:
                hatch.paths.add_edge_path().add_arc((x, y), r_in, 0.0, 360.0)
            hatch.set_xdata(CAP_APPID, [(1000, "cap ring")])


def _add_block(
    doc, kind: Kind, size: np.ndarray, version: str, tolerance: float, process=None
) -> None:
    """A block of one footprint (``size`` mm) at angle 0 about the origin, on layer 0
    (it takes the layer of the INSERT placing it); with a ``process``, what the mask
    draws for it (:func:`_mask_curve`)."""
    key = tuple(int(v) for v in np.round(size * 1e6))
    blk = doc.blocks.new(_block_name(key))
    if version == "R12":
        if process is None:
            ring = kind.outline(size, 0.0, tolerance)
        else:
            ring = mask_ring(process, kind, size, tolerance)
        blk.add_polyline2d([tuple(map(float, p)) for p in ring], close=True)
        return
    curve = kind.curve(size) if process is None else _mask_curve(process, kind, size, tolerance)
    if curve.form == "disc":
        blk.add_circle((0.0, 0.0), curve.a)
    elif curve.form == "ellipse":
        blk.add_ellipse((0.0, 0.0), major_axis=(curve.a, 0.0), ratio=curve.b / curve.a)
    elif curve.form == "bulged":
        ring = [(x, y, 0.0, 0.0, bulge) for x, y, bulge in curve.ring]
        blk.add_lwpolyline(ring, format="xyseb", close=True)
    else:
        raise ValueError(f"{kind.name}: a curve of form {curve.form!r} has no DXF entity")


def _mask_curve(process, kind: Kind, size: np.ndarray, tolerance: float) -> Curve:
    """What a mask draws for a printed footprint of ``size`` (``[k]`` mm): the kind's own
    curves at the size the gain shrinks it to, scaled for the shrink, where that is a
    footprint of the kind; else (an ellipse's parallel curve) its polygon within
    ``tolerance`` mm, each vertex on the grid."""
    mask = process.mask_size(kind, np.asarray(size, float)[None, :])
    if mask is None:
        ring = mask_ring(process, kind, size, tolerance)
        return Curve("bulged", ring=tuple((float(x), float(y), 0.0) for x, y in ring))
    curve = kind.curve(mask[0])
    k = float(process.scale[0])
    ring = tuple((x * k, y * k, b) for x, y, b in curve.ring)
    return Curve(curve.form, curve.a * k, curve.b * k, ring)


def _template(
    pattern: Pattern,
    version: str,
    provenance: tuple[str, ...] = (),
    sizes: list[np.ndarray] = (),
    tolerance: float = 1e-4,
    pattern_process=None,
    sheet=None,
    labels: tuple[str, ...] = (),
) -> tuple[str, str, str, int]:
    """(head, dot format, tail, first free handle) of a document for ``pattern``.

    The circle format takes ``(handle, x, y)`` (R12: ``(x, y)``), plus the radius last
    when the dots' sizes vary; with one size the radius is part of the template.
    Shaped dots: an INSERT of the block of each of ``sizes`` (``[k]`` mm each), its
    format ``(handle, [block name,] x, y, rotation in degrees)`` (the name when there
    are several blocks; ``tolerance``, mm, draws R12's polygons). With a
    ``pattern_process``, the outline, caps, circles and blocks are the mask's. On a
    ``sheet``, the panel is the block :data:`PANEL_BLOCK`, arrayed by one INSERT."""
    uniform = pattern.uniform_diameter
    radius = _MARK_R if uniform is None else _mask_radius(pattern_process, 0.5 * uniform)
    shaped = not pattern.kind.round
    doc = _new_document(version)
    if version != "R12":  # R12 has no $INSUNITS: drawing units are mm by convention
        doc.header["$INSUNITS"] = 4  # millimetres
        doc.header["$MEASUREMENT"] = 1  # metric
        for line in provenance:  # what made this drawing: custom drawing properties
            key, value = line.split(": ", 1)
            doc.header.custom_vars.append(key, value)
    doc.layers.add("DOTS", color=7)
    doc.layers.add("OUTLINE", color=1)
    msp = doc.modelspace()
    # the panel: the modelspace, or on a production sheet a block the sheet arrays
    panel = msp if sheet is None else doc.blocks.new(PANEL_BLOCK)
    process = pattern_process
    rings = pattern.outline_rings()
    if process is not None:
        rings = mask_rings(process, rings, pattern.box)
    for ring in rings:  # outline and holes, one closed polyline each
        pts = [(float(x), float(y)) for x, y in ring]
        if version == "R12":
            panel.add_polyline2d(pts, close=True, dxfattribs={"layer": "OUTLINE"})
        else:
            panel.add_lwpolyline(pts, close=True, dxfattribs={"layer": "OUTLINE"})
    caps = caps_of(pattern)
    graded = pattern.outline is not None and pattern.outline.cap_rings is not None
    cap_rings = pattern.outline.cap_rings if graded else None
    if len(caps) and process is not None:  # what prints as the caps
        k = float(process.scale[0])
        at = process.place(caps[:, :2], pattern.box)
        caps = np.column_stack([at, k * (caps[:, 2] - 2.0 * process.dot_gain)])
        cap_rings = mask_cap_rings(process, cap_rings) if graded else None
    if len(caps):
        doc.appids.add(CAP_APPID)
    if graded and len(caps):
        _graded_caps(panel, caps, cap_rings)
    for x, y, d in caps.tolist() if not graded else []:  # a circle marked by its XDATA
        cap = panel.add_circle((x, y), 0.5 * d, dxfattribs={"layer": "DOTS"})
        cap.set_xdata(CAP_APPID, [(1000, "cap")])
    names = []
    if shaped:
        for size in sizes:
            _add_block(doc, pattern.kind, size, version, tolerance, process)
            names.append(_block_name(tuple(int(v) for v in np.round(size * 1e6))))
        panel.add_blockref(
            names[0], (_MARK_X, _MARK_Y), dxfattribs={"layer": "DOTS", "rotation": _MARK_A}
        )
    else:
        panel.add_circle((_MARK_X, _MARK_Y), radius, dxfattribs={"layer": "DOTS"})
    if sheet is not None:
        _sheet(doc, msp, sheet, labels, rings, version)
    buf = io.StringIO()
    doc.write(buf)
    text = buf.getvalue()
    lines = _sorted_classes(text.split("\n"))
    ix = lines.index(f"{_MARK_X}") if f"{_MARK_X}" in lines else _find_float(lines, _MARK_X)
    start = ix
    while lines[start] != ("INSERT" if shaped else "CIRCLE"):
        start -= 1
    start -= 1  # the "  0" group code before CIRCLE
    end = ix
    while lines[end].strip() != "0":
        end += 1
    entity = lines[start:end]
    fmt: list[str] = []
    for k in range(0, len(entity), 2):
        code, value = entity[k], entity[k + 1]
        c = code.strip()
        if c == "5":
            value = "%X"
        elif c == "10":
            value = "%.6f"
        elif c == "20":
            value = "%.6f"
        elif c == "40" and uniform is None and not shaped:
            value = "%.6f"
        elif c == "50" and shaped:
            value = "%.6f"
        elif c == "2" and shaped and len(names) > 1:
            value = "%s"
        else:
            value = value.replace("%", "%%")
        fmt += [code, value]
    for i, line in enumerate(lines):  # fixed dates and GUIDs: same input, same bytes
        if line in _FIXED:
            lines[i + 2] = _FIXED[line]
        elif _STAMP.match(line):  # ezdxf's CREATED_BY/WRITTEN_BY_EZDXF time stamps
            lines[i] = _STAMP.sub(r"\1 @ 2000-01-01T00:00:00+00:00", line)
    seed_line = lines.index("$HANDSEED")
    seed = int(lines[seed_line + 2], 16)
    head = "\n".join(lines[:start]) + "\n"
    tail = "\n".join(lines[end:])
    head = head.replace(f"$HANDSEED\n  5\n{lines[seed_line + 2]}\n", "$HANDSEED\n  5\n{SEED}\n", 1)
    return head, "\n".join(fmt) + "\n", tail, seed


def _sorted_classes(lines: list[str]) -> list[str]:
    """ezdxf emits the CLASSES section in set order (varies with PYTHONHASHSEED); sort it."""
    if "CLASSES" not in lines:
        return lines
    a = lines.index("CLASSES") + 1
    b = a
    while lines[b] != "ENDSEC":
        b += 1
    b -= 1  # the "  0" before ENDSEC
    body = lines[a:b]
    starts = [
        i for i in range(0, len(body), 2) if body[i].strip() == "0" and body[i + 1] == "CLASS"
    ]
    items = [body[s:e] for s, e in zip(starts, starts[1:] + [len(body)], strict=True)]
    items.sort(key=lambda it: it[3])  # by class name
    return lines[:a] + [x for it in items for x in it] + lines[b:]


def _find_float(lines: list[str], value: float) -> int:
    for i, s in enumerate(lines):
        try:
            if abs(float(s) - value) < 1e-6:
                return i
        except ValueError:
            continue
    raise RuntimeError("template circle not found in ezdxf output")  # pragma: no cover


def _sheet(doc, msp, sheet, labels: tuple[str, ...], rings, version: str) -> None:
    """The production sheet into ``msp``: one INSERT of the panel's block with its rows
    and columns (no dot written twice), the fiducials, a label per panel (the text's
    outlines, closed polylines) and the cut lines, each on its layer."""
    import gdstk

    for _, name in (FIDUCIAL_LAYER, LABEL_LAYER, CUT_LAYER):
        doc.layers.add(name)
    msp.add_blockref(
        PANEL_BLOCK,
        (0.0, 0.0),
        dxfattribs={
            "column_count": sheet.columns,
            "row_count": sheet.rows,
            "column_spacing": sheet.pitch[0],
            "row_spacing": sheet.pitch[1],
        },
    )
    pts = np.concatenate(rings)
    box = (*pts.min(axis=0), *pts.max(axis=0))
    shapes = [(FIDUCIAL_LAYER[1], r) for r in sheet.fiducial_polygons()]
    shapes += [(CUT_LAYER[1], r) for r in sheet.cut_lines(box)]
    if sheet.label_height > 0:
        at = np.asarray(sheet.label_at(box))
        for off, text in zip(sheet.offsets(), labels, strict=True):
            x, y = at + off
            for poly in gdstk.text(text, sheet.label_height, (float(x), float(y))):
                shapes.append((LABEL_LAYER[1], poly.points))
    for layer, ring in shapes:
        pts = [(float(x), float(y)) for x, y in ring]
        if version == "R12":
            msp.add_polyline2d(pts, close=True, dxfattribs={"layer": layer})
        else:
            msp.add_lwpolyline(pts, close=True, dxfattribs={"layer": layer})


def _mask_radius(process, r):
    """A circle's radius (mm; a number or ``[n]``) on the mask: shrunk by the gain,
    scaled (unchanged without a process)."""
    return r if process is None else float(process.scale[0]) * (r - process.dot_gain)


def write_dxf(pattern: DotSource, path: str | Path, opts: ExportOptions) -> None:
    """Write the DXF atomically (R2010 by default, ``opts.dxf_version`` otherwise); a
    dataset is streamed part by part (memory: one part).

    Raises:
        ExportError: graded caps in an R12 drawing (it has no HATCH)."""
    outline = pattern.outline
    if opts.dxf_version == "R12" and outline is not None and outline.cap_rings is not None:
        raise ExportError(
            f"{path}: DXF R12 has no HATCH to fill the rings of graded caps over the LEDs; "
            "write R2000 or later (--dxf-version)"
        )
    process = opts.process
    if process is not None and not process.isotropic:
        raise ExportError(
            f"{path}: process.shrink = [{process.shrink[0]:g}, {process.shrink[1]:g}] scales x "
            "and y apart; DXF draws circles and arcs, which such a scale makes ellipses: "
            "write GDSII or OASIS"
        )
    shaped = not pattern.kind.round
    sizes, names = [], {}
    if shaped:  # every size the dots have: a block each
        keys = set()
        for _, _, part in pattern.chunks():
            keys.update(key for key, _ in part.groups(1e6))
        sizes = [np.array(k) * 1e-6 for k in sorted(keys)]
        names = {k: _block_name(k) for k in sorted(keys)}
    tol = opts.tolerance_um * 1e-3
    head, fmt, tail, seed = _template(
        pattern, opts.dxf_version, opts.provenance, sizes, tol, process, opts.sheet, opts.labels
    )
    has_handle = "%X" in fmt
    varying = pattern.uniform_diameter is None and not shaped
    named = shaped and len(names) > 1
    n = pattern.n
    head = head.replace("{SEED}", f"{seed + n:X}")
    verify = expect_tail(tail[-8:].encode("ascii"), str(path))  # "  0\nEOF\n"
    with atomic_path(path, verify) as tmp, open(tmp, "w", encoding="ascii", newline="\n") as fh:
        fh.write(head)
        chunk = 100_000
        done = 0
        for _, part_xy, footprints in pattern.chunks():  # one part, or one per tile
            part_d = footprints.diameter
            if process is not None:  # places and angles on the mask
                part_xy = process.place(part_xy, pattern.box)
                part_d = 2.0 * _mask_radius(process, 0.5 * part_d)
                if footprints.angle is not None:
                    footprints = Footprints(
                        footprints.kind, footprints.size, process.turn(footprints.angle)
                    )
            for a in range(0, len(part_xy), chunk):
                xy = part_xy[a : a + chunk]
                cols = [xy[:, 0].tolist(), xy[:, 1].tolist()]
                if has_handle:
                    cols.insert(0, list(range(seed + done, seed + done + len(xy))))
                if named:
                    keys = np.round(footprints.size[a : a + chunk] * 1e6).astype(np.int64)
                    cols.insert(len(cols) - 2, [names[tuple(k)] for k in keys.tolist()])
                if varying:
                    cols.append((0.5 * part_d[a : a + chunk]).tolist())
                if shaped:
                    cols.append(degrees(footprints.angles[a : a + chunk]).tolist())
                rows = zip(*cols, strict=True)
                fh.write("".join(fmt % row for row in rows))
                done += len(xy)
        fh.write(tail)
