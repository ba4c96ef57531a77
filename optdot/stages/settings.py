"""What every stage of a run takes: its penalty problem, formulation, L-BFGS settings,
size rule, halo and spacing, as one value (:class:`StageSettings`). A job becomes it once
per run, in the orchestration (:func:`optdot.orchestration.job_settings.stage_settings`),
shared by the panel and its tiles; no stage sees the job."""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from ..relax.circles import hex_radius
from ..relax.formulation import Containers, Formulation, Problem
from ..relax.optdot import RelaxSettings

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


@dataclass(frozen=True, eq=False)
class StageSettings:
    """What every stage of a run takes from its job, derived once: the stages take this
    value, never the job.

    Attributes:
        problem: the fields a formulation builds its penalty terms from.
        formulation: the job's (or a benchmark's) formulation.
        relax: the L-BFGS settings.
        spacing: the map's median hexagonal spacing, mm
            (:func:`~optdot.orchestration.job_settings.job_spacing`).
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
        containers: the fills the containers are sized for
            (:func:`~optdot.orchestration.job_settings.containers`).
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
