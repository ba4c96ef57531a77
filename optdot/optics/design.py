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

When to stop: once a trace of the full rays finds no luminance structure beyond its noise
(:func:`settled`), the map's updates no longer push the same way (:class:`Update`) and,
for a guide, the level is at the top, the next trace is the last; ``design.tolerance =
0`` runs every iteration.

With a viewing area (``[domain] active_area`` or ``bezel``) the luminance is judged where
the viewer sees it: the level ``s`` is the mean over the area's cells, and the figures
each iteration prints (9-point, RMS) are the area's (:func:`simulate` measures them
there). The hidden cells follow the same rule, so the map stays smooth across the
area's edge.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np
from scipy.ndimage import distance_transform_edt, gaussian_filter, map_coordinates, zoom

from ..config.bench import Bench
from ..errors import JobError
from ..geometry.caps import cap_shares, design_bands, ring_shares, ring_table
from ..geometry.domain import centres_in_box, polygon_cell_fractions
from ..geometry.limits import MAX_RANDOM_FILL
from .periodic import fold, period_classes
from .scene import Coverage, has_optics
from .simulate import DEFAULT_BINS, Simulation, simulate

#: Exponent of the multiplicative step.
GAMMA = 0.8
#: Largest change of a cell's target ratio per iteration.
MAX_STEP = 2.0
#: The map's level starts at this share of the fill maximum and grows by LEVEL_GROWTH
#: per iteration (continuation: see the module doc).
LEVEL_START = 1.0 / 8.0
LEVEL_GROWTH = 1.5
#: Smallest default cell, mm (``[design] cell``'s own lower bound).
MIN_CELL = 0.05
#: Rays per cell of the last iteration when ``[design] rays`` is not given.
RAYS_PER_CELL = 400
#: Fewest rays a design cell the last iteration may trace: under it each cell's
#: luminance is mostly noise (32 % at 10), the map follows it and never settles.
MIN_RAYS_PER_CELL = 10
#: Highest claim ``fill (1 + gap / D) ** 2`` the sizes a design asks for allow: random
#: patterns hold to 0.80 (and the relaxation's guarantee to 0.78); hard disks begin to
#: order near 0.70 (Bernard & Krauth 2011), but at 0.75 QA's psi6 stays at 0.02 (the
#: 60 x 40 mm benchmark film, 100 µm dots) while the dots' grain in 0.5 mm bins falls
#: from 1.25 % (135 µm, claim 0.70) to 1.05 % (BENCHMARKS.md "Backlights").
SIZE_CLAIM = 0.75
#: Above this share of :data:`SIZE_CLAIM` the fill asks for the claim of 0.80 (the sizes
#: that keep 0.75 grow without bound as the fill nears it).
SIZE_SWITCH = 0.9
#: Largest diameter a design asks for, mm.
MAX_SIZE_ASKED = 1.0


@dataclass
class Designed:
    """The designed map and how it got there.

    Attributes:
        fill: ``[ny, nx]`` fill fractions (row 0 = bottom) over the panel box.
        cell: ``(dx, dy)`` cell size, mm.
        history: one dict per iteration (rays, uniformity, RMS, efficiency).
        last: the last iteration's simulation (of the returned map).
        sizes: ``(low, high)`` diameters, mm, the map asks for when the job's one dot
            size cannot keep QA's close gap at its largest fill (:func:`sizes_asked`), or
            None.
        cap_ink: ``[n]`` the graded caps' band inks (``[backlight.leds] cap_ink``), or
            None when the caps are solid or there are none.
    """

    fill: np.ndarray
    cell: tuple[float, float]
    history: list[dict]
    last: Simulation
    sizes: tuple[float, float] | None = None
    cap_ink: np.ndarray | None = None
    stopped: str = ""


#: The luminance's structure beyond the rays' noise (``sqrt(RMS² - noise²)``) at or under
#: which ``design`` stops, as a share of that noise, when the job sets no
#: ``design.tolerance``: the map no longer changes anything a trace of this many rays
#: resolves (the lgp sample's RMS held at 6.1-6.6 % over a noise of 6.1-6.2 % from its
#: 7th to its 16th iteration).
SETTLED_SHARE = 0.3


def settled(figures: dict, tolerance: float | None) -> bool:
    """Whether an iteration's luminance (its ``figures``) holds no structure the map still
    needs to correct: its RMS (against the design's target when it has one) beyond the
    rays' noise at or under ``tolerance`` (a share of the mean), or under
    :data:`SETTLED_SHARE` of the noise when None; never for 0."""
    rms = figures.get("luminance_rms_target", figures["luminance_rms"])
    return _within(rms, figures["luminance_rms_noise"], tolerance)


def _within(rms: float, noise: float, tolerance: float | None) -> bool:
    """``sqrt(rms² - noise²)`` at or under ``tolerance``, or under :data:`SETTLED_SHARE`
    of ``noise`` when None; never for a tolerance of 0 or a figure not finite."""
    if tolerance == 0 or not (math.isfinite(rms) and math.isfinite(noise)):
        return False  # 0: every iteration runs
    structure = math.sqrt(max(rms * rms - noise * noise, 0.0))
    return structure <= (SETTLED_SHARE * noise if tolerance is None else tolerance)


class Update:
    """Whether the map's updates still have a direction.

    Each step moves every live cell by ``u = log x_new - log x_old`` (``x`` the fill of a
    guide's cell, the relative transmission ``1 - k fill`` of a film's). While the map
    converges, consecutive updates push the same cells the same way (a border cell
    climbing, a slow mode of the light's recycling): they correlate positively. Once
    what moves the map is the rays' noise, each update undoes part of the last one's
    noise and the correlation turns negative (the samples: +0.1 to +0.9 while converging,
    -0.03 to -0.34 after, on every seed tried). ``agreement`` is that correlation over
    the live cells (each update less its mean, which the level takes). The map is
    settled when :data:`DISAGREEMENTS` updates in a row disagree with the one before: the
    first crossing comes while a slow trend still moves the map by about half the noise
    (the minled sample stopped there left a luminance RMS of 2.97 % with its real dots
    where 16 iterations leave 2.84 %; one more, 2.87 %).

    Attributes:
        agreement: the correlation of the last two updates (NaN before two).
    """

    def __init__(self) -> None:
        self.last: np.ndarray | None = None
        self.agreement = math.nan
        self.run = 0  # updates in a row that disagreed with the one before

    def measure(self, old: np.ndarray, new: np.ndarray, live: np.ndarray) -> None:
        """One step: ``old``, ``new`` ``[ny, nx]`` the cells' ``x`` before and after (>
        0 on ``live``)."""
        u = np.zeros(old.shape)
        u[live] = np.log(new[live]) - np.log(old[live])
        u[live] -= u[live].mean() if live.any() else 0.0
        if self.last is not None:
            a, b = u[live], self.last[live]
            norm = math.sqrt(float(a @ a) * float(b @ b))
            self.agreement = float(a @ b) / norm if norm > 0 else 0.0
            self.run = self.run + 1 if self.agreement <= 0.0 else 0
        self.last = u

    def settled(self) -> bool:
        """The last :data:`DISAGREEMENTS` updates each disagreed with the one before
        (or were nil): noise moves the map."""
        return self.run >= DISAGREEMENTS


#: Updates in a row that must disagree with the one before for a map to be settled.
DISAGREEMENTS = 2


def sizes_asked(bench: Bench, fill_max: float) -> tuple[float, float] | None:
    """The diameter range ``(low, high)`` (mm, high rounded up to 1 µm) whose largest dots
    keep QA's close gap at ``fill_max``: with a claim ``fill (1 + gap / D) ** 2`` of at
    most :data:`SIZE_CLAIM`, or of :data:`~optdot.geometry.limits.MAX_RANDOM_FILL` for a
    fill over :data:`SIZE_SWITCH` of it. None when the job's dots already do (or are
    shaped: their sizes are ``[dots] scale``).

    Raises:
        JobError: no dot size up to :data:`MAX_SIZE_ASKED` reaches ``fill_max``.
    """
    if not bench.shape.kind.round:
        return None
    gap = bench.close_gap
    top = bench.sizes.high if bench.sizes is not None else bench.diameter
    if fill_max * (1 + gap / top) ** 2 <= SIZE_CLAIM:
        return None
    low = bench.sizes.low if bench.sizes is not None else bench.diameter
    claim = SIZE_CLAIM if fill_max <= SIZE_SWITCH * SIZE_CLAIM else MAX_RANDOM_FILL
    high = gap / (math.sqrt(claim / fill_max) - 1) if fill_max < claim else math.inf
    if high > MAX_SIZE_ASKED:
        raise JobError(
            f"{bench.where}: the designed map's largest fill {fill_max:.3g} is more "
            f"than dots up to {MAX_SIZE_ASKED:g} mm reach with a {gap * 1e3:.3g} µm gap; "
            "lower design.fill_range's top"
        )
    return low, max(low, math.ceil(round(high * 1e3, 6)) / 1e3)


def check_iterations(bench: Bench, n_iter: int) -> None:
    """Refuse a design of one iteration: the first iteration only traces the map it
    starts from (a film's bare film, a guide's flat level), so one would return that
    start, never a designed map."""
    if n_iter < 2:
        start = "the bare film" if prints_on_film(bench) else "a flat map at its starting level"
        raise JobError(
            f"{bench.where}: design.iterations = {n_iter}: a map needs at least 2 "
            f"(the first traces {start}, the next the first designed map)"
        )


def prints_on_film(bench: Bench) -> bool:
    """The job's dots are printed on a film (direct-lit, or over the guide): more ink
    means less light through (the film rule), not more out of the guide."""
    return bench.backlight is not None and bench.backlight.on_film


def design_grid(bench: Bench) -> tuple[int, int, float, float]:
    """``(nx, ny, dx, dy)`` of the design grid over the panel box: cells of ``[design]
    cell`` mm, by default a tenth of a direct-lit grid's LED pitch (at least
    :data:`MIN_CELL`, and no more cells than ``simulate``'s default bins), else 1 mm."""
    x0, y0, x1, y1 = bench.box
    c = bench.design.cell
    if c is None:
        pitch = bench.backlight.pitch if bench.backlight is not None else None
        c = 1.0
        if pitch is not None:  # no finer than the bins simulate makes by default
            floor = math.sqrt((x1 - x0) * (y1 - y0) / DEFAULT_BINS)
            c = max(pitch / 10, MIN_CELL, floor)
    nx = max(1, int(round((x1 - x0) / c)))
    ny = max(1, int(round((y1 - y0) / c)))
    return nx, ny, (x1 - x0) / nx, (y1 - y0) / ny


def design(
    bench: Bench,
    seed: int = 0,
    rays: int | None = None,
    iterations: int | None = None,
    report: Callable[[dict], None] | None = None,
    start: np.ndarray | None = None,
) -> Designed:
    """Design the fill map of a job's light guide (see the module doc).

    Args:
        bench: a job's (:attr:`~optdot.config.job.Job.bench`) with a ``[light_guide]``;
            ``[design]`` sets cell, fill range, target.
        seed: Monte Carlo seed (each iteration offsets it).
        rays: rays of the last iteration (default ``[design] rays`` or 400 per cell).
        iterations: most iterations (default ``[design] iterations``).
        report: called with each iteration's figures.
        start: ``[ny, nx]`` starting map (default uniform at the middle of the range).
    """
    if not has_optics(bench):
        raise JobError(f"{bench.where}: no [light_guide] or [backlight] to design for")
    p = bench.design
    nx, ny, dx, dy = design_grid(bench)
    x0, y0 = bench.box[:2]
    inside, panel, capped = _shares(bench, nx, ny, dx, dy)
    lo, hi = p.fill_range
    target = _target(p.target, ny, nx)
    total = rays or p.rays or RAYS_PER_CELL * nx * ny
    n_iter = iterations or p.iterations
    live = panel > 0.5
    cells = max(int(live.sum()), 1)
    if total < MIN_RAYS_PER_CELL * cells:
        raise JobError(
            f"{bench.where}: {total:,} rays for {cells:,} design cells is under "
            f"{MIN_RAYS_PER_CELL} a cell: each cell's luminance would be mostly the rays' "
            f"noise ({1 / math.sqrt(max(total / cells, 1e-9)):.0%} or more); give at least "
            f"{MIN_RAYS_PER_CELL * cells:,} rays (--rays or design.rays) or larger cells "
            "(design.cell)"
        )
    seen = live & _in_area(bench, nx, ny, dx, dy)
    grades = None
    update = Update()
    if start is None:
        check_iterations(bench, n_iter)
    if prints_on_film(bench):
        phi = np.full((ny, nx), lo) if start is None else np.array(start, np.float64)
        if bench.domain.cap_rings is not None:
            grades = Grades(bench, nx, ny, dx, dy)
        shares = (inside, panel, capped)
        step = _film_step(bench, nx, ny, dx, dy, shares, live, target, seen, update, grades)
    else:
        # the level starts at LEVEL_START of the top (never under the floor) and reaches
        # the top by the last update however few the iterations: fill_range is honoured
        level = max(hi * LEVEL_START, lo) if start is None else hi
        growth = max(LEVEL_GROWTH, (hi / level) ** (1.0 / max(1, n_iter - 2)))
        phi = np.full((ny, nx), level) if start is None else np.array(start, np.float64)
        step = _guide_step(inside, live, target, p.smoothing, lo, hi, level, growth, seen, update)
    phi[~live] = 0.0
    history: list[dict] = []
    sim = None
    stopped = f"ran its {n_iter} iterations"
    finishing = False
    for it in range(n_iter):
        last = it == n_iter - 1 or finishing
        n_rays = total if last else min(total, max(1000, total // 16) * 2**it)
        cov = Coverage(phi * inside, x0, y0, dx, dy, phi)
        now = bench if grades is None else grades.printing(bench)
        sim = simulate(now, n_rays, seed + 7919 * it, coverage=cov, bins=(nx, ny))
        if sim.fates["extracted"] == 0:  # no luminance to design from
            raise JobError(
                f"{bench.where}: no light leaves the top through the map of iteration "
                f"{it + 1} (fill up to {float(phi.max()):.3g}; 0 of {n_rays:,} rays): the "
                "dots extract nothing (light_guide.dot_albedo 0, or a dots.profile too flat "
                "to bend light out of the guide)"
            )
        figures = _figures(it, sim, None if p.target is None else target)
        history.append(figures)
        if not last:
            phi = step(phi, sim)
            figures["update_agreement"] = update.agreement
        if report is not None:
            report(figures)
        if last:
            break
        # done: a full trace finds nothing left to correct in the luminance, the map's
        # update is within its noise, and a guide's level is at its top; the next trace,
        # of the map this update made, is the last
        if (
            n_rays >= total
            and step.may_stop()
            and settled(figures, p.tolerance)
            and update.settled()
        ):
            finishing = True
            stopped = _why_stopped(it, n_iter, figures, p.tolerance)
    assert sim is not None
    if not phi.max() > 0:
        raise JobError(
            f"{bench.where}: the designed map is empty: the luminance follows the "
            "target without any ink (nothing to print), or design.fill_range leaves none"
        )
    sizes = None
    if prints_on_film(bench):
        dotted = inside > 1e-9
        sizes = sizes_asked(bench, float(phi[dotted].max()) if dotted.any() else 0.0)
        if capped is not None:
            phi = _extended(phi, dotted & live)
    ink = None if grades is None else grades.ink
    return Designed(phi, (dx, dy), history, sim, sizes, ink, stopped)


def _why_stopped(it: int, n_iter: int, figures: dict, tolerance: float | None) -> str:
    """The line that says why a design stopped after iteration ``it + 1`` (0-based
    ``it``) and one more trace."""
    within = "within the rays' noise" if tolerance is None else "within design.tolerance"
    told = "" if tolerance is None else f", tolerance {tolerance:.2%}"
    return (
        f"stopped after {it + 2} of at most {n_iter} iterations: at iteration {it + 1} the "
        f"luminance RMS {figures.get('luminance_rms_target', figures['luminance_rms']):.2%}"
        f"{' against the target' if 'luminance_rms_target' in figures else ''} was {within} "
        f"({figures['luminance_rms_noise']:.2%}{told}) and the map's last {DISAGREEMENTS + 1} "
        f"updates took turns (the last two's correlation {figures['update_agreement']:+.2f}): "
        "noise moves it now"
    )


def _figures(it: int, sim: Simulation, target: np.ndarray | None = None) -> dict:
    """An iteration's figures; with a ``target`` (``[ny, nx]`` on the traced bins) the
    RMS the stop judges is the luminance's against it (``luminance_rms_target``)."""
    u9, u9s = sim.uniformity9()
    rms, noise, lmin, lmax = sim.rms()
    extra = {}
    if target is not None:
        m = sim.measured & (target > 0)
        c = sim.counts[m].astype(np.float64)
        want = target[m] * (c.sum() / max(float(target[m].sum()), 1e-300))
        extra["luminance_rms_target"] = float(np.std(c / want)) if c.sum() > 0 else math.nan
    return {
        **extra,
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


def _shares(bench: Bench, nx: int, ny: int, dx: float, dy: float):
    """``(inside, panel, capped)``, each ``[ny, nx]`` over the design grid: the share of
    each cell where dots may go, where the light is seen (the panel: ``inside`` when the
    job has no caps) and under a cap (None without caps)."""
    x0, y0 = bench.box[:2]
    dom = bench.domain
    inside = polygon_cell_fractions(dom.geometry, x0, y0, dx, dy, nx, ny, dom.rectangle)
    if dom.caps is None:
        return inside, inside, None
    panel = polygon_cell_fractions(dom.lit, x0, y0, dx, dy, nx, ny)
    return inside, panel, cap_shares(dom.caps, x0, y0, dx, dy, nx, ny)


def _in_area(bench: Bench, nx: int, ny: int, dx: float, dy: float) -> np.ndarray:
    """``[ny, nx]`` bool: design cells whose centres lie in the job's viewing area
    (every cell without one)."""
    if bench.viewing_area is None:
        return np.ones((ny, nx), bool)
    x0, y0 = bench.box[:2]
    seen = centres_in_box(x0, y0, dx, dy, nx, ny, bench.viewing_area)
    return seen if seen.any() else np.ones((ny, nx), bool)


def _guide_step(inside, live, target, smoothing, lo, hi, level, growth, seen, update=None):
    """The guide rule's update ``step(phi, sim) -> phi``: one damped multiplicative
    step of the map, scaled so its largest fill is the level, which grows by ``growth``
    per step up to ``hi``; the luminance's level ``s`` is taken over the ``seen`` cells
    (the viewing area's; see the module doc). ``update`` (:class:`Update`, a new one
    when None) measures each step."""
    update = update if update is not None else Update()
    state = {"level": level}

    def step(phi: np.ndarray, sim: Simulation) -> np.ndarray:
        state["level"] = level_now = min(hi, state["level"] * growth)
        logq, w = _log_ratio(sim.counts, inside, live, target, seen)
        logq = _smoothed(logq, w, smoothing)
        new = phi * np.exp(GAMMA * logq)
        new = np.where(live, new, 0.0)
        peak = float(new[live].max()) if live.any() else 0.0
        if peak > 0:
            new *= level_now / peak
        new = np.where(live, np.clip(new, lo, level_now), 0.0)
        moved = live & (phi > 0) & (new > 0)
        update.measure(np.where(moved, phi, 1.0), np.where(moved, new, 1.0), moved)
        return new

    step.may_stop = lambda: state["level"] >= hi  # the level has reached the range's top
    return step


def _extended(phi: np.ndarray, dotted: np.ndarray) -> np.ndarray:
    """``phi`` with each cell where no dot may go (under a cap) set to the nearest
    dotted cell's fill, so a map read between cell centres (``generate`` interpolates)
    gives the dots beside a cap the fill designed for them."""
    if dotted.all() or not dotted.any():
        return phi
    _, (iy, ix) = distance_transform_edt(~dotted, return_indices=True)
    return phi[iy, ix]


#: Angles a band samples the cells' corrections at.
ANGLES = 32


class Grades:
    """The ink of graded caps' bands (:func:`optdot.geometry.caps.ring_table`) as the
    design sizes them. Each band takes the film rule's step on its own: its relative
    transmission ``1 - k ink`` is multiplied by ``q ** gamma`` and the level's factor
    like a cell's, where ``log q`` is the cells' smoothed log ratio sampled on a circle
    at the band's middle radius (bilinear between cell centres, :data:`ANGLES` angles,
    the mean over the LEDs whose centre cells are judged, all LEDs when none is). A band
    keeps its own ink from step to step: it is corrected by the luminance about its
    radius, not reset to the mean ink of the cells it crosses (which flattens the
    profile the LED's light asks for).

    Attributes:
        ink: ``[n]`` the bands' ink shares now; rings: their printed rings ``[k, 2]``
            mm; capped: ``[ny, nx]`` the share of each design cell they print.
    """

    def __init__(self, bench: Bench, nx: int, ny: int, dx: float, dy: float) -> None:
        leds = bench.backlight.leds
        self.diameter = float(leds.cap)
        self.caps = bench.domain.caps
        given = leds.cap_ink
        n = design_bands(self.diameter)
        self.ink = np.zeros(n) if isinstance(given, str) else np.array(given, np.float64)
        self.grid = (*bench.box[:2], dx, dy, nx, ny)
        self._set(self.ink)

    def _set(self, ink: np.ndarray) -> None:
        self.ink = ink
        self.rings = ring_table(self.diameter, ink)
        self.capped = ring_shares(self.caps, self.rings, *self.grid)

    def printing(self, bench: Bench) -> Bench:
        """``bench`` printing the rings of now."""
        return replace(bench, domain=replace(bench.domain, cap_rings=self.rings))

    def update(self, logq: np.ndarray, judged: np.ndarray, k: float, level: float) -> None:
        """One step of the bands: ``logq`` ``[ny, nx]`` the cells' log ratios, ``k`` the
        ink's contrast, ``level`` the factor the step scales every transmission by."""
        x0, y0, dx, dy, nx, ny = self.grid
        n = len(self.ink)
        r = (np.arange(n) + 0.5) * 0.5 * self.diameter / n
        cx, cy = self.caps[:, 0], self.caps[:, 1]
        ix = np.clip(((cx - x0) / dx).astype(int), 0, nx - 1)
        iy = np.clip(((cy - y0) / dy).astype(int), 0, ny - 1)
        pick = judged[iy, ix]
        if not pick.any():
            pick[:] = True
        an = 2 * math.pi * (np.arange(ANGLES) + 0.5) / ANGLES
        px = cx[pick, None, None] + r[None, :, None] * np.cos(an)
        py = cy[pick, None, None] + r[None, :, None] * np.sin(an)
        at = [((py - y0) / dy - 0.5).ravel(), ((px - x0) / dx - 0.5).ravel()]
        got = map_coordinates(logq, at, order=1, mode="nearest").reshape(px.shape)
        band = got.mean(axis=(0, 2))
        v = (1.0 - k * self.ink) * np.exp(GAMMA * band) * level
        self._set(np.clip((1.0 - v) / k, 0.0, 1.0))


def _film_step(bench, nx, ny, dx, dy, shares, live, target, seen, update=None, grades=None):
    """The film rule's update ``step(phi, sim) -> phi`` (see the module doc): the map's
    clear share carries light through, so the multiplicative step acts on each cell's
    relative transmission ``v = 1 - k phi`` (``k = 1 - T_ink / T_clear``), and the map is
    shifted so its emptiest cell where the luminance is judged (where ``simulate`` judges
    it: the viewing area, else the panel less its border) holds ``fill_range[0]``: the
    least ink that makes the luminance follow the target there. Outside, cells that would
    need less ink than that stay at it: a rim the frame dims cannot be lifted by a film,
    only matched by darkening all the rest, so the level is set where the viewer looks.
    Over a direct-lit LED grid each cell's update is averaged over the cells that lie
    alike within their LEDs' pitch cells
    (:func:`optdot.optics.periodic.period_classes`).

    With caps (``shares`` = ``(inside, panel, capped)``: :func:`_shares`) a cell's ink is
    its cap share plus the fill over the share dots may use, ``c = (capped + phi inside)
    / panel``: the step acts on ``v = 1 - k c`` and the fill is what gives the new ``v``
    (a cell a cap darkens more than it should keeps the least fill).

    Graded caps (``grades``: :class:`Grades`): ``capped`` is the share their rings
    print now; the bands take the same step over their own radius
    (:meth:`Grades.update`), and a cell the caps' rim crosses is filled with the ink
    it asks for, like a cell without caps. (Making up the rings' shortfall with the dots
    would divide it by the cell's dotted share: a sliver of dots at the rim would ask
    for the top fill, and the largest dots the job's sizes allow.)

    ``update`` (:class:`Update`, a new one when None) measures each step."""
    lo, hi = bench.design.fill_range
    k = bench.backlight.ink_contrast
    classes = period_classes(bench, nx, ny, dx, dy)
    update = update if update is not None else Update()
    inside, panel, capped = shares

    def step(phi: np.ndarray, sim: Simulation) -> np.ndarray:
        judged = live & sim.measured  # the viewing area, else the panel less the border
        judged = judged if judged.any() else seen
        logq, w = _log_ratio(sim.counts, panel, live, target, judged)

        if classes is not None:
            logq = fold(logq, w, classes)
        logq = _smoothed(logq, w, bench.design.smoothing)
        now = capped if grades is None else grades.capped
        if now is None:
            ink = phi
        else:
            ink = (now + phi * inside) / np.maximum(panel, 1e-12)
        v = (1.0 - k * ink) * np.exp(GAMMA * logq)
        top = float(v[judged].max())
        level = (1.0 - k * lo) / top if top > 0 else 1.0
        v *= level
        fill = (1.0 - v) / k
        if grades is not None:
            grades.update(logq, judged, k, level)
            now = grades.capped
        if grades is None and now is not None:
            fill = (fill * panel - now) / np.maximum(inside, 1e-12)
        new = np.where(live, np.clip(fill, lo, hi), 0.0)
        update.measure(1.0 - k * phi, 1.0 - k * new, live)
        return new

    step.may_stop = lambda: True  # a film's level is set every step
    return step


def _log_ratio(counts, inside, live, target, seen) -> tuple[np.ndarray, np.ndarray]:
    """``(log q, w)``: each cell's log of the target over its luminance (the level the
    mean over the ``seen`` cells), clipped to ``[1 / MAX_STEP, MAX_STEP]``, and its
    weight (share inside the panel; 0 for dead cells)."""
    w = np.where(live, inside, 0.0)
    lum = counts / np.maximum(inside, 1e-9)
    ws = np.where(seen, w, 0.0)
    scale = float((lum * ws).sum() / max((target * ws).sum(), 1e-300))
    want = scale * target
    q = np.where(live & (counts > 0), want / np.maximum(lum, 1e-300), MAX_STEP)
    q = np.clip(q, 1.0 / MAX_STEP, MAX_STEP)
    return np.log(q) * w, w


def _smoothed(logq: np.ndarray, w: np.ndarray, smoothing: float) -> np.ndarray:
    """``logq`` (weighted by ``w``) through a Gaussian of ``smoothing`` cells."""
    if smoothing <= 0:
        return logq
    num = gaussian_filter(logq, smoothing, mode="nearest")
    den = gaussian_filter(w, smoothing, mode="nearest")
    return np.where(den > 1e-9, num / np.maximum(den, 1e-9), 0.0)
