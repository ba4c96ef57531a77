"""Morton (Z-order) sorting of points: neighbours in space end up close in memory."""

from __future__ import annotations

import numpy as np


def spatial_order(xy: np.ndarray) -> np.ndarray:
    """Permutation sorting points along a Morton (Z-order) curve, ``[n]`` int64.

    Neighbouring dots end up close in memory, which speeds up every pair kernel.
    """
    xy = np.asarray(xy, dtype=np.float64)
    if len(xy) == 0:
        return np.zeros(0, np.int64)
    # column by column: numpy's min and max along the first axis of an [n, 2] array walk
    # it with a stride of two, 30x slower (optdot.spatial.window.bounds)
    x, y = xy[:, 0], xy[:, 1]
    lo = np.array([x.min(), y.min()])
    span = max(float((np.array([x.max(), y.max()]) - lo).max()), 1e-300)
    q = np.minimum(((xy - lo) / span * 65535.0).astype(np.uint64), 65535)
    code = _spread(q[:, 0]) | (_spread(q[:, 1]) << np.uint64(1))
    return np.argsort(code, kind="stable")


def _spread(v: np.ndarray) -> np.ndarray:
    v = v & np.uint64(0xFFFF)
    v = (v | (v << np.uint64(8))) & np.uint64(0x00FF00FF)
    v = (v | (v << np.uint64(4))) & np.uint64(0x0F0F0F0F)
    v = (v | (v << np.uint64(2))) & np.uint64(0x33333333)
    v = (v | (v << np.uint64(1))) & np.uint64(0x55555555)
    return v
