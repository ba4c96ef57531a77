"""Where a job becomes the values the stages take: its penalty problem, formulation,
L-BFGS settings, size rule, halo, spacing and containers (:func:`stage_settings`, one
:class:`~optdot.stages.settings.StageSettings` a run, built once and reused by every stage,
in each worker process of a tiled run once)."""

from __future__ import annotations

from functools import lru_cache

import numpy as np

from ..config.job import Job
from ..relax.circles import hex_radius
from ..relax.formulation import Containers, Formulation, Problem, containers_of, formulation_of
from ..relax.optdot import RelaxSettings
from ..relax.resize import reach
from ..stages.settings import FIT_SHARE, StageSettings


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


@lru_cache(maxsize=4)
def stage_settings(job: Job, formulation: Formulation | None = None) -> StageSettings:
    """The stage settings of ``job`` (with ``formulation`` instead of the job's, for
    benchmarks trying variants), built on the first call of a run and reused by every
    stage after it (in each worker process of a tiled run, once). Where a job becomes
    the values the stages take."""
    return StageSettings(
        problem=problem_of(job),
        formulation=formulation_for(job) if formulation is None else formulation,
        relax=settings_for(job),
        spacing=job_spacing(job),
        fit_sigma=fit_sigma(job),
        fitted=fitted(job),
        halo=halo_width(job),
        domain=job.domain,
        density=job.density,
        sizes=job.sizes,
        shape=job.shape,
        orientation=job.orientation,
        optimize=job.optimize,
        diameter=float(job.diameter),
        min_distance=job.min_distance,
        dot_radius=job.dot_radius,
        dart_weights=job.dart_weights,
        cell_diameters=job.cell_diameters,
        containers=containers(job),
    )


def containers(job: Job) -> Containers:
    """The fills ``job``'s containers are sized for: the map's, floored beside its
    zero-fill cells (:class:`~optdot.relax.formulation.Containers`)."""
    widest = job.diameter if job.sizes is None else job.sizes.high
    return containers_of(job.density, float(widest))


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
