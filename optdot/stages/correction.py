"""The long-wavelength correction after the relaxation (:mod:`optdot.relax.lowpass`),
over the panel or over a tile's blended windows, and the hard-core iterations that
follow it.

The last of two or more passes (the wide one, 3 spacings by default) is solved over the
whole panel at once on a lattice of half its blur (:func:`wide_part`, :func:`wide_solve`),
in one process and in tiles alike: its error is a sum of per-dot deposits, so a tiled
run adds every tile's part and gets the panel's field, where its windows a tile wide
could not (each solves with its own mean and walls). The lattice is also what the wide
pass wants: against the half-spacing grid of the first pass it leaves less at the walls,
where the map is deposited as the dots are and nothing flows across the walls' faces
(notebook strip 140 x 20 mm, one process: strongest blob 0.54 JND on the lattice, 1.09
on the grid, p99 0.21 against 0.35; the tsuno sample 0.43 against 1.10; BENCHMARKS.md).
Steps of 0.5 and 1 spacing (a sixth and a third of the blur) left 0.72 and 0.62 JND on
the strip's run of the pass on tiled dots (1.3 without the pass), 1.5 spacings 0.50.
"""

from __future__ import annotations

import dataclasses
from functools import lru_cache

import numpy as np

from ..relax.lowpass import (
    MAX_SHIFT,
    CoarseField,
    Lattice,
    LatticePart,
    RegionError,
    coarse_field,
    deposit_part,
    displacement,
    grid_step,
    steepness,
)
from ..relax.optdot import relax_staged
from ..relax.result import RelaxResult
from ..sampling.initial import Rect
from ..spatial.window import bounds, grown
from .beyond_walls import with_phantoms
from .settings import StageSettings


def corrected(s: StageSettings) -> bool:
    """Whether the run gets the long-wavelength correction."""
    return s.optimize.method != "md" and s.formulation.lowpass > 0 and s.relax.max_iter > 0


#: Lattice step of the wide pass, in its blurs (two cells a sigma).
WIDE_STEP = 0.5
#: Cells of the wide pass's lattice at most (32 MB a float32 array): a 55-inch panel's
#: step grows to 0.31 mm, 1.4 cells a sigma.
WIDE_CELLS = 1 << 23


def wide_sigma(s: StageSettings) -> float | None:
    """The blur of the correction's last pass, mm, when it is solved over the whole panel
    (two passes or more); None otherwise."""
    form = s.formulation
    if not corrected(s) or form.lowpass < 2:
        return None
    return form.lowpass_sigmas()[-1] * s.spacing


def wide_part(s: StageSettings, xy: np.ndarray, area: np.ndarray) -> LatticePart | None:
    """Dots at ``xy`` (``[n, 2]`` mm) of areas ``area`` (``[n]`` mm²) deposited on the
    wide pass's lattice, for :func:`wide_solve`; None when the run has no wide pass."""
    sigma = wide_sigma(s)
    if sigma is None:
        return None
    return deposit_part(xy, area, _wide_lattice(s, sigma))


def wide_solve(s: StageSettings, parts: list[LatticePart | None]) -> CoarseField | None:
    """The wide pass's field over the panel from the :func:`wide_part` of every set of
    its dots, added in the order given (the plan's tile order: the same bytes whoever
    computed what); None when the run has no wide pass."""
    sigma = wide_sigma(s)
    if sigma is None:
        return None
    form = s.formulation
    rounds = wide_rounds(s) > 1  # a steep map: its own cap (one round: the first's)
    cap = ((form.lowpass_last_cap if rounds else 0.0) or MAX_SHIFT) * s.spacing
    return coarse_field(list(parts), _wide_lattice(s, sigma), s.density, sigma, cap, s.domain)


#: Largest relative change of the blurred fill between neighbouring cells of the wide
#: pass's lattice (:func:`optdot.relax.lowpass.steepness`) that one round handles: the
#: smooth maps of the panel benchmarks reach 0.02-0.07 and the rounds change nothing
#: there (outline sample 0.41 JND either way), the led sample's LED edge 0.15, a designed
#: map's LED fronts 0.3-0.4 (tsuno's empty corner 0.65).
STEEP = 0.1


def wide_rounds(s: StageSettings) -> int:
    """How many rounds of the wide pass the run gets (0 without a wide pass): the
    formulation's ``lowpass_last_steps`` where the map is steep (:data:`STEEP`), else one
    (each round in tiles is a barrier over the panel)."""
    form = s.formulation
    sigma = wide_sigma(s)
    if sigma is None:
        return 0
    steps = max(1, form.lowpass_last_steps)
    if steps == 1:
        return 1
    return steps if _steepness(s, sigma) > STEEP else 1


@lru_cache(maxsize=8)
def _steepness(s: StageSettings, sigma: float) -> float:
    return steepness(s.density, _wide_lattice(s, sigma), sigma)


def _wide_lattice(s: StageSettings, sigma: float) -> Lattice:
    """The wide pass's lattice over the panel's box for a blur of ``sigma`` mm."""
    return Lattice.over(s.box, WIDE_STEP * sigma, WIDE_CELLS)


def correction_region(s: StageSettings, xy0: np.ndarray, xy: np.ndarray, region: Rect):
    """The coverage error a tile's correction solves, over ``region`` (the windows it
    blends grown by :func:`correction_pad`, :func:`optdot.orchestration.tiling.tasks.correct_tile`)
    on
    the lattice every tile shares: ``(RegionError, cap mm)``, or None when the formulation
    has no correction. Every dot in the region and within a lattice cell around it must be
    given."""
    form = s.formulation
    if not corrected(s) or not len(xy0):
        return None
    area, _ = s.areas(s.density.at(xy0), s.rule_diameters(xy0))
    spacing = s.spacing
    h = max(grid_step(s.density, spacing), TILE_GRID * spacing)
    err = RegionError(xy, area, s.density, h, form.lowpass_sigma * spacing, region, s.domain)
    return err, MAX_SHIFT * spacing


#: Lattice step of the tiles' correction, in spacings (one process: half a spacing). The
#: grain it removes lies at 6 spacings and longer (S(k a 0.3-1)); a spacing resolves it
#: and takes a quarter of the cells.
TILE_GRID = 0.5


def correction_pad(s: StageSettings) -> float:
    """How far beyond its windows a tile's correction deposits and blurs, mm (4 blur
    sigmas and 2 lattice cells): a window's error is then the same in every tile that
    solves it, whatever lies past its edge in the tile's region. At most 3.8 spacings."""
    form = s.formulation
    spacing = s.spacing
    h = max(grid_step(s.density, spacing), TILE_GRID * spacing)
    return 4.0 * form.lowpass_sigma * spacing + 2.0 * h


def hard_core(
    s: StageSettings,
    xy0: np.ndarray,
    xy: np.ndarray,
    held: tuple[np.ndarray, np.ndarray | float] | None = None,
) -> np.ndarray:
    """The formulation's hard-core iterations (see :func:`long_wavelength`) for a tile's dots
    after its correction, with its neighbours' dots held: ``[n, 2]`` new positions, mm.

    Args:
        held: ``(positions [h, 2] mm, diameters [h] or one, mm)`` of the neighbours (final
            for the tiles settled before, corrected for the others).
    """
    form = s.formulation
    if s.optimize.method == "md" or not form.lowpass_core_iter or not len(xy0):
        return xy
    if s.relax.max_iter == 0:
        return xy
    n = len(xy0)
    diameters = s.rule_diameters(xy0)
    frozen = None
    if held is not None and len(held[0]):
        hxy = np.asarray(held[0], np.float64)
        xy0 = np.concatenate([xy0, hxy])
        xy = np.concatenate([xy, hxy])
        frozen = np.zeros(len(xy0), bool)
        frozen[n:] = True
        if diameters is not None:
            diameters = np.concatenate([diameters, np.broadcast_to(held[1], (len(hxy),))])
    rho = s.container_fill(xy0)
    if frozen is not None:
        # a held dot of a later tile, not yet made legal, may stand in a zero cell: it has
        # no fill of its own there (its circle would be infinite); the map's largest
        # gives it the smallest circle, the least push on the dots around it, and the
        # guarantee pass settles the pair by the true sizes
        rho = np.where(frozen & (rho <= 0), float(s.density.grid.max()), rho)
    phantom = None
    if form.phantoms:
        xy0, rho, start, frozen, diameters, phantom = with_phantoms(
            s, xy0, rho, xy, frozen, diameters
        )
        xy = start
    res = RelaxResult(np.ascontiguousarray(xy), np.nan, 0, 0, 0, "", [])
    res = core_iterations(s, res, xy0, rho, frozen, diameters, phantom)
    return np.ascontiguousarray(res.xy[:n])


def long_wavelength(s: StageSettings, res, xy0, rho, frozen, diameters, phantom) -> RelaxResult:
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
    iterations) without bringing the grain back. Measured in BENCHMARKS.md.
    """
    form = s.formulation
    res, xy0 = correction_passes(s, res, xy0, rho, frozen, diameters, phantom)
    res = core_iterations(s, res, xy0, rho, frozen, diameters, phantom)
    if form.lowpass or form.lowpass_core_iter:
        res.message += (
            f"; then {form.lowpass} long-wavelength passes ({form.lowpass_iter} iterations "
            f"each) and {form.lowpass_core_iter} hard-core iterations"
        )
    return res


def correction_passes(s: StageSettings, res, xy0, rho, frozen, diameters, phantom):
    """The correction passes of :func:`long_wavelength`: ``(result, containers moved)``."""
    form = s.formulation
    real = np.ones(len(xy0), bool) if phantom is None else ~phantom
    movers = real if frozen is None else real & ~frozen
    area, spacing = s.areas(rho[real], None if diameters is None else diameters[real])
    # the dots' box grown by a spacing (clipped to the map's): the target must cover the
    # strip between the outermost centres and the walls, whose coverage they carry
    window = grown(bounds(xy0[real]), spacing)
    settings = dataclasses.replace(s.relax, max_iter=form.lowpass_iter)
    sigmas = form.lowpass_sigmas()
    wide = wide_sigma(s) is not None
    for k, sigma in enumerate(sigmas):
        last = k == len(sigmas) - 1
        for _ in range(wide_rounds(s) if wide and last else 1):
            u = np.zeros_like(xy0)
            if wide and last:
                part = wide_part(s, res.xy[real], area)
                shift = wide_solve(s, [part]).displacement(res.xy[real])
            else:
                shift = displacement(
                    res.xy[real], area, s.density, spacing, sigma, window, s.domain
                )
            u[real] = shift
            u[~movers] = 0.0
            xy0 = xy0 + u
            res.xy = res.xy + u
        if form.lowpass_iter:
            more = relax_staged(
                s.problem, form, xy0, rho, settings, None, start=res.xy, frozen=frozen,
                diameters=diameters, phantom=phantom,
            )  # fmt: skip
            res = continued(res, more)
    return res, xy0


def core_iterations(s: StageSettings, res, xy0, rho, frozen, diameters, phantom) -> RelaxResult:
    """The hard-core iterations of :func:`long_wavelength`: soft circles too small to meet,
    containers as they were."""
    form = s.formulation
    if not form.lowpass_core_iter:
        return res
    shrink = 1e-3
    core_only = dataclasses.replace(
        form, radius_factor=form.radius_factor * shrink,
        container_factor=form.container_factor / shrink,
    )  # fmt: skip
    settings = dataclasses.replace(s.relax, max_iter=form.lowpass_core_iter)
    more = relax_staged(
        s.problem, core_only, xy0, rho, settings, None, start=res.xy, frozen=frozen,
        diameters=diameters, phantom=phantom,
    )  # fmt: skip
    return continued(res, more)


def continued(res: RelaxResult, more: RelaxResult) -> RelaxResult:
    """``res`` continued by ``more``: its positions, evaluations and history added; the
    iteration count, status and message stay the relaxation's (what its progress bar
    showed)."""
    res.xy = more.xy
    res.penalty = more.penalty
    res.nfev += more.nfev
    res.rebuilds += more.rebuilds
    res.history = res.history + more.history
    return res
