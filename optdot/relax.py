"""Overlap removal (paper §3.1–3.2): penalty (3) minimized by L-BFGS over a Verlet list."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from .lbfgs import minimize_lbfgs
from .neighbors import VerletList
from .penalty import PenaltyTerms, penalty_fast


class VerletPenalty:
    """Penalty + gradient over a :class:`~optdot.neighbors.VerletList`.

    Interaction radii are :attr:`PenaltyTerms.reach` (the circle, or the hard core where
    it reaches further), so the list holds every pair the penalty can see.

    Args:
        terms: the penalty's radii, containers and panel.
        skin: relative skin of the list.
        rebuild_fraction: share of movers that triggers a full rebuild.
    """

    def __init__(self, terms: PenaltyTerms, skin: float, rebuild_fraction: float = 0.01) -> None:
        self.terms = terms
        self.verlet = VerletList(terms.reach, skin, rebuild_fraction)

    @property
    def rebuilds(self) -> int:
        """Full neighbour-list builds so far."""
        return self.verlet.rebuilds

    @property
    def n_movers(self) -> int:
        """Dots currently handled outside the list."""
        return self.verlet.n_movers

    def __call__(self, x: np.ndarray, grad: np.ndarray) -> float:
        """``x`` and ``grad`` are flat ``[2n]`` views of ``[n, 2]`` positions, mm."""
        xy = x.reshape(-1, 2)
        return penalty_fast(xy, self.terms, self.verlet.update(xy), grad.reshape(-1, 2))


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
