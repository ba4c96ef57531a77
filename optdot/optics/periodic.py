"""The LED grid's periodicity, used to design a direct-lit film's map with less noise.

Over a grid of identical LEDs every pitch cell sees the same light, except where the
frame breaks the symmetry. So a design cell's correction is the same as that of every
cell lying alike within its LED's pitch cell **and** alike towards the frame: the pitch
cells are classed by row (first, inner, last) and column (first, inner, last), nine
classes: the inner cells share one correction, those along an edge share theirs along
the edge, each corner keeps its own. Averaging the Monte Carlo estimate over a class cuts
its noise by the square root of the class's size (60 inner cells on a 12 x 8 grid: 7.7x)
at no cost in rays, and keeps what the frame does at the edges.

It applies when the symmetry is exact: a rectangular panel, a uniform target, LEDs on a
grid (``pitch``), design cells that divide the pitch and line up with the pitch cells.
Otherwise :func:`period_classes` returns None and each cell keeps its own estimate.
"""

from __future__ import annotations

import numpy as np

from ..config.bench import Bench

#: How close to a whole number the cells per pitch and the grid's offset must be.
TOLERANCE = 1e-6


def period_classes(bench: Bench, nx: int, ny: int, dx: float, dy: float) -> np.ndarray | None:
    """``[ny, nx]`` int64 class of each design cell (cells of one class get one
    correction), or None when the grid's symmetry does not hold (see the module doc)."""
    bl = bench.backlight
    if bl is None or bl.leds is None or bl.leds.pitch is None:
        return None
    if bench.design.target is not None or not _rectangle_panel(bench):
        return None
    px, py = bl.leds.pitch
    xy = bl.leds.positions
    x0, y0 = bench.box[:2]
    ix = _axis(nx, dx, px, float(xy[:, 0].min()) - 0.5 * px - x0, len(np.unique(xy[:, 0])))
    iy = _axis(ny, dy, py, float(xy[:, 1].min()) - 0.5 * py - y0, len(np.unique(xy[:, 1])))
    if ix is None or iy is None:
        return None
    (cx, phx, mx), (cy, phy, my) = ix, iy
    inside = (cx[None, :] >= 0) & (cy[:, None] >= 0)
    key = ((cy[:, None] * 3 + cx[None, :]) * my + phy[:, None]) * mx + phx[None, :]
    alone = 9 * mx * my + np.arange(nx * ny).reshape(ny, nx)  # cells off the pitch cells
    return np.where(inside, key, alone).astype(np.int64)


def _axis(n: int, d: float, pitch: float, start: float, leds: int):
    """Along one axis: each cell's pitch-cell class (0 first, 1 inner, 2 last; -1 off the
    pitch cells) and phase within its pitch cell, and the cells per pitch; None when the
    cells do not divide the pitch or line up with it."""
    per = pitch / d
    shift = start / d
    m = int(round(per))
    s = int(round(shift))
    if m < 1 or abs(per - m) > TOLERANCE * per or abs(shift - s) > TOLERANCE * max(1.0, per):
        return None
    k = np.arange(n) - s
    col = np.floor_divide(k, m)
    phase = k - col * m
    cls = np.where(col == 0, 0, np.where(col == leds - 1, 2, 1))
    cls = np.where((col < 0) | (col >= leds), -1, cls)
    return cls, phase, m


def fold(logq_w: np.ndarray, w: np.ndarray, classes: np.ndarray) -> np.ndarray:
    """The weighted corrections ``logq_w`` (``log q * w``) averaged over each class,
    weighted again by ``w``: ``[ny, nx]``."""
    c = classes.ravel()
    total = np.bincount(c, logq_w.ravel())
    weight = np.bincount(c, w.ravel())
    mean = np.where(weight > 0, total / np.maximum(weight, 1e-300), 0.0)
    return mean[classes] * w


def _rectangle_panel(bench: Bench) -> bool:
    """The panel is its box: the plain rectangle, or one whose only holes are the caps
    over its LEDs (they sit on the grid, so the symmetry holds)."""
    dom = bench.domain
    if dom.rectangle:
        return True
    x0, y0, x1, y1 = bench.box
    return dom.caps is not None and abs(dom.lit.area - (x1 - x0) * (y1 - y0)) <= 1e-9 * (
        (x1 - x0) * (y1 - y0)
    )
