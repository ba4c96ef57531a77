"""Figures drawn the same in ``simulate``'s PNG and in the QA report: a luminance map beside
its smoothed view, the halo of one LED lit alone, the luminance's angles. Matplotlib axes
in, nothing out; the numbers come from a simulation's figures (the JSON ``simulate``
writes), so both callers draw from the same values."""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

#: Gaussian sigma of the smoothed luminance view, bins.
SMOOTH_BINS = 1.5

#: Rays within the first polar ring (5° of the normal) under which the on-axis luminance
#: and the half-luminance angles are not stated: their noise would be 10 % or more.
MIN_ON_AXIS_RAYS = 100


def angles_judged(angles: dict) -> bool:
    """Whether a simulation's ``angles`` figures hold rays enough on axis to state the
    on-axis luminance and its half angles (:data:`MIN_ON_AXIS_RAYS`)."""
    return (angles.get("on_axis_rays", MIN_ON_AXIS_RAYS) or 0) >= MIN_ON_AXIS_RAYS


def smoothed(lum: np.ndarray, sigma: float = SMOOTH_BINS) -> tuple[np.ndarray, float]:
    """``(lum smoothed, factor)``: ``lum`` (``[ny, nx]``) under a Gaussian of ``sigma``
    bins (edges held), and the factor it cuts independent bins' noise by (``1 / (2 sqrt(pi)
    sigma)`` in two dimensions)."""
    from scipy.ndimage import gaussian_filter

    return gaussian_filter(lum, sigma, mode="nearest"), 1.0 / (2.0 * math.sqrt(math.pi) * sigma)


def noise_text(figures: dict) -> str:
    """The luminance's structure against its noise in words, for a title or a caption:
    ``RMS 3.8 % (noise alone 3.8 %): no structure beyond the noise; ~2.9e+07 rays bring
    the noise to 1 %``."""
    rms, noise = figures.get("luminance_rms"), figures.get("luminance_rms_noise")
    if rms is None or noise is None or not (math.isfinite(rms) and math.isfinite(noise)):
        return "no light measured"
    return f"RMS {rms:.1%} (noise alone {noise:.1%}): {structure_text(figures)}"


def structure_text(figures: dict) -> str:
    """What the luminance holds beyond its Monte Carlo noise, and the rays that would
    bring the noise to 1 % of the mean (when it is over it)."""
    noise = figures.get("luminance_rms_noise") or 0.0
    structure = figures.get("luminance_structure")
    if structure is None or not math.isfinite(structure) or structure < 0.5 * noise:
        text = "no structure beyond the noise"
    else:
        text = f"structure beyond the noise ~{structure:.1%}"
    rays = figures.get("rays_for_1pct_noise")
    if rays is not None and noise > 0.01:
        text += f"; ~{rays:.2g} rays bring the noise to 1 %"
    return text


def luminance_pair(
    axes: Sequence, lum: np.ndarray, extent: tuple[float, float, float, float], noise: float
) -> tuple:
    """The luminance ``lum`` (``[ny, nx]``, relative to its mean) over ``extent`` (``x0,
    x1, y0, y1`` mm) on ``axes[0]`` and smoothed (:func:`smoothed`) on ``axes[1]``, on one
    scale around 1 (its 1st-99th percentiles, at least ±2 %): ``(image, image)``."""
    soft, factor = smoothed(lum)
    vals = lum[np.isfinite(lum)]
    lo, hi = np.percentile(vals, [1, 99]) if len(vals) else (1.0, 1.0)
    span = max(abs(1 - lo), abs(hi - 1), 0.02)
    kw = dict(origin="lower", extent=extent, cmap="RdBu_r", vmin=1 - span, vmax=1 + span)
    raw = axes[0].imshow(lum, interpolation="nearest", **kw)
    soft_im = axes[1].imshow(soft, interpolation="nearest", **kw)
    axes[0].set_title(f"bins as traced (noise {noise:.1%} a bin)", fontsize=9)
    axes[1].set_title(
        f"smoothed, Gaussian of {SMOOTH_BINS:g} bins (noise ~{noise * factor:.1%})", fontsize=9
    )
    for ax in axes[:2]:
        ax.set_xlabel("x, mm")
        ax.set_ylabel("y, mm")
    return raw, soft_im


def halo_pair(axes: Sequence, halo: dict) -> None:
    """The halo of one LED lit alone (``simulate``'s ``halo`` figures): its map on
    ``axes[0]`` (log scale, circles at the widths at 50 % and 10 %) and its radial profile
    on ``axes[1]`` (the 50 % and 10 % levels and widths marked)."""
    from matplotlib.colors import LogNorm
    from matplotlib.patches import Circle

    cx, cy = halo["led_mm"]
    widths = [(halo.get("width50_mm"), "50 %", "k"), (halo.get("width10_mm"), "10 %", "0.4")]
    lit = np.asarray(halo.get("map") or [[0.0]], np.float64)
    ax = axes[0]
    if lit.size and float(lit.max()) > 0:
        floor = max(1e-3, float(lit[lit > 0].min()))
        im = ax.imshow(
            np.maximum(lit, floor), origin="lower", extent=halo["map_extent_mm"], cmap="magma",
            norm=LogNorm(vmin=floor, vmax=max(float(lit.max()), floor * 10)),
            interpolation="nearest",
        )  # fmt: skip
        ax.figure.colorbar(im, ax=ax, label="exitance / peak", shrink=0.8)
    for w, _, color in widths:
        if w:
            ax.add_patch(Circle((cx, cy), 0.5 * w, fill=False, color=color, lw=1, ls="--"))
    ax.set_title(f"LED at ({cx:.2f}, {cy:.2f}) mm lit alone", fontsize=9)
    ax.set_xlabel("x, mm")
    ax.set_ylabel("y, mm")
    ax = axes[1]
    prof = np.asarray(halo.get("profile") or np.zeros((0, 2)), np.float64).reshape(-1, 2)
    ax.plot(prof[:, 0], prof[:, 1], color="C0", lw=1)
    for level, (w, label, color) in zip((0.5, 0.1), widths, strict=True):
        ax.axhline(level, color=color, lw=0.7, ls=":")
        if w:
            ax.axvline(0.5 * w, color=color, lw=0.8, ls="--", label=f"width at {label}: {w:.3g} mm")
        else:
            ax.plot([], [], color=color, ls="--", label=f"width at {label}: beyond the panel")
    ax.set(xlabel="distance from the LED, mm", ylabel="exitance / peak", ylim=(0, 1.15))
    ax.legend(fontsize=8)
    share = halo.get("share_own_cell")
    extra = f"; {share:.0%} of its light in its own cell" if share is not None else ""
    ax.set_title(f"radial profile{extra}", fontsize=9)


def angles_pair(axes: Sequence, table, angles: dict) -> list:
    """The luminance's angles (``simulate``'s ``angular_luminance`` table, rows polar
    rings, columns azimuth bins, and its ``angles`` figures with the planes' profiles): a
    polar map on ``axes[0]``
    (replaced by a polar axes in the same place, returned in the list) and the profiles
    in the horizontal and vertical planes on ``axes[1]`` (half the on-axis luminance
    and the half angles marked). Luminance relative to a Lambertian of the same flux."""
    lum = np.array([[np.nan if v is None else v for v in r] for r in table], np.float64)
    nt, nphi = lum.shape
    fig = axes[0].figure
    spec = axes[0].get_subplotspec()
    axes[0].remove()
    ax = fig.add_subplot(spec, projection="polar")
    phi = np.radians(np.linspace(0, 360, nphi + 1))
    theta = np.linspace(0, 90, nt + 1)
    im = ax.pcolormesh(phi, theta, lum, cmap="viridis", shading="flat")
    ax.set_ylim(0, 90)
    ax.set_yticks([30, 60, 90])
    ax.set_yticklabels(["30°", "60°", "90°"], fontsize=7)
    ax.set_title("luminance by direction (radius: polar angle)", fontsize=9)
    fig.colorbar(im, ax=ax, label="luminance / Lambertian's", shrink=0.8)
    pr = axes[1]
    centres = (np.arange(nt) + 0.5) * (90 / nt)
    half = angles.get("half_luminance_deg") or {}
    judged = angles_judged(angles)
    for (name, prof), color in zip(
        (angles.get("profiles") or {}).items(), "C0 C1".split(), strict=False
    ):
        prof = np.array([np.nan if v is None else v for v in prof], np.float64)
        h = half.get(name)
        label = f"{name}: half at {h:.1f}°" if h is not None else f"{name}: over half to 90°"
        label = label if judged else name
        pr.plot(centres, prof, color=color, lw=1.2, label=label)
        if h is not None:
            pr.axvline(h, color=color, lw=0.8, ls="--")
    on = angles.get("on_axis")
    if on is not None and math.isfinite(on) and judged:
        pr.axhline(0.5 * on, color="0.4", lw=0.7, ls=":")
    pr.axhline(1.0, color="k", lw=0.6)
    pr.set(xlabel="polar angle, degrees", ylabel="luminance / Lambertian's", xlim=(0, 90))
    pr.legend(fontsize=8)
    title = f"on axis {on:.3f} of a Lambertian's" if on is not None else ""
    if not judged:
        title = f"{angles.get('on_axis_rays', 0)} rays within 5° of the normal: too few to judge"
    pr.set_title(title, fontsize=9)
    return [ax, pr]
