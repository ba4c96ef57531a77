"""Laser dotting: a machine that makes dots of a few sizes (pulse sets), one after another
along a path. :class:`Laser` holds the machine's figures (``[laser]``); the path visits the
dots in serpentine bands of the width that makes it shortest, and its machining time is
estimated from the stage's speed, acceleration and the dwell per dot.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

#: Band widths tried, in mean dot spacings (the best lies near 1.5: wider bands zigzag,
#: narrower ones run back more often).
BAND_WIDTHS = (0.5, 0.75, 1.0, 1.25, 1.5, 2.0, 3.0, 4.0)


@dataclass(frozen=True)
class Laser:
    """A laser dotting machine (``[laser]``).

    Attributes:
        sizes: the dot diameters it makes, mm, ascending (a pulse set each, numbered from
            1), or None: one set, whatever the dots' size.
        speed: the stage's travel speed, mm/s, or None (no time estimated).
        acceleration: the stage's acceleration, mm/s², or None (moves at full speed).
        dwell: the time a dot takes at its place, s.
    """

    sizes: tuple[float, ...] | None = None
    speed: float | None = None
    acceleration: float | None = None
    dwell: float = 0.0

    def pulse_sets(self, diameter: np.ndarray) -> np.ndarray:
        """``[n]`` the pulse set (1-based) of dots of ``diameter`` (``[n]`` mm): the
        nearest size's; all 1 without sizes."""
        d = np.asarray(diameter, float)
        if self.sizes is None:
            return np.ones(len(d), np.int64)
        s = np.asarray(self.sizes)
        return np.argmin(np.abs(d[:, None] - s[None, :]), axis=1).astype(np.int64) + 1

    def nearest(self, diameter: np.ndarray) -> np.ndarray:
        """``[n]`` the size each diameter (``[n]`` mm) takes, mm."""
        return np.asarray(self.sizes)[self.pulse_sets(diameter) - 1]

    def move_time(self, d: np.ndarray) -> np.ndarray:
        """``[m]`` seconds for moves of ``d`` mm from rest to rest: a trapezoid
        ``d/v + v/a`` when the stage reaches its speed, else a triangle ``2 √(d/a)``."""
        v, a = self.speed, self.acceleration
        if a is None:
            return d / v
        return np.where(d >= v * v / a, d / v + v / a, 2.0 * np.sqrt(d / a))

    def machining_time(self, xy: np.ndarray) -> float | None:
        """Seconds to dot ``xy`` (``[n, 2]`` mm, in the order visited): every move plus
        the dwell per dot; None without a speed."""
        if self.speed is None:
            return None
        steps = np.hypot(*np.diff(xy, axis=0).T) if len(xy) > 1 else np.zeros(0)
        return float(self.move_time(steps).sum()) + self.dwell * len(xy)


def path_length(xy: np.ndarray) -> float:
    """The length of the path through ``xy`` (``[n, 2]`` mm) in its order, mm."""
    return float(np.hypot(*np.diff(xy, axis=0).T).sum()) if len(xy) > 1 else 0.0


def serpentine(xy: np.ndarray, width: float, y0: float) -> np.ndarray:
    """``[n]`` the order that visits ``xy`` (``[n, 2]`` mm) in horizontal bands of
    ``width`` mm from ``y0`` up, left to right in even bands and back in odd ones."""
    band = np.floor((xy[:, 1] - y0) / width).astype(np.int64)
    along = np.where(band % 2 == 0, xy[:, 0], -xy[:, 0])
    return np.lexsort((xy[:, 1], along, band))


def shortest_path(xy: np.ndarray, box) -> tuple[np.ndarray, float, float]:
    """``(order [n], band width mm, length mm)``: the serpentine of
    :data:`BAND_WIDTHS` (in mean spacings over the ``box``) whose path is shortest."""
    n = len(xy)
    if n < 2:
        return np.arange(n), 0.0, 0.0
    x0, y0, x1, y1 = box
    spacing = math.sqrt(max((x1 - x0) * (y1 - y0), 1e-12) / n)
    best = None
    for f in BAND_WIDTHS:
        order = serpentine(xy, f * spacing, y0)
        length = path_length(xy[order])
        if best is None or length < best[2]:
            best = (order, f * spacing, length)
    return best
