"""What a job asks of every stage: its penalty problem, formulation, L-BFGS settings,
size rule, halo and spacing. Derived from the job once per run (:func:`stage_settings`)
and shared by the panel and its tiles; the functions below are how each is derived."""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from ..config.job import Job
from ..relax.circles import hex_radius
from ..relax.formulation import Containers, Formulation, Problem, containers_of, formulation_of
from ..relax.optdot import RelaxSettings
from ..relax.resize import reach

#: Width of the blur the dot sizes are fitted under, as a share of ``qa.smoothing``
#: (:mod:`optdot.relax.resize`): what a diffuser or the eye blurs at least.
FIT_SHARE = 0.5


def problem_of(job: Job) -> Problem:
    """The fields of ``job`` a formulation builds its penalty terms from."""
    return Problem(
        domain=job.domain,
        density=job.density,
        dot_radius=0.5 * job.diameter,
        min_distance=job.min_distance,
        close_target=job.close_target,
        seed=job.optimize.seed,
        reach=None if job.shape.kind.round else job.dot_radius,
        shaped=None if job.shape.kind.round else (job.shape, job.orientation, job.optimize.gap),
    )


def formulation_for(job: Job) -> Formulation:
    """The job's formulation with its radius and container factors."""
    opt = job.optimize
    return formulation_of(opt.formulation, opt.radius_factor, opt.container_factor)


def settings_for(job: Job) -> RelaxSettings:
    """The job's L-BFGS settings."""
    opt = job.optimize
    return RelaxSettings(opt.max_iter, opt.lbfgs_memory, opt.ftol, opt.skin)


def fit_sigma(job: Job) -> float:
    """Gaussian width the dot sizes are fitted under, mm."""
    return FIT_SHARE * job.qa.smoothing


def fitted(job: Job) -> bool:
    """Whether ``job``'s dot sizes are fitted after relaxation (sizes vary by a rule; an
    explicit diameter grid is the user's choice and kept)."""
    return job.sizes is not None and job.sizes.rule != "grid"


def halo_width(job: Job) -> float:
    """How far around a set of dots :func:`finish` needs the dots held still, mm: the
    size fit's blur reach when sizes are fitted, else two of the largest spacings."""
    widest = job.diameter if job.sizes is None else job.sizes.high
    width = 2.0 * (widest + job.optimize.gap)
    return max(width, reach(fit_sigma(job))) if fitted(job) else width


@dataclass(frozen=True, eq=False)
class StageSettings:
    """What every stage of a run takes from its job, derived once.

    Attributes:
        problem: the fields a formulation builds its penalty terms from.
        formulation: the job's (or a benchmark's) formulation.
        relax: the L-BFGS settings.
        spacing: the map's median hexagonal spacing, mm (:func:`job_spacing`).
        fit_sigma: the Gaussian the dot sizes are fitted under, mm.
        fitted: whether sizes are fitted after the relaxation.
        halo: how far around a set of dots the guarantee pass holds dots still, mm.
    """

    problem: Problem
    formulation: Formulation
    relax: RelaxSettings
    spacing: float
    fit_sigma: float
    fitted: bool
    halo: float


@lru_cache(maxsize=4)
def stage_settings(job: Job, formulation: Formulation | None = None) -> StageSettings:
    """The stage settings of ``job`` (with ``formulation`` instead of the job's, for
    benchmarks trying variants), built on the first call of a run and reused by every
    stage after it (in each worker process of a tiled run, once)."""
    return StageSettings(
        problem=problem_of(job),
        formulation=formulation_for(job) if formulation is None else formulation,
        relax=settings_for(job),
        spacing=job_spacing(job),
        fit_sigma=fit_sigma(job),
        fitted=fitted(job),
        halo=halo_width(job),
    )


def containers(job: Job) -> Containers:
    """The fills ``job``'s containers are sized for: the map's, floored beside its
    zero-fill cells (:class:`~optdot.relax.formulation.Containers`)."""
    widest = job.diameter if job.sizes is None else job.sizes.high
    return containers_of(job.density, float(widest))


def container_fill(job: Job, xy: np.ndarray) -> np.ndarray:
    """``[n]`` the fill the containers of dots at ``xy`` (``[n, 2]`` mm) are sized for."""
    return containers(job).floored(job.density.at(xy), xy)


def rule_diameters(job: Job, xy0: np.ndarray) -> np.ndarray | None:
    """``[n]`` diameter the size rule gives the dots thrown at ``xy0`` (their start
    cells'), mm; None for dots of one size."""
    if job.sizes is None:
        return None
    return np.asarray(job.diameters_at(job.density.cell_index(xy0)), dtype=np.float64)


@lru_cache(maxsize=8)
def job_spacing(job: Job) -> float:
    """The map's median hexagonal spacing over its non-zero cells, weighted by dot
    count, mm: one figure for every tile (their lattice and blur must agree)."""
    g = job.density.grid
    d = job.cell_diameters
    live = g > 0
    if not live.any():
        return float(job.diameter)
    r0 = 0.5 * (job.diameter if d is None else d[live])
    a = np.broadcast_to(np.pi * r0**2, (int(live.sum()),))
    spacing = 2.0 * hex_radius(g[live], r0)
    count = g[live] / a
    order = np.argsort(spacing)
    cum = np.cumsum(count[order])
    return float(spacing[order][np.searchsorted(cum, 0.5 * cum[-1])])


def thrown_areas(job: Job, xy0: np.ndarray) -> np.ndarray:
    """``[n]`` areas (mm²) of the dots thrown at ``xy0`` (``[n, 2]`` mm): their rule
    sizes, from their start cells."""
    return _dot_areas(job, rule_diameters(job, xy0), len(xy0))


def _dot_areas(job: Job, diameters: np.ndarray | None, n: int) -> np.ndarray:
    """``[n]`` areas (mm²) of ``n`` dots of ``diameters`` (``[n]`` mm, or None: the
    job's)."""
    d = np.broadcast_to(job.diameter if diameters is None else diameters, (n,))
    return np.pi * 0.25 * d**2


def areas(job: Job, rho: np.ndarray, diameters: np.ndarray | None) -> tuple[np.ndarray, float]:
    """``([n] dot areas mm², median hexagonal spacing mm)`` of dots at fills ``rho``
    (``[n]``) and of ``diameters`` (``[n]`` mm, or None: the job's)."""
    d = np.broadcast_to(job.diameter if diameters is None else diameters, (len(rho),))
    area = _dot_areas(job, diameters, len(rho))
    if not len(rho):  # no dots (a tile of an empty region): the map's spacing
        return area, job_spacing(job)
    return area, float(np.median(2.0 * hex_radius(rho, 0.5 * d)))
