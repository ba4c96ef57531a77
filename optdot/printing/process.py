"""The process that turns a mask into a print (``[process]``): its figures, and the maps
between the print's coordinates (the pattern's: what is designed and judged) and the
mask's (what a writer draws: mirrored, scaled up for the shrink, on the address grid).

A footprint ``K`` prints as its outer parallel body ``K ⊕ B(g)`` (``g`` the dot gain per
edge; negative, an etch that undercuts, its inner parallel body), so the mask draws the
print's parallel body at ``-g``: exact for every kind while ``g`` is at most the
footprint's smallest radius of curvature (:meth:`Kind.curvature_floor`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

#: Largest moulding shrink taken, as a share (resins shrink 0.2-0.8 %).
MAX_SHRINK = 0.1
#: The masks' database unit, mm (GDSII/OASIS 1 nm): the finest grid there is.
DATABASE_UNIT_MM = 1e-6
#: What ``mirror`` may be.
MIRRORS = ("none", "x", "y")


@dataclass(frozen=True)
class Process:
    """How a mask prints (every length in mm).

    Attributes:
        dot_gain: how far the print's edge lies outside the mask's, per edge (screen
            printing, inkjet: positive; an etch that undercuts: negative).
        gain_tolerance: the gain's spread (±), for the tolerance band.
        min_feature: the narrowest mask feature that prints: a mask dot's width, and the
            clear space between two mask dots.
        min_space: the narrowest clear gap between two printed dots.
        grid: the mask writer's address grid (0: the file's database unit, 1 nm).
        shrink: ``(sx, sy)`` the part's shrink as it cools, a share per axis: the mask
            is drawn scaled by ``1 / (1 - s)`` about the origin.
        mirror: ``"none"``, ``"x"`` (x mirrored: left and right swap, about the panel's
            centre line) or ``"y"`` (top and bottom swap): a film printed emulsion side
            down.
    """

    dot_gain: float = 0.0
    gain_tolerance: float = 0.0
    min_feature: float = 0.0
    min_space: float = 0.0
    grid: float = 0.0
    shrink: tuple[float, float] = (0.0, 0.0)
    mirror: str = "none"

    @property
    def scale(self) -> np.ndarray:
        """``[2]`` the mask's scale per axis, ``1 / (1 - shrink)``."""
        return 1.0 / (1.0 - np.asarray(self.shrink, float))

    @property
    def isotropic(self) -> bool:
        """Whether the mask is scaled alike along x and y."""
        return self.shrink[0] == self.shrink[1]

    @property
    def snap_margin(self) -> float:
        """How much nearer two printed footprints can come when their mask is put on the
        grid, mm: each footprint's centre and each vertex move by at most ``grid/√2``
        (mask units, at most as much printed), so a pair by ``2√2 grid``."""
        return 2.0 * math.sqrt(2.0) * self.grid

    def relaxation_gap(self, gap: float) -> float:
        """The edge gap the printed dots are relaxed to, mm: the job's ``gap``, at least
        ``min_space`` and the room a mask's clear space needs (``min_feature - 2 g``), with
        the grid's :attr:`snap_margin` on top (none without a grid)."""
        return max(gap, self.min_space, self.min_feature - 2.0 * self.dot_gain) + self.snap_margin

    def mask_size(self, kind, size: np.ndarray) -> np.ndarray | None:
        """``[n, k]`` the mask's footprint sizes (print units) for printed ``size`` where
        the kind draws its parallel body as one of its own, else None."""
        return kind.parallel(size, -self.dot_gain)

    def snap(self, v: np.ndarray) -> np.ndarray:
        """``v`` (mask mm) on the address grid, or without one on the files' 1 nm (a
        scaled centre off it would drift in an OASIS repetition's rounded offsets)."""
        step = self.grid if self.grid > 0 else DATABASE_UNIT_MM
        return np.round(np.asarray(v) / step) * step

    def place(self, xy: np.ndarray, box) -> np.ndarray:
        """``[n, 2]`` mask positions (mm, on the grid) of printed positions ``xy``:
        mirrored about the panel ``box``'s centre line, scaled about the origin."""
        return self.snap(self._mirrored(np.asarray(xy, float), box) * self.scale)

    def unplace(self, xy: np.ndarray, box) -> np.ndarray:
        """``[n, 2]`` printed positions (mm) of mask positions ``xy`` (:meth:`place`'s
        inverse, but for the grid); ``box`` is the printed panel's."""
        return self._mirrored(np.asarray(xy, float) / self.scale, box)

    def mask_box(self, box) -> tuple[float, float, float, float]:
        """The mask's bounding box of a printed panel ``box``."""
        corners = self.place(np.array([[box[0], box[1]], [box[2], box[3]]]), box)
        lo, hi = corners.min(axis=0), corners.max(axis=0)
        return (float(lo[0]), float(lo[1]), float(hi[0]), float(hi[1]))

    def turn(self, angle: np.ndarray) -> np.ndarray:
        """Footprint angles (rad) on the mask: a mirror turns them the other way (every
        kind is symmetric about its own axes)."""
        return -angle if self.mirror != "none" else angle

    def _mirrored(self, xy: np.ndarray, box) -> np.ndarray:
        if self.mirror == "none":
            return xy
        out = xy.copy()
        axis = 0 if self.mirror == "x" else 1
        out[:, axis] = (box[axis] + box[axis + 2]) - xy[:, axis]
        return out

    @property
    def reflects(self) -> bool:
        """Whether the mask is the print mirrored (its rings run the other way round)."""
        return self.mirror != "none"

    def gain_ends(self) -> tuple[float, float, float]:
        """The offsets of the tolerance band from the nominal print, mm: ``(-tol, 0,
        +tol)``."""
        t = self.gain_tolerance
        return (-t, 0.0, t)

    def steiner_area(self, kind, size: np.ndarray, g: float) -> np.ndarray:
        """``[n]`` the area of footprints (``size [n, k]`` mm) grown by ``g`` mm (Steiner:
        ``A + P g + π g²``; shrunk, exact while ``-g`` is within their curvature)."""
        return kind.area(size) + kind.perimeter(size) * g + math.pi * g * g


def grown_sizes(kind, size: np.ndarray, delta: float) -> np.ndarray:
    """``[n, k]`` footprints of ``size`` (``[n, k]`` mm) grown by ``delta`` mm: exact where
    the kind's parallel body is one of its own (circles, rounded rectangles); otherwise
    (an ellipse) the footprint whose two lengths grow alike by ``2 u``, ``u`` chosen so
    that its area is the parallel body's (Steiner's ``A + P δ + π δ²``) exactly: the
    shape within ``u - δ`` (a few percent of δ) of it everywhere."""
    out = kind.parallel(size, delta)
    if out is not None:
        return out
    out = np.array(size, float, copy=True)
    a, b = 0.5 * out[:, 0], 0.5 * out[:, 1]
    target = (kind.area(out) + kind.perimeter(out) * delta) / np.pi + delta * delta
    u = 0.5 * (-(a + b) + np.sqrt((a + b) ** 2 - 4.0 * (a * b - target)))
    out[:, :2] += 2.0 * u[:, None]
    return out
