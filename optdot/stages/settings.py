"""What a job asks of every stage: its penalty problem, formulation, L-BFGS settings,
size rule, halo and spacing. Derived from the job once per run (:func:`stage_settings`)
and shared by the panel and its tiles; the functions below are how each is derived."""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache
from typing import TYPE_CHECKING

import numpy as np

from ..config.job import Job
from ..relax.circles import hex_radius
from ..relax.formulation import Containers, Formulation, Problem, containers_of, formulation_of
from ..relax.optdot import RelaxSettings
from ..relax.resize import reach

if TYPE_CHECKING:
    from ..config.job import OptimizeParams
    from ..geometry.density import DensityMap
    from ..geometry.domain import Domain
    from ..geometry.orientation import Orientation
    from ..geometry.shapes import DotShape
    from ..geometry.sizes import DotSizes

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
    """What every stage of a run takes from its job, derived once: the stages take this
    value, never the job.

    Attributes:
        problem: the fields a formulation builds its penalty terms from.
        formulation: the job's (or a benchmark's) formulation.
        relax: the L-BFGS settings.
        spacing: the map's median hexagonal spacing, mm (:func:`job_spacing`).
        fit_sigma: the Gaussian the dot sizes are fitted under, mm.
        fitted: whether sizes are fitted after the relaxation.
        halo: how far around a set of dots the guarantee pass holds dots still, mm.
        domain: where dots may go.
        density: the fill-fraction map.
        sizes: how diameters vary, or None for one size.
        shape: the dot's kind and size (:attr:`~optdot.config.job.Job.shape`).
        orientation: where the dots' long axes point.
        optimize: the optimizer's parameters (method, seed, gap, MD's law).
        diameter: the (smallest) dot's diameter, mm.
        min_distance: the smallest centre distance, mm.
        dot_radius: how far the (smallest) dot reaches from its centre, mm.
        dart_weights: ``[ny, nx]`` each cell's weight in the dart throw, or None.
        cell_diameters: ``[ny, nx]`` each cell's dot diameter, mm, or None (one size).
        containers: the fills the containers are sized for (:func:`containers`).
    """

    problem: Problem
    formulation: Formulation
    relax: RelaxSettings
    spacing: float
    fit_sigma: float
    fitted: bool
    halo: float
    domain: Domain
    density: DensityMap
    sizes: DotSizes | None
    shape: DotShape
    orientation: Orientation
    optimize: OptimizeParams
    diameter: float
    min_distance: float
    dot_radius: float
    dart_weights: np.ndarray | None
    cell_diameters: np.ndarray | None
    containers: Containers

    @property
    def box(self) -> tuple[float, float, float, float]:
        """The panel's bounding box ``(xmin, ymin, xmax, ymax)``, mm."""
        return self.domain.box

    @property
    def widest(self) -> float:
        """The largest dot's diameter, mm."""
        return float(self.diameter if self.sizes is None else self.sizes.high)

    def container_fill(self, xy: np.ndarray) -> np.ndarray:
        """``[n]`` the fill the containers of dots at ``xy`` (``[n, 2]`` mm) are sized
        for."""
        return self.containers.floored(self.density.at(xy), xy)

    def rule_diameters(self, xy0: np.ndarray) -> np.ndarray | None:
        """``[n]`` diameter the size rule gives the dots thrown at ``xy0`` (their start
        cells'), mm; None for dots of one size."""
        if self.cell_diameters is None:
            return None
        cells = self.density.cell_index(xy0)
        return np.asarray(self.cell_diameters.ravel()[cells], dtype=np.float64)

    def thrown_areas(self, xy0: np.ndarray) -> np.ndarray:
        """``[n]`` areas (mm²) of the dots thrown at ``xy0`` (``[n, 2]`` mm): their rule
        sizes, from their start cells."""
        return self.dot_areas(self.rule_diameters(xy0), len(xy0))

    def dot_areas(self, diameters: np.ndarray | None, n: int) -> np.ndarray:
        """``[n]`` areas (mm²) of ``n`` dots of ``diameters`` (``[n]`` mm, or None: the
        one diameter)."""
        d = np.broadcast_to(self.diameter if diameters is None else diameters, (n,))
        return np.pi * 0.25 * d**2

    def areas(self, rho: np.ndarray, diameters: np.ndarray | None) -> tuple[np.ndarray, float]:
        """``([n] dot areas mm², median hexagonal spacing mm)`` of dots at fills ``rho``
        (``[n]``) and of ``diameters`` (``[n]`` mm, or None: the one diameter)."""
        d = np.broadcast_to(self.diameter if diameters is None else diameters, (len(rho),))
        area = self.dot_areas(diameters, len(rho))
        if not len(rho):  # no dots (a tile of an empty region): the map's spacing
            return area, self.spacing
        return area, float(np.median(2.0 * hex_radius(rho, 0.5 * d)))


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
