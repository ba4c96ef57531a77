"""Pair search in O(n log n + K): a uniform cell grid for circles of varying radius.

One search serves the OptDot relaxation (Verlet lists with a skin), the MD baseline and
the guarantee pass. Each pair is found once, from its larger circle: dot i scans the cells
within ``2 * r_i * (1 + skin)`` and keeps j when ``r_j < r_i`` (ties broken by index), so a
grid sized for the typical radius stays efficient when radii vary 5x across a map.

The result is a CSR half list: the partners of dot i are ``nbr[ptr[i]:ptr[i + 1]]``.
:func:`pairs_brute_force` is the O(n²) reference the tests compare against.
"""

from __future__ import annotations

from dataclasses import dataclass

import numba as nb
import numpy as np

#: Dots per block of the parallel pair kernels (penalty, MD forces). Fixed, not the
#: thread count, so sums are added in the same order on every machine: bit-identical.
BLOCK = 4096


@nb.njit(cache=True)
def _bin_points(xy, reff, x0, y0, cell, nx, ny):  # pragma: no cover - compiled
    """Counting sort of the dots into cells; returns cell starts and sorted copies.

    The copies (index, x, y, radius in cell order) make every cell scan read contiguous
    memory, which is what the scan's speed depends on.
    """
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
    order = np.empty(n, np.int32)
    cellmax = np.zeros(nx * ny)
    bx = np.empty(n)
    by = np.empty(n)
    br = np.empty(n)
    for i in range(n):
        c = cid[i]
        k = fill[c]
        order[k] = i
        bx[k] = xy[i, 0]
        by[k] = xy[i, 1]
        br[k] = reff[i]
        cellmax[c] = max(cellmax[c], reff[i])
        fill[c] += 1
    return start, order, bx, by, br, cellmax


@nb.njit(cache=True)
def _scan(
    i, xy, reff, grow, start, order, bx, by, br, x0, y0, cell, nx, ny, buf
):  # pragma: no cover
    """Partners of dot i: writes them to ``buf`` (as many as fit) and returns how many.

    Branch-free inner loop: a candidate is written at the cursor, which then advances by
    the test's 0/1 (clamped to the last slot, so ``buf`` is never overrun); the caller
    knows ``buf`` held them all when the count is below ``len(buf)``.
    """
    xi = xy[i, 0]
    yi = xy[i, 1]
    ri = reff[i]
    reach = 2.0 * ri * grow
    ix0 = max(int((xi - reach - x0) / cell), 0)
    ix1 = min(int((xi + reach - x0) / cell), nx - 1)
    iy0 = max(int((yi - reach - y0) / cell), 0)
    iy1 = min(int((yi + reach - y0) / cell), ny - 1)
    last = buf.shape[0] - 1
    cnt = 0
    for cy in range(iy0, iy1 + 1):
        row = cy * nx
        for k in range(start[row + ix0], start[row + ix1 + 1]):
            rj = br[k]
            j = order[k]
            dx = xi - bx[k]
            dy = yi - by[k]
            lim = (ri + rj) * grow
            keep = (dx * dx + dy * dy < lim * lim) & ((rj < ri) | ((rj == ri) & (j > i)))
            buf[min(cnt, last)] = j
            cnt += np.int64(keep)
    return cnt


_CHUNK = 2048


@nb.njit(parallel=True, cache=True)
def _pairs_csr(xy, reff, grow, x0, y0, cell, nx, ny, per_dot):  # pragma: no cover - compiled
    """One scan per dot into per-chunk segments of ``per_dot * _CHUNK`` slots, then one
    copy into the CSR arrays; a chunk whose segment overflowed is scanned again."""
    start, order, bx, by, br, cellmax = _bin_points(xy, reff, x0, y0, cell, nx, ny)
    n = xy.shape[0]
    nchunk = (n + _CHUNK - 1) // _CHUNK
    cap = per_dot * _CHUNK
    seg = np.empty(nchunk * cap, np.int32)
    counts = np.zeros(n + 1, np.int64)
    over = np.zeros(nchunk, np.bool_)
    for c in nb.prange(nchunk):
        row = np.empty(256, np.int32)
        pos = c * cap
        end = pos + cap
        for i in range(c * _CHUNK, min((c + 1) * _CHUNK, n)):
            m = _scan(i, xy, reff, grow, start, order, bx, by, br, x0, y0, cell, nx, ny, row)
            counts[i + 1] = m
            if m >= row.shape[0] or pos + m > end:
                over[c] = True
            elif not over[c]:
                seg[pos : pos + m] = row[:m]
                pos += m
    ptr = np.cumsum(counts)
    nbr = np.empty(ptr[n], np.int32)
    for c in nb.prange(nchunk):
        a = c * _CHUNK
        b = min(a + _CHUNK, n)
        if not over[c]:
            nbr[ptr[a] : ptr[b]] = seg[c * cap : c * cap + ptr[b] - ptr[a]]
            continue
        row = np.empty(counts[a + 1 : b + 1].max() + 1, np.int32)
        for i in range(a, b):
            m = _scan(i, xy, reff, grow, start, order, bx, by, br, x0, y0, cell, nx, ny, row)
            nbr[ptr[i] : ptr[i] + m] = row[:m]
    return ptr, nbr, start, order, cellmax


@dataclass
class CellGrid:
    """Dots binned into square cells at build time (cell order = counting sort).

    Attributes:
        x0, y0: lower-left corner of cell (0, 0), mm.
        cell: cell side, mm.
        nx, ny: cells per row and per column.
        start: ``[nx * ny + 1]`` int64, dots of cell c are ``order[start[c]:start[c + 1]]``.
        order: ``[n]`` int32 dot indices in cell order.
        cellmax: ``[nx * ny]`` largest radius binned in each cell, mm.
    """

    x0: float
    y0: float
    cell: float
    nx: int
    ny: int
    start: np.ndarray
    order: np.ndarray
    cellmax: np.ndarray


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


def cell_side(reff: np.ndarray, skin: float) -> float:
    """Default grid cell: twice the median reach ``2 * median(reff) * (1 + skin)``, mm."""
    return 2.0 * float(np.median(reff)) * (1.0 + skin)


def _grid_shape(xy: np.ndarray, cell: float) -> tuple[float, float, float, int, int]:
    x0, y0, x1, y1 = _bounds(xy)
    # never so small a cell that the grid explodes
    cell = max(cell, max(x1 - x0, y1 - y0) / 8192.0, np.finfo(float).tiny)
    nx = int((x1 - x0) / cell) + 1
    ny = int((y1 - y0) / cell) + 1
    return x0, y0, cell, nx, ny


def neighbor_grid(
    xy: np.ndarray,
    radius: np.ndarray | float,
    skin: float = 0.0,
    cell: float | None = None,
    per_dot: int = 8,
) -> tuple[np.ndarray, np.ndarray, CellGrid]:
    """:func:`neighbor_pairs` that also returns the :class:`CellGrid` it binned into.

    ``cell`` (mm) defaults to :func:`cell_side`; callers that build often pass it once.
    ``per_dot`` is the expected partners per dot (a guess: more costs memory, fewer a
    second scan of the chunks that overflow; the result is the same).
    """
    xy = np.ascontiguousarray(xy, dtype=np.float64)
    n = xy.shape[0]
    reff = np.ascontiguousarray(np.broadcast_to(np.asarray(radius, np.float64), (n,)))
    if n == 0:
        empty = CellGrid(
            0.0, 0.0, 1.0, 1, 1, np.zeros(2, np.int64), np.zeros(0, np.int32), np.zeros(1)
        )
        return np.zeros(1, np.int64), np.zeros(0, np.int32), empty
    grow = 1.0 + float(skin)
    x0, y0, cell, nx, ny = _grid_shape(xy, cell_side(reff, skin) if cell is None else cell)
    ptr, nbr, start, order, cellmax = _pairs_csr(
        xy, reff, grow, x0, y0, cell, nx, ny, max(int(per_dot), 1)
    )
    return ptr, nbr, CellGrid(x0, y0, cell, nx, ny, start, order, cellmax)


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
    ptr, nbr, _ = neighbor_grid(xy, radius, skin)
    return ptr, nbr


@nb.njit(cache=True)
def _mover_pairs(
    xy, reff, movers, is_mover, grow, start, order, cellmax, x0, y0, cell, nx, ny
):  # pragma: no cover
    """Pairs closer than ``re_i + re_j`` now between a mover i and a non-mover j.

    A cell is scanned only if its rectangle is within ``re_i + cellmax * grow`` of the
    mover: every non-mover j binned there is within ``skin * re_j`` of its bin position.
    """
    cap = 64
    ei = np.empty(cap, np.int32)
    ej = np.empty(cap, np.int32)
    m = 0
    rmax = 0.0
    for c in range(cellmax.shape[0]):
        rmax = max(rmax, cellmax[c])
    for a in range(movers.shape[0]):
        i = movers[a]
        xi = xy[i, 0]
        yi = xy[i, 1]
        reach = reff[i] + rmax * grow
        ix0 = max(int((xi - reach - x0) / cell), 0)
        ix1 = min(int((xi + reach - x0) / cell), nx - 1)
        iy0 = max(int((yi - reach - y0) / cell), 0)
        iy1 = min(int((yi + reach - y0) / cell), ny - 1)
        for cy in range(iy0, iy1 + 1):
            ey = max(y0 + cy * cell - yi, yi - (y0 + (cy + 1) * cell), 0.0)
            for cx in range(ix0, ix1 + 1):
                c = cy * nx + cx
                if start[c] == start[c + 1]:
                    continue
                ex = max(x0 + cx * cell - xi, xi - (x0 + (cx + 1) * cell), 0.0)
                lim = reff[i] + cellmax[c] * grow + 1e-9 * cell  # binning round-off
                if ex * ex + ey * ey >= lim * lim:
                    continue
                for k in range(start[c], start[c + 1]):
                    j = order[k]
                    if is_mover[j]:  # binned where it was, not where it is
                        continue
                    lim = reff[i] + reff[j]
                    dx = xi - xy[j, 0]
                    dy = yi - xy[j, 1]
                    if dx * dx + dy * dy < lim * lim:
                        if m == cap:
                            cap *= 2
                            ei2 = np.empty(cap, np.int32)
                            ej2 = np.empty(cap, np.int32)
                            ei2[:m] = ei[:m]
                            ej2[:m] = ej[:m]
                            ei, ej = ei2, ej2
                        ei[m] = i
                        ej[m] = j
                        m += 1
    return ei[:m], ej[:m]


def mover_pairs(
    xy: np.ndarray,
    reff: np.ndarray,
    movers: np.ndarray,
    is_mover: np.ndarray,
    skin: float,
    grid: CellGrid,
) -> tuple[np.ndarray, np.ndarray]:
    """Pairs ``(i, j)`` with ``|x_i - x_j| < re_i + re_j`` now, at least one a mover.

    A *mover* moved more than ``skin * re`` since ``grid`` was built; every other dot is
    within ``skin * re_j`` of where the grid binned it, so scanning the grid around a
    mover over the cells within ``re_i + max(re in cell) * (1 + skin)`` finds all its
    partners. Movers may
    sit anywhere, so the grid (binned at the old positions) cannot find pairs of two
    movers: those come from a fresh search over the movers alone.

    Args:
        xy: ``[n, 2]`` current positions, mm.
        reff: ``[n]`` effective radii, mm.
        movers: ``[M]`` int64 mover indices, ascending.
        is_mover: ``[n]`` bool mask of the same.
        skin: the skin the grid was built with.
        grid: the grid of the last full build.

    Returns:
        ``(ei, ej)``: ``[P]`` int32 each.
    """
    ei, ej = _mover_pairs(
        xy,
        reff,
        movers,
        is_mover,
        1.0 + skin,
        grid.start,
        grid.order,
        grid.cellmax,
        grid.x0,
        grid.y0,
        grid.cell,
        grid.nx,
        grid.ny,
    )
    ptr, nbr = neighbor_pairs(xy[movers], reff[movers], 0.0)
    if len(nbr):
        mi = movers[np.repeat(np.arange(len(movers)), np.diff(ptr))].astype(np.int32)
        ei = np.concatenate([ei, mi])
        ej = np.concatenate([ej, movers[nbr].astype(np.int32)])
    return ei, ej


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


@nb.njit(parallel=True, cache=True)
def _split_blocks(ptr, nbr):  # pragma: no cover - compiled
    """Reorder each dot's partners: same BLOCK first; returns (nbr', mid, cross)."""
    n = ptr.shape[0] - 1
    out = np.empty_like(nbr)
    mid = np.empty(n, np.int64)
    has_cross = np.zeros(n, np.bool_)
    for i in nb.prange(n):
        b = i // BLOCK
        k = ptr[i]
        for q in range(ptr[i], ptr[i + 1]):
            if nbr[q] // BLOCK == b:
                out[k] = nbr[q]
                k += 1
        mid[i] = k
        for q in range(ptr[i], ptr[i + 1]):
            if nbr[q] // BLOCK != b:
                out[k] = nbr[q]
                k += 1
        has_cross[i] = k > mid[i]
    return out, mid, np.flatnonzero(has_cross)


@dataclass
class PairList:
    """A CSR half list prepared for the block-parallel pair kernels, plus movers' pairs.

    Attributes:
        ptr: ``[n + 1]`` int64; partners of i are ``nbr[ptr[i]:ptr[i + 1]]``.
        nbr: ``[K]`` int32, each row with same-block partners first.
        mid: ``[n]`` int64, end of row i's same-block partners.
        skip: ``[n]`` bool, dots whose pairs come only from the extra list.
        cross: ``[C]`` int64 ascending, the rows with partners in other blocks.
        ei, ej: ``[P]`` int32 extra pairs (each once).
    """

    ptr: np.ndarray
    nbr: np.ndarray
    mid: np.ndarray
    skip: np.ndarray
    cross: np.ndarray
    ei: np.ndarray
    ej: np.ndarray

    @classmethod
    def from_csr(cls, ptr: np.ndarray, nbr: np.ndarray) -> PairList:
        """Wrap a CSR half list from :func:`optdot.neighbors.neighbor_pairs`."""
        nbr2, mid, cross = _split_blocks(ptr, nbr)
        none = np.zeros(0, np.int32)
        return cls(ptr, nbr2, mid, np.zeros(len(ptr) - 1, np.bool_), cross, none, none)


@nb.njit(cache=True)
def _new_movers(xy, ref, limit, is_mover):  # pragma: no cover - compiled
    """Mark dots that moved more than ``limit`` from ``ref``; returns how many are new."""
    new = 0
    for i in range(xy.shape[0]):
        if is_mover[i]:
            continue
        dx = xy[i, 0] - ref[i, 0]
        dy = xy[i, 1] - ref[i, 1]
        if dx * dx + dy * dy > limit[i] * limit[i]:
            is_mover[i] = True
            new += 1
    return new


class VerletList:
    """A Verlet list for circles of radii ``reff``, patched for the few dots that move far.

    The list holds every pair closer than ``(re_i + re_j) * (1 + skin)`` at build time. A
    pair it misses needs one of its dots to have moved more than ``skin * re`` since the
    build. Such dots (*movers*; typically a few dozen of 10⁵) leave the list: their pairs
    are searched afresh at every update (:func:`mover_pairs`). The list is rebuilt from
    scratch only when movers exceed ``rebuild_fraction`` of the dots. After
    :meth:`update`, :attr:`pairs` holds every pair closer than ``re_i + re_j``, once.

    Args:
        reff: ``[n]`` interaction radii, mm.
        skin: relative skin.
        rebuild_fraction: share of movers that triggers a full rebuild.
    """

    def __init__(self, reff: np.ndarray, skin: float, rebuild_fraction: float = 0.01) -> None:
        self.reff = np.ascontiguousarray(reff, dtype=np.float64)
        self.skin = skin
        self.limit = skin * self.reff
        self.cell = cell_side(self.reff, skin) if len(self.reff) else 1.0
        self.max_movers = max(16, int(rebuild_fraction * len(self.reff)))
        self.ref: np.ndarray | None = None
        self.pairs: PairList | None = None
        self.grid: CellGrid | None = None
        self.rebuilds = 0
        self.n_movers = 0

    def _rebuild(self, xy: np.ndarray) -> None:
        # guess partners per dot from the last build (+25 %); drop the old list first so
        # the two never sit in memory together
        per_dot = 8 if self.pairs is None else 2 + 5 * len(self.pairs.nbr) // (4 * len(xy))
        self.pairs = self.grid = None
        ptr, nbr, self.grid = neighbor_grid(xy, self.reff, self.skin, self.cell, per_dot)
        self.pairs = PairList.from_csr(ptr, nbr)
        self.ref = xy.copy()
        self.n_movers = 0
        self.rebuilds += 1

    def update(self, xy: np.ndarray) -> PairList:
        """The pair list valid at positions ``xy`` (``[n, 2]`` mm)."""
        if self.pairs is None:
            self._rebuild(xy)
        self.n_movers += _new_movers(xy, self.ref, self.limit, self.pairs.skip)
        if self.n_movers > self.max_movers:
            self._rebuild(xy)
        elif self.n_movers:
            pl = self.pairs
            movers = np.flatnonzero(pl.skip)
            pl.ei, pl.ej = mover_pairs(xy, self.reff, movers, pl.skip, self.skin, self.grid)
        return self.pairs
