"""Outline curves kept exact until the region side is known, then flattened on the safe side.

A CAD outline is a chain of *segments*: straight lines, conic arcs (circles, arcs, bulges
and ellipses, all the affine image of a circle arc) and sampled splines. A polygon made
from them must lie inside the region the user drew, so that a dot keeping ``r0`` from the
polygon keeps ``r0`` from the true curve. For a conic arc whose region side is
its concave side (the region holds the centre: a rounded outer corner, a round panel) the
flattening is *inscribed*: vertices on the curve, chords inside. Where the region is on the
convex side (a round hole, a concave fillet) it is *circumscribed*: tangent lines, whose
polygon contains the curve. Either way the polygon stays within ``tol`` of the curve.
Splines (whose flattening ezdxf does not bound exactly) are handled by the caller, which
removes a band of ``2 tol`` around them.

Coordinates are mm. A conic arc is ``C + cos(t) M + sin(t) m`` for ``t`` from ``t0`` to
``t1`` (``t1 < t0`` runs backwards).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..errors import GeometryError

#: Most vertices one flattened curve may take.
MAX_VERTICES = 1_000_000


@dataclass(frozen=True)
class Line:
    """A straight segment from ``p`` to ``q`` (``[2]`` each, mm)."""

    p: np.ndarray
    q: np.ndarray

    @property
    def start(self) -> np.ndarray:
        return self.p

    @property
    def end(self) -> np.ndarray:
        return self.q

    def reversed(self) -> Line:
        return Line(self.q, self.p)

    def points(self, tol: float, region_left: bool) -> np.ndarray:
        """``[2, 2]`` its end points."""
        return np.array([self.p, self.q], dtype=np.float64)


@dataclass(frozen=True)
class Conic:
    """An arc of the ellipse ``C + cos(t) M + sin(t) m`` (a circle when ``M ⊥ m``, equal).

    Attributes:
        c, M, m: centre and the two conjugate semi-axis vectors, ``[2]`` mm.
        t0, t1: parameter at the start and end, radians.
        p, q: the exact end points (``[2]``, mm) when given by the drawing (bulges),
            else computed from ``t0`` and ``t1``.
    """

    c: np.ndarray
    M: np.ndarray
    m: np.ndarray
    t0: float
    t1: float
    p: np.ndarray | None = None
    q: np.ndarray | None = None

    def at(self, t: np.ndarray) -> np.ndarray:
        """``[k, 2]`` points of the curve at parameters ``t`` ``[k]``."""
        t = np.asarray(t, dtype=np.float64)[:, None]
        return self.c + np.cos(t) * self.M + np.sin(t) * self.m

    @property
    def start(self) -> np.ndarray:
        return self.p if self.p is not None else self.at([self.t0])[0]

    @property
    def end(self) -> np.ndarray:
        return self.q if self.q is not None else self.at([self.t1])[0]

    def reversed(self) -> Conic:
        return Conic(self.c, self.M, self.m, self.t1, self.t0, self.q, self.p)

    @property
    def semi_major(self) -> float:
        """Largest stretch of a unit vector by ``[M m]``: the semi-major axis, mm."""
        return float(np.linalg.norm(np.column_stack([self.M, self.m]), 2))

    def check(self, smallest: float, largest: float) -> None:
        """Refuse a curve whose numbers are not finite or whose axes are outside
        ``[smallest, largest]`` mm (degenerate, or beyond any panel)."""
        nums = np.concatenate([self.c, self.M, self.m, [self.t0, self.t1]])
        if not np.all(np.isfinite(nums)):
            raise GeometryError("a curve with non-finite centre, axes or angles")
        axes = np.linalg.svd(np.column_stack([self.M, self.m]), compute_uv=False)
        if not (smallest <= axes.min() and axes.max() <= largest):
            raise GeometryError(
                f"a curve with axes {axes.max():.4g}, {axes.min():.4g} mm (allowed "
                f"{smallest:g}..{largest:g})"
            )

    @property
    def counter_clockwise(self) -> bool:
        """Runs counter-clockwise about its centre (in x-y, whatever the parameter sense)."""
        cross = self.M[0] * self.m[1] - self.M[1] * self.m[0]
        return (cross > 0) == (self.t1 > self.t0)

    def points(self, tol: float, region_left: bool) -> np.ndarray:
        """``[k + 1, 2]`` vertices of the flattening, on the region's safe side.

        Args:
            tol: largest distance between the polyline and the curve, mm.
            region_left: the region lies on the left of the direction of travel.

        Returns:
            Inscribed vertices (on the curve) when the region holds the centre side,
            circumscribed ones (tangent intersections) when it lies on the convex side;
            first and last vertex are the curve's end points.
        """
        sweep = self.t1 - self.t0
        a = self.semi_major
        # circumscribed deviation a (1/cos(d/2) - 1) <= tol (chords deviate less)
        step = 2.0 * math.acos(1.0 / (1.0 + tol / a))
        k = max(int(math.ceil(abs(sweep) / step)), 1, int(math.ceil(abs(sweep) / (0.5 * math.pi))))
        if k > MAX_VERTICES:
            raise GeometryError(
                f"a curve of radius {a:.4g} mm needs {k:,} vertices at tolerance {tol:g} mm "
                f"(at most {MAX_VERTICES:,})"
            )
        d = sweep / k
        inscribed = self.counter_clockwise == region_left
        if inscribed:
            pts = self.at(self.t0 + d * np.arange(k + 1))
        else:
            mid = self.at(self.t0 + d * (np.arange(k) + 0.5))
            pts = np.vstack([self.start, self.c + (mid - self.c) / math.cos(0.5 * d), self.end])
        pts[0], pts[-1] = self.start, self.end
        return pts


@dataclass(frozen=True)
class Sampled:
    """A curve known only by its flattening (splines): ``[k, 2]`` vertices, mm."""

    pts: np.ndarray

    @property
    def start(self) -> np.ndarray:
        return self.pts[0]

    @property
    def end(self) -> np.ndarray:
        return self.pts[-1]

    def reversed(self) -> Sampled:
        return Sampled(self.pts[::-1].copy())

    def points(self, tol: float, region_left: bool) -> np.ndarray:
        return self.pts


Segment = Line | Conic | Sampled


def bulge_arc(p: np.ndarray, q: np.ndarray, bulge: float) -> Segment:
    """The segment from ``p`` to ``q`` of a polyline vertex with ``bulge``
    (``tan(angle / 4)``, positive counter-clockwise); a line when the bulge is 0."""
    chord = q - p
    length = float(np.hypot(*chord))
    # the arc's sagitta is length / 2 * |bulge|: below 0.1 nm it is a straight line
    if length == 0.0 or 0.5 * length * abs(bulge) < 1e-7:
        return Line(p, q)
    theta = 4.0 * math.atan(bulge)
    radius = length / (2.0 * abs(math.sin(0.5 * theta)))
    normal = np.array([-chord[1], chord[0]]) / length  # left of p->q
    # centre is left of the chord for a ccw arc shorter than a half circle
    h = radius * math.cos(0.5 * theta)
    centre = 0.5 * (p + q) + math.copysign(1.0, theta) * h * normal
    t0 = math.atan2(p[1] - centre[1], p[0] - centre[0])
    return Conic(
        centre, np.array([radius, 0.0]), np.array([0.0, radius]), t0, t0 + theta, p.copy(), q.copy()
    )


def reverse_chain(segments: list[Segment]) -> list[Segment]:
    """The same chain travelled the other way."""
    return [s.reversed() for s in reversed(segments)]


def chain_points(segments: list[Segment], tol: float, region_left: bool) -> np.ndarray:
    """``[k, 2]`` vertices of a chain of segments flattened on the region's side (the
    shared end points appear once)."""
    parts = [s.points(tol, region_left) for s in segments]
    out = [parts[0]] + [p[1:] for p in parts[1:]]
    return np.vstack(out)


def rough_points(segments: list[Segment], tol: float) -> np.ndarray:
    """Vertices for deciding orientation and nesting (either side will do)."""
    return chain_points(segments, tol, True)
