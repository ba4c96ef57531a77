"""The Verlet policy: when to rebuild the pair list as dots move, and how to patch it.

The search itself (:mod:`optdot.spatial.cellgrid`) is a pure function; this module
decides when to call it. Each :meth:`VerletList.update` returns a fresh
:class:`~optdot.spatial.blocks.PairList`; one handed out before stays as it was until the
next full rebuild, which writes the new list into the same memory.
"""

from __future__ import annotations

from dataclasses import replace

import numba as nb
import numpy as np

from .blocks import PairList
from .cellgrid import CellGrid, Workspace, block_pairs, cell_side, neighbor_pairs


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
                        ei, ej = append_pair(ei, ej, m, i, j)
                        m += 1
    return ei[:m], ej[:m]


@nb.njit(cache=True, inline="always")
def append_pair(ei, ej, m, i, j):  # pragma: no cover - compiled
    """``(ei, ej)`` with pair ``(i, j)`` stored at ``m`` (their first ``m`` entries
    kept), doubled when full: a compiled pair list grown in place."""
    if m == ei.shape[0]:
        ei2 = np.empty(2 * m, ei.dtype)
        ej2 = np.empty(2 * m, ej.dtype)
        ei2[:m] = ei[:m]
        ej2[:m] = ej[:m]
        ei, ej = ei2, ej2
    ei[m] = i
    ej[m] = j
    return ei, ej


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
        self._is_mover = np.zeros(0, np.bool_)
        self.rebuilds = 0
        self.n_movers = 0
        # every rebuild writes into the last one's memory (:class:`.cellgrid.Workspace`)
        self._ws = Workspace()

    def _rebuild(self, xy: np.ndarray) -> None:
        # guess partners per dot from the last build (+25 %); the new list is written
        # over the old one, which nothing uses past this point
        per_dot = 8 if self.pairs is None else 2 + 5 * len(self.pairs.nbr) // (4 * len(xy))
        self.pairs = self.grid = None
        self.pairs, self.grid = block_pairs(xy, self.reff, self.skin, self.cell, per_dot, self._ws)
        if self.ref is None or self.ref.shape != xy.shape:
            self.ref = np.empty_like(xy)
            self._is_mover = np.zeros(len(xy), np.bool_)
        np.copyto(self.ref, xy)
        self._is_mover[:] = False
        self.n_movers = 0
        self.rebuilds += 1

    def update(self, xy: np.ndarray) -> PairList:
        """The pair list valid at positions ``xy`` (``[n, 2]`` mm).

        Returns a new :class:`PairList` whenever its contents change; a list returned
        earlier is not modified until the next full rebuild writes over it (its arrays
        may be shared with the new one)."""
        if self.pairs is None:
            self._rebuild(xy)
        new = _new_movers(xy, self.ref, self.limit, self._is_mover)
        self.n_movers += new
        if self.n_movers > self.max_movers:
            self._rebuild(xy)
        elif self.n_movers:
            skip = self._is_mover.copy() if new else self.pairs.skip
            movers = np.flatnonzero(skip)
            ei, ej = mover_pairs(xy, self.reff, movers, skip, self.skin, self.grid)
            self.pairs = replace(self.pairs, skip=skip, ei=ei, ej=ej)
        return self.pairs
