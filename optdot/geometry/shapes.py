"""A dot's footprint: what every stage asks of a dot's shape, answered in one place.

A footprint is a *kind* (:class:`Kind`: the circle today), its size parameters (the
circle's diameter, mm) and an orientation (the angle of its long axis, rad, from +x,
counter-clockwise; a circle has none). :class:`Footprints` holds the footprints of many
dots of one kind (``size [n, k]``, ``angle [n]``) and answers, vectorised:

- :meth:`Footprints.area`: each dot's area, mm² (coverage, counts, the size fit);
- :meth:`Footprints.extent`: the radius of the smallest disc about the centre that holds
  the footprint, mm (cell grids, halos, how far a dot may reach past a wall);
- :meth:`Footprints.gap`: the edge-to-edge distance of pairs, mm, negative when they
  overlap (collisions, close pairs, the guarantee);
- :meth:`Footprints.contains`: whether points lie on given dots (as the tracer asks);
- :meth:`Footprints.outline`: a polygon of one dot within a tolerance (masks, previews,
  the independent shapely checks).

The pattern, its files and datasets, the relaxation, the guarantee pass, QA, the
exporters, the read-back and the tracer ask these questions here rather than of a
diameter. Each kind is one module of :mod:`optdot.geometry.kinds`, its registry.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np

from .kinds import (
    CIRCLE,
    KINDS,
    MIN_VERTICES,
    Fit,
    Kind,
    contains_packed,
    half_width_packed,
    on_packed,
    packed,
    polygon_vertices,
)

#: Pairs per block of the vectorised gap search (bounds its memory).
GAP_BLOCK = 1 << 14


@dataclass(frozen=True)
class DotShape:
    """A job's dot: one kind at one size (``[dots] shape`` and its sizes).

    Attributes:
        kind: the :class:`Kind`.
        size: its size parameters, mm (``kind.params`` in order).
    """

    kind: Kind
    size: tuple[float, ...]

    @property
    def area(self) -> float:
        """The footprint's area, mm²."""
        return float(self.kind.area(np.array([self.size]))[0])

    @property
    def extent(self) -> float:
        """The radius of its bounding disc, mm."""
        return float(self.kind.extent(np.array([self.size]))[0])

    @property
    def inner_radius(self) -> float:
        """The radius of the largest disc about its centre inside it (half the width),
        mm: two footprints whose centres are nearer than twice it (plus the gap) are
        too close at any angles."""
        return float(self.kind.inradius(np.array([self.size]))[0])

    @property
    def equivalent_diameter(self) -> float:
        """The diameter of the disc of the same area, mm: what sets the spacing and the
        count (one footprint per ``area / fill``)."""
        return float(self.kind.equivalent_diameter(np.array([self.size]))[0])

    def scale_of(self, diameters: np.ndarray) -> np.ndarray:
        """``[n]`` factors dots of area-equivalent ``diameters`` (``[n]`` mm) are this
        footprint (``dots.length``, ``width``, ...) scaled by, to 1e-4 (the size rule's
        diameters are rounded to 1 nm: unrounded, a dot at ``dots.scale``'s low end of 1
        would be 80.001 µm long, not the 80 µm asked for; 1e-4 of a scale is nm on a
        footprint, far under the rule's 0.5 µm steps)."""
        return np.round(np.asarray(diameters, np.float64) / self.equivalent_diameter, 4)

    def footprints(self, angle: np.ndarray, scale: np.ndarray | None = None) -> Footprints:
        """The footprints of ``len(angle)`` dots at ``angle`` (``[n]`` rad), each this
        footprint scaled by ``scale`` (``[n]``; sizes rounded to 1 nm, as files hold
        them), or all of this size."""
        n = len(angle)
        if scale is not None:
            size = self.kind.drawable(np.round(np.outer(scale, self.size), 6))
            return Footprints(self.kind, size, angle)
        return Footprints(self.kind, np.tile(np.asarray(self.size, float), (n, 1)), angle)


@dataclass(frozen=True, eq=False)
class Footprints:
    """The footprints of ``n`` dots of one kind.

    Attributes:
        kind: the :class:`Kind`.
        size: ``[n, k]`` float64 size parameters, mm (``kind.params`` in order).
        angle: ``[n]`` float64 orientations, rad, or None (every dot at 0; round kinds).
    """

    kind: Kind
    size: np.ndarray
    angle: np.ndarray | None = None

    @classmethod
    def circles(cls, diameter: np.ndarray | float, n: int | None = None) -> Footprints:
        """Discs of ``diameter`` (``[n]`` mm, or one number for ``n`` dots)."""
        d = np.asarray(diameter, dtype=np.float64)
        if d.ndim == 0:
            d = np.broadcast_to(d, (1 if n is None else n,))
        return cls(CIRCLE, d.reshape(-1, 1))

    @property
    def n(self) -> int:
        """Number of dots."""
        return int(self.size.shape[0])

    @property
    def angles(self) -> np.ndarray:
        """``[n]`` orientations, rad (zeros when none are stored)."""
        return np.zeros(self.n) if self.angle is None else self.angle

    @property
    def diameter(self) -> np.ndarray:
        """``[n]`` diameters of circles, mm (the width of the bounding disc otherwise)."""
        return 2.0 * self.extent()

    def area(self) -> np.ndarray:
        """``[n]`` areas, mm²."""
        return self.kind.area(self.size)

    def extent(self) -> np.ndarray:
        """``[n]`` bounding radii, mm."""
        return self.kind.extent(self.size)

    def equivalent_diameter(self) -> np.ndarray:
        """``[n]`` diameters of the discs of the same areas, mm (a disc's own)."""
        return self.kind.equivalent_diameter(self.size)

    @classmethod
    def concat(cls, parts: list[Footprints], kind: Kind = CIRCLE) -> Footprints:
        """The footprints of ``parts`` one after the other (all of one kind; ``kind``
        when there are none)."""
        parts = [p for p in parts if p.n]  # an empty part may be of any kind
        if not parts:
            return cls(kind, np.zeros((0, len(kind.params))))
        angle = None
        if any(p.angle is not None for p in parts):
            angle = np.concatenate([p.angles for p in parts])
        return cls(parts[0].kind, np.concatenate([p.size for p in parts]), angle)

    def groups(self, per_mm: float) -> Iterator[tuple[tuple[int, ...], np.ndarray]]:
        """The dots grouped by size, each parameter rounded to a whole number of units of
        ``1 / per_mm`` mm (a mask's database unit: 1e6 for nm): ``(key, index [m])`` per
        distinct size, keys (the sizes in those units) ascending, each group's indices
        ascending. One sort, whatever the number of sizes."""
        keys = np.round(self.size * per_mm).astype(np.int64)
        if keys.shape[1] == 1:
            uniq, inverse = np.unique(keys[:, 0], return_inverse=True)
            uniq = uniq[:, None]
        else:
            uniq, inverse = np.unique(keys, axis=0, return_inverse=True)
        order = np.argsort(inverse.ravel(), kind="stable")
        bounds = np.searchsorted(inverse.ravel()[order], np.arange(len(uniq) + 1))
        for g, key in enumerate(uniq):
            yield tuple(int(v) for v in key), order[bounds[g] : bounds[g + 1]]

    def take(self, index) -> Footprints:
        """The footprints of the dots ``index`` (an index array or a boolean mask)."""
        return Footprints(
            self.kind, self.size[index], None if self.angle is None else self.angle[index]
        )

    def gap(self, xy: np.ndarray, i: np.ndarray, j: np.ndarray) -> np.ndarray:
        """``[m]`` edge-to-edge distances of the pairs ``(i[m], j[m])`` of dots centred at
        ``xy`` (``[n, 2]`` mm), mm; negative where they overlap."""
        return self.separation(xy, i, j)[0]

    def separation(
        self, xy: np.ndarray, i: np.ndarray, j: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """``(gap [m] mm, u [m, 2])``: :meth:`gap` of the pairs and the unit direction
        (from i toward j) moving them apart widens it fastest (:meth:`Kind.separation`)."""
        a = self.angles
        gap, u = np.empty(len(i)), np.empty((len(i), 2))
        for s in range(0, len(i), GAP_BLOCK):  # bounded memory for the search
            ii, jj = i[s : s + GAP_BLOCK], j[s : s + GAP_BLOCK]
            got = self.kind.separation(xy[jj] - xy[ii], self.size[ii], a[ii], self.size[jj], a[jj])
            gap[s : s + len(ii)], u[s : s + len(ii)] = got
        return gap, u

    def contains(self, points: np.ndarray, k: np.ndarray, xy: np.ndarray) -> np.ndarray:
        """``[m]`` whether ``points`` (``[m, 2]`` mm) lie on the dots ``k`` (``[m]``)
        centred at ``xy`` (``[n, 2]`` mm)."""
        f = packed(self.kind, self.size[k], self.angles[k])
        return contains_packed(f, np.ascontiguousarray(points - xy[k], dtype=np.float64))

    def outline(self, k: int, tolerance: float) -> np.ndarray:
        """``[v, 2]`` polygon of dot ``k`` about its centre, within ``tolerance`` mm."""
        return self.kind.outline(self.size[k], float(self.angles[k]), tolerance)


__all__ = [
    "CIRCLE",
    "GAP_BLOCK",
    "KINDS",
    "MIN_VERTICES",
    "DotShape",
    "Fit",
    "Footprints",
    "Kind",
    "half_width_packed",
    "on_packed",
    "packed",
    "polygon_vertices",
]
