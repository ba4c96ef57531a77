"""The stages of generation as functions of a job and a set of dots: one path for every dot.

:func:`optdot.pipeline.generate` runs them once over the whole panel; the tiles of
:mod:`optdot.tiling.tasks` run the same functions over a tile, with the neighbouring
tiles' dots held still around it. Nothing here knows whether it sees a panel or a tile:

* :func:`throw`: the initial dots of a window (the panel, or a tile), §2.1.
* :func:`relax`: circles and containers on the initial dots, then OptDot (L-BFGS through
  the formulation's stages) or the MD baseline of §2.2.
* :func:`finish`: dot sizes fitted to the coverage where the dots stand (when sizes
  vary, :mod:`optdot.relax.resize`), then the guarantee pass and its check.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from .config.job import Job
from .relax.circles import hex_radius
from .relax.formulation import Formulation, Problem, formulation_of
from .relax.legalize import LegalizeResult, make_legal
from .relax.lowpass import MAX_SHIFT, RegionError, displacement, grid_step
from .relax.md import MDForce, md_relax
from .relax.optdot import Progress, RelaxSettings, relax_staged
from .relax.resize import fit_sizes, reach
from .relax.result import RelaxResult
from .sampling.initial import Rect, initial_dots_in
from .sampling.phantoms import phantom_dots

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


def rule_diameters(job: Job, xy0: np.ndarray) -> np.ndarray | None:
    """``[n]`` diameter the size rule gives the dots thrown at ``xy0`` (their start
    cells'), mm; None for dots of one size."""
    if job.sizes is None:
        return None
    return np.asarray(job.diameters_at(job.density.cell_index(xy0)), dtype=np.float64)


def throw(job: Job, n: int, seed: int | Sequence[int], rect: Rect | None, where: str):
    """``[n, 2]`` initial dots of the window ``rect`` (None: the panel), mm, generation
    order: darts in proportion to the fill (to the dot count when sizes vary), only
    those inside the outline kept.

    Raises:
        GeometryError: the map is zero over (most of) the window's part of the panel.
    """
    inside = None if job.domain.rectangle else job.domain.contains
    return initial_dots_in(job.density, n, seed, inside, job.dart_weights, rect, where)


def relax(
    job: Job,
    xy0: np.ndarray,
    start: np.ndarray | None = None,
    frozen: np.ndarray | None = None,
    progress: Progress | None = None,
    formulation: Formulation | None = None,
    lowpass: bool = True,
) -> RelaxResult:
    """Relax the dots thrown at ``xy0`` (``[n, 2]`` mm, Morton order for speed): OptDot
    through the formulation's stages, or the MD baseline; one result either way.

    Args:
        start: ``[n, 2]`` positions to start from (default ``xy0``; containers stay on
            ``xy0``).
        frozen: ``[n]`` bool, dots held still (a tile's neighbours).
        progress: ``progress(iteration, value)``; a true return halts.
        formulation: overrides the job's (benchmarks try variants).
        lowpass: run the formulation's long-wavelength correction and its hard-core
            iterations (:func:`_lowpass`) after the relaxation. Tiles relax without
            (False): the correction runs once their seams are relaxed, blended over
            windows that span the seams (:func:`correction_region`), and the hard core in
            their guarantee task (:func:`hard_core`).
    """
    opt = job.optimize
    rho = job.density.at(xy0)
    if opt.method == "md":
        if start is not None or frozen is not None:
            raise ValueError("the MD baseline relaxes a whole panel, not a tile")
        r0 = 0.5 * job.diameter
        law = MDForce(
            core=job.min_distance,
            spacing=2.0 * hex_radius(rho, r0),
            decay=opt.md_decay,
            cutoff=opt.md_cutoff,
        )
        return md_relax(
            xy0, law, job.box, r0, steps=opt.max_iter, step=opt.md_step, skin=opt.skin,
            callback=progress,
        )  # fmt: skip
    form = formulation_for(job) if formulation is None else formulation
    diameters = rule_diameters(job, xy0)
    phantom = None
    if form.phantoms and len(xy0):
        xy0, rho, start, frozen, diameters, phantom = _with_phantoms(
            job, form, xy0, rho, start, frozen, diameters
        )
    res = relax_staged(
        problem_of(job),
        form,
        xy0,
        rho,
        settings_for(job),
        progress,
        start=start,
        frozen=frozen,
        diameters=diameters,
        phantom=phantom,
    )
    if lowpass and (form.lowpass or form.lowpass_core_iter) and settings_for(job).max_iter > 0:
        res = _lowpass(job, form, res, xy0, rho, frozen, diameters, phantom)
    if phantom is not None:
        res.xy = np.ascontiguousarray(res.xy[~phantom])
    return res


def correction_region(
    job: Job, xy0: np.ndarray, xy: np.ndarray, region: Rect, formulation: Formulation | None = None
):
    """The coverage error a tile's correction solves, over ``region`` (the windows it
    blends grown by :func:`correction_pad`, :func:`optdot.tiling.tasks.correct_tile`) on
    the lattice every tile shares: ``(RegionError, cap mm)``, or None when the formulation
    has no correction. Every dot in the region and within a lattice cell around it must be
    given."""
    form = formulation_for(job) if formulation is None else formulation
    if job.optimize.method == "md" or not form.lowpass or not len(xy0):
        return None
    if settings_for(job).max_iter == 0:
        return None
    area, _ = _areas(job, job.density.at(xy0), rule_diameters(job, xy0))
    spacing = job_spacing(job)
    h = max(grid_step(job.density, spacing), TILE_GRID * spacing)
    err = RegionError(xy, area, job.density, h, form.lowpass_sigma * spacing, region, job.domain)
    return err, MAX_SHIFT * spacing


#: Lattice step of the tiles' correction, in spacings (one process: half a spacing). The
#: grain it removes lies at 6 spacings and longer (S(k a 0.3-1)); a spacing resolves it
#: and takes a quarter of the cells.
TILE_GRID = 0.5


def correction_pad(job: Job, formulation: Formulation | None = None) -> float:
    """How far beyond its windows a tile's correction deposits and blurs, mm (4 blur
    sigmas and 2 lattice cells): a window's error is then the same in every tile that
    solves it, whatever lies past its edge in the tile's region. At most 3.8 spacings."""
    form = formulation_for(job) if formulation is None else formulation
    spacing = job_spacing(job)
    h = max(grid_step(job.density, spacing), TILE_GRID * spacing)
    return 4.0 * form.lowpass_sigma * spacing + 2.0 * h


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


def _areas(job: Job, rho: np.ndarray, diameters: np.ndarray | None) -> tuple[np.ndarray, float]:
    """``([n] dot areas mm², median hexagonal spacing mm)`` of dots at fills ``rho``."""
    d = np.broadcast_to(job.diameter if diameters is None else diameters, (len(rho),))
    area = np.pi * 0.25 * d**2
    return area, float(np.median(2.0 * hex_radius(rho, 0.5 * d)))


def hard_core(
    job: Job,
    xy0: np.ndarray,
    xy: np.ndarray,
    held: tuple[np.ndarray, np.ndarray | float] | None = None,
    formulation: Formulation | None = None,
) -> np.ndarray:
    """The formulation's hard-core iterations (see :func:`_lowpass`) for a tile's dots
    after its correction, with its neighbours' dots held: ``[n, 2]`` new positions, mm.

    Args:
        held: ``(positions [h, 2] mm, diameters [h] or one, mm)`` of the neighbours (final
            for the tiles settled before, corrected for the others).
    """
    form = formulation_for(job) if formulation is None else formulation
    if job.optimize.method == "md" or not form.lowpass_core_iter or not len(xy0):
        return xy
    if settings_for(job).max_iter == 0:
        return xy
    n = len(xy0)
    diameters = rule_diameters(job, xy0)
    frozen = None
    if held is not None and len(held[0]):
        hxy = np.asarray(held[0], np.float64)
        xy0 = np.concatenate([xy0, hxy])
        xy = np.concatenate([xy, hxy])
        frozen = np.zeros(len(xy0), bool)
        frozen[n:] = True
        if diameters is not None:
            diameters = np.concatenate([diameters, np.broadcast_to(held[1], (len(hxy),))])
    rho = job.density.at(xy0)
    phantom = None
    if form.phantoms:
        xy0, rho, start, frozen, diameters, phantom = _with_phantoms(
            job, form, xy0, rho, xy, frozen, diameters
        )
        xy = start
    res = RelaxResult(np.ascontiguousarray(xy), np.nan, 0, 0, 0, "", [])
    res = _core(job, form, res, xy0, rho, frozen, diameters, phantom)
    return np.ascontiguousarray(res.xy[:n])


def _with_phantoms(job, form, xy0, rho, start, frozen, diameters):
    """The phantom dots near the walls appended (frozen): ``(xy0, rho, start, frozen,
    diameters, phantom mask)``."""
    n = len(xy0)
    pxy, prho, pd = phantoms_near(job, form, xy0)
    xy0 = np.concatenate([xy0, pxy])
    rho = np.concatenate([rho, prho])
    start = None if start is None else np.concatenate([start, pxy])
    # phantoms stay where they were thrown: free, they would yield to the real dots'
    # hard core and let the first row settle against the wall again
    frozen = np.zeros(n, bool) if frozen is None else frozen
    frozen = np.concatenate([frozen, np.ones(len(pxy), bool)])
    if diameters is not None:
        diameters = np.concatenate([diameters, pd])
    phantom = np.zeros(len(xy0), bool)
    phantom[n:] = True
    return xy0, rho, start, frozen, diameters, phantom


def _lowpass(job, form, res, xy0, rho, frozen, diameters, phantom) -> RelaxResult:
    """The long-wavelength correction (:mod:`optdot.relax.lowpass`) after the
    relaxation, then the hard core alone.

    ``form.lowpass`` times: every real dot's coverage error over the window of the real
    dots, the movers (not phantoms, not held) and their containers moved along the
    field, then
    ``form.lowpass_iter`` L-BFGS iterations (default none). The relaxation
    comes first because it makes long-wavelength grain of its own: 30 more iterations
    of it after the correction bring half the grain back, and even 2 leave S(k a 0.3-1)
    at 0.00034 where none leaves 0.00005 (uniform 0.20 map). Last,
    ``form.lowpass_core_iter`` iterations of the hard-core term alone (soft circles
    shrunk until they no longer meet, containers kept): the correction moves dots at the
    scale of a spacing too and pushes pairs that stood just outside the core under
    60 µm; with the compressed soft circles gone the core clears them (LED sample: 5,484
    pairs under 60 µm after the relaxation, 7,357 after a correction, 541 after 10 core
    iterations) without bringing the grain back. Measured in BENCHMARKS.md (issue 24).
    """
    res, xy0 = _passes(job, form, res, xy0, rho, frozen, diameters, phantom)
    res = _core(job, form, res, xy0, rho, frozen, diameters, phantom)
    if form.lowpass or form.lowpass_core_iter:
        res.message += (
            f"; then {form.lowpass} long-wavelength passes ({form.lowpass_iter} iterations "
            f"each) and {form.lowpass_core_iter} hard-core iterations"
        )
    return res


def _passes(job, form, res, xy0, rho, frozen, diameters, phantom):
    """The correction passes of :func:`_lowpass`: ``(result, containers moved)``."""
    real = np.ones(len(xy0), bool) if phantom is None else ~phantom
    movers = real if frozen is None else real & ~frozen
    area, spacing = _areas(job, rho[real], None if diameters is None else diameters[real])
    # the dots' box grown by a spacing (clipped to the map's): the target must cover the
    # strip between the outermost centres and the walls, whose coverage they carry
    lo, hi = xy0[real].min(axis=0) - spacing, xy0[real].max(axis=0) + spacing
    window = (float(lo[0]), float(lo[1]), float(hi[0]), float(hi[1]))
    settings = dataclasses.replace(settings_for(job), max_iter=form.lowpass_iter)
    for _ in range(form.lowpass):
        u = np.zeros_like(xy0)
        shift = displacement(
            res.xy[real], area, job.density, spacing, form.lowpass_sigma, window, job.domain
        )
        u[real] = shift
        u[~movers] = 0.0
        xy0 = xy0 + u
        res.xy = res.xy + u
        if form.lowpass_iter:
            more = relax_staged(
                problem_of(job), form, xy0, rho, settings, None, start=res.xy, frozen=frozen,
                diameters=diameters, phantom=phantom,
            )  # fmt: skip
            res = _after(res, more)
    return res, xy0


def _core(job, form, res, xy0, rho, frozen, diameters, phantom) -> RelaxResult:
    """The hard-core iterations of :func:`_lowpass`: soft circles too small to meet,
    containers as they were."""
    if not form.lowpass_core_iter:
        return res
    shrink = 1e-3
    core_only = dataclasses.replace(
        form, radius_factor=form.radius_factor * shrink,
        container_factor=form.container_factor / shrink,
    )  # fmt: skip
    settings = dataclasses.replace(settings_for(job), max_iter=form.lowpass_core_iter)
    more = relax_staged(
        problem_of(job), core_only, xy0, rho, settings, None, start=res.xy, frozen=frozen,
        diameters=diameters, phantom=phantom,
    )  # fmt: skip
    return _after(res, more)


def _after(res: RelaxResult, more: RelaxResult) -> RelaxResult:
    """``res`` continued by ``more``: its positions, evaluations and history added; the
    iteration count, status and message stay the relaxation's (what its progress bar
    showed)."""
    res.xy = more.xy
    res.penalty = more.penalty
    res.nfev += more.nfev
    res.rebuilds += more.rebuilds
    res.history = res.history + more.history
    return res


def _allowed(job: Job):
    """``allowed(xy) -> [m] bool``: a real dot's centre may stand there (in the map's box,
    inside the outline, in a non-zero cell)."""
    dens, dom = job.density, job.domain

    def allowed(xy: np.ndarray) -> np.ndarray:
        ok = (
            (xy[:, 0] >= dens.x0)
            & (xy[:, 0] <= dens.x0 + dens.width)
            & (xy[:, 1] >= dens.y0)
            & (xy[:, 1] <= dens.y0 + dens.height)
        )
        ok[ok] = dens.at(xy[ok]) > 0
        if not dom.rectangle:
            ok[ok] = dom.contains(xy[ok])
        return ok

    return allowed


def phantom_reach(job: Job, form: Formulation) -> float:
    """How far beyond a wall phantoms reach the real dots: twice the largest circle
    (the lowest non-zero fill, the largest dot), mm."""
    live = job.density.grid[job.density.grid > 0]
    rho_min = float(live.min()) if live.size else 1.0
    widest = job.diameter if job.sizes is None else job.sizes.high
    r = float(form.radii(np.array([rho_min]), 0.5 * widest, 0)[0])
    return 2.0 * r * (1.0 + form.polydispersity)


@lru_cache(maxsize=4)
def job_phantoms(job: Job, reach: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The job's phantom dots (:func:`~optdot.sampling.phantoms.phantom_dots`), thrown
    once per job and process: ``(xy [m, 2] mm, rho [m], diameter [m] mm)``. The cache
    holds the job, so its identity stays unique while cached."""
    dens = job.density
    partial = None
    if not job.domain.rectangle:
        ny, nx = dens.shape
        cw, ch = dens.cell_size
        partial = job.domain.cell_fractions(dens.x0, dens.y0, cw, ch, nx, ny) < 1.0
    r0 = 0.5 * job.diameter
    xy, rho, weight = phantom_dots(
        dens, _allowed(job), partial, reach, np.pi * r0 * r0, job.optimize.seed, job.dart_weights
    )
    return xy, rho, job.diameter / np.sqrt(weight)


def phantoms_near(job: Job, form: Formulation, xy0: np.ndarray):
    """The job's phantom dots within reach of the box around ``xy0`` (``[n, 2]`` mm):
    ``(xy [m, 2] mm, rho [m], diameter [m] mm)``. A tile's phantoms are the panel's in
    its window, so they do not depend on the tiling."""
    reach = phantom_reach(job, form)
    xy, rho, d = job_phantoms(job, reach)
    lo = xy0.min(axis=0) - reach
    hi = xy0.max(axis=0) + reach
    m = (xy[:, 0] >= lo[0]) & (xy[:, 0] <= hi[0]) & (xy[:, 1] >= lo[1]) & (xy[:, 1] <= hi[1])
    return xy[m], rho[m], d[m]


@dataclass
class Finished:
    """What :func:`finish` made of a set of dots.

    Attributes:
        xy: ``[n, 2]`` final positions, mm, rounded to 1 nm.
        diameter: the one diameter, mm, or ``[n]`` per dot.
        legalize: the guarantee pass's facts (sweeps, fixes).
    """

    xy: np.ndarray
    diameter: float | np.ndarray
    legalize: LegalizeResult


def finish(
    job: Job,
    xy: np.ndarray,
    xy0: np.ndarray,
    where: str,
    held: tuple[np.ndarray, np.ndarray | float] | None = None,
    window: Rect | None = None,
) -> Finished:
    """Sizes fitted (when they vary by a rule), then the guarantee pass and its check.

    Args:
        xy: ``[n, 2]`` relaxed positions, mm.
        xy0: ``[n, 2]`` where they were thrown (their start cells: size and the cell a
            dot returns to if it drifted into a zero cell).
        where: the job or tile, for the error message.
        held: ``(positions [h, 2] mm, diameters [h] or one, mm)`` of dots held still
            around these (a tile's neighbours within :func:`halo_width`): they count in
            the coverage and the spacing, and someone else fixes them.
        window: the part of the panel the size fit covers (a tile grown by the fit's
            reach; None: the panel).

    Raises:
        GuaranteeError: a violation is left after the pass.
    """
    n = len(xy)
    d = rule_diameters(job, xy0)
    home = job.density.cell_index(xy0)
    frozen = None
    if held is not None and len(held[0]):
        xy = np.concatenate([xy, held[0]])
        home = np.concatenate([home, np.zeros(len(held[0]), np.int64)])
        frozen = np.zeros(len(xy), bool)
        frozen[n:] = True
        if d is not None:
            d = np.concatenate([d, np.broadcast_to(held[1], (len(held[0]),))])
    if d is None:
        radius, dmin = 0.5 * job.diameter, job.min_distance
    else:
        if fitted(job):
            fit = None if frozen is None else ~frozen
            d = fit_sizes(xy, d, job.sizes, job.density, job.domain, fit_sigma(job), fit, window)
        radius, dmin = 0.5 * d, d + job.optimize.gap
    leg = make_legal(xy, job.density, home, job.domain, radius, dmin, where, frozen)
    diameter = job.diameter if d is None else d[:n]
    return Finished(np.ascontiguousarray(leg.xy[:n]), diameter, leg)
