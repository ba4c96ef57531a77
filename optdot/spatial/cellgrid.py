"""Pair search in O(n log n + K): a uniform cell grid for circles of varying radius.

A pure function of positions and radii (and an optional frozen halo): :func:`neighbor_list`
returns every pair closer than ``(r_i + r_j) * (1 + skin)``, once, found from its larger
circle: dot i scans the cells within ``2 * r_i * (1 + skin)`` and keeps j when
``r_j < r_i`` (ties broken by index), so a grid sized for the typical radius stays
efficient when radii vary 5x across a map. The result is a CSR half list: the partners
of dot i are ``nbr[ptr[i]:ptr[i + 1]]``. :func:`optdot.testing.pairs_brute_force` is the
O(n²) reference the tests compare against. What to do with the list over an optimisation (the
Verlet policy) lives in :mod:`optdot.spatial.verlet`; the block layout of the parallel
kernels in :mod:`optdot.spatial.blocks`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numba as nb
import numpy as np

from .blocks import PairList, put_row
from .window import bounds

#: Most index ranges the counting sort splits the dots into (each holds a count per cell;
#: the sort is stable, so its result is the same for any split).
_BIN_PARTS = 4


def bin_parts() -> int:
    """Index ranges the counting sort of :func:`_bin_points` runs in parallel: one per
    thread, at most :data:`_BIN_PARTS` (each holds a count per cell)."""
    return max(1, min(_BIN_PARTS, nb.get_num_threads()))


@nb.njit(cache=True, inline="always")
def _cell_id(x, y, x0, y0, cell, nx, ny):  # pragma: no cover - compiled
    """The row-major id of the cell a point at (x, y) is binned into (clamped to the
    grid): one rule for the counting sort and the bisected search."""
    ix = min(max(int((x - x0) / cell), 0), nx - 1)
    iy = min(max(int((y - y0) / cell), 0), ny - 1)
    return iy * nx + ix


@nb.njit(parallel=True, cache=True)
def _bin_points(
    xy, reff, x0, y0, cell, nx, ny, parts, cid, at, start, order, bx, by, br, cellmax
):  # pragma: no cover - compiled
    """Counting sort of the dots into cells, written into the arrays given (any contents:
    every entry is overwritten): ``cid`` ``[n]`` int64, ``at`` at least ``[parts *
    ncell]`` int64, ``start`` ``[ncell + 1]`` int64, ``order`` ``[n]`` int32, the sorted
    copies ``bx``, ``by``, ``br`` ``[n]`` and ``cellmax`` ``[ncell]``.

    The copies (index, x, y, radius in cell order) make every cell scan read contiguous
    memory, which is what the scan's speed depends on. The sort is stable (a cell's dots
    in index order) and runs in parallel over a few index ranges, each placing its dots
    after those of the ranges before it (``parts`` of them at most, see
    :func:`bin_parts`): the result is the same for any ``parts``.
    """
    n = xy.shape[0]
    ncell = nx * ny
    for i in nb.prange(n):
        cid[i] = _cell_id(xy[i, 0], xy[i, 1], x0, y0, cell, nx, ny)
    parts = max(1, min(parts, n // 65536))
    step = (n + parts - 1) // parts
    at = at[: parts * ncell].reshape((parts, ncell))  # counts, then each range's next slot
    for p in nb.prange(parts):
        at[p, :] = 0
        for i in range(p * step, min((p + 1) * step, n)):
            at[p, cid[i]] += 1
    running = 0
    for c in range(ncell):
        start[c] = running
        for p in range(parts):
            m = at[p, c]
            at[p, c] = running
            running += m
    start[ncell] = running
    for p in nb.prange(parts):
        for i in range(p * step, min((p + 1) * step, n)):
            c = cid[i]
            k = at[p, c]
            order[k] = i
            bx[k] = xy[i, 0]
            by[k] = xy[i, 1]
            br[k] = reff[i]
            at[p, c] = k + 1
    for c in nb.prange(ncell):
        m = 0.0
        for k in range(start[c], start[c + 1]):
            m = max(m, br[k])
        cellmax[c] = m


class Workspace:
    """The arrays of a cell-grid search, kept from one search to the next: a Verlet list
    rebuilt a dozen times over one relaxation writes every rebuild into the same memory.
    Fresh arrays would make every rebuild fault in fresh pages (83 MB a rebuild at 1.2M
    dots, twenty times the page faults over a run). What a search returns lives in these arrays
    until the next search with the same workspace; ``Workspace(keep=False)`` hands out
    fresh arrays every time.
    """

    def __init__(self, keep: bool = True) -> None:
        self.keep = keep
        self._arrays: dict[str, np.ndarray] = {}

    def take(self, name: str, size: int, dtype) -> np.ndarray:
        """``[size]`` array of ``dtype`` (contents undefined): the kept one when it is
        large enough, else a new one (kept when the workspace keeps its arrays)."""
        a = self._arrays.get(name)
        if a is None or a.shape[0] < size or a.dtype != dtype:
            a = np.empty(size, dtype)
            if self.keep:
                self._arrays[name] = a
        return a[:size]


def bin_points(
    xy: np.ndarray, reff: np.ndarray, x0: float, y0: float, cell: float, nx: int, ny: int,
    parts: int, ws: Workspace | None = None,
) -> tuple[np.ndarray, ...]:  # fmt: skip
    """:func:`_bin_points` into ``ws``'s arrays (fresh ones without): ``(start [ncell +
    1], order [n], bx [n], by [n], br [n], cellmax [ncell])``."""
    ws = Workspace(keep=False) if ws is None else ws
    n, ncell = xy.shape[0], nx * ny
    out = (
        ws.take("start", ncell + 1, np.int64),
        ws.take("order", n, np.int32),
        ws.take("bx", n, np.float64),
        ws.take("by", n, np.float64),
        ws.take("br", n, np.float64),
        ws.take("cellmax", ncell, np.float64),
    )
    cid = ws.take("cid", n, np.int64)
    at = ws.take("at", max(1, min(parts, n // 65536)) * ncell, np.int64)
    _bin_points(xy, reff, x0, y0, cell, nx, ny, parts, cid, at, *out)
    return out


@nb.njit(cache=True)
def _scan(
    i, xy, reff, grow, start, keys, order, bx, by, br, x0, y0, cell, nx, ny, buf
):  # pragma: no cover
    """Partners of dot i: writes them to ``buf`` (as many as fit) and returns how many.

    Branch-free inner loop: a candidate is written at the cursor, which then advances by
    the test's 0/1 (clamped to the last slot, so ``buf`` is never overrun); the caller
    knows ``buf`` held them all when the count is below ``len(buf)``. A row's cells are
    ``start[row + ix0]`` to ``start[row + ix1 + 1]`` of the sorted copies (a dense grid),
    or, when ``keys`` (the sorted copies' cell ids) is given, found in it by bisection (a
    sparse one): the same candidates in the same order.
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
    sparse = keys.shape[0] > 0
    for cy in range(iy0, iy1 + 1):
        row = cy * nx
        if sparse:
            lo = np.searchsorted(keys, row + ix0)
            hi = np.searchsorted(keys, row + ix1, side="right")
        else:
            lo = start[row + ix0]
            hi = start[row + ix1 + 1]
        for k in range(lo, hi):
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


@nb.njit(cache=True)
def _pairs_sparse(xy, reff, grow, x0, y0, cell, nx, ny):  # pragma: no cover - compiled
    """:func:`_pairs_csr`'s ``(ptr, nbr)`` for a few dots on a grid of many cells: the
    dots sorted by cell id (stably, so a cell's dots in index order, as the counting sort
    leaves them) and each row's cells found by bisection, so nothing is the size of the
    grid. The same pairs in the same order."""
    n = xy.shape[0]
    cid = np.empty(n, np.int64)
    for i in range(n):
        cid[i] = _cell_id(xy[i, 0], xy[i, 1], x0, y0, cell, nx, ny)
    sort = np.argsort(cid, kind="mergesort")
    keys = cid[sort]
    order = sort.astype(np.int32)
    bx = np.empty(n)
    by = np.empty(n)
    br = np.empty(n)
    for k in range(n):
        bx[k] = xy[sort[k], 0]
        by[k] = xy[sort[k], 1]
        br[k] = reff[sort[k]]
    no_start = np.zeros(0, np.int64)
    ptr = np.zeros(n + 1, np.int64)
    nbr = np.empty(max(16, 8 * n), np.int32)
    row = np.empty(256, np.int32)
    for i in range(n):
        m = _scan(i, xy, reff, grow, no_start, keys, order, bx, by, br, x0, y0, cell, nx, ny, row)
        while m >= row.shape[0]:  # the row buffer was full: again with room for all
            row = np.empty(2 * m, np.int32)
            m = _scan(
                i, xy, reff, grow, no_start, keys, order, bx, by, br, x0, y0, cell, nx, ny, row
            )
        if ptr[i] + m > nbr.shape[0]:
            more = np.empty(2 * (ptr[i] + m), np.int32)
            more[: ptr[i]] = nbr[: ptr[i]]
            nbr = more
        nbr[ptr[i] : ptr[i] + m] = row[:m]
        ptr[i + 1] = ptr[i] + m
    return ptr, nbr[: ptr[n]].copy()


@nb.njit(parallel=True, cache=True)
def _pairs_csr(
    xy, reff, grow, x0, y0, cell, nx, ny, per_dot, split, bins, seg, ptr, nbr, mid, has_cross
):  # pragma: no cover - compiled
    """One scan per dot into per-chunk segments of ``per_dot * _CHUNK`` slots (``seg``,
    at least that many a chunk), then one copy into the CSR arrays; a chunk whose segment
    overflowed is scanned again. ``bins``: :func:`_bin_points`'s sorted dots. ``ptr``
    ``[n + 1]`` is written; ``nbr`` is used when large enough, else a new one is made;
    with ``split`` each row is laid out for the block kernels
    (:func:`~optdot.spatial.blocks.put_row`; ``mid`` and ``has_cross`` ``[n]`` written).
    Returns ``(nbr [K], overflowed)``."""
    start, order, bx, by, br, cellmax = bins
    no_keys = np.zeros(0, np.int64)  # a dense grid: rows from ``start``
    n = xy.shape[0]
    nchunk = (n + _CHUNK - 1) // _CHUNK
    cap = per_dot * _CHUNK
    over = np.zeros(nchunk, np.bool_)
    ptr[0] = 0
    for c in nb.prange(nchunk):
        row = np.empty(256, np.int32)
        pos = c * cap
        end = pos + cap
        for i in range(c * _CHUNK, min((c + 1) * _CHUNK, n)):
            m = _scan(
                i, xy, reff, grow, start, no_keys, order, bx, by, br, x0, y0, cell, nx, ny, row
            )
            ptr[i + 1] = m
            if m >= row.shape[0] or pos + m > end:
                over[c] = True
            elif not over[c]:
                seg[pos : pos + m] = row[:m]
                pos += m
    for i in range(n):
        ptr[i + 1] += ptr[i]
    if ptr[n] > nbr.shape[0]:
        nbr = np.empty(ptr[n], np.int32)
    else:
        nbr = nbr[: ptr[n]]
    for c in nb.prange(nchunk):
        a = c * _CHUNK
        b = min(a + _CHUNK, n)
        if not over[c]:
            lo = c * cap
            if not split:
                nbr[ptr[a] : ptr[b]] = seg[lo : lo + ptr[b] - ptr[a]]
                continue
            for i in range(a, b):
                m = ptr[i + 1] - ptr[i]
                put_row(i, seg, lo, m, nbr, ptr[i], split, mid, has_cross)
                lo += m
            continue
        big = 0
        for i in range(a, b):
            big = max(big, ptr[i + 1] - ptr[i])
        row = np.empty(big + 1, np.int32)
        for i in range(a, b):
            m = _scan(
                i, xy, reff, grow, start, no_keys, order, bx, by, br, x0, y0, cell, nx, ny, row
            )
            put_row(i, row, 0, m, nbr, ptr[i], split, mid, has_cross)
    return nbr, over.any()


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


#: Cells a dot beyond which :func:`neighbor_pairs` bisects the dots' cell ids instead of
#: binning them into the whole grid (whose arrays and loops are the size of the grid:
#: the movers of a large panel's Verlet list spread over ~10^7 cells).
SPARSE_CELLS = 16


def cell_side(reff: np.ndarray, skin: float) -> float:
    """Default grid cell: twice the median reach ``2 * median(reff) * (1 + skin)``, mm."""
    return 2.0 * float(np.median(reff)) * (1.0 + skin)


#: Most grid cells per point: a cell side from the median reach of points whose reach is
#: tiny (the phantoms of a hard-core pass, their soft circles shrunk a thousandfold) made
#: a grid of 59 million cells for 354k points (167 a point; binning 0.4 s a rebuild,
#: 1.4 GB). The samples' grids hold 2-16 cells a point: they keep their cells, and bytes.
CELLS_PER_POINT = 32.0


def _grid_shape(
    xy: np.ndarray, cell: float, crowd: bool = False
) -> tuple[float, float, float, int, int]:
    """``(x0, y0, cell, nx, ny)`` of the grid over ``xy`` with cells of ``cell`` mm, never
    so small that the grid explodes: at most 8192 a side and, with ``crowd``, at most
    :data:`CELLS_PER_POINT` cells a point (the scan reaches each pair's partner whatever
    the side: a larger cell only holds more points)."""
    x0, y0, x1, y1 = bounds(xy)
    least = math.sqrt((x1 - x0) * (y1 - y0) / (CELLS_PER_POINT * len(xy))) if crowd else 0.0
    cell = max(cell, max(x1 - x0, y1 - y0) / 8192.0, least, np.finfo(float).tiny)
    nx = int((x1 - x0) / cell) + 1
    ny = int((y1 - y0) / cell) + 1
    return x0, y0, cell, nx, ny


def _search(
    xy: np.ndarray,
    radius: np.ndarray | float,
    skin: float,
    cell: float | None,
    per_dot: int,
    sparse: bool = False,
    ws: Workspace | None = None,
    split: bool = False,
    crowd: bool = True,
) -> tuple[np.ndarray, np.ndarray, CellGrid | None, bool, np.ndarray, np.ndarray]:
    """(ptr, nbr, grid, overflow, mid, has_cross) of the cell-grid search (see
    :func:`neighbor_list`). With ``sparse``, a grid of more than :data:`SPARSE_CELLS`
    cells a dot is searched by bisection (:func:`_pairs_sparse`, the same pairs in the
    same order) and no grid is returned. With ``split``, rows are laid out for the block
    kernels (same-block partners first, ``mid`` ``[n]`` int64 their end, ``has_cross``
    ``[n]`` bool: :meth:`~optdot.spatial.blocks.PairList.from_csr`'s layout); else
    ``mid`` and ``has_cross`` are empty. A dense search over more than
    :data:`CELLS_PER_POINT` cells a dot takes larger cells (the same pairs, rows in
    another order), unless ``crowd`` is off. The arrays returned live in ``ws`` when
    given."""
    xy = np.ascontiguousarray(xy, dtype=np.float64).view()
    n = xy.shape[0]
    reff = np.ascontiguousarray(np.broadcast_to(np.asarray(radius, np.float64), (n,)))
    # read-only whether a view (radii per dot, a pattern's frozen centres) or a copy (one
    # radius, centres being moved): one signature for the compiled search, not two (each
    # took numba 7-15 s to compile on a first run); the centres as a read-only view, the
    # caller's array left writable
    xy.flags.writeable = False
    reff.flags.writeable = False
    mid, has_cross = np.zeros(n if split else 0, np.int64), np.zeros(n if split else 0, bool)
    if n == 0:
        empty = CellGrid(
            0.0, 0.0, 1.0, 1, 1, np.zeros(2, np.int64), np.zeros(0, np.int32), np.zeros(1)
        )
        return np.zeros(1, np.int64), np.zeros(0, np.int32), empty, False, mid, has_cross
    grow = 1.0 + float(skin)
    x0, y0, cell, nx, ny = _grid_shape(xy, cell_side(reff, skin) if cell is None else cell)
    if sparse and nx * ny > SPARSE_CELLS * n:  # a few dots far apart (a Verlet list's movers)
        ptr, nbr = _pairs_sparse(xy, reff, grow, x0, y0, cell, nx, ny)
        return ptr, nbr, None, False, mid, has_cross
    if crowd and nx * ny > CELLS_PER_POINT * n:  # a dense search over far more cells than points
        x0, y0, cell, nx, ny = _grid_shape(xy, cell, crowd=True)
    fresh = ws is None
    ws = Workspace(keep=False) if ws is None else ws
    bins = bin_points(xy, reff, x0, y0, cell, nx, ny, bin_parts(), ws)
    per = max(int(per_dot), 1)
    seg = ws.take("seg", (n + _CHUNK - 1) // _CHUNK * per * _CHUNK, np.int32)
    ptr = ws.take("ptr", n + 1, np.int64)
    # a kept list's room for the pairs: the search's own guess; a fresh one is made to size
    nbr = np.zeros(0, np.int32) if fresh else ws.take("nbr", per * n, np.int32)
    if split:
        mid, has_cross = ws.take("mid", n, np.int64), ws.take("has_cross", n, np.bool_)
    nbr, over = _pairs_csr(
        xy, reff, grow, x0, y0, cell, nx, ny, per, split, bins, seg, ptr, nbr, mid, has_cross
    )
    start, order, _, _, _, cellmax = bins
    grid = CellGrid(x0, y0, cell, nx, ny, start, order, cellmax)
    return ptr, nbr, grid, bool(over), mid, has_cross


@dataclass(frozen=True, eq=False)
class NeighborList:
    """The result of :func:`neighbor_list`.

    Attributes:
        ptr: ``[n + 1]`` int64; the live partners of live dot i are ``nbr[ptr[i]:ptr[i + 1]]``.
        nbr: ``[K]`` int32 live dot indices; every unordered live pair appears once.
        halo_i: ``[H]`` int32 live dot of each live–halo pair.
        halo_j: ``[H]`` int32 halo dot (index into the halo arrays) of the same pairs.
        overflow: the per-dot capacity guess was too small somewhere, and those chunks
            were scanned a second time (as jax-md's ``did_buffer_overflow``, but here the
            list is complete either way: the flag says a larger ``per_dot`` would save
            the second scan).
        grid: the cell grid the dots (live and halo) were binned into.
    """

    ptr: np.ndarray
    nbr: np.ndarray
    halo_i: np.ndarray
    halo_j: np.ndarray
    overflow: bool
    grid: CellGrid

    def pairs(self) -> np.ndarray:
        """The live pairs as sorted ``[K, 2]`` int64, i < j."""
        return csr_to_pairs(self.ptr, self.nbr)


def neighbor_list(
    xy: np.ndarray,
    radius: np.ndarray | float,
    skin: float = 0.0,
    halo_xy: np.ndarray | None = None,
    halo_radius: np.ndarray | float | None = None,
    cell: float | None = None,
    per_dot: int = 8,
) -> NeighborList:
    """Every pair of circles closer than ``(r_i + r_j) * (1 + skin)``: a pure function.

    Args:
        xy: ``[n, 2]`` live centres, mm.
        radius: ``[n]`` radii (or one radius), mm, > 0.
        skin: relative margin; pairs up to ``(1 + skin)`` times touching are listed.
        halo_xy: optional ``[h, 2]`` frozen centres, mm (e.g. the dots beyond a tile):
            pairs of a live and a halo dot are listed apart; halo–halo pairs are not.
        halo_radius: ``[h]`` radii of the halo (or one radius), mm; default ``radius``
            when that is a scalar.
        cell: grid cell side, mm (default :func:`cell_side`).
        per_dot: expected partners per dot (a capacity guess; the result never depends
            on it, see :attr:`NeighborList.overflow`).

    Returns:
        :class:`NeighborList`.
    """
    xy = np.ascontiguousarray(xy, dtype=np.float64).reshape(-1, 2)
    n = len(xy)
    r = np.broadcast_to(np.asarray(radius, np.float64), (n,))
    none = np.zeros(0, np.int32)
    if halo_xy is None or len(halo_xy) == 0:
        ptr, nbr, grid, over, _, _ = _search(xy, r, skin, cell, per_dot)
        return NeighborList(ptr, nbr, none, none, over, grid)
    halo_xy = np.ascontiguousarray(halo_xy, dtype=np.float64).reshape(-1, 2)
    if halo_radius is None:
        if np.ndim(radius) != 0:
            raise ValueError("halo_radius is required when radius is per dot")
        halo_radius = radius
    hr = np.broadcast_to(np.asarray(halo_radius, np.float64), (len(halo_xy),))
    ptr, nbr, grid, over, _, _ = _search(
        np.concatenate([xy, halo_xy]), np.concatenate([r, hr]), skin, cell, per_dot
    )
    row = np.repeat(np.arange(len(ptr) - 1, dtype=np.int64), np.diff(ptr))
    col = nbr.astype(np.int64)
    live = (row < n) & (col < n)
    cross = (row < n) != (col < n)
    keep = np.flatnonzero(live)
    counts = np.bincount(row[keep], minlength=n)
    live_ptr = np.zeros(n + 1, np.int64)
    np.cumsum(counts, out=live_ptr[1:])
    hi = np.where(row[cross] < n, row[cross], col[cross])
    hj = np.where(row[cross] < n, col[cross], row[cross]) - n
    order = np.lexsort((hj, hi))
    return NeighborList(
        live_ptr,
        nbr[keep].astype(np.int32),
        hi[order].astype(np.int32),
        hj[order].astype(np.int32),
        over,
        grid,
    )


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
    ptr, nbr, grid, _, _, _ = _search(xy, radius, skin, cell, per_dot)
    return ptr, nbr, grid


def block_pairs(
    xy: np.ndarray,
    radius: np.ndarray,
    skin: float,
    cell: float,
    per_dot: int,
    ws: Workspace,
) -> tuple[PairList, CellGrid]:
    """:func:`neighbor_grid`'s pairs laid out for the block kernels, as
    :meth:`PairList.from_csr <optdot.spatial.blocks.PairList.from_csr>` would lay them out
    (the same rows in the same order), written while copying the search's rows: no
    second pass, no second list. Both results live in ``ws`` until its next search."""
    ptr, nbr, grid, _, mid, has_cross = _search(xy, radius, skin, cell, per_dot, ws=ws, split=True)
    return PairList.from_split(ptr, nbr, mid, np.flatnonzero(has_cross)), grid


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
    ptr, nbr, _, _, _, _ = _search(xy, radius, skin, None, 8, sparse=True)
    return ptr, nbr


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
