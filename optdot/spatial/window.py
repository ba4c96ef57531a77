"""Rectangular windows of a point set: what a tile's halo and QA's per-part gathering share."""

from __future__ import annotations

import numba as nb
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
    """The bounding box of ``xy`` (``[n, 2]``, n > 0, finite), mm.

    Compiled: numpy's ``min`` and ``max`` along the first axis of an ``[n, 2]`` array
    walk it with a stride of two (42 ms against 0.5 ms for 600k points), and a tiled run
    asks for a few boxes of each tile's dots (the throw's Morton order, its phantoms, its
    deposits).

    Raises:
        ValueError: no points.
    """
    xy = np.ascontiguousarray(xy, dtype=np.float64).reshape(-1, 2)
    if not len(xy):
        raise ValueError("the bounding box of no points")
    x0, y0, x1, y1 = _bounds(xy)
    return (float(x0), float(y0), float(x1), float(y1))


@nb.njit(cache=True)
def _bounds(xy):  # pragma: no cover - compiled
    x0 = x1 = xy[0, 0]
    y0 = y1 = xy[0, 1]
    for i in range(1, xy.shape[0]):
        x0 = min(x0, xy[i, 0])
        x1 = max(x1, xy[i, 0])
        y0 = min(y0, xy[i, 1])
        y1 = max(y1, xy[i, 1])
    return x0, y0, x1, y1
