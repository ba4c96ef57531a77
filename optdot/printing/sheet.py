"""A production sheet: the panel's mask repeated ``rows × columns`` at a pitch on one
stamper, screen or photomask, with fiducials, a label per panel and cut lines
(``[sheet]``). Lengths in mm, in the mask's coordinates (the sheet is drawn as the tool
is: a process's shrink and mirror apply to the panel inside it, not to the sheet's
layout). Panel ``(row, column)`` sits at ``(column · pitch_x, row · pitch_y)`` from the
first, row 0 at the bottom.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

#: What a fiducial may be.
FIDUCIALS = ("cross", "disc")
#: The sheet's layers (GDSII/OASIS layer, DXF layer name): fiducials, labels, cut lines.
FIDUCIAL_LAYER, LABEL_LAYER, CUT_LAYER = (10, "FIDUCIALS"), (11, "LABELS"), (12, "CUT")
#: The name of the sheet's cell (GDSII/OASIS) or the panel's block (DXF).
SHEET_CELL, PANEL_BLOCK = "SHEET", "PANEL"


@dataclass(frozen=True)
class Sheet:
    """A production sheet (``[sheet]``).

    Attributes:
        rows, columns: how many panels up and across.
        pitch: ``(x, y)`` from one panel's origin to the next, mm.
        fiducials: ``[k, 2]`` the fiducials' centres on the sheet (the first panel's
            origin at 0, 0), mm.
        fiducial: ``"cross"`` or ``"disc"``. fiducial_size: its span (a disc's
            diameter, a cross's arms end to end), mm; its bar is a tenth of it.
        label_height: the labels' text height, mm (0: no labels).
        date: the date a label states (the job's own, so that the same job writes the
            same bytes), or "".
        cut_width: the cut lines' width, mm (0: none): the pitch grid around each panel.
    """

    rows: int = 1
    columns: int = 1
    pitch: tuple[float, float] = (0.0, 0.0)
    fiducials: tuple[tuple[float, float], ...] = ()
    fiducial: str = "cross"
    fiducial_size: float = 1.0
    label_height: float = 0.5
    date: str = ""
    cut_width: float = 0.05

    def offsets(self) -> np.ndarray:
        """``[rows · columns, 2]`` each panel's offset from the first, mm, row by row."""
        j, i = np.meshgrid(np.arange(self.columns), np.arange(self.rows))
        return np.column_stack([j.ravel() * self.pitch[0], i.ravel() * self.pitch[1]])

    def fiducial_polygons(self) -> list[np.ndarray]:
        """The fiducials as polygons (``[v, 2]`` mm, counter-clockwise): a disc within a
        thousandth of its size, or a cross of two bars a tenth of its span wide."""
        out = []
        s = self.fiducial_size
        for x, y in self.fiducials:
            if self.fiducial == "disc":
                n = 64
                t = 2.0 * math.pi * np.arange(n) / n
                out.append(np.column_stack([x + 0.5 * s * np.cos(t), y + 0.5 * s * np.sin(t)]))
                continue
            a, b = 0.5 * s, 0.05 * s
            ring = [(a, b), (b, b), (b, a), (-b, a), (-b, b), (-a, b),
                    (-a, -b), (-b, -b), (-b, -a), (b, -a), (b, -b), (a, -b)]  # fmt: skip
            out.append(np.array(ring) + (x, y))
        return out

    def cut_lines(self, box) -> list[np.ndarray]:
        """The cut lines as thin rectangles (mm): the pitch cell around each panel, the
        panel's mask ``box`` centred in it, as one grid (shared edges drawn once)."""
        if self.cut_width <= 0:
            return []
        x0, y0, x1, y1 = box
        px = self.pitch[0] if self.columns > 1 else (x1 - x0) + 2.0 * self.fiducial_size
        py = self.pitch[1] if self.rows > 1 else (y1 - y0) + 2.0 * self.fiducial_size
        left = 0.5 * (x0 + x1) - 0.5 * px
        bottom = 0.5 * (y0 + y1) - 0.5 * py
        right, top = left + self.columns * px, bottom + self.rows * py
        h = 0.5 * self.cut_width
        out = []
        for k in range(self.columns + 1):
            x = left + k * px
            out.append(_rect(x - h, bottom - h, x + h, top + h))
        for k in range(self.rows + 1):
            y = bottom + k * py
            out.append(_rect(left - h, y - h, right + h, y + h))
        return out

    def label_at(self, box) -> tuple[float, float]:
        """Where a panel's label starts, mm from the panel's origin: under its mask
        ``box``, a label's height below it."""
        return (float(box[0]), float(box[1]) - 2.0 * self.label_height)


def _rect(x0, y0, x1, y1) -> np.ndarray:
    return np.array([(x0, y0), (x1, y0), (x1, y1), (x0, y1)], float)


def label_text(
    name: str, version: str, seed, job_sha: str, date: str, process, row: int, column: int
) -> str:
    """A panel's label: the job's name, optdot's version, the seed, the job's SHA-256
    prefix, the date, the process's figures, and the panel's place (``r1c2``)."""
    known = "n/a" if seed is None else seed  # a pattern file that does not say its seed
    parts = [name, f"optdot {version}", f"seed {known}", f"job {job_sha[:12]}"]
    if date:
        parts.append(date)
    if process is not None:
        figures = [f"gain {process.dot_gain * 1e3:g}um"]
        if process.shrink != (0.0, 0.0):
            s = process.shrink
            figures.append(
                f"shrink {s[0] * 100:g}%"
                if s[0] == s[1]
                else f"shrink {s[0] * 100:g}/{s[1] * 100:g}%"
            )
        if process.mirror != "none":
            figures.append(f"mirror {process.mirror}")
        parts.append(" ".join(figures))
    parts.append(f"r{row + 1}c{column + 1}")
    return "  ".join(parts)
