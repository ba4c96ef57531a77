"""Rectangular windows of a point set: what a tile's halo and QA's per-part gathering share."""

from __future__ import annotations

import numpy as np

#: ``(x0, y0, x1, y1)``, mm.
Rect = tuple[float, float, float, float]


def grown(rect: Rect, margin: float) -> Rect:
    """``rect`` grown by ``margin`` (mm) on every side."""
    x0, y0, x1, y1 = rect
    return (x0 - margin, y0 - margin, x1 + margin, y1 + margin)


def in_rect(xy: np.ndarray, rect: Rect, closed: bool = True) -> np.ndarray:
    """``[n]`` bool: the point of ``xy`` (``[n, 2]`` mm) lies in ``rect`` (edges
    included when ``closed``)."""
    x, y = xy[:, 0], xy[:, 1]
    r = rect
    if closed:
        return (x >= r[0]) & (x <= r[2]) & (y >= r[1]) & (y <= r[3])
    return (x > r[0]) & (x < r[2]) & (y > r[1]) & (y < r[3])


def bounds(xy: np.ndarray) -> Rect:
    """The bounding box of ``xy`` (``[n, 2]``, n > 0), mm."""
    lo, hi = xy.min(axis=0), xy.max(axis=0)
    return (float(lo[0]), float(lo[1]), float(hi[0]), float(hi[1]))
