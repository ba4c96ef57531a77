"""Formulations: how the map becomes circles, containers and penalty terms.

``paper`` is the paper as written (§3, §3.3). The other presets and every variant in
``benchmarks/formulations.py`` are points in the same small space: the radius
rule, a density-dependent compression, polydisperse circles, a hard core and a soft gap,
how the panel edge and the zero-density cells are treated, and staged relaxation.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, replace

import numpy as np
from scipy.ndimage import gaussian_filter

from ..geometry.density import DensityMap
from ..geometry.domain import Domain
from ..geometry.edges import EdgeIndex
from ..geometry.orientation import Orientation
from ..geometry.shapes import DotShape
from .circles import circle_radius, container_half_sides, hex_radius
from .penalty import PenaltyTerms

#: The fill under which a container may be sized for its neighbourhood's instead. The
#: circle of §3.3 grows as ``1 / sqrt(rho)``: where a map dips towards zero (a film's
#: clear islands between LEDs, read bilinearly, or a designed cell of 1e-5 among cells of
#: 0.1) a 79 µm dot's circle reaches 17 mm, overlaps thousands of neighbours, sets the
#: phantoms' reach for the whole panel and pushes the dots around the dip by
#: millimetres, out of the band their sizes were given for. Such a dip is far narrower
#: than its own container; a map sparse over a wide region is not, and keeps its fill.
CONTAINER_FILL_FLOOR = 0.01


@dataclass(frozen=True, eq=False)
class Containers:
    """The fill each dot's container is sized for (:func:`containers_of`).

    Under :data:`CONTAINER_FILL_FLOOR`, where the map's mean over the neighbourhood a
    container at the floor would span (a Gaussian of that radius) is more than twice the
    fill, the container is sized for that mean, at most the floor: a dip narrower than
    its container takes its surroundings' spacing, up to the floor's. Elsewhere (a map
    sparse over a wide region, every fill at or over the floor) the map's own fill.

    Attributes:
        density: the map.
        mean: ``[ny, nx]`` the map's mean about each cell (the Gaussian's).
    """

    density: DensityMap
    mean: np.ndarray

    def floored(self, rho: np.ndarray, xy: np.ndarray) -> np.ndarray:
        """``[n]`` the container fill of points at ``xy`` (``[n, 2]`` mm; outside the
        map's box, its nearest cell's) whose own fill is ``rho`` (``[n]``; 0 stays 0)."""
        return _floored(rho, self.mean.ravel()[self.density.cell_index(xy)])

    def grid(self) -> np.ndarray:
        """``[ny, nx]`` the container fill of each of the map's cells."""
        return _floored(self.density.grid, self.mean)

    def lowest(self) -> float:
        """The least non-zero container fill over the map's cells (1 for an empty map)."""
        g = self.grid()
        live = g[g > 0]
        return float(live.min()) if live.size else 1.0


def _floored(rho: np.ndarray, mean: np.ndarray) -> np.ndarray:
    """``rho`` raised towards ``mean`` (at most to the floor) where it is a dip."""
    dip = (rho > 0) & (rho < CONTAINER_FILL_FLOOR) & (mean > 2.0 * rho)
    return np.where(dip, np.maximum(rho, np.minimum(mean, CONTAINER_FILL_FLOOR)), rho)


@functools.lru_cache(maxsize=4)
def containers_of(density: DensityMap, widest: float) -> Containers:
    """:class:`Containers` of ``density`` for dots up to ``widest`` mm across."""
    g = density.grid
    dx, dy = density.cell_size
    radius = float(circle_radius(np.array([CONTAINER_FILL_FLOOR]), 0.5 * widest)[0])
    if not ((g > 0) & (g < CONTAINER_FILL_FLOOR)).any():
        return Containers(density, g)  # no fill under the floor: nothing to size otherwise
    return Containers(density, gaussian_filter(g, (radius / dy, radius / dx), mode="nearest"))


@dataclass(frozen=True, eq=False)
class Problem:
    """What a formulation needs to know of a job: the panel, the map and the lengths.

    Attributes:
        domain: where dots may go.
        density: the fill-fraction map (its zero cells feed the empty-cell term).
        dot_radius: r0, mm.
        min_distance: smallest allowed centre distance (diameter + gap), mm.
        close_target: the centre distance the hard core aims to clear, mm (the job's
            ``optimize.close_target``, by default its ``qa.close_distance``).
        seed: seed of any random choice (polydispersity).
        reach: how far a shaped dot reaches from its centre (its bounding radius), mm:
            the hard panel term keeps it inside; None: ``dot_radius`` (discs).
        shaped: ``(shape, orientation field, gap mm)`` of shaped dots, whose footprints
            feel the multi-sphere penalty (:mod:`optdot.relax.multisphere`); None: discs.
    """

    domain: Domain
    density: DensityMap
    dot_radius: float
    min_distance: float
    close_target: float = 0.060
    seed: int = 1
    reach: float | None = None
    shaped: tuple[DotShape, Orientation, float] | None = None


@dataclass(frozen=True)
class Formulation:
    """One formulation of the relaxation.

    Attributes:
        radius_factor: multiplies the paper's radius r = r0 sqrt(pi / (sqrt3 rho)).
        dense_factor: extra factor reached at ``rho >= dense_rho`` (1 at ``rho <=
            light_rho``, linear in between): compresses only where the map is dense.
        light_rho, dense_rho: the ramp of ``dense_factor``.
        polydispersity: circle radii are multiplied by ``1 ± p`` (random sign per dot,
            normalised to keep the mean circle area): a bidisperse mixture does not
            crystallise the way equal circles do.
        w_hard: weight of the hard-core term (pairs closer than c_i + c_j) and of the
            hard panel term (dots protruding from the panel); 0 = off.
        gap: soft gap, mm: dots whose hexagonal spacing is at least ``gap / gap_share``
            get hard-core radius ``gap / 2`` instead of ``dmin / 2``; 0 = off.
        gap_share: see ``gap``.
        core_share: hard-core radius ``core_share * r'`` (a share of the hexagonal
            half-spacing, never below ``dmin / 2``): with ``w_hard`` it keeps every pair
            from coming much closer than the local lattice spacing; 0 = off.
        core_floor: the core applies only where it reaches at least this centre
            distance, mm (``core_share * 2 r' >= core_floor``): where the lattice itself
            is too tight to clear the close-pair threshold it would only add order.
        core_cap: the core's centre distance is at most this, mm (0 = no cap): in sparse
            regions a core near the lattice spacing would crystallise the pattern, and
            one just above the close-pair threshold is all that is needed.
        hex_panel: use the hexagonal radius r' (not r) against the panel edges.
        empty_term: penalise circles reaching into zero-density cells.
        phantoms: relax with phantom dots beyond every wall
            (:mod:`optdot.sampling.phantoms`); the real dots' soft edge terms then keep
            only ``r0``.
        lowpass: passes of the long-wavelength correction after the relaxation
            (:mod:`optdot.relax.lowpass`); 0 = off.
        lowpass_sigma: the correction's blur, in dot spacings.
        lowpass_last_sigma: the last pass's blur, in dot spacings (0: ``lowpass_sigma``).
            A fine pass first, a wide one last: at a wall the fine pass's displacement
            saturates its cap on the first row's layering (a structure of one spacing
            that dots pinned ``r0`` from the wall cannot undo) and leaves the error along
            the wall at scales the eye sees; the wide pass sees past the row.
        lowpass_last_steps: how many times the last (wide) pass is solved and applied on a
            steep map (:func:`optdot.stages.wide_rounds`), each time from where the dots
            stand: one linear step misses where the map is steep and sparse (a designed
            map's LED front: fill 0.01 beside 0.25 within 1 mm), since a lattice cell then
            spans fills apart by 2x and the dots in it move by one interpolated flux; the
            misses shrink step by step.
        lowpass_last_cap: the last pass's displacement cap in its rounds on a steep map, in
            dot spacings (0, and on a map of one round: the first passes'
            :data:`optdot.relax.lowpass.MAX_SHIFT`).
        lowpass_iter: L-BFGS iterations after each pass (0: none, the default: they bring
            grain back).
        lowpass_core_iter: L-BFGS iterations of the hard-core term alone after the
            passes (:func:`optdot.stages.relax`).
        stages: ``(share of max_iter, radius multiplier)`` per stage, relaxed in turn.
        container_factor: container side / circle radius (paper: 4).
        close_ref: the close-pair distance ``core_floor``, ``core_cap`` and ``gap`` are
            given for, mm: :meth:`terms` scales them by ``problem.close_target /
            close_ref``, so a job that aims to clear 80 µm gets the same rule around 80 µm.
    """

    radius_factor: float = 1.0
    dense_factor: float = 1.0
    light_rho: float = 0.25
    dense_rho: float = 0.5
    polydispersity: float = 0.0
    w_hard: float = 0.0
    gap: float = 0.0
    gap_share: float = 0.85
    core_share: float = 0.0
    core_floor: float = 0.0
    core_cap: float = 0.0
    hex_panel: bool = False
    empty_term: bool = False
    phantoms: bool = False
    lowpass: int = 0
    lowpass_sigma: float = 0.7
    lowpass_last_sigma: float = 0.0
    lowpass_last_steps: int = 1
    lowpass_last_cap: float = 0.0
    lowpass_iter: int = 0
    lowpass_core_iter: int = 0
    stages: tuple[tuple[float, float], ...] = ((1.0, 1.0),)
    container_factor: float = 4.0
    close_ref: float = 0.060

    def lowpass_sigmas(self) -> list[float]:
        """The blur of each long-wavelength pass, in dot spacings (``lowpass`` of them)."""
        sigmas = [self.lowpass_sigma] * self.lowpass
        if sigmas and self.lowpass_last_sigma > 0:
            sigmas[-1] = self.lowpass_last_sigma
        return sigmas

    def radii(
        self, rho: np.ndarray, r0: float | np.ndarray, seed: int, multiplier: float = 1.0
    ) -> np.ndarray:
        """``[n]`` circle radii, mm, for dots of radius ``r0`` (mm, one or ``[n]``) at
        fill ``rho`` (``[n]``)."""
        ramp = np.clip((rho - self.light_rho) / (self.dense_rho - self.light_rho), 0.0, 1.0)
        factor = self.radius_factor * multiplier * (1.0 + (self.dense_factor - 1.0) * ramp)
        r = circle_radius(rho, r0, 1.0) * factor
        if self.polydispersity > 0:
            sign = np.random.default_rng([seed, 0x9D]).integers(0, 2, len(r)) * 2 - 1
            p = self.polydispersity
            r = r * (1.0 + p * sign) / math.sqrt(1.0 + p * p)
        return r

    def terms(
        self,
        problem: Problem,
        xy0: np.ndarray,
        rho: np.ndarray,
        multiplier: float = 1.0,
        diameters: np.ndarray | None = None,
        phantom: np.ndarray | None = None,
    ) -> PenaltyTerms:
        """Penalty terms for dots starting at ``xy0`` (``[n, 2]`` mm) with fill ``rho``
        (``[n]``); ``multiplier`` scales the circle radii (staged relaxation).
        ``phantom`` (``[n]`` bool) marks the phantom dots among them.

        ``diameters`` (``[n]`` mm, dots of varying size): each dot's circle and hexagonal
        radii follow its own r0_i (the circle radius rule then depends only on the local
        dot count, r = 1 / sqrt(sqrt3 n)), and every centre distance of the hard-core
        rule (its minimum, floor, cap and gap, given for two dots of ``2 *
        problem.dot_radius``) shifts by ``d_i - 2 r0`` per dot, so a pair's core target
        keeps the same *edge gap* whatever the two sizes. The hard panel term keeps r0
        (the smallest dot); the soft one uses each dot's own radius and the guarantee
        pass keeps every centre its own radius from the edges.
        """
        r0 = problem.dot_radius
        r0i = r0 if diameters is None else 0.5 * np.asarray(diameters, dtype=np.float64)
        shift = 0.0 if diameters is None else 2.0 * (r0i - r0)
        r = self.radii(rho, r0i, problem.seed, multiplier)
        core = np.full(len(r), 0.5 * problem.min_distance) + 0.5 * shift
        k = problem.close_target / self.close_ref
        if self.core_share > 0:
            share = self.core_share * hex_radius(rho, r0i)
            if self.core_cap > 0:
                share = np.minimum(share, 0.5 * (k * self.core_cap + shift))
            floor = k * self.core_floor + shift
            core = np.where(2.0 * share >= floor, np.maximum(core, share), core)
        if self.gap > 0:
            wide = 2.0 * hex_radius(rho, r0i) * self.gap_share >= k * self.gap + shift
            core = np.where(wide, np.maximum(core, 0.5 * (k * self.gap + shift)), core)
        panel_r = np.maximum(hex_radius(rho, r0i), r0i) if self.hex_panel else r
        if phantom is not None:
            panel_r = np.broadcast_to(np.asarray(r0i, dtype=np.float64), r.shape).copy()
        density = problem.density
        empty = (density.grid <= 0).astype(np.uint8) if self.empty_term else None
        dom = problem.domain
        edges = None
        if not dom.rectangle:
            reach = max(float(panel_r.max(initial=0.0)), r0, problem.reach or 0.0)
            reach += dom.edge_margin
            if phantom is not None:
                reach = max(reach, 2.0 * float(r.max(initial=0.0)) + dom.edge_margin)
            edges = EdgeIndex.build(dom, reach)
        return PenaltyTerms(
            radius=r,
            panel_radius=np.ascontiguousarray(panel_r),
            center=np.ascontiguousarray(xy0),
            half_side=container_half_sides(r, self.container_factor),
            box=dom.box,
            dmin=problem.min_distance,
            dot_radius=r0 if problem.reach is None else problem.reach,
            w_hard=self.w_hard,
            empty=np.zeros((1, 1), np.uint8) if empty is None else empty,
            grid_box=(density.x0, density.y0, *density.cell_size),
            core=core,
            margin=dom.edge_margin,
            edges=edges,
            phantom=phantom,
        )


#: Named formulations a job can select with ``optimize.formulation``. ``optdot`` won the
#: comparison in benchmarks/formulations.py (BENCHMARKS.md): the paper's soft circles,
#: 5 % larger, keep the pattern irregular, 3.5 r containers hold the coverage, and a hard
#: core (weight 15) trims the pairs under 60 µm. Its centre distance, with a = the local
#: hexagonal spacing: 0.93 a clamped to 61..64 µm where a >= 62.2 µm (61 / 0.98); the dot
#: diameter (+ gap) elsewhere, where a core cannot clear 60 µm and would only add order.
#: The 61 µm floor matters: a core just under 60 µm pins pairs just under 60 µm.
#: Phantom dots beyond every wall keep the density flat up to the walls; two
#: passes of the long-wavelength correction cut the grain seen through a 0.5 mm blur from
#: 0.28 % to 0.015 % RMS (uniform 0.20 map; the second pass takes the LED sample's
#: largest JND from 3.7 to 3.0), and 10 iterations of the hard core alone after them
#: clear most pairs under 60 µm. The second pass blurs over 3 spacings, not 0.7: the
#: largest JND of led 0.69 against 2.18, tsuno 1.10 against 1.84, chokka 0.29 against
#: 0.45, the grain on the uniform map 0.015 % either way (BENCHMARKS.md).
PRESETS: dict[str, Formulation] = {
    "paper": Formulation(),
    "optdot": Formulation(
        radius_factor=1.05,
        w_hard=15.0,
        core_share=0.93,
        core_floor=0.061,  # = the 61 µm floor below: 0.93 a is only used above it
        core_cap=0.064,
        gap=0.061,
        gap_share=0.98,
        hex_panel=True,
        empty_term=True,
        container_factor=3.5,
        phantoms=True,
        lowpass=2,
        lowpass_last_sigma=3.0,
        lowpass_last_steps=6,
        lowpass_last_cap=0.2,
        lowpass_core_iter=10,
    ),
}


def formulation_of(
    name: str, radius_factor: float | None = None, container_factor: float | None = None
) -> Formulation:
    """The preset ``name`` with an explicit ``radius_factor`` and ``container_factor``
    where given (None keeps the preset's)."""
    form = PRESETS[name]
    if radius_factor is not None:
        form = replace(form, radius_factor=radius_factor)
    if container_factor is not None:
        form = replace(form, container_factor=container_factor)
    return form
