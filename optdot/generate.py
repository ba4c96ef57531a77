"""The pipeline: a :class:`~optdot.job.Job` becomes a :class:`~optdot.pattern.Pattern`.

initial dots (§2.1) → circles and containers (§3.3, §3) → relaxation (OptDot, or the
MD baseline of §2.2 on the same initial dots)
→ guarantee pass → Pattern. The core never prints; progress goes to a callback.
"""

from __future__ import annotations

import time
from collections.abc import Callable

import numpy as np

from .circles import hex_radius
from .errors import GeometryError, GuaranteeError
from .formulation import Formulation, formulation_of
from .initial import initial_dots, initial_dots_in
from .job import Job
from .legalize import check_guarantee, legalize
from .md import MDForce, md_relax
from .memory import check_memory
from .neighbors import spatial_order
from .pattern import Pattern
from .relax import relax

Progress = Callable[[int, float], None]


def relax_staged(
    job: Job,
    form: Formulation,
    xy0: np.ndarray,
    rho: np.ndarray,
    progress: Progress | None = None,
) -> tuple[np.ndarray, dict, list[float]]:
    """Relax ``xy0`` (``[n, 2]`` mm, fill ``rho`` ``[n]``) through the formulation's stages.

    Containers stay centred on ``xy0`` in every stage. Returns positions, run info and
    the penalty after each iteration.
    """
    opt = job.optimize
    xy = xy0
    info = {"iterations": 0, "evaluations": 0, "neighbor_builds": 0}
    history: list[float] = []
    done = 0
    for k, (share, multiplier) in enumerate(form.stages):
        last = k == len(form.stages) - 1
        iters = opt.max_iter - done if last else round(share * opt.max_iter)
        res = relax(
            xy,
            form.terms(job, xy0, rho, multiplier),
            max_iter=iters,
            memory=opt.lbfgs_memory,
            ftol=opt.ftol,
            skin=opt.skin,
            callback=None if progress is None else (lambda i, f, o=done: progress(o + i, f)),
        )
        done += iters
        xy = res.xy
        info["iterations"] += res.nit
        info["evaluations"] += res.nfev
        info["neighbor_builds"] += res.rebuilds
        info.update(penalty=float(res.penalty), message=res.message)
        history += res.history
    return xy, info, history


def generate(
    job: Job,
    progress: Progress | None = None,
    keep_stages: bool = False,
    formulation: Formulation | None = None,
) -> Pattern:
    """Generate the dot pattern of ``job``.

    Args:
        job: a validated job.
        progress: optional ``progress(iteration, value)`` callback (penalty for OptDot,
            largest force for MD).
        keep_stages: also put ``initial_xy`` and ``relaxed_xy`` (``[n, 2]``, generation
            order, before the guarantee pass) in ``pattern.stats``, for comparisons.
        formulation: overrides the job's (benchmarks try variants this way).

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

    if job.domain.rectangle:
        xy_init = initial_dots(job.density, n, opt.seed)
    else:
        xy_init = initial_dots_in(job.density, n, opt.seed, job.domain.contains)
        if len(xy_init) < n:
            raise GeometryError(
                f"{where}: could only place {len(xy_init)} of {n} dots inside the outline; "
                "the map is zero over most of it"
            )
    home = job.density.cell_index(xy_init)
    rho = job.density.grid.ravel()[home]
    order = spatial_order(xy_init)
    xy0 = np.ascontiguousarray(xy_init[order])
    timings["initial_s"] = time.perf_counter() - t0

    t1 = time.perf_counter()
    box = job.box
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
        form = formulation_of(job) if formulation is None else formulation
        relaxed, info, history = relax_staged(job, form, xy0, rho[order], progress)
    timings["relax_s"] = time.perf_counter() - t1

    t2 = time.perf_counter()
    leg = legalize(relaxed, job.density, home[order], job.domain, r0, job.min_distance)
    viol = check_guarantee(leg.xy, job.density, job.domain, r0, job.min_distance)
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
    outline = None if job.domain.rectangle else job.domain
    return Pattern(xy=xy, diameter=job.diameter, box=box, meta=meta, stats=stats, outline=outline)
