"""Phantom dots: the pattern continued across every wall for the relaxation to lean on.

Why. A dot near a wall (panel edge, hole, zero-fill border) misses the neighbours that
would stand beyond it. With a hard wall in their place the relaxation layers the dots: a
dense first row against the wall (+8 to +26 % coverage in the first 0.1 mm) and a
depleted band behind it. A smooth wall potential that stands for the missing
neighbours on average (a mean-field wall, tried first) moves the row but keeps it: every
dot near a flat potential settles on the same equipotential. The missing neighbours
themselves do better: phantom dots thrown beyond each wall at the fill of the nearest
cell inside, relaxed with the real dots (same circles, same containers) but kept out of
the allowed region, and dropped afterwards. The real dots then see an irregular
continuation of the pattern on every side and the density stays flat up to the wall;
the hard rules still hold (``r0 + margin`` from the edges, no dot in a zero cell).

Phantoms are thrown once per job by the same Sobol thrower as the dots (another seed)
over the band of cells within ``reach`` of an allowed cell and outside it; only darts
outside the allowed region are kept. A tile takes the phantoms in its window, so a
panel's phantoms are the same whatever the tiling.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence

import numpy as np
from scipy.ndimage import binary_dilation, distance_transform_edt

from ..geometry.density import DensityMap
from .initial import initial_dots

#: Salt of the phantoms' Sobol scrambling (another sequence than the dots').
PHANTOM_SALT = 0x9A47


def _padded(g: np.ndarray, pad: int) -> np.ndarray:
    big = np.zeros((g.shape[0] + 2 * pad, g.shape[1] + 2 * pad))
    big[pad : pad + g.shape[0], pad : pad + g.shape[1]] = g
    return big


def extended(density: DensityMap, pad: int) -> tuple[DensityMap, np.ndarray, tuple]:
    """The map grown by ``pad`` cells on every side, each zero or added cell given the
    fill of the nearest non-zero cell.

    Returns:
        ``(grown, live, nearest)``: the grown map, ``[ny', nx']`` bool of the cells that
        were non-zero map cells, and ``(iy, ix)`` of each grown cell's nearest live cell
        (indices into the grown grid).
    """
    cw, ch = density.cell_size
    big = _padded(density.grid, pad)
    live = big > 0
    if live.any():
        _, nearest = distance_transform_edt(~live, sampling=(ch, cw), return_indices=True)
        big = big[nearest[0], nearest[1]]
    else:
        nearest = np.indices(big.shape)
    grown = DensityMap(
        big,
        density.width + 2 * pad * cw,
        density.height + 2 * pad * ch,
        density.x0 - pad * cw,
        density.y0 - pad * ch,
    )
    return grown, live, (nearest[0], nearest[1])


def phantom_dots(
    density: DensityMap,
    allowed: Callable[[np.ndarray], np.ndarray],
    partial: np.ndarray | None,
    reach: float,
    dot_area: float,
    seed: int | Sequence[int],
    cell_weights: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Phantom dots beyond every wall, within about ``reach`` of the allowed region.

    Args:
        density: the job's map.
        allowed: ``allowed(xy) -> [m] bool``: the point may hold a real dot (inside the
            outline and in a non-zero cell).
        partial: ``[ny, nx]`` bool of map cells only partly allowed (crossed by the
            outline or outside it), or None for a rectangle panel.
        reach: how far beyond a wall phantoms are needed (the circles' interaction
            range), mm.
        dot_area: area one dot stands for at fill 1 (``pi r0²``), mm².
        seed: the job's seed.
        cell_weights: ``[ny, nx]`` dart weights of the map (dots of varying size).

    Returns:
        ``(xy [m, 2] mm, rho [m], weight [m])``: phantom positions, the fill they stand
        for and their cell's dart weight (``(nominal / diameter)²``).
    """
    cw, ch = density.cell_size
    pad = max(1, math.ceil(reach / min(cw, ch)))
    grown, live, nearest = extended(density, pad)
    band = ~live
    if partial is not None:
        band[pad:-pad, pad:-pad] |= partial
    band &= binary_dilation(live, iterations=pad)
    none = np.zeros((0, 2)), np.zeros(0), np.zeros(0)
    if not band.any():
        return none
    g = np.where(band, grown.grid, 0.0)
    w = None
    if cell_weights is not None:
        w = _padded(cell_weights, pad)[nearest[0], nearest[1]]
    n = int(round(float((g if w is None else g * w).sum()) * cw * ch / dot_area))
    if n == 0:
        return none
    seeds = [seed] if isinstance(seed, int) else list(seed)
    thrown = DensityMap(g, grown.width, grown.height, grown.x0, grown.y0)
    xy = initial_dots(thrown, n, [*seeds, PHANTOM_SALT], w)
    xy = xy[~allowed(xy)]
    cells = grown.cell_index(xy)
    weight = np.ones(len(xy)) if w is None else w.ravel()[cells]
    return xy, grown.grid.ravel()[cells], weight
