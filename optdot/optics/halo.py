"""The halo of one lit LED of a direct-lit backlight: how far its light spreads (local dimming).

A mini-LED backlight dims zone by zone; how sharp a zone can be is how far one LED's light
spreads through the cavity, the printed film and the sheets. :func:`halo` lights one LED
(the one nearest the centre of the viewing area, else of the panel), traces it through the
same stack and dots, and measures the exitance around it from where each ray left the top:

- the **radial profile** ``L(r)``: extracted rays per unit area in rings of ``dr`` around
  the LED's centre, relative to its peak (the highest of the rings smoothed over three);
- the **widths at 50 % and 10 %**: twice the largest radius where the profile is still at
  half (a tenth) of its peak, linear between rings (a bare Lambertian source at height
  ``h`` gives ``2 h tan(arccos(0.5 ** 0.25)) = 1.287 h`` and ``2.941 h``);
- the **shares** of its extracted light inside its own pitch cell and the 3 x 3 cells
  around it (what a neighbouring zone receives is the rest);
- the **lit-alone map**: the exitance over the square around the LED that the rings
  reach, in bins of :data:`MAP_BINS_PER_PITCH` per pitch, relative to the same peak.

Rings run out to the nearest panel edge, so the profile is never cut by the frame.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from ..config.bench import Bench
from ..errors import JobError
from ..pattern import DotSource
from .scene import Coverage, is_direct, scene_of
from .simulate import traced
from .tables import FATES, UNCOUPLED

#: Rings per LED pitch (or per cavity gap without a grid) of the radial profile.
RINGS_PER_PITCH = 40
#: Bins per LED pitch (or cavity gap) of the lit-alone map around the LED.
MAP_BINS_PER_PITCH = 8


def halo_led(bench: Bench) -> int:
    """Index of the LED nearest the centre of the viewing area (else of the panel)."""
    bl = bench.backlight
    assert bl is not None and bl.leds is not None
    x0, y0, x1, y1 = bench.viewing_area or bench.box
    xy = bl.leds.positions
    d = np.hypot(xy[:, 0] - 0.5 * (x0 + x1), xy[:, 1] - 0.5 * (y0 + y1))
    return int(np.argmin(d))


def halo(
    bench: Bench,
    rays: int,
    seed: int = 0,
    dots: DotSource | None = None,
    coverage: Coverage | None = None,
    progress: Callable[[int, int], None] | None = None,
) -> dict:
    """Trace ``rays`` rays from one LED (:func:`halo_led`) and measure its halo (see the
    module doc).

    Returns:
        JSON-ready figures: ``led_mm``, ``rays``, ``extracted``, ``width50_mm``,
        ``width10_mm`` (None when no light left the top, or it never fell that low within
        the panel), ``share_own_cell``, ``share_3x3`` (None without a pitch), ``dr_mm`` and
        ``profile`` (``[[r_mm, L / peak], ...]``), ``map`` (``[ny][nx]`` L / peak, rows
        from the bottom) over ``map_extent_mm`` (``[x0, x1, y0, y1]``).

    Raises:
        JobError: the job is not direct-lit.
    """
    if not is_direct(bench):
        raise JobError(f"{bench.where}: a halo needs a direct-lit [backlight]")
    bl = bench.backlight
    assert bl is not None and bl.leds is not None
    k = halo_led(bench)
    cx, cy = (float(v) for v in bl.leds.positions[k])
    x0, y0, x1, y1 = bench.box
    reach = min(cx - x0, x1 - cx, cy - y0, y1 - cy)
    scale = bl.pitch if bl.pitch is not None else bl.gap
    dr = scale / RINGS_PER_PITCH
    n_rings = max(1, int(reach / dr))
    rings = np.zeros(n_rings, np.int64)
    own = near = 0
    px_, py_ = bl.leds.pitch if bl.leds.pitch is not None else (math.inf, math.inf)
    fates = np.zeros(len(FATES), np.int64)
    cell = scale / MAP_BINS_PER_PITCH
    side = max(1, int(reach / cell))
    square = (cx - side * cell, cx + side * cell, cy - side * cell, cy + side * cell)
    lit = np.zeros((2 * side, 2 * side), np.int64)
    scene = scene_of(bench, rays, dots, coverage, only_led=k)
    for px, py, _ in traced(bench, scene, seed, rays, fates, progress):
        h, _, _ = np.histogram2d(py, px, bins=(2 * side, 2 * side), range=(square[2:], square[:2]))
        lit += h.astype(np.int64)
        dx, dy = px - cx, py - cy
        r = np.hypot(dx, dy)
        i = (r / dr).astype(np.int64)
        rings += np.bincount(i[i < n_rings], minlength=n_rings)
        ax, ay = np.abs(dx), np.abs(dy)
        own += int(np.count_nonzero((ax <= 0.5 * px_) & (ay <= 0.5 * py_)))
        near += int(np.count_nonzero((ax <= 1.5 * px_) & (ay <= 1.5 * py_)))
    extracted = int(fates[0])
    edges = dr * np.arange(n_rings + 1)
    area = math.pi * (edges[1:] ** 2 - edges[:-1] ** 2)
    lum = rings / area
    # over three rings; the ring inside the first is the first (the profile is even in r)
    smooth = np.convolve(np.pad(lum, 1, mode="edge"), np.ones(3) / 3, mode="valid")
    peak = float(smooth.max()) if n_rings else 0.0
    rel = lum / peak if peak > 0 else lum * 0.0
    centres = 0.5 * (edges[1:] + edges[:-1])
    pitched = bl.leds.pitch is not None and extracted > 0
    return {
        "led_mm": [cx, cy],
        "rays": rays,
        "injected": rays - int(fates[UNCOUPLED]),
        "extracted": extracted,
        "width50_mm": _width(centres, smooth / peak, 0.5) if peak > 0 else None,
        "width10_mm": _width(centres, smooth / peak, 0.1) if peak > 0 else None,
        "share_own_cell": own / extracted if pitched else None,
        "share_3x3": near / extracted if pitched else None,
        "dr_mm": dr,
        "profile": [
            [round(float(a), 6), round(float(b), 6)] for a, b in zip(centres, rel, strict=True)
        ],
        "map_extent_mm": [round(float(v), 6) for v in square],
        "map": np.round(lit / (cell * cell) / peak if peak > 0 else lit * 0.0, 5).tolist(),
    }


def _width(r: np.ndarray, rel: np.ndarray, level: float) -> float | None:
    """Twice the largest radius where ``rel`` is still >= ``level`` (linear between rings),
    or None when it never falls below it within the rings."""
    above = np.nonzero(rel >= level)[0]
    if len(above) == 0:
        return 0.0
    k = int(above[-1])
    if k + 1 >= len(r):
        return None
    a, b = rel[k], rel[k + 1]
    f = (a - level) / (a - b) if a != b else 0.0
    return float(2.0 * (r[k] + f * (r[k + 1] - r[k])))
