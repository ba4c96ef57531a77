"""Size fitting: dots of varying size meet the fill where they stand, not only on average.

With one size, a pattern's coverage in a window is its dot count there, so the coverage
error is the count's noise. When sizes may vary (:mod:`optdot.geometry.sizes`), the
sizes can absorb that noise: after relaxation every dot's diameter is scaled so that the
coverage, blurred by a Gaussian of width ``sigma``, equals the target map blurred the
same way, ``d_i <- d_i sqrt(T_s(x_i) / C_s(x_i))``, repeated :data:`ROUNDS` times (each
round shrinks the blurred error; on a relaxed pattern, whose error is small to begin
with, the first does most of the work), then quantised. Each dot may move within
``1 / f .. f`` of its rule diameter, f the largest factor up to ``1 + FREEDOM`` that
keeps that band inside the range: a band clipped on one
side only would let dots near an end of the range grow but not shrink (or the other way),
and that one-sided clipping would bias the fill where the count carries the map. Dots at
an end keep their size; their free neighbours absorb the noise. Last, the free dots are
scaled together so that the total dot area is what it was: the fit moves area between
dots, the count (which the map's integral set) keeps the total (near the panel's edges
the truncated blur would otherwise add a few tenths of a percent). A dot whose
neighbours sit close gets a little smaller, one with room a little larger, so the edge
gaps even out too.

``sigma`` defaults to half the QA's coverage smoothing (0.5 mm): a diffuser or the eye
sees coverage blurred at least that much, and a smaller window would chase the noise of
single dots. The blurs are normalised convolutions over the panel (the panel's share of
each pixel is the weight), so edges, holes and zero-density regions are neither starved
nor flooded. The explicit ``diameter_grid`` rule is the user's choice of sizes and is
left as it is.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.ndimage import gaussian_filter, map_coordinates

from ..geometry.density import DensityMap
from ..geometry.domain import Domain
from ..geometry.sizes import DotSizes

#: Rounds of the fit (each: blur, compare, rescale).
ROUNDS = 3
#: Pixels per sigma of the blur grid.
PIXELS_PER_SIGMA = 3.0
#: A fitted diameter stays within ``1 / (1 + FREEDOM)`` .. ``1 + FREEDOM`` of the rule's.
FREEDOM = 0.15


def fit_sizes(
    xy: np.ndarray,
    diameters: np.ndarray,
    sizes: DotSizes,
    density: DensityMap,
    domain: Domain,
    sigma: float,
    fit: np.ndarray | None = None,
    window: tuple[float, float, float, float] | None = None,
) -> np.ndarray:
    """Diameters that make the ``sigma``-blurred coverage equal the blurred map.

    Args:
        xy: ``[n, 2]`` dot centres, mm.
        diameters: ``[n]`` their diameters before the fit, mm.
        sizes: the job's size rule (range and quantisation step).
        density: the target fill map.
        domain: the panel.
        sigma: Gaussian width of the blur, mm (> 0).
        fit: ``[n]`` bool, the dots whose size is fitted (default all); the others keep
            theirs and count in the coverage (a tile's neighbours).
        window: ``(x0, y0, x1, y1)`` mm, the part of the panel the blur covers (default
            the panel's box): a tile grown by :func:`reach` of the blur, holding the
            tile's dots and every neighbour within that reach. Blurs are truncated at
            the window's sides for the target and the coverage alike, and the fitted dots
            lie a reach inside them, where the truncation does not show.

    Returns:
        ``[n]`` diameters, mm: the fitted ones in ``[sizes.low, sizes.high]``, quantised;
        the others as given.
    """
    x0, y0, x1, y1 = domain.box
    if window is not None:
        x0, y0 = max(x0, window[0]), max(y0, window[1])
        x1, y1 = min(x1, window[2]), min(y1, window[3])
    px = sigma / PIXELS_PER_SIGMA
    nx, ny = max(1, math.ceil((x1 - x0) / px)), max(1, math.ceil((y1 - y0) / px))
    cw, ch = (x1 - x0) / nx, (y1 - y0) / ny
    if domain.rectangle:
        share = np.ones((ny, nx))
    else:
        share = domain.cell_fractions(x0, y0, cw, ch, nx, ny)
    blur = (sigma / ch, sigma / cw)
    fill = density.resampled(x0, y0, cw, ch, nx, ny)  # exact mean fill of each pixel
    target = gaussian_filter(fill * share, blur, mode="constant")
    # fractional pixel coordinates of the dots, for bilinear reads of the blurred ratio
    coords = np.stack([(xy[:, 1] - y0) / ch - 0.5, (xy[:, 0] - x0) / cw - 0.5])
    rng = ((y0, y1), (x0, x1))
    d = np.asarray(diameters, dtype=np.float64).copy()
    f = np.minimum(np.minimum(1.0 + FREEDOM, sizes.high / d), d / sizes.low)
    f = np.maximum(f, 1.0)
    if fit is not None:
        f[~fit] = 1.0  # held: a band of width zero
    lo, hi = d / f, d * f
    for _ in range(ROUNDS):
        area = 0.25 * math.pi * d * d
        cover, _, _ = np.histogram2d(xy[:, 1], xy[:, 0], bins=(ny, nx), range=rng, weights=area)
        have = gaussian_filter(cover / (cw * ch), blur, mode="constant")
        with np.errstate(divide="ignore", invalid="ignore"):
            ratio = np.where(have > 0, target / have, 1.0)
        at = map_coordinates(ratio, coords, order=1, mode="nearest")
        d = np.clip(d * np.sqrt(np.maximum(at, 0.0)), lo, hi)
    free = hi > lo
    mine = slice(None) if fit is None else fit
    before = float(np.sum(np.square(diameters[mine])))
    pinned = float(np.sum(np.square(d[mine][~free[mine]])))
    moved = float(np.sum(np.square(d[free])))
    if moved > 0:
        d[free] *= math.sqrt(max(before - pinned, 0.0) / moved)
    if fit is None:
        return sizes.quantise(d)
    out = np.asarray(diameters, dtype=np.float64).copy()
    out[fit] = sizes.quantise(d[fit])
    return out


def reach(sigma: float) -> float:
    """How far the blur of :func:`fit_sizes` carries a dot's coverage, mm (4 sigma and
    a pixel): a tile's fit needs its neighbours' dots within this."""
    return 4.0 * sigma + sigma / PIXELS_PER_SIGMA
