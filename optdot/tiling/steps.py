"""What the relaxation needs of a job, shared by the single-process path and the tiles."""

from __future__ import annotations

from ..config.job import Job
from ..relax.formulation import Formulation, Problem, formulation_of
from ..relax.optdot import RelaxSettings


def problem_of(job: Job) -> Problem:
    """The fields of ``job`` a formulation builds its penalty terms from."""
    return Problem(
        domain=job.domain,
        density=job.density,
        dot_radius=0.5 * job.diameter,
        min_distance=job.min_distance,
        close_target=job.close_target,
        seed=job.optimize.seed,
    )


def formulation_for(job: Job) -> Formulation:
    """The job's formulation with its radius and container factors."""
    opt = job.optimize
    return formulation_of(opt.formulation, opt.radius_factor, opt.container_factor)


def settings_for(job: Job) -> RelaxSettings:
    """The job's L-BFGS settings."""
    opt = job.optimize
    return RelaxSettings(opt.max_iter, opt.lbfgs_memory, opt.ftol, opt.skin)
