"""Texture of a pattern: its long-wavelength grain and its layering against walls.

Three measures of what a viewer sees through a diffuser that the per-cell coverage
misses (``../shared/quality.md``):

* :func:`structure_factor`: ``S(k) = |Σ w_j exp(-i k·x_j)|² / Σ w_j²`` of the dot
  centres in a window, with a separable Hann taper ``w`` so the window's edges do not
  leak, radially averaged, ``k`` in units of ``1 / a`` (``a`` the hexagonal spacing at
  the window's density). Poisson points give 1 at every k; a pattern whose S falls
  toward 0 as k → 0 has no long-wavelength grain. The centres are deposited on a raster
  of ``a / 8`` by cloud-in-cell and the deposit's transfer function divided out: below
  ``k a = 3`` the raster changes S by less than 1 %.
* :func:`blurred_coverage_rms`: the dot area on a fine raster seen through a Gaussian
  of ``sigma`` mm, RMS relative to its mean over the window shrunk by ``3 sigma``.
* the wall profile (:mod:`optdot.quality.wall_profile`): coverage over the map's fill in bands
  of distance from the nearest wall.

All lengths in mm.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.ndimage import gaussian_filter

Window = tuple[float, float, float, float]


def hex_spacing(n: int, area: float) -> float:
    """Hexagonal spacing of ``n`` points on ``area`` mm², mm."""
    return math.sqrt(2.0 * area / (math.sqrt(3.0) * max(n, 1)))


def _cic(xy: np.ndarray, weights: np.ndarray, window: Window, px: float):
    """Cloud-in-cell deposit of weighted points on a ``px`` raster of ``window``,
    ``[nx, ny]``."""
    x0, y0, x1, y1 = window
    nx, ny = max(4, round((x1 - x0) / px)), max(4, round((y1 - y0) / px))
    gx = (xy[:, 0] - x0) / px - 0.5
    gy = (xy[:, 1] - y0) / px - 0.5
    ix, iy = np.floor(gx).astype(np.int64), np.floor(gy).astype(np.int64)
    fx, fy = gx - ix, gy - iy
    out = np.zeros((nx + 2, ny + 2))
    for dx, wx in ((0, 1.0 - fx), (1, fx)):
        for dy, wy in ((0, 1.0 - fy), (1, fy)):
            np.add.at(out, (np.clip(ix + dx + 1, 0, nx + 1), np.clip(iy + dy + 1, 0, ny + 1)),
                      weights * wx * wy)  # fmt: skip
    return out[1:-1, 1:-1]


def structure_factor(
    xy: np.ndarray, window: Window, spacing: float | None = None, bins: int = 60,
    k_max: float = 6.0,
) -> tuple[np.ndarray, np.ndarray, float]:  # fmt: skip
    """Radially averaged structure factor of the centres ``xy`` (``[n, 2]`` mm) in
    ``window`` ``(x0, y0, x1, y1)`` mm.

    Args:
        spacing: ``a``, mm (default: the hexagonal spacing of the points in the window).
        bins: radial bins from 0 to ``k_max`` (in units of ``1 / a``).

    Returns:
        ``(ka [bins], S [bins], a)``: bin centres of ``k·a``, S per bin (NaN where a bin
        holds no wave vector), the spacing used.
    """
    x0, y0, x1, y1 = window
    inside = (xy[:, 0] >= x0) & (xy[:, 0] < x1) & (xy[:, 1] >= y0) & (xy[:, 1] < y1)
    p = xy[inside]
    a = spacing or hex_spacing(len(p), (x1 - x0) * (y1 - y0))
    w = (
        np.sin(np.pi * (p[:, 0] - x0) / (x1 - x0)) * np.sin(np.pi * (p[:, 1] - y0) / (y1 - y0))
    ) ** 2
    px = a / 8.0
    grid = _cic(p, w, window, px)
    nx, ny = grid.shape
    f = np.abs(np.fft.rfft2(grid)) ** 2
    kx = 2 * np.pi * np.fft.fftfreq(nx, d=px)
    ky = 2 * np.pi * np.fft.rfftfreq(ny, d=px)
    transfer = (
        np.sinc(kx * px / (2 * np.pi))[:, None] * np.sinc(ky * px / (2 * np.pi))[None, :]
    ) ** 4
    s = f / np.maximum(transfer, 1e-12) / max(float(np.sum(w * w)), 1e-300)
    ka = np.hypot(kx[:, None], ky[None, :]) * a
    # the taper's own transform: the k = 0 peak spreads over a few 2 pi / L
    leak = 8.0 * np.pi * a / min(x1 - x0, y1 - y0)
    s = np.where(ka < leak, np.nan, s)
    edges = np.linspace(0.0, k_max, bins + 1)
    b = np.digitize(ka.ravel(), edges) - 1
    ok = (b >= 0) & (b < bins) & np.isfinite(s.ravel())
    cnt = np.bincount(b[ok], minlength=bins)
    tot = np.bincount(b[ok], s.ravel()[ok], minlength=bins)
    with np.errstate(invalid="ignore", divide="ignore"):
        mean = np.where(cnt > 0, tot / np.maximum(cnt, 1), np.nan)
    return 0.5 * (edges[1:] + edges[:-1]), mean, a


def band_mean(ka: np.ndarray, s: np.ndarray, lo: float, hi: float) -> float:
    """Mean of S over the bins with ``lo <= k a < hi``."""
    m = (ka >= lo) & (ka < hi) & np.isfinite(s)
    return float(np.mean(s[m])) if m.any() else float("nan")


def blurred_coverage_rms(
    xy: np.ndarray, diameter: float | np.ndarray, window: Window, sigma: float = 0.5,
    px: float | None = None,
) -> float:  # fmt: skip
    """RMS of the dot coverage seen through a Gaussian of ``sigma`` mm, relative to its
    mean, over ``window`` shrunk by ``3 sigma`` (dots of ``window`` grown by ``3 sigma``
    deposited). Dots are deposited as their area at the centre (cloud-in-cell on a
    raster of ``px``, default ``sigma / 10``): at this blur the disc shape changes
    nothing."""
    px = px or sigma / 10.0
    x0, y0, x1, y1 = window
    d = np.broadcast_to(np.asarray(diameter, dtype=np.float64), (len(xy),))
    area = np.pi * 0.25 * d * d
    grid = _cic(xy, area, window, px)
    blurred = gaussian_filter(grid, sigma / px, mode="constant")
    m = round(3 * sigma / px)
    inner = blurred[m:-m, m:-m] if m > 0 else blurred
    if inner.size == 0:
        return float("nan")
    mean = float(inner.mean())
    return float(inner.std() / mean) if mean > 0 else float("nan")
