"""The pipeline: a :class:`~optdot.job.Job` becomes a :class:`~optdot.pattern.Pattern`.

initial dots (§2.1) → circles and containers (§3.3, §3) → relaxation (OptDot or MD)
→ guarantee pass → Pattern. The core never prints; progress goes to a callback.
"""

from __future__ import annotations

import time
from collections.abc import Callable

import numpy as np

from .circles import circle_radius, container_half_sides, hex_radius
from .errors import GuaranteeError
from .initial import initial_dots
from .job import Job
from .legalize import check_guarantee, legalize
from .memory import check_memory
from .neighbors import spatial_order
from .pattern import Pattern
from .penalty import PenaltyTerms
from .relax import relax

#: Weight of optdot's hard-core and hard-panel terms (0 in the paper formulation).
W_HARD = 10.0

Progress = Callable[[int, float], None]


def build_terms(job: Job, xy0: np.ndarray, rho: np.ndarray) -> PenaltyTerms:
    """Radii, containers and panel of the penalty for dots starting at ``xy0``.

    Args:
        job: the job.
        xy0: ``[n, 2]`` start positions, mm.
        rho: ``[n]`` fill fraction at each start position.
    """
    opt = job.optimize
    r0 = 0.5 * job.diameter
    r = circle_radius(rho, r0, opt.effective_radius_factor)
    paper = opt.formulation == "paper"
    panel_r = r if paper else np.maximum(hex_radius(rho, r0), r0)
    return PenaltyTerms(
        radius=r,
        panel_radius=np.ascontiguousarray(panel_r),
        center=np.ascontiguousarray(xy0),
        half_side=container_half_sides(r, opt.container_factor),
        box=(0.0, 0.0, job.width, job.height),
        dmin=job.min_distance,
        dot_radius=r0,
        w_hard=0.0 if paper else W_HARD,
        empty=np.zeros((1, 1), np.uint8) if paper else (job.density.grid <= 0).astype(np.uint8),
        grid_box=(job.density.x0, job.density.y0, *job.density.cell_size),
    )


def generate(job: Job, progress: Progress | None = None) -> Pattern:
    """Generate the dot pattern of ``job``.

    Args:
        job: a validated job.
        progress: optional ``progress(iteration, penalty)`` callback.

    Returns:
        The pattern, dots in generation order, positions rounded to 1 nm.

    Raises:
        ResourceError: the job would not fit in memory.
        GuaranteeError: the spacing/placement guarantee could not be met.
    """
    where = str(job.source) if job.source else job.name
    opt = job.optimize
    n = job.n_dots
    check_memory(n, opt.lbfgs_memory, where)
    t0 = time.perf_counter()
    timings: dict[str, float] = {}

    xy_init = initial_dots(job.density, n, opt.seed)
    home = job.density.cell_index(xy_init)
    rho = job.density.grid.ravel()[home]
    order = spatial_order(xy_init)
    xy0 = np.ascontiguousarray(xy_init[order])
    timings["initial_s"] = time.perf_counter() - t0

    t1 = time.perf_counter()
    terms = build_terms(job, xy0, rho[order])
    res = relax(
        xy0,
        terms,
        max_iter=opt.max_iter,
        memory=opt.lbfgs_memory,
        ftol=opt.ftol,
        skin=opt.skin,
        callback=progress,
    )
    timings["relax_s"] = time.perf_counter() - t1

    t2 = time.perf_counter()
    box = (0.0, 0.0, job.width, job.height)
    r0 = 0.5 * job.diameter
    leg = legalize(res.xy, job.density, home[order], box, r0, job.min_distance)
    viol = check_guarantee(leg.xy, job.density, box, r0, job.min_distance)
    if not viol.ok:
        raise GuaranteeError(
            f"{where}: could not meet the guarantee after {leg.sweeps} sweeps: "
            f"{viol.collisions} pairs closer than {job.min_distance * 1e3:.1f} um, "
            f"{viol.protruding} dots protruding, {viol.in_empty} dots in zero-density cells"
        )
    timings["legalize_s"] = time.perf_counter() - t2

    xy = np.empty_like(leg.xy)
    xy[order] = leg.xy
    timings["total_s"] = time.perf_counter() - t0
    meta = {
        "job": job.name,
        "method": opt.method,
        "formulation": opt.formulation,
        "seed": opt.seed,
        "max_iter": opt.max_iter,
        "n": int(n),
        "iterations": int(res.nit),
        "evaluations": int(res.nfev),
        "penalty": float(res.penalty),
        "message": res.message,
        "neighbor_builds": int(res.rebuilds),
        "legalize_sweeps": int(leg.sweeps),
        "legalize_pair_fixes": int(leg.pair_fixes),
        "legalize_dot_fixes": int(leg.dot_fixes),
    }
    return Pattern(
        xy=xy, diameter=job.diameter, box=box, meta=meta, stats={**timings, "history": res.history}
    )
