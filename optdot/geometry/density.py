"""Fill-fraction maps: a grid of per-cell dot area / cell area over the panel's box.

Conventions: ``grid`` has shape ``[ny, nx]``; row 0 is the bottom row (y = 0) and column 0
the left column (x = 0); the cells split the box ``[x0, x0 + width] x [y0, y0 + height]``
(mm) evenly.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

#: Densest packing of equal discs in the plane, pi / (2 sqrt 3) ~ 0.9069.
HEX_PACKING_LIMIT = math.pi / (2.0 * math.sqrt(3.0))


@dataclass(frozen=True, eq=False)
class DensityMap:
    """A validated fill-fraction grid.

    Attributes:
        grid: ``[ny, nx]`` float64 fill fractions in ``[0, HEX_PACKING_LIMIT)``.
        width, height: size of the box the grid covers, mm.
        x0, y0: lower-left corner of that box, mm.
    """

    grid: np.ndarray
    width: float
    height: float
    x0: float = 0.0
    y0: float = 0.0

    def __post_init__(self) -> None:
        g = np.ascontiguousarray(self.grid, dtype=np.float64)
        if g.ndim != 2 or g.shape[0] < 1 or g.shape[1] < 1:
            raise ValueError(f"grid must be 2-D and non-empty, got shape {g.shape}")
        g.setflags(write=False)
        object.__setattr__(self, "grid", g)

    @property
    def shape(self) -> tuple[int, int]:
        """``(ny, nx)``."""
        return self.grid.shape  # type: ignore[return-value]

    @property
    def cell_size(self) -> tuple[float, float]:
        """``(dx, dy)`` of one cell, mm."""
        ny, nx = self.grid.shape
        return self.width / nx, self.height / ny

    def cell_index(self, xy: np.ndarray) -> np.ndarray:
        """Flat cell index ``iy * nx + ix`` of each point.

        Args:
            xy: ``[n, 2]`` positions, mm. Points outside the box are clamped to the
                nearest cell.

        Returns:
            ``[n]`` int64.
        """
        ny, nx = self.grid.shape
        dx, dy = self.cell_size
        ix = np.clip(np.floor((xy[:, 0] - self.x0) / dx).astype(np.int64), 0, nx - 1)
        iy = np.clip(np.floor((xy[:, 1] - self.y0) / dy).astype(np.int64), 0, ny - 1)
        return iy * nx + ix

    def at(self, xy: np.ndarray) -> np.ndarray:
        """Fill fraction of the cell holding each point, ``[n]`` float64."""
        return self.grid.ravel()[self.cell_index(xy)]

    def empty_mask(self, xy: np.ndarray) -> np.ndarray:
        """``[n]`` bool: the point lies inside the map's box, in a cell whose fill is 0."""
        inside = (
            (xy[:, 0] >= self.x0)
            & (xy[:, 0] <= self.x0 + self.width)
            & (xy[:, 1] >= self.y0)
            & (xy[:, 1] <= self.y0 + self.height)
        )
        return inside & (self.at(xy) <= 0.0)

    def integral(
        self, x0: float, y0: float, x1: float, y1: float, cell_weights: np.ndarray | None = None
    ) -> float:
        """Integral of the fill fraction over the rectangle ``[x0, x1] x [y0, y1]``, mm²
        (each cell's value times ``cell_weights`` when given)."""
        g = self.grid if cell_weights is None else self.grid * cell_weights
        cw, ch = self.cell_size
        fx = axis_overlap(np.array([x0, x1]), self.x0, cw, self.shape[1])[0]
        fy = axis_overlap(np.array([y0, y1]), self.y0, ch, self.shape[0])[0]
        return float(fy @ g @ fx)

    def dot_count(self, dot_area: float, cell_weights: np.ndarray | None = None) -> int:
        """Number of dots of area ``dot_area`` (mm²) that realise the map.

        Args:
            dot_area: area of one dot, mm².
            cell_weights: optional ``[ny, nx]`` share of each cell's area that belongs to
                the domain (1 for a full rectangle).
        """
        dx, dy = self.cell_size
        g = self.grid if cell_weights is None else self.grid * cell_weights
        return int(round(float(g.sum()) * dx * dy / dot_area))


def axis_overlap(edges: np.ndarray, lo: float, step: float, n: int) -> np.ndarray:
    """``[len(edges) - 1, n]`` length of each interval ``edges[k]..edges[k + 1]`` inside
    each of ``n`` grid cells of width ``step`` starting at ``lo``, mm."""
    c0 = lo + np.arange(n) * step
    c1 = c0 + step
    a = np.maximum(edges[:-1, None], c0[None, :])
    b = np.minimum(edges[1:, None], c1[None, :])
    return np.clip(b - a, 0.0, None)
