"""Initial dot pattern by low-discrepancy dart throwing (paper §2.1)."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from ..geometry.density import DensityMap
from .sobol import sobol_points


def initial_dots(
    density: DensityMap, n: int, seed: int, cell_weights: np.ndarray | None = None
) -> np.ndarray:
    """Throw ``n`` darts at the map with a scrambled 3-D Sobol sequence.

    Point ``(U0, U1, U2)`` picks cell k with probability ``P_k = rho_k / sum(rho)`` from
    ``U0`` and the position inside the cell from ``(U1, U2)``, as in the paper.

    Args:
        density: the fill-fraction map (cells of equal area).
        n: number of dots.
        seed: seed of the scrambling (same seed, same dots).
        cell_weights: optional ``[ny, nx]`` multiplier of each cell's probability (share of
            the cell inside the domain).

    Returns:
        ``[n, 2]`` float64 positions, mm, in generation order.
    """
    g = density.grid if cell_weights is None else density.grid * cell_weights
    p = g.ravel()
    cum = np.cumsum(p)
    cum /= cum[-1]
    u = sobol_points(n, seed)
    k = np.searchsorted(cum, u[:, 0], side="right")
    last = int(np.flatnonzero(p > 0)[-1])
    k = np.minimum(k, last)
    ny, nx = density.shape
    dx, dy = density.cell_size
    iy, ix = np.divmod(k, nx)
    xy = np.empty((n, 2))
    xy[:, 0] = density.x0 + (ix + u[:, 1]) * dx
    xy[:, 1] = density.y0 + (iy + u[:, 2]) * dy
    return xy


def initial_dots_in(
    density: DensityMap,
    n: int,
    seed: int,
    inside: Callable[[np.ndarray], np.ndarray],
    cell_weights: np.ndarray | None = None,
) -> np.ndarray:
    """:func:`initial_dots` restricted to a domain: the first ``n`` darts that land inside.

    Darts are thrown at the whole map (cells picked in proportion to rho) and those
    outside the domain are dropped, so inside it the dots still follow rho; the sequence
    is extended until ``n`` have landed.

    Args:
        inside: ``inside(xy) -> [m] bool`` for ``[m, 2]`` positions.
        cell_weights: optional ``[ny, nx]`` multiplier of each cell's probability (dots
            of varying size: in proportion to the dot count, not the fill).
    """
    m = max(n, 16)
    while True:
        xy = initial_dots(density, m, seed, cell_weights)
        keep = xy[inside(xy)]
        if len(keep) >= n or m > 64 * max(n, 16):
            return keep[:n]
        m = int(m * 1.25 * n / max(len(keep), 1)) + 16
