"""Overlap removal (paper §3.1–3.2): penalty (3) minimized by L-BFGS over a Verlet list."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numba as nb
import numpy as np

from .lbfgs import minimize_lbfgs
from .neighbors import neighbor_pairs
from .penalty import PenaltyTerms, penalty_fast


@nb.njit(cache=True)
def _moved_beyond(xy, ref, limit):  # pragma: no cover - compiled
    for i in range(xy.shape[0]):
        dx = xy[i, 0] - ref[i, 0]
        dy = xy[i, 1] - ref[i, 1]
        if dx * dx + dy * dy > limit[i] * limit[i]:
            return True
    return False


class VerletPenalty:
    """Penalty + gradient with a Verlet list rebuilt only when some dot moved too far.

    The list holds every pair closer than ``(re_i + re_j) * (1 + skin)`` at build time,
    where ``re_i = max(r_i, dmin / 2)``. A pair it misses would need
    ``|dx_i| + |dx_j| > skin * (re_i + re_j)``, so the list is rebuilt as soon as any dot
    moved more than ``skin * re_i`` from where it was at the build: never a missed pair.

    Args:
        terms: the penalty's radii, containers and panel.
        skin: relative skin.
    """

    def __init__(self, terms: PenaltyTerms, skin: float) -> None:
        self.terms = terms
        self.skin = skin
        self.reff = np.maximum(terms.radius, 0.5 * terms.dmin if terms.w_hard > 0 else 0.0)
        self.limit = skin * self.reff
        self.ref: np.ndarray | None = None
        self.ptr = self.nbr = None
        self.rebuilds = 0

    def __call__(self, x: np.ndarray, grad: np.ndarray) -> float:
        """``x`` and ``grad`` are flat ``[2n]`` views of ``[n, 2]`` positions, mm."""
        xy = x.reshape(-1, 2)
        if self.ref is None or _moved_beyond(xy, self.ref, self.limit):
            self.ptr, self.nbr = neighbor_pairs(xy, self.reff, self.skin)
            self.ref = xy.copy()
            self.rebuilds += 1
        return penalty_fast(xy, self.terms, self.ptr, self.nbr, grad.reshape(-1, 2))


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
