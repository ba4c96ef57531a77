"""Overlap removal (paper §3.1–3.2): penalty (3) minimized by L-BFGS over a Verlet list."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numba as nb
import numpy as np

from .lbfgs import minimize_lbfgs
from .neighbors import CellGrid, cell_side, mover_pairs, neighbor_grid
from .penalty import PairList, PenaltyTerms, penalty_fast


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


class VerletPenalty:
    """Penalty + gradient over a Verlet list, patched for the few dots that move far.

    The list holds every pair closer than ``(re_i + re_j) * (1 + skin)`` at build time,
    where ``re_i = max(r_i, dmin / 2)``. A pair it misses needs one of its dots to have
    moved more than ``skin * re`` since the build. Such dots (*movers*; typically a few
    dozen of 10⁵) leave the list: their pairs are searched afresh at every evaluation
    (:func:`optdot.neighbors.mover_pairs`). The list is rebuilt from scratch only when
    movers exceed ``rebuild_fraction`` of the dots. No pair is ever missed.

    Args:
        terms: the penalty's radii, containers and panel.
        skin: relative skin.
        rebuild_fraction: share of movers that triggers a full rebuild.
    """

    def __init__(self, terms: PenaltyTerms, skin: float, rebuild_fraction: float = 0.01) -> None:
        self.terms = terms
        self.skin = skin
        self.reff = np.maximum(terms.radius, 0.5 * terms.dmin if terms.w_hard > 0 else 0.0)
        self.limit = skin * self.reff
        self.cell = cell_side(self.reff, skin)
        self.max_movers = max(16, int(rebuild_fraction * len(self.reff)))
        self.ref: np.ndarray | None = None
        self.pairs: PairList | None = None
        self.grid: CellGrid | None = None
        self.rebuilds = 0
        self.n_movers = 0

    def _rebuild(self, xy: np.ndarray) -> None:
        ptr, nbr, self.grid = neighbor_grid(xy, self.reff, self.skin, self.cell)
        self.pairs = PairList.from_csr(ptr, nbr)
        self.ref = xy.copy()
        self.n_movers = 0
        self.rebuilds += 1

    def __call__(self, x: np.ndarray, grad: np.ndarray) -> float:
        """``x`` and ``grad`` are flat ``[2n]`` views of ``[n, 2]`` positions, mm."""
        xy = x.reshape(-1, 2)
        if self.pairs is None:
            self._rebuild(xy)
        pl = self.pairs
        self.n_movers += _new_movers(xy, self.ref, self.limit, pl.skip)
        if self.n_movers:
            movers = np.flatnonzero(pl.skip)
            if self.n_movers > self.max_movers:
                self._rebuild(xy)
                pl = self.pairs
            else:
                pl.ei, pl.ej = mover_pairs(xy, self.reff, movers, pl.skip, self.skin, self.grid)
        return penalty_fast(xy, self.terms, pl, grad.reshape(-1, 2))


@dataclass
class RelaxResult:
    """Outcome of :func:`relax`.

    Attributes:
        xy: ``[n, 2]`` relaxed positions, mm.
        penalty: final penalty, mm².
        nit, nfev: iterations and evaluations.
        rebuilds: neighbour-list builds.
        message: why it stopped.
        history: penalty after each iteration.
    """

    xy: np.ndarray
    penalty: float
    nit: int
    nfev: int
    rebuilds: int
    message: str
    history: list[float]


def relax(
    xy0: np.ndarray,
    terms: PenaltyTerms,
    max_iter: int = 200,
    memory: int = 6,
    ftol: float = 0.0,
    skin: float = 0.3,
    callback: Callable[[int, float], None] | None = None,
) -> RelaxResult:
    """Minimize the penalty from ``xy0`` (``[n, 2]`` mm) by L-BFGS with memory ``memory``."""
    fun = VerletPenalty(terms, skin)
    res = minimize_lbfgs(
        fun, xy0.ravel(), memory=memory, max_iter=max_iter, ftol=ftol, callback=callback
    )
    return RelaxResult(
        xy=res.x.reshape(-1, 2),
        penalty=res.fun,
        nit=res.nit,
        nfev=res.nfev,
        rebuilds=fun.rebuilds,
        message=res.message,
        history=res.history,
    )
