"""The job as a value: :class:`Job` with its :class:`OptimizeParams` and :class:`QAParams`.

Frozen dataclasses validated in ``__post_init__`` (messages name the field, the value and
the allowed range). Reading TOML lives in :mod:`optdot.config.schema`, grids in
:mod:`optdot.config.grids`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from functools import cached_property
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import JobError
from ..geometry.density import DensityMap
from ..geometry.domain import Domain
from ..geometry.limits import DIAMETER_RANGE_MM, MAX_EXTENT_MM
from ..geometry.orientation import Orientation
from ..geometry.profile import DotProfile
from ..geometry.shapes import CIRCLE, DotShape
from ..geometry.sizes import DotSizes, dots_per_cell
from ..printing.laser import Laser
from ..printing.process import Process
from ..printing.sheet import Sheet
from .backlight import Backlight
from .bench import Bench
from .grids import validate_grid
from .light_guide import DesignParams, LightGuide
from .viewing import DEFAULT_VIEW, Viewing, viewing

METHODS = ("optdot", "md")
#: Edge gap below which two dots of varying size are "too close", mm: the 60 µm centre
#: rule for 46 µm dots (``qa.close_gap``).
DEFAULT_CLOSE_GAP = 0.014
FORMULATIONS = ("paper", "optdot")


@dataclass(frozen=True)
class OptimizeParams:
    """How the dots are relaxed.

    Attributes:
        method: ``"optdot"`` (L-BFGS on penalty (3), the paper's method) or ``"md"``
            (the molecular-dynamics baseline of Idé et al. 2003, see :mod:`optdot.relax.md`).
        max_iter: iterations of L-BFGS or MD steps (paper: 200).
        seed: seed of the scrambled low-discrepancy sequence.
        formulation: ``"paper"`` reproduces the paper exactly (radius factor 1, panel
            penalty with the circle radius); ``"optdot"`` is our default, see README.
        radius_factor: multiplies the paper's circle radius r = r0 sqrt(pi/(sqrt3 rho));
            ``None`` takes the formulation's (see :mod:`optdot.relax.formulation`).
        container_factor: container side / circle radius (paper: 4); ``None`` takes the
            formulation's.
        lbfgs_memory: L-BFGS history length m (paper: 6).
        ftol: stop when the penalty fell by less than ``ftol`` (relative) over 10
            iterations; 0 runs all ``max_iter`` iterations.
        gap: manufacturing gap, mm: dot centres keep at least ``diameter + gap``.
        skin: Verlet skin as a fraction of each circle's radius.
        md_step: MD only: dt / c as a fraction of the collision distance.
        md_decay: MD only: decay length L of the force tail / hexagonal spacing.
        md_cutoff: MD only: the tail is cut at D = b + md_cutoff * L.
        close_target: centre distance the hard core of the ``optdot`` formulation aims
            to clear, mm; ``None`` (default) follows ``qa.close_distance``.
    """

    method: str = "optdot"
    max_iter: int = 200
    seed: int = 1
    formulation: str = "optdot"
    radius_factor: float | None = None
    container_factor: float | None = None
    lbfgs_memory: int = 6
    ftol: float = 1e-3
    gap: float = 0.0
    skin: float = 0.3
    md_step: float = 0.02
    md_decay: float = 0.25
    md_cutoff: float = 3.0
    close_target: float | None = None

    def __post_init__(self) -> None:
        _check(self.method in METHODS, "optimize.method", self.method, f"one of {METHODS}")
        _check(
            self.formulation in FORMULATIONS,
            "optimize.formulation",
            self.formulation,
            f"one of {FORMULATIONS}",
        )
        _check(0 <= self.max_iter <= 100_000, "optimize.max_iter", self.max_iter, "0..100000")
        _check(0 <= self.seed < 2**63, "optimize.seed", self.seed, "0..2^63-1")
        if self.radius_factor is not None:
            _check(
                0.5 <= self.radius_factor <= 3.0,
                "optimize.radius_factor",
                self.radius_factor,
                "0.5..3",
            )
        _check(
            self.container_factor is None or 1.0 <= self.container_factor <= 100.0,
            "optimize.container_factor",
            self.container_factor,
            "1..100",
        )
        _check(1 <= self.lbfgs_memory <= 50, "optimize.lbfgs_memory", self.lbfgs_memory, "1..50")
        _check(0.0 <= self.ftol < 1.0, "optimize.ftol", self.ftol, "0 <= ftol < 1")
        _check(0.0 <= self.gap < 10.0, "optimize.gap", self.gap, "0 <= gap < 10 mm")
        _check(0.01 <= self.skin <= 2.0, "optimize.skin", self.skin, "0.01..2")
        _check(0.0 < self.md_step <= 0.5, "optimize.md_step", self.md_step, "0 < md_step <= 0.5")
        _check(0.01 <= self.md_decay <= 2.0, "optimize.md_decay", self.md_decay, "0.01..2")
        _check(0.0 <= self.md_cutoff <= 20.0, "optimize.md_cutoff", self.md_cutoff, "0..20")
        if self.close_target is not None:
            _check(
                0.0 < self.close_target < 10.0,
                "optimize.close_target",
                self.close_target,
                "0 < x < 10 mm",
            )


@dataclass(frozen=True)
class QAParams:
    """Pass/fail thresholds of the QA gate (all distances in mm; None = from the job).

    Attributes:
        collision_distance: centres closer than this collide (default: dot diameter + gap).
        close_distance: centres closer than this are "too close" (default 0.060).
        max_collisions: allowed pairs below ``collision_distance`` (default 0).
        max_close_fraction: allowed share of dots in a too-close pair (default 1.0 = off).
        max_protruding: allowed dots protruding from the panel (default 0).
        max_in_empty: allowed dots in zero-density cells (default 0).
        max_coverage_rms: allowed RMS relative coverage error after 1 mm smoothing.
        max_psi6_coherence: allowed |mean psi6| over 2 mm patches (moire risk).
        smoothing: Gaussian sigma for the visible-coverage check, mm.
        close_gap: edge gap below which a pair is "too close", mm. Dots of varying size
            are always judged this way (default :data:`DEFAULT_CLOSE_GAP`); dots of one
            size by ``close_distance`` unless this is given (then diameter + close_gap).
        view: viewing preset of the visibility check (:data:`~optdot.config.viewing.VIEW_PRESETS`).
        view_distance, view_luminance: override the preset's distance (mm) and luminance
            (cd/m²). psf: Gaussian sigma of the stack's blur, mm.
        max_jnd: allowed largest |JND| of the visibility map (None = reported, not gated).
        warn_jnd: advisory level of the largest |JND|: above it the verdict is PASS WITH
            WARNINGS (the gate still passes; 1 JND = just visible).
    """

    collision_distance: float | None = None
    close_distance: float = 0.060
    max_collisions: int = 0
    max_close_fraction: float = 1.0
    max_protruding: int = 0
    max_in_empty: int = 0
    max_coverage_rms: float = 0.05
    max_psi6_coherence: float = 0.10
    smoothing: float = 1.0
    close_gap: float | None = None
    view: str = DEFAULT_VIEW
    view_distance: float | None = None
    view_luminance: float | None = None
    psf: float | None = None
    max_jnd: float | None = None
    warn_jnd: float = 1.0

    @property
    def viewing(self) -> Viewing:
        """The viewing condition of the visibility check."""
        return viewing(self.view, self.view_distance, self.view_luminance, self.psf)

    @property
    def effective_close_gap(self) -> float:
        """``close_gap``, or :data:`DEFAULT_CLOSE_GAP` when not given, mm."""
        return DEFAULT_CLOSE_GAP if self.close_gap is None else self.close_gap

    def __post_init__(self) -> None:
        if self.close_gap is not None:
            _check(0 <= self.close_gap < 10, "qa.close_gap", self.close_gap, "0 <= x < 10 mm")
        if self.collision_distance is not None:
            _check(
                self.collision_distance > 0, "qa.collision_distance", self.collision_distance, "> 0"
            )
        _check(self.close_distance > 0, "qa.close_distance", self.close_distance, "> 0")
        _check(
            math.isfinite(self.warn_jnd) and self.warn_jnd > 0, "qa.warn_jnd", self.warn_jnd, "> 0"
        )
        _check(self.max_collisions >= 0, "qa.max_collisions", self.max_collisions, ">= 0")
        _check(
            0 <= self.max_close_fraction <= 1,
            "qa.max_close_fraction",
            self.max_close_fraction,
            "0..1",
        )
        _check(self.max_protruding >= 0, "qa.max_protruding", self.max_protruding, ">= 0")
        _check(self.max_in_empty >= 0, "qa.max_in_empty", self.max_in_empty, ">= 0")
        _check(self.max_coverage_rms > 0, "qa.max_coverage_rms", self.max_coverage_rms, "> 0")
        _check(
            0 < self.max_psi6_coherence <= 1,
            "qa.max_psi6_coherence",
            self.max_psi6_coherence,
            "0 < x <= 1",
        )
        _check(self.smoothing > 0, "qa.smoothing", self.smoothing, "> 0")
        if self.max_jnd is not None:
            _check(0 < self.max_jnd < 1e6, "qa.max_jnd", self.max_jnd, "> 0")
        viewing(self.view, self.view_distance, self.view_luminance, self.psf)  # validates


@dataclass(frozen=True, eq=False)
class Job:
    """A validated job: panel, fill-fraction map, dot size and optimizer settings.

    Attributes:
        width, height: size of the density grid, mm. Without an outline the panel is
            ``[0, width] x [0, height]``; with one, the grid covers its bounding box.
        density: the fill-fraction map over the panel (with ``interpolation = "linear"``
            already refined into sub-cells, see :meth:`DensityMap.interpolated`).
        diameter: dot diameter, mm; with ``sizes``, the smallest diameter of the range
            (the reference the optimizer's gap rules are shifted from).
        sizes: how diameters vary (``[dots] diameter = [lo, hi]``), or None for one size.
        interpolation: how the map was read, ``"nearest"`` or ``"linear"``.
        optimize: optimizer settings.
        qa: QA gate thresholds.
        name: a label carried into outputs.
        source: the job file this came from, if any.
        domain: where dots may go (default: the rectangle of the grid).
        inputs: every file the job reads (job, grid, outline, keep-out files); outputs
            may not overwrite them.
        light_guide: the slab and LEDs ``simulate`` and ``design`` trace, or None.
        backlight: the stack around the printed face (``[backlight]``: a direct-lit
            cavity, or a film over the guide), or None for the bare guide.
        design: how ``design`` makes a map (``[design]``).
        viewing_area: ``(x0, y0, x1, y1)`` mm, the part of the panel a viewer sees
            (``[domain] active_area`` or ``bezel``), or None for the whole panel. QA's
            visibility and ``simulate``'s figures are judged inside it; every geometric
            check (collisions, protrusion, empty cells, coverage) covers the whole panel.
        shape: the dot's kind and size (``[dots] shape``; given None, a circle of
            :attr:`diameter`). A round kind's size is its (smallest) diameter; any
            other's is its footprint at scale 1, and :attr:`diameter` the disc of the
            same area's (the smallest's).
        profile: the dots' 3-D profile (``[dots] profile``: ink, a bump or a dimple).
        orientation: where shaped dots' long axes point (``[orientation]``).
        process: how the masks print (``[process]``), or None: masks are the pattern.
            The pattern is then the print, relaxed to the process's gaps
            (``optimize.gap`` already raised to :meth:`Process.relaxation_gap`).
        laser: the laser dotting machine of ``export --laser`` (``[laser]``), or None;
            with sizes, :attr:`diameter` and :attr:`sizes` are already the laser's.
        sheet: the production sheet the masks repeat the panel on (``[sheet]``), or None.
    """

    width: float
    height: float
    density: DensityMap
    diameter: float
    optimize: OptimizeParams = field(default_factory=OptimizeParams)
    qa: QAParams = field(default_factory=QAParams)
    name: str = "optdot"
    source: Path | None = None
    domain: Domain | None = None
    inputs: tuple[Path, ...] = ()
    sizes: DotSizes | None = None
    interpolation: str = "nearest"
    light_guide: LightGuide | None = None
    backlight: Backlight | None = None
    design: DesignParams = field(default_factory=DesignParams)
    viewing_area: tuple[float, float, float, float] | None = None
    shape: DotShape = None  # type: ignore[assignment]  # filled in: a circle
    profile: DotProfile = field(default_factory=DotProfile)
    orientation: Orientation = field(default_factory=Orientation)
    process: Process | None = None
    laser: Laser | None = None
    sheet: Sheet | None = None

    @property
    def ink(self) -> float | None:
        """The printed film's ink contrast ``k`` (its luminance goes as ``1 - k phi``:
        more ink, less light), or None when the dots extract light from a guide (luminance
        as the fill)."""
        bl = self.backlight
        return bl.ink_contrast if bl is not None and bl.on_film else None

    def __post_init__(self) -> None:
        where = str(self.source) if self.source else "job"
        if not isinstance(self.shape, DotShape):  # not given: the paper's circle
            object.__setattr__(self, "shape", DotShape(CIRCLE, (self.diameter,)))
        if self.domain is None:
            d = self.density
            object.__setattr__(
                self, "domain", Domain.rect(d.x0, d.y0, d.x0 + self.width, d.y0 + self.height)
            )
        for key, v in (("domain.width", self.width), ("domain.height", self.height)):
            if not (math.isfinite(v) and 0 < v <= MAX_EXTENT_MM):
                raise JobError(
                    f"{where}: {key} = {v!r} must be a size in mm, 0 < x <= {MAX_EXTENT_MM:g}"
                )
        lo, hi = DIAMETER_RANGE_MM
        if not (math.isfinite(self.diameter) and lo <= self.diameter <= hi):
            raise JobError(
                f"{where}: dots.diameter = {self.diameter!r} must be in mm, {lo:g} <= d <= {hi:g}"
            )
        if self.diameter >= min(self.width, self.height):
            raise JobError(f"{where}: dots.diameter = {self.diameter} does not fit the panel")
        if self.sizes is not None:
            high = self.sizes.high
            if not (math.isfinite(high) and self.diameter < high <= hi):
                raise JobError(
                    f"{where}: dots.diameter = [{self.diameter}, {high}] must be two diameters "
                    f"in mm, {lo:g} <= low < high <= {hi:g}"
                )
            if high >= min(self.width, self.height):
                raise JobError(f"{where}: dots.diameter = {high} does not fit the panel")
            if self.optimize.method == "md":
                raise JobError(
                    f"{where}: optimize.method = 'md' takes one dot size (the baseline of "
                    "Idé et al. has one); give dots.diameter as a number or use 'optdot'"
                )
        if not self.shape.kind.round:
            if self.optimize.method == "md":
                raise JobError(
                    f"{where}: optimize.method = 'md' places discs (the baseline of Idé et al.); "
                    "shaped dots use 'optdot'"
                )
            top = 1.0 if self.sizes is None else self.shape_scale(np.array([self.sizes.high]))[0]
            if 2.0 * self.shape.extent * top >= min(self.width, self.height):
                raise JobError(
                    f"{where}: dots.length = {self.shape.size[0] * top:g} does not fit the panel"
                )
        validate_grid(self.density.grid, f"{where}: density.grid")

    @cached_property
    def bench(self) -> Bench:
        """What the optics take from the job (:class:`~optdot.config.bench.Bench`)."""
        return Bench(
            source=self.source,
            name=self.name,
            domain=self.domain,
            density=self.density,
            viewing_area=self.viewing_area,
            light_guide=self.light_guide,
            backlight=self.backlight,
            design=self.design,
            process=self.process,
            shape=self.shape,
            profile=self.profile,
            orientation=self.orientation,
            sizes=self.sizes,
            diameter=self.diameter,
            close_gap=self.qa.effective_close_gap,
        )

    @property
    def min_distance(self) -> float:
        """Smallest allowed centre distance, mm (diameter + gap; with ``sizes``, of two
        dots of the smallest size; for shaped dots, the width + gap: nearer, two
        footprints are too close at any angles; the guarantee pass then holds their
        exact edge gaps to ``optimize.gap``)."""
        if self.shape.kind.round:
            return self.diameter + self.optimize.gap
        return 2.0 * self.shape.inner_radius * self._low_scale + self.optimize.gap

    def shape_scale(self, diameters: np.ndarray) -> np.ndarray:
        """``[n]`` factors shaped dots of area-equivalent ``diameters`` (``[n]`` mm) are
        their footprint scaled by (:meth:`DotShape.scale_of`)."""
        return self.shape.scale_of(diameters)

    @property
    def _low_scale(self) -> float:
        """The smallest shaped dot's scale (1 for one size)."""
        return self.diameter / self.shape.equivalent_diameter

    @property
    def dot_radius(self) -> float:
        """How far a dot reaches from its centre, mm: the radius (the smallest, with
        ``sizes``), or a shaped dot's bounding radius (the smallest's)."""
        if self.shape.kind.round:
            return 0.5 * self.diameter
        return self.shape.extent * self._low_scale

    @cached_property
    def cell_diameters(self) -> np.ndarray | None:
        """``[ny, nx]`` diameter of each map cell's dots, mm (None: one size)."""
        return None if self.sizes is None else self.sizes.cell_diameters(self.density)

    @property
    def dart_weights(self) -> np.ndarray | None:
        """``[ny, nx]`` multiplier of each cell's fill in the dart throw, so that darts
        land in proportion to the dot count (fill / dot area); None: one size."""
        d = self.cell_diameters
        return None if d is None else (self.diameter / d) ** 2

    def diameters_at(self, cells: np.ndarray) -> np.ndarray | float:
        """Diameter of the dots whose cells (flat indices ``[n]``) are given, mm: ``[n]``,
        or the one diameter."""
        d = self.cell_diameters
        return self.diameter if d is None else d.ravel()[cells]

    @property
    def collision_distance(self) -> float:
        """QA collision threshold, mm (the smallest centre distance, less the grid's
        snapping margin the relaxation keeps on top: :attr:`judged_gap`)."""
        c = self.qa.collision_distance
        return self.min_distance - self._snap_margin if c is None else c

    @property
    def judged_gap(self) -> float:
        """The edge gap QA holds the dots to, mm: ``optimize.gap``, less the margin a
        process's address grid may take from it when the mask is snapped (the relaxation
        keeps that margin on top, :meth:`Process.relaxation_gap`)."""
        return self.optimize.gap - self._snap_margin

    @property
    def _snap_margin(self) -> float:
        return 0.0 if self.process is None else self.process.snap_margin

    @property
    def close_target(self) -> float:
        """Centre distance the optimizer's hard core aims to clear, mm (with ``sizes``,
        for two dots of :attr:`diameter`; the others' targets shift with their size)."""
        c = self.optimize.close_target
        if c is not None:
            return c
        if self.sizes is not None or self.qa.close_gap is not None:
            return self.diameter + self.qa.effective_close_gap
        return self.qa.close_distance

    @property
    def dot_area(self) -> float:
        """Area of one dot, mm²."""
        return math.pi * (0.5 * self.diameter) ** 2

    @property
    def box(self) -> tuple[float, float, float, float]:
        """Bounding box of the panel ``(xmin, ymin, xmax, ymax)``, mm."""
        return self.domain.box

    @property
    def cell_weights(self) -> np.ndarray | None:
        """``[ny, nx]`` share of each grid cell inside the domain (None: all of it; the
        :attr:`bench`'s, computed once)."""
        return self.bench.cell_weights

    @property
    def n_dots(self) -> int:
        """Number of dots the map asks for over the domain (paper §2.1); with ``sizes``,
        each cell's fill over its own dot area."""
        d = self.cell_diameters
        if d is None:
            return self.density.dot_count(self.dot_area, self.cell_weights)
        return int(round(float(dots_per_cell(self.density, d, self.cell_weights).sum())))

    def with_overrides(self, **optimize: Any) -> Job:
        """A copy with some :class:`OptimizeParams` fields replaced (None = keep)."""
        kw = {k: v for k, v in optimize.items() if v is not None}
        if not kw:
            return self
        try:
            opt = replace(self.optimize, **kw)
        except JobError:
            raise
        return replace(self, optimize=opt)


def _check(ok: bool, name: str, value: Any, allowed: str) -> None:
    if not ok:
        raise JobError(f"{name} = {value!r} is out of range ({allowed})")
