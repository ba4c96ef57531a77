"""Pair search in O(n log n + K): a uniform cell grid for circles of varying radius.

One search serves the OptDot relaxation (Verlet lists with a skin), the MD baseline and
the guarantee pass. Each pair is found once, from its larger circle: dot i scans the cells
within ``2 * r_i * (1 + skin)`` and keeps j when ``r_j < r_i`` (ties broken by index), so a
grid sized for the typical radius stays efficient when radii vary 5x across a map.

The result is a CSR half list: the partners of dot i are ``nbr[ptr[i]:ptr[i + 1]]``.
:func:`pairs_brute_force` is the O(n²) reference the tests compare against.
"""

from __future__ import annotations

import numba as nb
import numpy as np


@nb.njit(cache=True)
def _bin_points(xy, x0, y0, cell, nx, ny):  # pragma: no cover - compiled
    n = xy.shape[0]
    cid = np.empty(n, np.int64)
    for i in range(n):
        ix = int((xy[i, 0] - x0) / cell)
        iy = int((xy[i, 1] - y0) / cell)
        ix = min(max(ix, 0), nx - 1)
        iy = min(max(iy, 0), ny - 1)
        cid[i] = iy * nx + ix
    start = np.zeros(nx * ny + 1, np.int64)
    for i in range(n):
        start[cid[i] + 1] += 1
    for c in range(nx * ny):
        start[c + 1] += start[c]
    fill = start[:-1].copy()
    order = np.empty(n, np.int64)
    for i in range(n):
        c = cid[i]
        order[fill[c]] = i
        fill[c] += 1
    return start, order


@nb.njit(cache=True)
def _scan(i, xy, reff, grow, start, order, x0, y0, cell, nx, ny, out, pos):  # pragma: no cover
    """Count (out is None-like: size 0) or write the partners of dot i; returns count."""
    xi = xy[i, 0]
    yi = xy[i, 1]
    ri = reff[i]
    reach = 2.0 * ri * grow
    ix0 = max(int((xi - reach - x0) / cell), 0)
    ix1 = min(int((xi + reach - x0) / cell), nx - 1)
    iy0 = max(int((yi - reach - y0) / cell), 0)
    iy1 = min(int((yi + reach - y0) / cell), ny - 1)
    cnt = 0
    for cy in range(iy0, iy1 + 1):
        for cx in range(ix0, ix1 + 1):
            c = cy * nx + cx
            for k in range(start[c], start[c + 1]):
                j = order[k]
                rj = reff[j]
                if rj > ri or (rj == ri and j <= i):
                    continue
                lim = (ri + rj) * grow
                dx = xi - xy[j, 0]
                dy = yi - xy[j, 1]
                if dx * dx + dy * dy < lim * lim:
                    if out.shape[0] > 0:
                        out[pos + cnt] = j
                    cnt += 1
    return cnt


@nb.njit(parallel=True, cache=True)
def _pairs_csr(xy, reff, grow, x0, y0, cell, nx, ny):  # pragma: no cover - compiled
    start, order = _bin_points(xy, x0, y0, cell, nx, ny)
    n = xy.shape[0]
    counts = np.zeros(n + 1, np.int64)
    empty = np.empty(0, np.int32)
    for i in nb.prange(n):
        counts[i + 1] = _scan(i, xy, reff, grow, start, order, x0, y0, cell, nx, ny, empty, 0)
    ptr = np.cumsum(counts)
    nbr = np.empty(ptr[n], np.int32)
    for i in nb.prange(n):
        _scan(i, xy, reff, grow, start, order, x0, y0, cell, nx, ny, nbr, ptr[i])
    return ptr, nbr


def neighbor_pairs(
    xy: np.ndarray, radius: np.ndarray | float, skin: float = 0.0
) -> tuple[np.ndarray, np.ndarray]:
    """All pairs of circles whose distance is below ``(r_i + r_j) * (1 + skin)``.

    Args:
        xy: ``[n, 2]`` float64 centres, mm.
        radius: ``[n]`` radii (or one radius), mm, > 0.
        skin: relative margin; pairs up to ``(1 + skin)`` times touching are listed.

    Returns:
        ``(ptr, nbr)``: CSR half list, ``ptr`` ``[n + 1]`` int64, ``nbr`` ``[K]`` int32;
        every unordered pair appears once.
    """
    xy = np.ascontiguousarray(xy, dtype=np.float64)
    n = xy.shape[0]
    reff = np.ascontiguousarray(np.broadcast_to(np.asarray(radius, np.float64), (n,)))
    if n == 0:
        return np.zeros(1, np.int64), np.zeros(0, np.int32)
    grow = 1.0 + float(skin)
    lo = xy.min(axis=0)
    hi = xy.max(axis=0)
    # cell side: twice the median reach, but never so small that the grid explodes
    cell = 2.0 * float(np.median(reff)) * grow
    span = float(max(hi[0] - lo[0], hi[1] - lo[1], cell))
    cell = max(cell, span / 8192.0, np.finfo(float).tiny)
    nx = int((hi[0] - lo[0]) / cell) + 1
    ny = int((hi[1] - lo[1]) / cell) + 1
    return _pairs_csr(xy, reff, grow, float(lo[0]), float(lo[1]), cell, nx, ny)


def pairs_within(xy: np.ndarray, distance: float) -> np.ndarray:
    """All pairs of centres closer than ``distance`` (strictly), as ``[K, 2]`` int64 with i < j.

    Args:
        xy: ``[n, 2]`` centres, mm.
        distance: mm.
    """
    ptr, nbr = neighbor_pairs(xy, 0.5 * distance)
    return csr_to_pairs(ptr, nbr)


def csr_to_pairs(ptr: np.ndarray, nbr: np.ndarray) -> np.ndarray:
    """Turn a CSR half list into sorted ``[K, 2]`` int64 pairs with ``i < j``."""
    i = np.repeat(np.arange(len(ptr) - 1, dtype=np.int64), np.diff(ptr))
    j = nbr.astype(np.int64)
    p = np.stack([np.minimum(i, j), np.maximum(i, j)], axis=1)
    if len(p):
        p = p[np.lexsort((p[:, 1], p[:, 0]))]
    return p


def pairs_brute_force(xy: np.ndarray, radius: np.ndarray | float, skin: float = 0.0) -> np.ndarray:
    """O(n²) reference of :func:`neighbor_pairs`, as sorted ``[K, 2]`` int64 pairs, i < j."""
    xy = np.asarray(xy, dtype=np.float64)
    n = len(xy)
    r = np.broadcast_to(np.asarray(radius, np.float64), (n,))
    d2 = ((xy[:, None, :] - xy[None, :, :]) ** 2).sum(-1)
    lim = (r[:, None] + r[None, :]) * (1.0 + skin)
    i, j = np.nonzero(np.triu(d2 < lim * lim, k=1))
    return np.stack([i, j], axis=1).astype(np.int64)


def spatial_order(xy: np.ndarray) -> np.ndarray:
    """Permutation sorting points along a Morton (Z-order) curve, ``[n]`` int64.

    Neighbouring dots end up close in memory, which speeds up every pair kernel.
    """
    xy = np.asarray(xy, dtype=np.float64)
    if len(xy) == 0:
        return np.zeros(0, np.int64)
    lo = xy.min(axis=0)
    span = max(float((xy.max(axis=0) - lo).max()), 1e-300)
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
