"""The pipeline: a :class:`~optdot.job.Job` becomes a :class:`~optdot.pattern.Pattern`.

initial dots (§2.1) → circles and containers (§3.3, §3) → relaxation (OptDot, or the
MD baseline of §2.2 on the same initial dots)
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
from .md import MDForce, md_relax
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


def generate(job: Job, progress: Progress | None = None, keep_stages: bool = False) -> Pattern:
    """Generate the dot pattern of ``job``.

    Args:
        job: a validated job.
        progress: optional ``progress(iteration, value)`` callback (penalty for OptDot,
            largest force for MD).
        keep_stages: also put ``initial_xy`` and ``relaxed_xy`` (``[n, 2]``, generation
            order, before the guarantee pass) in ``pattern.stats``, for comparisons.

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
    box = (0.0, 0.0, job.width, job.height)
    r0 = 0.5 * job.diameter
    if opt.method == "md":
        law = MDForce(
            core=job.min_distance,
            spacing=2.0 * hex_radius(rho[order], r0),
            decay=opt.md_decay,
            cutoff=opt.md_cutoff,
        )
        md = md_relax(
            xy0,
            law,
            box,
            r0,
            steps=opt.max_iter,
            step=opt.md_step,
            skin=opt.skin,
            callback=progress,
        )
        relaxed = md.xy
        info = {"iterations": md.steps, "evaluations": md.steps, "neighbor_builds": md.rebuilds}
        info.update(md_step_mm=md.eta, message=f"ran {md.steps} MD steps")
        history = md.history
    else:
        res = relax(
            xy0,
            build_terms(job, xy0, rho[order]),
            max_iter=opt.max_iter,
            memory=opt.lbfgs_memory,
            ftol=opt.ftol,
            skin=opt.skin,
            callback=progress,
        )
        relaxed = res.xy
        info = {"iterations": res.nit, "evaluations": res.nfev, "neighbor_builds": res.rebuilds}
        info.update(penalty=float(res.penalty), message=res.message)
        history = res.history
    timings["relax_s"] = time.perf_counter() - t1

    t2 = time.perf_counter()
    leg = legalize(relaxed, job.density, home[order], box, r0, job.min_distance)
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
        **info,
        "legalize_sweeps": int(leg.sweeps),
        "legalize_pair_fixes": int(leg.pair_fixes),
        "legalize_dot_fixes": int(leg.dot_fixes),
    }
    stats: dict = {**timings, "history": history}
    if keep_stages:
        stats["initial_xy"] = xy_init
        stats["relaxed_xy"] = np.empty_like(relaxed)
        stats["relaxed_xy"][order] = relaxed
    return Pattern(xy=xy, diameter=job.diameter, box=box, meta=meta, stats=stats)
