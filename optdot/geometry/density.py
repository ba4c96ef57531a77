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
#: How the map's values are read between its cells: ``nearest`` (each cell one value, as
#: given) or ``linear`` (the values are samples of a smooth field at the cell centres).
INTERPOLATIONS = ("nearest", "linear")
#: Sub-cells per map cell and axis that ``linear`` aims for, and the most sub-cells in all.
LINEAR_FACTOR = 8
LINEAR_MAX_CELLS = 1 << 24


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

    def interpolated(self, factor: int | None = None) -> DensityMap:
        """The map read as samples of a smooth field: bilinear between the cell centres
        (constant beyond the outermost centres), stored on ``factor`` x ``factor``
        sub-cells per cell, each holding the field's value at its centre.

        ``factor`` is even, so the sub-cells' edges include the lines through the cell
        centres where the bilinear pieces meet: within each sub-cell the field is one
        bilinear piece, whose mean is its value at the centre, so the sub-cells carry the
        smooth field's integral exactly and every consumer (dart throwing, circle radii,
        the zero-density rule, dot counts, QA coverage) reads the same field. A sub-cell is
        zero only where all four samples around it are zero, i.e. where the field is zero
        throughout. Default ``factor``: :data:`LINEAR_FACTOR`, lowered (to 2 at least)
        while the sub-cells would exceed :data:`LINEAR_MAX_CELLS`.
        """
        ny, nx = self.shape
        if factor is None:
            factor = LINEAR_FACTOR
            while factor > 2 and ny * nx * factor * factor > LINEAR_MAX_CELLS:
                factor -= 2
        if factor < 2 or factor % 2:
            raise ValueError(f"factor must be an even number >= 2, got {factor}")
        fine = _linear_axis(self.grid, factor, axis=1)
        fine = _linear_axis(fine, factor, axis=0)
        return DensityMap(np.maximum(fine, 0.0), self.width, self.height, self.x0, self.y0)

    def resampled(self, x0: float, y0: float, cw: float, ch: float, nx: int, ny: int) -> np.ndarray:
        """``[ny, nx]`` mean fill over each pixel of another grid (lower-left corner
        ``x0, y0``, pixels ``cw x ch``, mm), exact: each pixel weighs the cells it
        overlaps by the shared area (0 outside the map). Memory ~ the two grids."""
        fx = sparse_overlap(x0 + np.arange(nx + 1) * cw, self.x0, self.cell_size[0], self.shape[1])
        fy = sparse_overlap(y0 + np.arange(ny + 1) * ch, self.y0, self.cell_size[1], self.shape[0])
        return np.asarray(fy @ (fx @ self.grid.T).T) / (cw * ch)

    def deposited(self, x0: float, y0: float, cw: float, ch: float, nx: int, ny: int) -> np.ndarray:
        """``[ny, nx]`` fill of the map as a cloud-in-cell deposit on another grid sees it
        (lower-left corner ``x0, y0``, pixels ``cw x ch``, mm): every bit of the map's area
        shared among the 4 nearest pixel centres by bilinear weights, what lies past the
        outermost centres given to the outermost pixels, exactly as dots are deposited
        (:class:`optdot.quality.visibility.LuminanceGrid`), then divided by the pixel
        area. Comparing a deposit of dots with :meth:`resampled` instead mistakes the
        deposit's own smoothing for an error where the map is steep: the led sample's
        LED edge read +0.38 % too bright through a 1 mm blur on 0.25 mm pixels, where a
        0.025 mm grid finds +0.005 %."""
        fx = sparse_hats(x0, cw, nx, self.x0, self.cell_size[0], self.shape[1])
        fy = sparse_hats(y0, ch, ny, self.y0, self.cell_size[1], self.shape[0])
        return np.asarray(fy @ (fx @ self.grid.T).T) / (cw * ch)

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


def _linear_axis(g: np.ndarray, factor: int, axis: int) -> np.ndarray:
    """``g`` resampled along ``axis`` at the centres of ``factor`` sub-cells per cell,
    linearly between the cell centres and constant beyond the outermost ones."""
    n = g.shape[axis]
    t = np.clip((np.arange(n * factor) + 0.5) / factor - 0.5, 0.0, n - 1)
    i0 = np.minimum(np.floor(t).astype(np.int64), max(n - 2, 0))
    i1 = np.minimum(i0 + 1, n - 1)
    w = t - i0
    a, b = np.take(g, i0, axis=axis), np.take(g, i1, axis=axis)
    shape = [1, 1]
    shape[axis] = -1
    w = w.reshape(shape)
    return a * (1.0 - w) + b * w


def _spans(a: np.ndarray, b: np.ndarray, lo: float, step: float, n: int):
    """``(rows, cols)``: for each interval ``a[k]..b[k]`` (mm) the indices of the ``n``
    grid cells (width ``step`` from ``lo``) it touches, clamped to the grid, at least one
    each."""
    k0 = np.clip(np.floor((a - lo) / step).astype(np.int64), 0, n - 1)
    k1 = np.clip(np.ceil((b - lo) / step).astype(np.int64) - 1, 0, n - 1)
    k1 = np.maximum(k1, k0)
    count = k1 - k0 + 1
    rows = np.repeat(np.arange(len(a)), count)
    within = np.arange(count.sum()) - np.repeat(np.cumsum(count) - count, count)
    return rows, np.repeat(k0, count) + within


def sparse_overlap(edges: np.ndarray, lo: float, step: float, n: int):
    """:func:`axis_overlap` as a ``scipy.sparse`` CSR matrix ``[len(edges) - 1, n]``,
    storing only the overlaps that are there (~ len(edges) + n of them)."""
    from scipy.sparse import csr_matrix

    a, b = edges[:-1], edges[1:]
    rows, cols = _spans(a, b, lo, step, n)
    c0 = lo + cols * step
    val = np.clip(np.minimum(b[rows], c0 + step) - np.maximum(a[rows], c0), 0.0, None)
    return csr_matrix((val, (rows, cols)), shape=(len(a), n))


def _hat_integral(t: np.ndarray, w: float) -> np.ndarray:
    """Integral from -inf to ``t`` of the hat ``max(0, 1 - |u| / w)``."""
    t = np.clip(t, -w, w)
    return np.where(t <= 0, (t + w) ** 2 / (2 * w), w - (w - t) ** 2 / (2 * w))


def sparse_hats(p0: float, step: float, n: int, lo: float, cell: float, m: int):
    """``[n, m]`` CSR: the length (mm) of each of ``m`` map cells (width ``cell`` from
    ``lo``) weighted by the cloud-in-cell hat of each of ``n`` pixels (width ``step``
    from ``p0``, centres ``p0 + (j + 0.5) step``); the first and last hats stay at 1
    beyond their centres (a deposit gives what lies past them to the outermost pixels)."""
    from scipy.sparse import csr_matrix

    c = p0 + (np.arange(n) + 0.5) * step
    left = c - step
    right = c + step
    left[0] = lo
    right[-1] = lo + m * cell
    rows, cols = _spans(np.maximum(left, lo), np.minimum(right, lo + m * cell), lo, cell, m)
    a = lo + cols * cell
    b = a + cell
    cj = c[rows]
    val = _hat_integral(b - cj, step) - _hat_integral(a - cj, step)
    if n == 1:
        val = b - a
    else:
        first, last = rows == 0, rows == n - 1
        # the flat part past the outermost centres
        val[first] += np.clip(np.minimum(b[first], c[0]) - a[first], 0.0, None) - (
            _hat_integral(np.minimum(b[first], c[0]) - c[0], step)
            - _hat_integral(np.minimum(a[first], c[0]) - c[0], step)
        )
        val[last] += np.clip(b[last] - np.maximum(a[last], c[-1]), 0.0, None) - (
            _hat_integral(np.maximum(b[last], c[-1]) - c[-1], step)
            - _hat_integral(np.maximum(a[last], c[-1]) - c[-1], step)
        )
    return csr_matrix((val, (rows, cols)), shape=(n, m))
