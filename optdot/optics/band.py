"""The luminance across a process's gain tolerance: the real dots grown to each end of
``[process] dot_gain ± gain_tolerance`` and traced as the nominal ones were."""

from __future__ import annotations

from dataclasses import replace

from ..geometry.shapes import Footprints
from ..printing.process import grown_sizes
from .simulate import simulate

#: The figures the band keeps at each end.
BAND_FIGURES = (
    "efficiency",
    "uniformity_9point",
    "luminance_rms",
    "luminance_min",
    "luminance_max",
)


def tolerance_band(bench, dots, nominal, rays: int, seed: int, **where) -> dict:
    """``{"gain_mm": [3], <figure>: [3]}`` at ``gain - tol``, nominal and ``gain + tol``:
    the pattern ``dots`` (the nominal print) grown by ``∓tol``
    (:func:`optdot.printing.process.grown_sizes`) and traced with the same ``rays`` and
    ``seed`` and binning (``where``: ``bin_mm``, ``spot_mm``, ``border_mm``) as
    ``nominal`` (its :class:`~optdot.optics.simulate.Simulation`)."""
    band = {"gain_mm": [], **{k: [] for k in BAND_FIGURES}}
    feet = dots.shape
    for delta in bench.process.gain_ends():
        if delta == 0.0:
            s = nominal.summary()
        else:
            grown = Footprints(feet.kind, grown_sizes(feet.kind, feet.size, delta), feet.angle)
            other = replace(
                dots, diameter=grown.diameter, dots=None if dots.dots is None else grown
            )
            s = simulate(bench, rays, seed, dots=other, **where).summary()
        band["gain_mm"].append(bench.process.dot_gain + delta)
        for k in BAND_FIGURES:
            band[k].append(s[k])
    return band
