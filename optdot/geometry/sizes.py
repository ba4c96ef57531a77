"""Dot-size modulation: the diameter each dot of a map gets.

Why sizes vary
--------------
A mould or screen holds an *absolute* gap g between dot edges (14 µm is the industry's
60 µm centre rule for 46 µm dots), so the area a dot claims together with half that gap
is ``rho (1 + g/d)^2`` of the panel: 1.70 rho for 46 µm dots, 1.25 rho for 120 µm dots.
Hard disks are forced into hexagonal order above a packing of ~0.70 (Bernard & Krauth
2011), so a fill whose claim exceeds that cannot be both irregular and free of close
pairs. Larger dots where the fill is high keep the claim down; smaller dots where it is
low keep the texture fine (46 µm dots at 3 % fill sit 0.24 mm apart and show through a
weak diffuser). Industry varies the radius (Chang & Fang 2007), Speos textures take
per-element scales, screen-printed guides vary the diameter on a fixed pitch.

The rules (``[dots] diameter = [lo, hi]``)
------------------------------------------
Each density cell k (fill rho_k) gets one diameter D_k, quantised to ``step`` and kept
in ``[lo, hi]``; the dots of the cell are ``rho_k A_k / (pi D_k^2 / 4)`` of that size, so
every cell's dot area equals its fill exactly, whatever the diameter (the count is the
free variable, the coverage is not).

* ``spacing = s`` (hybrid pitch rule): the diameter that puts the dots on a hexagonal
  pitch s at this fill, ``D = s sqrt(2 sqrt3 rho / pi)``, clipped to the range. Inside
  the range the local mean spacing stays s and the size carries the gradient (as on a
  screen-printed guide); where the clip bites, the count carries it.
* no ``spacing`` (claim rule, the default): the smallest diameter whose claim
  ``rho (1 + g/D)^2`` stays at or below :data:`CLAIM_TARGET` (0.60, a margin under the
  ~0.70 where disks order), ``D = g / (sqrt(0.60 / rho) - 1)``, clipped to the range:
  small dots (a fine texture) wherever the fill allows it, larger ones only where the
  gap demands it. g is the job's close gap (``qa.close_gap``, default 14 µm).
* ``diameter_grid = "d.csv"``: an explicit diameter map (mm; CSV or ``.npy``, row 0 at
  the bottom, cells splitting the panel's box evenly like the density grid, any shape),
  read at each density cell's centre; values must lie in the range.

Dots take their cell's diameter. With ``[density] interpolation = "linear"`` the map's
cells are fine sub-cells of a smooth field (:meth:`DensityMap.interpolated`), so the
diameters follow the fill smoothly instead of stepping at the map's cell borders.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .density import DensityMap

#: Highest claim ``rho (1 + g/D)^2`` the default rule allows (hard disks order above ~0.70).
CLAIM_TARGET = 0.60
#: Default quantisation of diameters, mm (0.5 µm; masks get one cell per size).
DEFAULT_STEP = 0.0005


@dataclass(frozen=True, eq=False)
class DotSizes:
    """How a job's dot diameters vary (see the module docstring).

    Attributes:
        low, high: the diameter range, mm (``low < high``).
        step: quantisation of diameters, mm (> 0).
        spacing: the hybrid rule's hexagonal pitch, mm, or None.
        gap: the edge gap the claim rule keeps in mind, mm (``qa.close_gap``).
        grid: ``[my, mx]`` explicit diameters, mm, over the map's box (row 0 at the
            bottom), or None.
        levels: the only diameters dots may take, mm, ascending from ``low`` to ``high``
            (a laser's sizes), or None (every step of the range).
    """

    low: float
    high: float
    step: float = DEFAULT_STEP
    spacing: float | None = None
    gap: float = 0.014
    grid: np.ndarray | None = None
    levels: tuple[float, ...] | None = None

    @property
    def rule(self) -> str:
        """``"grid"``, ``"spacing"`` or ``"claim"``."""
        if self.grid is not None:
            return "grid"
        return "spacing" if self.spacing is not None else "claim"

    def raw(self, rho: np.ndarray) -> np.ndarray:
        """Unclipped, unquantised diameter of the rule at fill ``rho`` (``[...]``), mm."""
        rho = np.asarray(rho, dtype=np.float64)
        with np.errstate(divide="ignore", invalid="ignore"):
            if self.spacing is not None:
                return self.spacing * np.sqrt(2.0 * math.sqrt(3.0) * rho / math.pi)
            room = np.sqrt(CLAIM_TARGET / rho) - 1.0
            return np.where(room > 0, self.gap / room, np.inf)

    def quantise(self, d: np.ndarray) -> np.ndarray:
        """``d`` (mm) rounded to the step (with :attr:`levels`, the nearest level) and
        kept in the range, to 1 nm."""
        if self.levels is not None:
            lv = np.asarray(self.levels)
            d = np.asarray(d, np.float64)
            near = np.argmin(np.abs(d[..., None] - lv), axis=-1)
            return np.round(lv[near], 6)
        q = np.round(np.clip(d, self.low, self.high) / self.step) * self.step
        q = np.clip(q, self.low, self.high)
        return np.round(q, 6)

    def cell_diameters(self, density: DensityMap) -> np.ndarray:
        """``[ny, nx]`` diameter of each density cell's dots, mm (cells of zero fill get
        ``low``; they hold no dots)."""
        if self.grid is not None:
            d = self.quantise(
                np.where(density.grid > 0, _sample_at_centres(self.grid, density), self.low)
            )
        else:
            d = self.at_fill(density.grid)
        d.setflags(write=False)
        return d

    def at_fill(self, rho: np.ndarray) -> np.ndarray:
        """``[...]`` the diameter the fill rule gives dots at fill ``rho`` (``[...]``),
        quantised, mm (``low`` where the fill is 0: no dots there)."""
        return self.quantise(np.where(rho > 0, self.raw(rho), self.low))


def _sample_at_centres(grid: np.ndarray, density: DensityMap) -> np.ndarray:
    """``grid`` (``[my, mx]`` over the map's box) at the centres of the map's cells."""
    ny, nx = density.shape
    my, mx = grid.shape
    ix = np.minimum(((np.arange(nx) + 0.5) * mx / nx).astype(np.int64), mx - 1)
    iy = np.minimum(((np.arange(ny) + 0.5) * my / ny).astype(np.int64), my - 1)
    return grid[np.ix_(iy, ix)]


def dots_per_cell(density: DensityMap, diameters: np.ndarray, weights=None) -> np.ndarray:
    """``[ny, nx]`` expected dot count of each cell: fill x area (x ``weights``, the share
    inside the domain) over one dot's area at the cell's diameter (``[ny, nx]`` mm)."""
    dx, dy = density.cell_size
    g = density.grid if weights is None else density.grid * weights
    return g * (dx * dy) / (math.pi * 0.25 * diameters * diameters)
