"""What prints across a process's tolerance: the coverage of the printed footprints against
the map at the dot gain's ends (``gain - tolerance``, nominal, ``gain + tolerance``).

The pattern is the nominal print; a gain off by ``δ`` grows each printed footprint by
``δ`` per edge, whose area Steiner's formula gives exactly for a convex footprint
(``A + P δ + π δ²``; shrunk, exact while ``-δ`` is within its curvature). The coverage is
then measured as QA measures the nominal's (per map cell, after the same smoothing).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ..geometry.density import DensityMap
from ..printing.process import Process
from .gate import Check
from .metrics import cell_area_sums, coverage


def tolerance_band(
    dots, process: Process, density: DensityMap, outline, smoothing: float
) -> dict[str, Any]:
    """The coverage at the gain's ends and at nominal: per end, the printed coverage over
    the map's (the whole panel) and the coverage error RMS after ``smoothing`` mm.

    Args:
        dots: a :class:`~optdot.pattern.DotSource` (the print at nominal gain), read chunk
            by chunk.
        outline: the panel's :class:`~optdot.geometry.domain.Domain`, or None (the map's
            box).

    Returns:
        ``{"gain_mm": [3], "coverage_ratio": [3], "coverage_rel_rms_smoothed": [3]}``,
        the ends in the order ``gain - tolerance``, nominal, ``gain + tolerance``.
    """
    tol = process.gain_tolerance
    offsets = (-tol, 0.0, tol)
    sums = [np.zeros(density.grid.size) for _ in offsets]
    n = 0
    total = [0.0 for _ in offsets]
    for _, xy, feet in dots.chunks():
        n += len(xy)
        for k, delta in enumerate(offsets):
            area = process.steiner_area(feet.kind, feet.size, delta)
            d = 2.0 * np.sqrt(area / np.pi)  # deposited as its area at the centre
            sums[k] += cell_area_sums(xy, d, False, density)
            total[k] += float(area.sum())
    cw, ch = density.cell_size
    ny, nx = density.shape
    frac = (
        np.ones_like(density.grid)
        if outline is None
        else outline.cell_fractions(density.x0, density.y0, cw, ch, nx, ny)
    )
    wanted = float((density.grid * frac).sum()) * cw * ch
    rms = [
        coverage(s, None, n, dots.nominal_diameter, outline, density, smoothing)[0][
            "coverage_rel_rms_smoothed"
        ]
        for s in sums
    ]
    return {
        "gain_mm": [process.dot_gain + d for d in offsets],
        "coverage_ratio": [t / wanted if wanted > 0 else float("nan") for t in total],
        "coverage_rel_rms_smoothed": rms,
    }


def band_check(band: dict[str, Any], limit: float) -> Check:
    """The advisory line of the band: its worst coverage error RMS against the gate's
    limit (a process at the end of its tolerance prints a map off by that much)."""
    worst = max(band["coverage_rel_rms_smoothed"])
    lo, hi = band["gain_mm"][0], band["gain_mm"][-1]
    return Check(
        f"coverage error RMS across the gain's tolerance ({lo * 1e3:.4g}–{hi * 1e3:.4g} µm "
        "per edge; advisory: what the process may print)",
        worst,
        limit,
        worst <= limit,
        advisory=True,
    )
