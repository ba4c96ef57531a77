"""How a panel is cut into tiles, and how many dots each tile gets.

A :class:`TilePlan` is a pure function of the job and the tile size: every worker can
compute it, and two runs with the same job and tile size compute the same plan, bit for
bit. The dot quotas are the map's integral over each tile, apportioned to the job's dot
count by largest remainders (ties to the lower tile index), so the tiles together hold
exactly ``job.n_dots``, the count the single-process path makes.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ...config.job import Job
from ...errors import JobError
from ...geometry.density import axis_overlap
from ...relax.circles import hex_radius
from ..job_settings import containers

#: Dots per tile that minimise the time per dot on this kind of machine (2 cores, L2 of
#: 1-2 MB per core): measured by ``benchmarks/panels.py --sweep`` (BENCHMARKS.md).
DEFAULT_TILE_DOTS = 150_000
#: Phase-2 band half-width and frozen shell, in units of the largest hexagonal spacing.
BAND_SPACINGS = 6.0
HALO_SPACINGS = 2.0
#: Margin of the long-wavelength correction's windows beyond their tile-sized core, in
#: hexagonal spacings at the lowest fill (at most half a tile less the halo and the
#: correction's pad of 4 spacings, so a tile's neighbours hold every dot it reads).
MARGIN_SPACINGS = 10


@dataclass(frozen=True)
class TilePlan:
    """A grid of ``nx * ny`` equal tiles over the panel box.

    Attributes:
        xs: ``[nx + 1]`` tile edges along x, mm (``xs[0]``, ``xs[-1]`` = the box).
        ys: ``[ny + 1]`` tile edges along y, mm.
        quotas: ``[ny, nx]`` int64 dots of each tile (row j = tiles at ``ys[j]..ys[j+1]``).
        band: half-width of the strip along each inner tile border that phase 2 relaxes
            again, mm.
        halo: width of the frozen dots kept around what a task moves, mm.
        margin: how far beyond its tile the long-wavelength correction of a tile reads
            its neighbours' dots, mm (:func:`optdot.orchestration.tiling.tasks.correct_tile`).
    """

    xs: np.ndarray
    ys: np.ndarray
    quotas: np.ndarray
    band: float
    halo: float
    margin: float = 0.0

    @property
    def nx(self) -> int:
        return len(self.xs) - 1

    @property
    def ny(self) -> int:
        return len(self.ys) - 1

    @property
    def count(self) -> int:
        """Number of tiles."""
        return self.nx * self.ny

    @property
    def size(self) -> tuple[float, float]:
        """``(width, height)`` of one tile, mm."""
        return float(self.xs[1] - self.xs[0]), float(self.ys[1] - self.ys[0])

    def tiles(self) -> list[tuple[int, int]]:
        """Every tile ``(i, j)``, row by row (the order of the dataset's parts)."""
        return [(i, j) for j in range(self.ny) for i in range(self.nx)]

    def index(self, i: int, j: int) -> int:
        """Flat index of tile ``(i, j)``: ``j * nx + i``."""
        return j * self.nx + i

    def rect(self, i: int, j: int) -> tuple[float, float, float, float]:
        """``(x0, y0, x1, y1)`` of tile ``(i, j)``, mm."""
        return float(self.xs[i]), float(self.ys[j]), float(self.xs[i + 1]), float(self.ys[j + 1])

    def neighbours(self, i: int, j: int) -> list[tuple[int, int]]:
        """The up to 8 tiles around ``(i, j)``."""
        return [
            (a, b)
            for b in (j - 1, j, j + 1)
            for a in (i - 1, i, i + 1)
            if (a, b) != (i, j) and 0 <= a < self.nx and 0 <= b < self.ny
        ]

    def colour(self, i: int, j: int) -> int:
        """Checkerboard colour 0..3: tiles of one colour never touch, not even at a corner."""
        return (i % 2) + 2 * (j % 2)

    def corners(self) -> list[tuple[int, int]]:
        """Grid points ``(i, j)`` (0..nx, 0..ny) whose shifted square holds a seam band."""
        return [
            (i, j)
            for j in range(self.ny + 1)
            for i in range(self.nx + 1)
            if (0 < i < self.nx) or (0 < j < self.ny)
        ]

    def corner_tiles(self, i: int, j: int) -> list[tuple[int, int]]:
        """The up to 4 tiles meeting at grid point ``(i, j)``."""
        return [
            (a, b) for b in (j - 1, j) for a in (i - 1, i) if 0 <= a < self.nx and 0 <= b < self.ny
        ]

    def square_of(self, xy: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``([n], [n])`` grid point whose shifted square (the tiling moved by half a tile)
        holds each position; the squares partition the plane."""
        mx = 0.5 * (self.xs[:-1] + self.xs[1:])
        my = 0.5 * (self.ys[:-1] + self.ys[1:])
        return np.searchsorted(mx, xy[:, 0], "right"), np.searchsorted(my, xy[:, 1], "right")

    def in_band(self, xy: np.ndarray, i: int, j: int, width: float) -> np.ndarray:
        """``[n]`` bool: within ``width`` of an inner tile border through grid point
        ``(i, j)``."""
        near = np.zeros(len(xy), bool)
        if 0 < i < self.nx:
            near |= np.abs(xy[:, 0] - self.xs[i]) < width
        if 0 < j < self.ny:
            near |= np.abs(xy[:, 1] - self.ys[j]) < width
        return near

    def to_json(self) -> dict:
        return {
            "nx": self.nx,
            "ny": self.ny,
            "xs": [float(v) for v in self.xs],
            "ys": [float(v) for v in self.ys],
            "band_mm": self.band,
            "halo_mm": self.halo,
        }


def max_spacing(job: Job) -> float:
    """Largest hexagonal spacing of the map's non-zero cells, mm (2 r' at the lowest
    container fill, :class:`~optdot.relax.formulation.Containers`; when sizes vary, of
    each cell's fill at its own diameter)."""
    g = containers(job).grid()
    if not (g > 0).any():
        return float(2.0 * hex_radius(np.array([1.0]), 0.5 * job.diameter)[0])
    d = job.cell_diameters
    r0 = 0.5 * (job.diameter if d is None else d[g > 0])
    return float(2.0 * np.max(hex_radius(g[g > 0], r0)))


def tile_side(job: Job, tile_dots: int) -> float:
    """Side of a square tile holding about ``tile_dots`` dots at the map's mean fill, mm."""
    area = job.width * job.height
    return math.sqrt(area * tile_dots / max(job.n_dots, 1))


def plan_tiles(job: Job, side: float | None = None, tile_dots: int = DEFAULT_TILE_DOTS) -> TilePlan:
    """The tiling of ``job``: square-ish tiles of ``side`` mm (default: about
    ``tile_dots`` dots each), as many as fit evenly along each axis.

    Raises:
        JobError: tiles too small for the seam bands (a tile must be wider than twice
            the band plus halo, or a seam strip would reach the next one).
    """
    x0, y0, x1, y1 = job.box
    spacing = max_spacing(job)
    band = BAND_SPACINGS * spacing
    halo = HALO_SPACINGS * spacing
    side = tile_side(job, tile_dots) if side is None else float(side)
    nx = max(1, round((x1 - x0) / side))
    ny = max(1, round((y1 - y0) / side))
    xs = np.linspace(x0, x1, nx + 1)
    ys = np.linspace(y0, y1, ny + 1)
    need = 2.0 * (band + halo)
    smallest = min(xs[1] - xs[0], ys[1] - ys[0])
    if (nx > 1 or ny > 1) and smallest < need:
        raise JobError(
            f"tiles of {smallest:.3g} mm are too small: the seam bands need at least "
            f"{need:.3g} mm ({2 * (BAND_SPACINGS + HALO_SPACINGS):g} hexagonal spacings of "
            f"{spacing * 1e3:.4g} µm); use larger tiles"
        )
    margin = max(0.0, min(MARGIN_SPACINGS * spacing, 0.5 * smallest - halo - 4.0 * spacing))
    return TilePlan(
        xs=xs, ys=ys, quotas=tile_quotas(job, xs, ys), band=band, halo=halo, margin=margin
    )


def tile_integrals(job: Job, xs: np.ndarray, ys: np.ndarray) -> np.ndarray:
    """``[ny, nx]`` integral of the fill fraction over each tile (inside the outline), mm²;
    when sizes vary, weighted by the dart weights (in proportion to the dot count)."""
    d = job.density
    g = d.grid if job.cell_weights is None else d.grid * job.cell_weights
    if job.dart_weights is not None:
        g = g * job.dart_weights
    cw, ch = d.cell_size
    fx = axis_overlap(xs, d.x0, cw, d.shape[1])  # [nx_t, nx_c]
    fy = axis_overlap(ys, d.y0, ch, d.shape[0])  # [ny_t, ny_c]
    return fy @ g @ fx.T


def tile_quotas(job: Job, xs: np.ndarray, ys: np.ndarray) -> np.ndarray:
    """``[ny, nx]`` int64 dots per tile summing to ``job.n_dots`` (largest remainders)."""
    n = job.n_dots
    w = tile_integrals(job, xs, ys).ravel()
    total = float(w.sum())
    if total <= 0:
        raise JobError("the map is zero over the whole panel")
    exact = n * w / total
    q = np.floor(exact).astype(np.int64)
    short = n - int(q.sum())
    if short > 0:
        order = np.lexsort((np.arange(len(w)), -(exact - q)))
        q[order[:short]] += 1
    return q.reshape(len(ys) - 1, len(xs) - 1)
