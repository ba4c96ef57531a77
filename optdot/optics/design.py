"""``design``: the fill map whose simulated luminance is uniform (or follows a target).

The loop traces the guide in the coverage mode (:func:`optdot.optics.simulate.simulate`)
on the design grid and updates every cell multiplicatively::

    phi <- clip(phi * smooth(q) ** gamma, min, max) rescaled so max(phi) = fill max,
    q = (s * target / L) clipped to [1/2, 2],   s = sum(L w) / sum(target w)

Why this rule. In the 1-D model (``../docs/light-guide.md``) the exitance is
``M = T kappa phi P``: locally proportional to the fill, times the guided power ``P`` that
reaches the cell. A multiplicative step corrects the local factor exactly and leaves the
coupling through ``P`` (raising fill upstream starves what lies downstream) to the next
iteration; the damping ``gamma`` (0.8) and the clip of ``q`` keep that coupling from
overshooting, and the fixed point is the map with ``L`` proportional to the target. A
downstream march would be exact in 1-D but needs a flow direction, which a 2-D guide with
LEDs on several edges and diffuse recycling does not have. The level is not free: the
scale of ``phi`` decides how much light is extracted before the far edges, so after each
step the map is scaled until its largest fill is the top of ``fill_range``: the most
efficient map a tool can print. Near that top nearly all light is extracted and the far
cells hang on every upstream one (the problem is ill-conditioned there), so the level
starts at 1/8 of it, where light reaches everywhere and the multiplicative step is nearly
exact, and grows 1.5x per iteration: each level starts from the shape of the last
(continuation).

Monte Carlo noise: the rays double from 1/16 of the final count each iteration (early
iterations only need the trend), ``q`` is smoothed with a Gaussian of ``smoothing`` cells
(weighted by each cell's share inside the panel), and the last iteration runs the full
count. Cells outside the panel (holes, keep-outs) hold no dots.

With a viewing area (``[domain] active_area`` or ``bezel``) the luminance is judged where
the viewer sees it: the level ``s`` is the mean over the area's cells, and the figures
each iteration prints (9-point, RMS) are the area's (:func:`simulate` measures them
there). The hidden cells follow the same rule, so the map stays smooth across the
area's edge.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from scipy.ndimage import gaussian_filter, zoom

from ..config.job import Job
from ..errors import JobError
from ..geometry.domain import centres_in_box, polygon_cell_fractions
from .scene import Coverage
from .simulate import Simulation, simulate

#: Exponent of the multiplicative step.
GAMMA = 0.8
#: Largest change of a cell's target ratio per iteration.
MAX_STEP = 2.0
#: The map's level starts at this share of the fill maximum and grows by LEVEL_GROWTH
#: per iteration (continuation: see the module doc).
LEVEL_START = 1.0 / 8.0
LEVEL_GROWTH = 1.5
#: Rays per cell of the last iteration when ``[design] rays`` is not given.
RAYS_PER_CELL = 400


@dataclass
class Designed:
    """The designed map and how it got there.

    Attributes:
        fill: ``[ny, nx]`` fill fractions (row 0 = bottom) over the panel box.
        cell: ``(dx, dy)`` cell size, mm.
        history: one dict per iteration (rays, uniformity, RMS, efficiency).
        last: the last iteration's simulation (of the returned map).
    """

    fill: np.ndarray
    cell: tuple[float, float]
    history: list[dict]
    last: Simulation


def design_grid(job: Job) -> tuple[int, int, float, float]:
    """``(nx, ny, dx, dy)`` of the design grid over the panel box."""
    x0, y0, x1, y1 = job.box
    c = job.design.cell
    nx = max(1, int(round((x1 - x0) / c)))
    ny = max(1, int(round((y1 - y0) / c)))
    return nx, ny, (x1 - x0) / nx, (y1 - y0) / ny


def design(
    job: Job,
    seed: int = 0,
    rays: int | None = None,
    iterations: int | None = None,
    report: Callable[[dict], None] | None = None,
    start: np.ndarray | None = None,
) -> Designed:
    """Design the fill map of ``job``'s light guide (see the module doc).

    Args:
        job: with a ``[light_guide]``; ``[design]`` sets cell, fill range, target.
        seed: Monte Carlo seed (each iteration offsets it).
        rays: rays of the last iteration (default ``[design] rays`` or 400 per cell).
        iterations: most iterations (default ``[design] iterations``).
        report: called with each iteration's figures.
        start: ``[ny, nx]`` starting map (default uniform at the middle of the range).
    """
    if job.light_guide is None:
        raise JobError(f"{job.source or 'job'}: no [light_guide] section to design for")
    p = job.design
    nx, ny, dx, dy = design_grid(job)
    x0, y0 = job.box[:2]
    inside = polygon_cell_fractions(
        job.domain.geometry, x0, y0, dx, dy, nx, ny, job.domain.rectangle
    )
    lo, hi = p.fill_range
    target = _target(p.target, ny, nx)
    total = rays or p.rays or RAYS_PER_CELL * nx * ny
    n_iter = iterations or p.iterations
    # the level starts at LEVEL_START of the top (never under the floor) and reaches the
    # top by the last update however few the iterations: fill_range is honoured
    level = max(hi * LEVEL_START, lo) if start is None else hi
    growth = max(LEVEL_GROWTH, (hi / level) ** (1.0 / max(1, n_iter - 2)))
    phi = np.full((ny, nx), level) if start is None else np.array(start, np.float64)
    live = inside > 0.5
    phi[~live] = 0.0
    seen = live & _in_area(job, nx, ny, dx, dy)
    history: list[dict] = []
    sim = None
    for it in range(n_iter):
        last = it == n_iter - 1
        n_rays = total if last else min(total, max(1000, total // 16) * 2**it)
        cov = Coverage(phi * inside, x0, y0, dx, dy)
        sim = simulate(job, n_rays, seed + 7919 * it, coverage=cov, bins=(nx, ny))
        figures = _figures(it, sim)
        history.append(figures)
        if report is not None:
            report(figures)
        if last:
            break
        level = min(hi, level * growth)
        phi = _step(phi, sim.counts, inside, live, target, p.smoothing, lo, level, seen)
    assert sim is not None
    return Designed(phi, (dx, dy), history, sim)


def _figures(it: int, sim: Simulation) -> dict:
    u9, u9s = sim.uniformity9()
    rms, noise, lmin, lmax = sim.rms()
    return {
        "iteration": it + 1,
        "rays": sim.rays,
        "uniformity_9point": u9,
        "uniformity_9point_sigma": u9s,
        "luminance_rms": rms,
        "luminance_rms_noise": noise,
        "min_over_max": lmin / lmax if lmax > 0 else math.nan,
        "efficiency": sim.efficiency,
    }


def _target(target: np.ndarray | None, ny: int, nx: int) -> np.ndarray:
    """The target luminance on the design grid (uniform by default), mean 1: the target's
    cells cover the panel box, read as samples at their centres, bilinear between them and
    constant beyond the outermost."""
    if target is None:
        return np.ones((ny, nx))
    t = np.asarray(target, np.float64)
    t = zoom(t, (ny / t.shape[0], nx / t.shape[1]), order=1, grid_mode=True, mode="nearest")
    if t.shape != (ny, nx):  # zoom rounds the output shape
        t = np.pad(
            t[:ny, :nx], ((0, max(0, ny - t.shape[0])), (0, max(0, nx - t.shape[1]))), mode="edge"
        )
    return np.maximum(t, 0.0) / max(float(t.mean()), 1e-300)


def _in_area(job: Job, nx: int, ny: int, dx: float, dy: float) -> np.ndarray:
    """``[ny, nx]`` bool: design cells whose centres lie in the job's viewing area
    (every cell without one)."""
    if job.viewing_area is None:
        return np.ones((ny, nx), bool)
    x0, y0 = job.box[:2]
    seen = centres_in_box(x0, y0, dx, dy, nx, ny, job.viewing_area)
    return seen if seen.any() else np.ones((ny, nx), bool)


def _step(phi, counts, inside, live, target, smoothing, lo, level, seen) -> np.ndarray:
    """One damped multiplicative update of the map, scaled so its largest fill is
    ``level``; the luminance's level ``s`` is taken over the ``seen`` cells (the viewing
    area's; see the module doc)."""
    w = np.where(live, inside, 0.0)
    lum = counts / np.maximum(inside, 1e-9)
    ws = np.where(seen, w, 0.0)
    scale = float((lum * ws).sum() / max((target * ws).sum(), 1e-300))
    want = scale * target
    q = np.where(live & (counts > 0), want / np.maximum(lum, 1e-300), MAX_STEP)
    q = np.clip(q, 1.0 / MAX_STEP, MAX_STEP)
    logq = np.log(q) * w
    if smoothing > 0:
        num = gaussian_filter(logq, smoothing, mode="nearest")
        den = gaussian_filter(w, smoothing, mode="nearest")
        logq = np.where(den > 1e-9, num / np.maximum(den, 1e-9), 0.0)
    new = phi * np.exp(GAMMA * logq)
    new = np.where(live, new, 0.0)
    peak = float(new[live].max()) if live.any() else 0.0
    if peak > 0:
        new *= level / peak
    return np.where(live, np.clip(new, lo, level), 0.0)
