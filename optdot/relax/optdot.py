"""Overlap removal (paper §3.1–3.2): penalty (3) minimized by L-BFGS over a Verlet list,
through a formulation's stages."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from ..spatial.verlet import VerletList
from .exactgap import ExactGapTerm
from .formulation import Formulation, Problem
from .lbfgs import HALTED, minimize_lbfgs
from .multisphere import MULTISPHERE_WEIGHT, MultiSphereTerm
from .penalty import PenaltyTerms, penalty_fast
from .result import RelaxResult

#: The penalty terms shaped dots relax with, by the name a kind gives as its
#: :attr:`~optdot.geometry.kinds.base.Kind.relaxation` (``benchmarks/penalty_choice.py``
#: measures each on each kind): the exact edge gap, or the multi-sphere scheme.
FOOTPRINT_TERMS = {"exact_gap": ExactGapTerm, "spheres": MultiSphereTerm}

#: ``progress(iteration, value)``; a true return value halts the run.
Progress = Callable[[int, float], bool | None]


class VerletPenalty:
    """Penalty + gradient over a :class:`~optdot.spatial.verlet.VerletList`.

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


class FrozenPenalty(VerletPenalty):
    """:class:`VerletPenalty` with some dots held still: their gradient is zero, so every
    L-BFGS direction (built from gradients and steps only) is zero for them and they keep
    their positions exactly, while the dots around them feel them as fixed neighbours.

    Args:
        frozen: ``[n]`` bool, the dots that do not move.
    """

    def __init__(self, terms: PenaltyTerms, skin: float, frozen: np.ndarray) -> None:
        super().__init__(terms, skin)
        self.frozen = np.flatnonzero(frozen)

    def __call__(self, x: np.ndarray, grad: np.ndarray) -> float:
        f = super().__call__(x, grad)
        grad.reshape(-1, 2)[self.frozen] = 0.0
        return f


class _Added:
    """A penalty plus an extra term (frozen dots' gradient kept zero)."""

    def __init__(self, fun, extra, frozen: np.ndarray | None) -> None:
        self.fun, self.extra = fun, extra
        self.frozen = None if frozen is None else np.flatnonzero(frozen)

    @property
    def rebuilds(self) -> int:
        return self.fun.rebuilds

    def __call__(self, x: np.ndarray, grad: np.ndarray) -> float:
        f = self.fun(x, grad)
        g = grad.reshape(-1, 2)
        f += self.extra(x.reshape(-1, 2), g)
        if self.frozen is not None:
            g[self.frozen] = 0.0
        return f


def first_move(terms: PenaltyTerms, skin: float) -> float:
    """How far a steepest-descent step of the relaxation may move any coordinate, mm: one
    skin of the median dot (``skin`` times its interaction radius).

    L-BFGS knows no scale before its first pair of steps. Its first trial along the
    gradient, scaled by a fixed guess, moved dots up to 1 mm (20 radii) on the led map
    and was rejected three times; each trial moved so many dots past the Verlet skin that
    the list was rebuilt four times for one step (5 of a 1.2M-dot run's 15 rebuilds). A
    first step bounded by the skin is accepted at once, leaves the list built at the start
    valid for nearly every dot, and from the second step on the pairs of steps set the
    scale (1.2M-dot led: 15 rebuilds and 86 evaluations become 10 and 83, in as many
    iterations)."""
    reach = terms.reach
    return skin * float(np.median(reach)) if len(reach) else 0.0


def relax(
    xy0: np.ndarray,
    terms: PenaltyTerms,
    max_iter: int = 200,
    memory: int = 6,
    ftol: float = 0.0,
    skin: float = 0.3,
    callback: Progress | None = None,
    gtol: float = 0.0,
    frozen: np.ndarray | None = None,
    extra: Callable[[np.ndarray, np.ndarray], float] | None = None,
) -> RelaxResult:
    """Minimize the penalty from ``xy0`` (``[n, 2]`` mm) by L-BFGS with memory ``memory``;
    dots marked in ``frozen`` (``[n]`` bool) stay where they are; ``extra(xy [n, 2],
    grad [n, 2]) -> value`` adds a term (the multi-sphere penalty of shaped dots)."""
    fun = VerletPenalty(terms, skin) if frozen is None else FrozenPenalty(terms, skin, frozen)
    if extra is not None:
        fun = _Added(fun, extra, frozen)
    res = minimize_lbfgs(
        fun,
        xy0.ravel(),
        first_move=first_move(terms, skin),
        memory=memory,
        max_iter=max_iter,
        ftol=ftol,
        callback=callback,
        gtol=gtol,
    )
    return RelaxResult(
        xy=res.x.reshape(-1, 2),
        penalty=res.fun,
        nit=res.nit,
        nfev=res.nfev,
        rebuilds=fun.rebuilds,
        message=res.message,
        history=res.history,
        status=res.status,
    )


@dataclass(frozen=True)
class RelaxSettings:
    """How long and how the L-BFGS stages run (the job's ``[optimize]`` fields)."""

    max_iter: int = 200
    memory: int = 6
    ftol: float = 0.0
    skin: float = 0.3
    gtol: float = 0.0


def relax_staged(
    problem: Problem,
    form: Formulation,
    xy0: np.ndarray,
    rho: np.ndarray,
    settings: RelaxSettings,
    progress: Progress | None = None,
    start: np.ndarray | None = None,
    frozen: np.ndarray | None = None,
    diameters: np.ndarray | None = None,
    phantom: np.ndarray | None = None,
) -> RelaxResult:
    """Relax ``xy0`` (``[n, 2]`` mm, fill ``rho`` ``[n]``) through the formulation's stages.

    Containers stay centred on ``xy0`` in every stage. A stage halted by ``progress``
    ends the run.

    Args:
        start: ``[n, 2]`` positions to start from, mm (default ``xy0``): a tile's second
            phase resumes from the first phase's positions, containers still on ``xy0``.
        frozen: ``[n]`` bool, dots that do not move (a tile's halo).
        diameters: ``[n]`` dot diameters, mm, when sizes vary (see
            :meth:`~optdot.relax.formulation.Formulation.terms`).
        phantom: ``[n]`` bool, phantom dots among them (relaxed, never legalised).

    Returns:
        One :class:`RelaxResult` over all stages (counts and history summed; penalty,
        status and message of the last stage run).
    """
    xy = xy0 if start is None else start
    extra = None
    if problem.shaped is not None:
        shape, field, gap = problem.shaped
        active = np.ones(len(xy0), bool) if phantom is None else ~phantom
        scale = None if diameters is None else diameters / shape.equivalent_diameter
        term = FOOTPRINT_TERMS[shape.kind.relaxation]
        extra = term(shape, field.at(xy0, xy0), active, gap, MULTISPHERE_WEIGHT, scale=scale)
    total = RelaxResult(xy, 0.0, 0, 0, 0, "no stage ran", [])
    done = 0
    for k, (share, multiplier) in enumerate(form.stages):
        last = k == len(form.stages) - 1
        iters = settings.max_iter - done if last else round(share * settings.max_iter)
        res = relax(
            xy,
            form.terms(problem, xy0, rho, multiplier, diameters, phantom),
            max_iter=iters,
            memory=settings.memory,
            ftol=settings.ftol,
            skin=settings.skin,
            callback=None if progress is None else (lambda i, f, o=done: progress(o + i, f)),
            gtol=settings.gtol,
            frozen=frozen,
            extra=extra,
        )
        done += iters
        xy = res.xy
        total = RelaxResult(
            xy,
            float(res.penalty),
            total.nit + res.nit,
            total.nfev + res.nfev,
            total.rebuilds + res.rebuilds,
            res.message,
            total.history + res.history,
            res.status,
        )
        if res.status == HALTED:
            break
    return total
