"""Laser dotting paths: one point per dot with its pulse set, in the order of a short path
(:mod:`optdot.printing.laser`), in the dialect the file's name asks for. Coordinates are
the pattern's (mm, the panel's origin), the print's (a process's mirror and shrink apply
to masks, not to a laser that dots the part itself).

- **G-code** (``.nc``, ``.gcode``, ``.ngc``): ``G21`` (mm), ``G90`` (absolute), then per dot
  ``G0 X.. Y..`` (4 decimals: 0.1 µm) and ``M3 S<pulse set>`` (fire), ``M5`` and ``M2`` at
  the end; comments in parentheses.
- **HPGL/2** (``.plt``, ``.hpgl``): ``IN;`` and ``SC0,0.04,0,0.04,2;`` (user units of 1 µm,
  0.04 plotter units of 25 µm each), then per pulse set change ``SP<set>;`` and per dot
  ``PU x,y;PD x,y;`` (integer µm).
- **CSV** (``.csv``): ``order,x_mm,y_mm,diameter_mm,pulse_set``, 6 decimals (1 nm).
"""

from __future__ import annotations

import io
from pathlib import Path

import numpy as np

from optdot.errors import ExportError
from optdot.io.atomic import atomic_path, expect_tail
from optdot.pattern import Pattern
from optdot.printing.laser import Laser, path_length, shortest_path

from .options import ExportOptions

GCODE = (".nc", ".gcode", ".ngc")
HPGL = (".plt", ".hpgl")


def write_laser(pattern: Pattern, path: str | Path, opts: ExportOptions) -> str:
    """Write ``pattern``'s dots as a laser path to ``path`` (dialect by its suffix),
    atomically; returns what it holds: the dots, the pulse sets, the path's length
    against the pattern's own order, and the machining time estimated.

    Raises:
        ExportError: a suffix of no dialect, shaped dots (a laser's dots are round), a
            process's mirror (a laser path is the print; it has none).
    """
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix not in (*GCODE, *HPGL, ".csv"):
        raise ExportError(
            f"{path}: a laser path is G-code ({', '.join(GCODE)}), HPGL/2 "
            f"({', '.join(HPGL)}) or a CSV point list (.csv)"
        )
    process = opts.process
    if process is not None and process.mirror != "none":
        raise ExportError(
            f"{path}: process.mirror = {process.mirror!r} mirrors a mask printed emulsion side "
            "down; a laser path dots the part itself and has no mirror: leave mirror out of a "
            "laser-dotted job"
        )
    if not pattern.kind.round:
        raise ExportError(
            f"{path}: a laser dots round craters; these dots are {pattern.kind.name}s"
        )
    laser = opts.laser or Laser()
    xy = np.asarray(pattern.xy, float)
    d = np.asarray(pattern.diameter, float)
    order, width, length = shortest_path(xy, pattern.box)
    own = path_length(xy)
    xy, d = xy[order], d[order]
    sets = laser.pulse_sets(d)
    buf = io.StringIO()
    if suffix in GCODE:
        _gcode(buf, xy, sets, length)
    elif suffix in HPGL:
        _hpgl(buf, xy, sets)
    else:
        _csv(buf, xy, d, sets)
    text = buf.getvalue()
    with atomic_path(path, expect_tail(text[-32:].encode("ascii"), str(path))) as tmp:
        tmp.write_text(text, encoding="ascii", newline="\n")
    seconds = laser.machining_time(xy)
    ratio = own / length if length > 0 else float("inf")
    said = (
        f"laser path, {len(xy):,} dots in {len(np.unique(sets))} pulse set(s): "
        f"{length:,.1f} mm (bands {width * 1e3:.0f} µm; the pattern's order {own:,.1f} mm, "
        f"{ratio:.1f}x longer)"
    )
    if seconds is not None:
        said += f", about {_duration(seconds)} to machine"
    return said


def _gcode(buf, xy: np.ndarray, sets: np.ndarray, length: float) -> None:
    buf.write(f"(optdot laser path: {len(xy)} dots, {length:.3f} mm, units mm)\n")
    buf.write("G21\nG90\n")
    for (x, y), s in zip(xy.tolist(), sets.tolist(), strict=True):
        buf.write(f"G0 X{x:.4f} Y{y:.4f}\nM3 S{s}\n")
    buf.write("M5\nM2\n")


def _hpgl(buf, xy: np.ndarray, sets: np.ndarray) -> None:
    buf.write("IN;SC0,0.04,0,0.04,2;")
    um = np.round(xy * 1e3).astype(np.int64)
    current = None
    for (x, y), s in zip(um.tolist(), sets.tolist(), strict=True):
        if s != current:
            buf.write(f"SP{s};")
            current = s
        buf.write(f"PU{x},{y};PD{x},{y};")
    buf.write("PU;SP0;\n")


def _csv(buf, xy: np.ndarray, d: np.ndarray, sets: np.ndarray) -> None:
    buf.write("order,x_mm,y_mm,diameter_mm,pulse_set\n")
    for i, ((x, y), dd, s) in enumerate(zip(xy.tolist(), d.tolist(), sets.tolist(), strict=True)):
        buf.write(f"{i},{x:.6f},{y:.6f},{dd:.6f},{s}\n")


def _duration(seconds: float) -> str:
    """``1 h 02 min``, ``12 min 03 s`` or ``4.2 s``."""
    if seconds >= 3600:
        h, rest = divmod(round(seconds), 3600)
        return f"{h} h {rest // 60:02d} min"
    if seconds >= 60:
        m, s = divmod(round(seconds), 60)
        return f"{m} min {s:02d} s"
    return f"{seconds:.1f} s"
