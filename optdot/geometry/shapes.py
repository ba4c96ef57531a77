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
- :meth:`Footprints.contains`: whether points lie on given dots (the tracer);
- :meth:`Footprints.outline`: a polygon of one dot within a tolerance (masks, previews,
  the independent shapely checks).

The pattern, its files and datasets, the relaxation, the guarantee pass, QA, the
exporters, the read-back and the tracer ask these questions here rather than of a
diameter; a new kind is one :class:`Kind` in :data:`KINDS`.
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np


class Kind:
    """One kind of footprint: how its size parameters make a shape. Methods take
    ``size [n, k]`` (mm, :attr:`params` in order) and ``angle [n]`` (rad) arrays."""

    #: The kind's name, as a job's ``[dots] shape`` and a file's ``shape`` field say it.
    name: str = ""
    #: Its size parameters, in the order of ``size``'s columns.
    params: tuple[str, ...] = ()
    #: Whether the footprint is the same at every angle (then ``angle`` is ignored).
    round: bool = False

    def area(self, size: np.ndarray) -> np.ndarray:
        """``[n]`` areas, mm²."""
        raise NotImplementedError

    def extent(self, size: np.ndarray) -> np.ndarray:
        """``[n]`` bounding radii about the centre, mm."""
        raise NotImplementedError

    def gap(
        self,
        d: np.ndarray,
        size_i: np.ndarray,
        angle_i: np.ndarray,
        size_j: np.ndarray,
        angle_j: np.ndarray,
    ) -> np.ndarray:
        """``[m]`` edge-to-edge distances of pairs whose centres differ by ``d`` (``[m,
        2]`` mm, j minus i), mm; negative: the footprints overlap."""
        raise NotImplementedError

    def contains(self, p: np.ndarray, size: np.ndarray, angle: np.ndarray) -> np.ndarray:
        """``[m]`` whether the points ``p`` (``[m, 2]`` mm, relative to each dot's
        centre) lie on the dots (closed: the edge counts)."""
        raise NotImplementedError

    def outline(self, size: np.ndarray, angle: float, tolerance: float) -> np.ndarray:
        """``[v, 2]`` vertices (counter-clockwise, mm, about the centre) of a polygon
        within ``tolerance`` mm of one footprint of ``size`` (``[k]``) at ``angle``."""
        raise NotImplementedError

    def fit(self, points: np.ndarray, slack: float, share: float = 0.0) -> Fit:
        """The footprint a polygon's vertices (``[v, 2]``, any unit) draw: what a mask
        reader recognises a dot by. A vertex may stray from the fitted outline by
        ``slack`` (same unit: the file's grid) plus ``share`` of the footprint's size."""
        raise NotImplementedError


class Circle(Kind):
    """A disc of ``diameter`` mm."""

    name = "circle"
    params = ("diameter",)
    round = True

    def area(self, size: np.ndarray) -> np.ndarray:
        return np.pi * 0.25 * size[:, 0] ** 2

    def extent(self, size: np.ndarray) -> np.ndarray:
        return 0.5 * size[:, 0]

    def gap(self, d, size_i, angle_i, size_j, angle_j) -> np.ndarray:
        return np.hypot(d[:, 0], d[:, 1]) - 0.5 * (size_i[:, 0] + size_j[:, 0])

    def contains(self, p, size, angle) -> np.ndarray:
        r = 0.5 * size[:, 0]
        return p[:, 0] * p[:, 0] + p[:, 1] * p[:, 1] <= r * r

    def outline(self, size, angle, tolerance) -> np.ndarray:
        r = 0.5 * float(size[0])
        n = polygon_vertices(r, tolerance)
        t = 2.0 * np.pi * np.arange(n) / n
        return r * np.column_stack([np.cos(t), np.sin(t)])

    def fit(self, points: np.ndarray, slack: float, share: float = 0.0) -> Fit:
        """Centre: the vertices' mean; diameter: twice their mean distance from it (a
        polygon inscribed in the circle, snapped to a grid, recovers it to well under
        the grid step); a fit when the vertex radii spread by at most ``slack + share
        r`` and there are :data:`MIN_VERTICES` or more."""
        c = points.mean(axis=0)
        rad = np.hypot(*(points - c).T)
        r = float(rad.mean())
        spread = float(rad.max() - rad.min())
        ok = len(points) >= MIN_VERTICES and spread <= slack + share * r
        return Fit(ok, c, np.array([2.0 * r]), 0.0, (float(rad.min()), float(rad.max())))


@dataclass(frozen=True)
class Fit:
    """A footprint recognised from a polygon (:meth:`Kind.fit`).

    Attributes:
        ok: whether the polygon is this kind. centre: ``[2]`` its centre. size: ``[k]``
        its size parameters. angle: its orientation, rad. radii: the smallest and
        largest distance of a vertex from the centre (for messages). All in the
        polygon's unit.
    """

    ok: bool
    centre: np.ndarray
    size: np.ndarray
    angle: float
    radii: tuple[float, float]


#: Fewest vertices a polygon needs to be read as a round dot (an octagon).
MIN_VERTICES = 8


def polygon_vertices(radius: float, tolerance: float) -> int:
    """Vertices of a regular polygon inscribed in a circle of ``radius`` that stays within
    ``tolerance`` of it (same unit), at least 8."""
    t = min(tolerance, radius)
    return max(MIN_VERTICES, math.ceil(math.pi / math.acos(1.0 - t / radius)))


#: Every kind, by name.
KINDS: dict[str, Kind] = {k.name: k for k in (Circle(),)}
#: The circle, the kind of every pattern that does not name one.
CIRCLE = KINDS["circle"]


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
        return self.size[:, 0] if self.kind is CIRCLE else 2.0 * self.extent()

    def area(self) -> np.ndarray:
        """``[n]`` areas, mm²."""
        return self.kind.area(self.size)

    def extent(self) -> np.ndarray:
        """``[n]`` bounding radii, mm."""
        return self.kind.extent(self.size)

    @classmethod
    def concat(cls, parts: list[Footprints], kind: Kind = CIRCLE) -> Footprints:
        """The footprints of ``parts`` one after the other (all of one kind; ``kind``
        when there are none)."""
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
        a = self.angles
        return self.kind.gap(xy[j] - xy[i], self.size[i], a[i], self.size[j], a[j])

    def contains(self, points: np.ndarray, k: np.ndarray, xy: np.ndarray) -> np.ndarray:
        """``[m]`` whether ``points`` (``[m, 2]`` mm) lie on the dots ``k`` (``[m]``)
        centred at ``xy`` (``[n, 2]`` mm)."""
        return self.kind.contains(points - xy[k], self.size[k], self.angles[k])

    def outline(self, k: int, tolerance: float) -> np.ndarray:
        """``[v, 2]`` polygon of dot ``k`` about its centre, within ``tolerance`` mm."""
        return self.kind.outline(self.size[k], float(self.angles[k]), tolerance)


__all__ = [
    "CIRCLE",
    "KINDS",
    "MIN_VERTICES",
    "Circle",
    "Fit",
    "Footprints",
    "Kind",
    "polygon_vertices",
]
