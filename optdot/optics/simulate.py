"""``simulate``: the luminance of a light guide, traced with the map's coverage or the real dots.

:func:`simulate` sets up what the compiled tracer (:mod:`optdot.optics.trace`) needs from
a job (emitters, profiles, walls, the coverage raster or the dots' cell grid), traces the
rays in fixed batches, and bins where they leave the top face. What it reports, with the
Monte Carlo noise of each figure:

- **efficiency**: extracted / injected (rays Fresnel turns back at the LED edge are not
  injected), and where the rest went (absorbed in the bulk or the dots, lost at the edges
  or the bottom); binomial noise ``sqrt(p (1 - p) / injected)``.
- **9-point uniformity**: min/max of the exitance over 9 discs at 1/6, 1/2, 5/6 of each
  side (the catalogue measure of backlights; spot diameter an option).
- **luminance RMS and min/max** over bins of the region a viewer sees (the job's
  ``viewing_area``, else the panel less a border), and the RMS the Monte Carlo noise
  alone would give (``sqrt(mean(1 / count))``); the brightest bin outside that region
  (the LED hot spots a bezel hides) with where it is.
- With a viewing area, the 9 spots sit at 1/6, 1/2, 5/6 of its sides, not the panel's.

The exitance of the top face is what a diffuser sheet turns into luminance, so the map is
called luminance (relative: 1 = the mean over the measured region).

Reproducible: the same bench, rays and seed give the same counts on any thread count (each
ray has its own random stream; counts are integers).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field

import numpy as np

from ..config.bench import Bench
from ..errors import JobError
from ..geometry.profile import DotProfile
from ..pattern import DotSource
from ..runtime.stop import check_interrupt
from .angles import Angles
from .scene import Coverage, coverage_of, has_optics, is_direct, probe, scene_of
from .tables import FATES, MAX_EVENTS, PRISM_FACE, SHEET_FACE, UNCOUPLED, UNFINISHED, Scene
from .trace import trace

__all__ = ["Coverage", "Simulation", "coverage_of", "simulate"]

#: Border left out of the figures when the job names no viewing area, mm.
BORDER_MM = 5.0
#: Most rays per compiled call (outputs 9 bytes per ray).
BATCH = 1 << 20
#: Fewest rays per compiled call.
MIN_BATCH = 1 << 10
#: Seconds a batch should take: Ctrl-C and SIGTERM are heard between batches, so a stack
#: whose rays bounce for long is cut into smaller ones (the counts do not depend on it).
BATCH_SECONDS = 0.5
#: Most luminance bins (each a few dozen bytes, and a box in the measured-region test).
MAX_BINS = 1 << 22
#: Most bins the default bin size makes.
DEFAULT_BINS = 1 << 20


@dataclass
class Simulation:
    """What :func:`simulate` found.

    Attributes:
        rays: rays emitted. injected: rays that entered the guide.
        fates: rays per fate (``trace.FATES``; ``not_coupled`` is of the emitted).
        counts: ``[nby, nbx]`` extracted rays per bin over the panel box.
        box: the panel box, mm. bin: ``(dx, dy)`` bin size, mm.
        measured: ``[nby, nbx]`` bool, the bins the RMS and min/max are taken over.
        spots: ``[9, 3]`` spot centre x, y (mm) and extracted rays in it; spot: diameter, mm.
        mode: ``"coverage"`` or ``"dots"``.
        border: mm left out inside the measured region's edge.
        area: ``(x0, y0, x1, y1)`` mm, the viewing area the figures are judged in, or None
            (the panel).
        stack: ``"guide"`` (an edge-lit guide), ``"edge"`` (a film over it) or
            ``"direct"`` (a direct-lit backlight).
    """

    rays: int
    injected: int
    fates: dict[str, int]
    counts: np.ndarray
    box: tuple[float, float, float, float]
    bin: tuple[float, float]
    measured: np.ndarray
    spots: np.ndarray
    spot: float
    mode: str
    border: float
    seed: int
    extra: dict = field(default_factory=dict)
    area: tuple[float, float, float, float] | None = None
    stack: str = "guide"
    angles: Angles | None = None

    @property
    def efficiency(self) -> float:
        """Extracted / injected."""
        return self.fates["extracted"] / max(self.injected, 1)

    @property
    def luminance(self) -> np.ndarray:
        """``[nby, nbx]`` relative exitance (1 = mean over the measured bins)."""
        c = self.counts.astype(np.float64)
        mean = c[self.measured].mean() if self.measured.any() else c.mean()
        return c / mean if mean > 0 else c

    def uniformity9(self) -> tuple[float, float]:
        """9-point uniformity (min/max over the spots) and its Monte Carlo sigma."""
        c = self.spots[:, 2]
        if c.max() <= 0:
            return 0.0, 0.0
        u = float(c.min() / c.max())
        sigma = u * math.sqrt(1.0 / max(c.min(), 1.0) + 1.0 / c.max())
        return u, sigma

    def rms(self) -> tuple[float, float, float, float]:
        """Over the measured bins: (RMS of L / mean - 1, the noise's share of it, min/mean,
        max/mean)."""
        c = self.counts[self.measured].astype(np.float64)
        if len(c) == 0 or c.mean() <= 0:
            return math.nan, math.nan, math.nan, math.nan
        rel = c / c.mean()
        noise = math.sqrt(float(np.mean(1.0 / np.maximum(c, 1.0))))
        return float(rel.std()), noise, float(rel.min()), float(rel.max())

    def resolution(self) -> tuple[float, int | None]:
        """``(structure, rays)``: the luminance's RMS beyond the Monte Carlo noise (``sqrt(
        RMS² - noise²)``, 0 when the noise explains it all) and the rays that would bring
        the noise to :data:`RESOLVED_NOISE` of the mean (None: no light measured). The
        noise falls as one over the root of the rays."""
        rms, noise, _, _ = self.rms()
        if not (math.isfinite(rms) and math.isfinite(noise)):
            return math.nan, None
        structure = math.sqrt(max(rms * rms - noise * noise, 0.0))
        rays = int(math.ceil(self.rays * (noise / RESOLVED_NOISE) ** 2))
        return structure, rays

    def hidden_peak(self) -> tuple[float, tuple[float, float]] | None:
        """The brightest bin outside the measured region that holds light (relative to
        the measured mean) and its centre, mm; None when every lit bin is measured."""
        lum = self.luminance
        out = ~self.measured & (self.counts > 0)
        if not out.any():
            return None
        k = int(np.argmax(np.where(out, lum, -np.inf)))
        iy, ix = divmod(k, lum.shape[1])
        x0, y0 = self.box[:2]
        return float(lum[iy, ix]), (x0 + (ix + 0.5) * self.bin[0], y0 + (iy + 0.5) * self.bin[1])

    def summary(self) -> dict:
        """Every figure with its Monte Carlo sigma, JSON-ready."""
        eff = self.efficiency
        inj = max(self.injected, 1)
        u9, u9s = self.uniformity9()
        rms, noise, lo, hi = self.rms()
        shares = {k: v / inj for k, v in self.fates.items() if k != "not_coupled"}
        hidden = self.hidden_peak()
        structure, resolving = self.resolution()
        warned = unfinished_warning(shares)
        outside = (
            {"outside_max": hidden[0], "outside_max_at_mm": [round(v, 4) for v in hidden[1]]}
            if hidden is not None
            else {}
        )
        return {
            "mode": self.mode,
            **({"stack": self.stack} if self.stack != "guide" else {}),
            "rays": self.rays,
            "seed": self.seed,
            "injected": self.injected,
            "coupling": self.injected / max(self.rays, 1),
            "efficiency": eff,
            "efficiency_sigma": math.sqrt(eff * (1 - eff) / inj),
            "shares": shares,
            "counts": dict(self.fates),
            "uniformity_9point": u9,
            "uniformity_9point_sigma": u9s,
            "spot_diameter_mm": self.spot,
            "spots": [[float(a), float(b), int(c)] for a, b, c in self.spots],
            "luminance_rms": rms,
            "luminance_rms_noise": noise,
            "luminance_structure": structure,
            "rays_for_1pct_noise": resolving,
            "luminance_min": lo,
            "luminance_max": hi,
            "bin_mm": list(self.bin),
            "border_mm": self.border,
            **({"viewing_area_mm": list(self.area)} if self.area is not None else {}),
            **outside,
            **({"warnings": [warned]} if warned is not None else {}),
            **({"angles": self.angles.figures()} if self.angles is not None else {}),
            **self.extra,
        }


def simulate(
    bench: Bench,
    rays: int,
    seed: int = 0,
    dots: DotSource | None = None,
    coverage: Coverage | None = None,
    bin_mm: float | None = None,
    spot_mm: float | None = None,
    border_mm: float | None = None,
    bins: tuple[int, int] | None = None,
    progress: Callable[[int, int], None] | None = None,
    only_led: int | None = None,
) -> Simulation:
    """Trace ``rays`` rays through the job's backlight.

    Args:
        bench: a job's (:attr:`~optdot.config.job.Job.bench`) with a ``[light_guide]``
            or a ``[backlight]``.
        rays: rays to emit (shared among the LEDs by power).
        seed: random seed (>= 0).
        dots: the real pattern to trace (explicit mode); None for the coverage mode.
        coverage: the raster of the coverage mode (default: the job's map).
        bin_mm: luminance bin size, mm (default: :func:`default_bin`).
        spot_mm: 9-point spot diameter, mm (default: 1/6 of the shorter side, at most 10).
        border_mm: excluded from the RMS and min/max, mm inside the measured region's edge
            (the job's viewing area, else the panel's outline; default 0 inside a viewing
            area, else :data:`BORDER_MM`, or 0 where that leaves no bin). A border given
            that leaves no bin is an error.
        bins: ``(nbx, nby)`` luminance bins over the box (instead of ``bin_mm``).
        progress: ``progress(done, total)`` after each batch.
        only_led: light only this LED of a direct-lit grid (its index), for its halo.
    """
    if not has_optics(bench):
        raise JobError(f"{bench.where}: no [light_guide] or [backlight] to simulate")
    if not 1 <= rays <= 10**10:
        raise JobError(f"{bench.where}: rays = {rays} must be 1..1e10")
    if seed < 0:
        raise JobError(f"{bench.where}: seed = {seed} must be >= 0")
    x0, y0, x1, y1 = box = bench.box
    area = bench.viewing_area
    given = border_mm is not None
    if border_mm is None:
        border_mm = 0.0 if area is not None else BORDER_MM
    short = min(x1 - x0, y1 - y0)
    bin_mm = default_bin(bench) if bin_mm is None else float(bin_mm)
    spot_mm = min(10.0, short / 6) if spot_mm is None else float(spot_mm)
    if not 0 < bin_mm <= max(x1 - x0, y1 - y0) or not 0 < spot_mm <= short / 3:
        raise JobError(
            f"{bench.where}: bin {bin_mm:g} mm / spot {spot_mm:g} mm: must be > 0 and "
            f"fit the panel ({x1 - x0:g} x {y1 - y0:g} mm; bins at most its longer side, "
            "spots at most a third of the shorter side)"
        )
    scene = scene_of(bench, rays, dots, coverage, only_led)
    if bins is None:
        nbx = max(1, int(round((x1 - x0) / bin_mm)))
        nby = max(1, int(round((y1 - y0) / bin_mm)))
    else:
        nbx, nby = bins
    if nbx * nby > MAX_BINS:
        raise JobError(
            f"{bench.where}: bins of {(x1 - x0) / nbx:.3g} x {(y1 - y0) / nby:.3g} mm "
            f"make {nbx * nby:,} over the panel, more than {MAX_BINS:,}; give a larger --bin"
        )
    measured = _measured(bench, nbx, nby, border_mm)
    if not measured.any() and not given and border_mm > 0:  # a panel narrower than two
        border_mm = 0.0  # default borders: its figures over all of it (``border`` says so)
        measured = _measured(bench, nbx, nby, border_mm)
    if not measured.any():
        where = "the viewing area" if area is not None else "the panel"
        raise JobError(
            f"{bench.where}: a border of {border_mm:g} mm leaves no "
            f"{(x1 - x0) / nbx:.3g} x {(y1 - y0) / nby:.3g} mm bin of {where} to measure: give "
            + (
                "a smaller --border or --bin"
                if bins is None
                else "a smaller bezel or a larger active_area, or smaller cells (design.cell)"
            )
        )
    counts = np.zeros(nby * nbx, np.int64)
    spots = _spot_centres(area if area is not None else box)
    spot_counts = np.zeros(9, np.int64)
    r2 = (0.5 * spot_mm) ** 2
    fates = np.zeros(len(FATES), np.int64)
    angles = Angles.empty()
    for px, py, air in traced(bench, scene, seed, rays, fates, progress):
        angles.add(air)
        ix = np.clip(((px - x0) / (x1 - x0) * nbx).astype(np.int64), 0, nbx - 1)
        iy = np.clip(((py - y0) / (y1 - y0) * nby).astype(np.int64), 0, nby - 1)
        counts += np.bincount(iy * nbx + ix, minlength=nby * nbx)
        for k, (sx, sy) in enumerate(spots):
            spot_counts[k] += int(np.count_nonzero((px - sx) ** 2 + (py - sy) ** 2 <= r2))
    fate_counts = fates_of(scene, fates)
    counts = counts.reshape(nby, nbx)
    return Simulation(
        rays=rays,
        injected=rays - int(fates[UNCOUPLED]),
        fates=fate_counts,
        counts=counts,
        box=box,
        bin=((x1 - x0) / nbx, (y1 - y0) / nby),
        measured=measured,
        spots=np.column_stack([spots, spot_counts]),
        spot=spot_mm,
        mode="dots" if dots is not None else "coverage",
        border=border_mm,
        seed=seed,
        area=area,
        stack=bench.backlight.kind if bench.backlight is not None else "guide",
        angles=angles,
        extra=_profile_extra(bench),
    )


def traced_what(sim: Simulation) -> str:
    """What ``sim`` traced, in words: ``real dots`` or ``map coverage``, with a guide's 3-D
    dots and their height (``real dots (bumps 10 µm high)``)."""
    mode = "real dots" if sim.mode == "dots" else "map coverage"
    shaped = sim.extra.get("dot_profile")
    if shaped is not None:
        facets = tuple(shaped.get("facets_deg", (0.0, 0.0)))
        cut, sized = shaped.get("cut", False), "height_of" in shaped
        p = DotProfile(shaped["kind"], shaped["height_mm"], facets, cut, sized)
        mode += f" ({p.words()})"
    return mode


def _profile_extra(bench: Bench) -> dict:
    """The guide's 3-D dots for the summary (``dot_profile``: kind and height, mm; a
    prism's facets and whether it is cut), or nothing for ink (an ink summary is as it
    always was)."""
    p = bench.profile  # a job refuses a profile on a film's dots
    if p.code == 0:
        return {}
    return {"dot_profile": p.summary()}


def traced(
    bench: Bench,
    scene: Scene,
    seed: int,
    rays: int,
    fates: np.ndarray,
    progress: Callable[[int, int], None] | None = None,
) -> Iterator[tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """Trace ``rays`` rays of ``scene`` batch by batch (after checking light can leave),
    adding each batch's fates to ``fates`` (``[len(FATES)]`` int64) and yielding ``(x,
    y, air)``: where the batch's extracted rays left the top, mm (float64), and their
    directions in air (``[m, 3]`` float32; an idealised extractor's rays end at the dot,
    going down: :class:`~optdot.optics.angles.Angles` leaves them out).

    Raises:
        JobError: light stays in the stack, or none enters it.
    """
    per_ray = _check_light_leaves(bench, seed, rays, scene)
    size = _batch(BATCH_SECONDS / max(per_ray, 1e-12))
    first = 0
    while first < rays:
        check_interrupt()  # Ctrl-C or SIGTERM: stop at the next batch, nothing written
        count = min(size, rays - first)
        t0 = time.perf_counter()
        fate, ex, ey, ed = trace(seed, first, count, scene)
        size = _batch(count * BATCH_SECONDS / max(time.perf_counter() - t0, 1e-9))
        fates += np.bincount(fate, minlength=len(FATES))
        if first == 0 and fates[UNCOUPLED] == count:
            raise JobError(
                f"{bench.where}: no light enters the {_what(bench)}: all {count:,} "
                "rays of the first batch are turned back at the LED edge (a collimated tilt "
                "near 90 degrees meets the edge at grazing incidence)"
            )
        out = fate == 0
        yield ex[out].astype(np.float64), ey[out].astype(np.float64), ed[out]
        first += count
        if progress is not None:
            progress(first, rays)


def _batch(rays: float) -> int:
    """A batch of ``rays`` kept within :data:`MIN_BATCH` .. :data:`BATCH`."""
    return int(min(max(rays, MIN_BATCH), BATCH))


def fates_of(scene: Scene, fates: np.ndarray) -> dict[str, int]:
    """Rays per fate by name; ``absorbed_sheets`` only where the stack has sheets."""
    sheets = bool(np.any(np.isin(scene.stack.face[:, 0], (SHEET_FACE, PRISM_FACE))))
    return {
        name: int(v)
        for name, v in zip(FATES, fates, strict=True)
        if sheets or name != "absorbed_sheets"
    }


#: The Monte Carlo noise (RMS of a bin, of the mean) :meth:`Simulation.resolution` asks
#: the rays for.
RESOLVED_NOISE = 0.01

#: Rays of the probe that checks, before the run, that light can leave the guide.
PROBE_RAYS = 1000
#: Events after which a probe ray counts as trapped.
PROBE_EVENTS = 1 << 12
#: The share of a run's rays the probe may predict unfinished at the event limit before
#: the run is refused.
REFUSED_UNFINISHED = 0.05
#: The share of a run's rays unfinished at the event limit over which the run warns.
WARNED_UNFINISHED = 0.005


def unfinished_warning(shares: dict[str, float]) -> str | None:
    """A warning when over :data:`WARNED_UNFINISHED` of the rays ended unfinished at the
    event limit (``shares``: the fates' shares of the rays that entered), else None."""
    u = shares.get("unfinished", 0.0)
    if u <= WARNED_UNFINISHED:
        return None
    return (
        f"{u:.1%} of the rays ended unfinished at the limit of {MAX_EVENTS:,} events: the "
        "efficiency and luminance miss that light (it barely leaves the stack)"
    )


def _check_light_leaves(bench, seed: int, rays: int, scene: Scene) -> float:
    """Refuse a set-up that keeps its light: a guide with nothing that lets light out
    (no dots, no absorption, mirror edges) traces every ray to :data:`MAX_EVENTS`, days
    for a default run. The first :data:`PROBE_RAYS` rays (the run's own) are traced with
    at most :data:`PROBE_EVENTS` events each. A ray still inside after them leaves within
    the next as often as it did within the first, so a share ``s`` still inside leaves
    about ``s ** (MAX_EVENTS / PROBE_EVENTS)`` unfinished at the run's limit (a
    near-lossless stack: 22 % predicted, 26 % in the run); the run is refused when that
    is over :data:`REFUSED_UNFINISHED` (its efficiency and luminance would miss that much
    light, and its rays run to the limit, hours for a default run): a guide whose light
    leaves slowly but leaves runs, its few unfinished rays reported (and warned of over
    :data:`WARNED_UNFINISHED`, :func:`unfinished_warning`).

    Returns:
        Seconds the probe took per ray (the first batch is sized from it).

    Raises:
        JobError: light stays in the stack (one line: the share, and what lets it out).
    """
    count = min(rays, PROBE_RAYS)
    t0 = time.perf_counter()
    fate, _, _, _ = trace(seed, 0, count, probe(scene, PROBE_EVENTS))
    per_ray = (time.perf_counter() - t0) / count
    entered = int(np.count_nonzero(fate != UNCOUPLED))
    inside = int(np.count_nonzero(fate == UNFINISHED))
    share = inside / entered if entered else 0.0
    unfinished = share ** (MAX_EVENTS / PROBE_EVENTS)
    if unfinished > REFUSED_UNFINISHED:
        raise JobError(
            f"{bench.where}: light hardly leaves this {_what(bench)}: {inside:,} of the "
            f"first {entered:,} rays that entered are still inside after {PROBE_EVENTS:,} "
            f"events, so about {unfinished:.0%} of a run's rays would end unfinished at its "
            f"limit of {MAX_EVENTS:,}; give the light a way out ({_ways_out(bench)})"
        )
    return per_ray


def _ways_out(bench: Bench) -> str:
    """What lets light out of the job's stack, for a message."""
    if bench.backlight is None:
        return "more dots, absorption > 0, edge_reflectance < 1, a reflector < 1"
    ways = "ink that transmits, a sheet that transmits more, frame < 1, a reflector < 1"
    if not bench.backlight.direct:
        ways += ", edge_reflectance < 1"
    return ways


def _what(bench: Bench) -> str:
    return "backlight" if is_direct(bench) else "guide"


def default_bin(bench: Bench) -> float:
    """The luminance bin, mm: a direct-lit grid's pitch / 10 (its LEDs' pattern resolved;
    no finer than :data:`DEFAULT_BINS` bins over the panel), else 1/20 of the panel's
    shorter side, at most 5 mm."""
    x0, y0, x1, y1 = bench.box
    short = min(x1 - x0, y1 - y0)
    pitch = bench.backlight.pitch if bench.backlight is not None else None
    if pitch is not None:  # at most DEFAULT_BINS of them
        floor = math.sqrt((x1 - x0) * (y1 - y0) / DEFAULT_BINS)
        return max(min(pitch / 10, short / 20), floor)
    return min(5.0, short / 20)


def _spot_centres(box) -> np.ndarray:
    x0, y0, x1, y1 = box
    f = np.array([1 / 6, 1 / 2, 5 / 6])
    gx, gy = np.meshgrid(x0 + f * (x1 - x0), y0 + f * (y1 - y0))
    return np.column_stack([gx.ravel(), gy.ravel()])


def _measured(bench: Bench, nbx: int, nby: int, border: float) -> np.ndarray:
    """Bins wholly inside the panel (and the job's viewing area) shrunk by ``border``
    mm; caps and their rings are panel (:attr:`~optdot.geometry.domain.Domain.lit`)."""
    import shapely

    x0, y0, x1, y1 = bench.box
    region = bench.domain.lit
    if bench.viewing_area is not None:
        region = region.intersection(shapely.box(*bench.viewing_area))
    inner = region.buffer(-border) if border > 0 else region
    xs = np.linspace(x0, x1, nbx + 1)
    ys = np.linspace(y0, y1, nby + 1)
    gx0, gy0 = np.meshgrid(xs[:-1], ys[:-1])
    gx1, gy1 = np.meshgrid(xs[1:], ys[1:])
    boxes = shapely.box(gx0.ravel(), gy0.ravel(), gx1.ravel(), gy1.ravel())
    ok = shapely.contains(inner, boxes) if not inner.is_empty else np.zeros(len(boxes), bool)
    return np.asarray(ok).reshape(nby, nbx)
