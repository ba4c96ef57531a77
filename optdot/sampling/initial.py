"""Initial dot pattern by low-discrepancy dart throwing (paper §2.1).

One thrower for the whole panel and for a tile of it: a tile is the special case of a
window, where each cell's probability is its weight times the share of the cell inside
the window and the dart lands uniformly in that share, so a tile's dots follow the map
exactly as the panel's do (the single-process throw is the window = the map's box).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np

from ..errors import GeometryError
from ..geometry.density import DensityMap, axis_overlap
from .sobol import sobol_points

#: ``(x0, y0, x1, y1)`` of a window, mm.
Rect = tuple[float, float, float, float]
#: Darts thrown at most, as a multiple of the dots asked for, before giving up on a domain.
MAX_DARTS_PER_DOT = 64


def _window(density: DensityMap, rect: Rect | None):
    """Cells a window touches and their shares: ``(rows [ny'], cols [nx'], fy [ny'],
    fx [nx'])``, shares as fractions of a cell (1.0 for the whole map)."""
    ny, nx = density.shape
    if rect is None:
        return np.arange(ny), np.arange(nx), np.ones(ny), np.ones(nx)
    cw, ch = density.cell_size
    x0, y0, x1, y1 = rect
    fx = axis_overlap(np.array([x0, x1]), density.x0, cw, nx)[0] / cw
    fy = axis_overlap(np.array([y0, y1]), density.y0, ch, ny)[0] / ch
    cols, rows = np.flatnonzero(fx > 0), np.flatnonzero(fy > 0)
    return rows, cols, fy[rows], fx[cols]


def _span(k: np.ndarray, origin: float, step: float, window: tuple[float, float] | None):
    """``(lo [m], width [m])`` of the cells ``k`` inside ``window``, in cell units."""
    k = k.astype(np.float64)
    if window is None:
        return k, np.ones_like(k)
    lo = np.maximum(k, (window[0] - origin) / step)
    hi = np.minimum(k + 1.0, (window[1] - origin) / step)
    return lo, hi - lo


def initial_dots(
    density: DensityMap,
    n: int,
    seed: int | Sequence[int],
    cell_weights: np.ndarray | None = None,
    rect: Rect | None = None,
) -> np.ndarray:
    """Throw ``n`` darts at the map (or the window ``rect`` of it) with a scrambled 3-D
    Sobol sequence.

    Point ``(U0, U1, U2)`` picks cell k with probability ``P_k ∝ rho_k w_k s_k`` from
    ``U0`` (``w`` the cell weights, ``s`` the share of the cell inside the window) and the
    position inside that share of the cell from ``(U1, U2)``, as in the paper.

    Args:
        density: the fill-fraction map (cells of equal area).
        n: number of dots.
        seed: seed of the scrambling (same seed, same dots): an int or a sequence of
            ints (a tile's ``[seed, salt, index]``).
        cell_weights: optional ``[ny, nx]`` multiplier of each cell's probability (dots
            of varying size: in proportion to the dot count, not the fill).
        rect: ``(x0, y0, x1, y1)`` window, mm (a tile); None: the map's box.

    Returns:
        ``[n, 2]`` float64 positions, mm, in generation order (inside the window).

    Raises:
        GeometryError: the map (times the weights) is zero over the whole window.
    """
    rows, cols, fy, fx = _window(density, rect)
    g = density.grid if cell_weights is None else density.grid * cell_weights
    p = g[np.ix_(rows, cols)]
    if rect is not None:
        p = p * fy[:, None] * fx[None, :]
    p = p.ravel()
    if not (p > 0).any():
        raise GeometryError(f"the map is zero over {'the panel' if rect is None else rect}")
    cum = np.cumsum(p)
    cum /= cum[-1]
    u = sobol_points(n, seed)
    k = np.searchsorted(cum, u[:, 0], side="right")
    k = np.minimum(k, int(np.flatnonzero(p > 0)[-1]))
    r, c = np.divmod(k, len(cols))
    dx, dy = density.cell_size
    wx = None if rect is None else (rect[0], rect[2])
    wy = None if rect is None else (rect[1], rect[3])
    lx, sx = _span(cols[c], density.x0, dx, wx)
    ly, sy = _span(rows[r], density.y0, dy, wy)
    xy = np.empty((n, 2))
    xy[:, 0] = density.x0 + (lx + u[:, 1] * sx) * dx
    xy[:, 1] = density.y0 + (ly + u[:, 2] * sy) * dy
    return xy


def initial_dots_in(
    density: DensityMap,
    n: int,
    seed: int | Sequence[int],
    inside: Callable[[np.ndarray], np.ndarray] | None,
    cell_weights: np.ndarray | None = None,
    rect: Rect | None = None,
    where: str = "the panel",
) -> np.ndarray:
    """:func:`initial_dots` restricted to a domain: the first ``n`` darts that land inside.

    Darts are thrown at the whole map (or window; cells picked in proportion to rho) and
    those outside the domain are dropped, so inside it the dots still follow rho; the
    sequence is extended until ``n`` have landed.

    Args:
        inside: ``inside(xy) -> [m] bool`` for ``[m, 2]`` positions; None: every dart
            counts (a rectangular panel).
        where: the job or tile, for the error message.

    Raises:
        GeometryError: fewer than ``n`` of :data:`MAX_DARTS_PER_DOT` x ``n`` darts landed
            inside (the map is zero over most of the domain).
    """
    if inside is None:
        return initial_dots(density, n, seed, cell_weights, rect)
    m = max(n, 16)
    while True:
        xy = initial_dots(density, m, seed, cell_weights, rect)
        keep = xy[inside(xy)]
        if len(keep) >= n:
            return keep[:n]
        if m > MAX_DARTS_PER_DOT * max(n, 16):
            raise GeometryError(
                f"{where}: could only place {len(keep)} of {n} dots inside the outline; "
                "the map is zero over most of it"
            )
        m = int(m * 1.25 * n / max(len(keep), 1)) + 16
