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

import numba as nb
import numpy as np

#: Sizes of a footprint within this of each other make a disc (:meth:`Kind.disc`), mm:
#: files hold sizes to 1 nm, masks read back to 1-2 nm.
DISC_SLACK = 2e-6


class Kind:
    """One kind of footprint: how its size parameters make a shape. Methods take
    ``size [n, k]`` (mm, :attr:`params` in order) and ``angle [n]`` (rad) arrays."""

    #: The kind's name, as a job's ``[dots] shape`` and a file's ``shape`` field say it.
    name: str = ""
    #: Its size parameters, in the order of ``size``'s columns.
    params: tuple[str, ...] = ()
    #: Whether the footprint is the same at every angle (then ``angle`` is ignored).
    round: bool = False
    #: The kind's number in a packed footprint (:func:`packed`, the compiled kernels).
    code: int = -1

    def __reduce__(self):
        """Pickled by name, so a kind sent to a worker or read in a child process comes
        back as the registry's own (kinds are compared by identity)."""
        return (kind_named, (self.name,))

    def shape_params(self, size: np.ndarray) -> np.ndarray:
        """``[n, 3]`` the numbers :func:`on_packed` tests a point against, mm (or mm²)."""
        raise NotImplementedError

    def disc(self, size: np.ndarray) -> np.ndarray:
        """``[n]`` the diameter of the disc each footprint of ``size`` (``[n, k]`` mm) is,
        mm, NaN where it is not a disc (its sizes equal within :data:`DISC_SLACK`): how a
        circle a mask reader recognises matches a kind that draws a disc."""
        return np.full(len(size), np.nan)

    def undrawable(self, size: np.ndarray) -> np.ndarray:
        """``[n]`` bool: sizes (``[n, k]`` mm) no footprint of this kind has (a width
        not > 0, a length under the width; NaN)."""
        return ~(size[:, 1] > 0) | ~(size[:, 0] >= size[:, 1])

    def drawable(self, size: np.ndarray) -> np.ndarray:
        """``size`` (``[n, k]`` mm, rounded to 1 nm) kept drawable after the rounding
        (a capsule's corner radius not over half its rounded width)."""
        return size

    def support(self, theta: np.ndarray, size: np.ndarray, angle: np.ndarray) -> np.ndarray:
        """The support function ``h(θ) = max over the footprint of ⟨p, u(θ)⟩`` (mm, about
        the centre) in the directions ``theta`` (rad): what :meth:`separation` maximises
        ``⟨d, u⟩ - h_i - h_j`` over."""
        raise NotImplementedError

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
        return self.separation(d, size_i, angle_i, size_j, angle_j)[0]

    def separation(
        self,
        d: np.ndarray,
        size_i: np.ndarray,
        angle_i: np.ndarray,
        size_j: np.ndarray,
        angle_j: np.ndarray,
    ) -> tuple[np.ndarray, np.ndarray]:
        """``(gap [m] mm, u [m, 2])``: :meth:`gap` and the unit direction it is measured
        along (from i toward j): moving j along ``u`` widens the gap at rate 1, the
        gap's gradient in ``d``."""
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
    code = 0

    def shape_params(self, size: np.ndarray) -> np.ndarray:
        r = 0.5 * size[:, 0]
        return np.column_stack([r * r, np.zeros((len(r), 2))])

    def undrawable(self, size: np.ndarray) -> np.ndarray:
        return ~(size[:, 0] > 0)

    def disc(self, size: np.ndarray) -> np.ndarray:
        return size[:, 0].astype(np.float64, copy=True)

    def area(self, size: np.ndarray) -> np.ndarray:
        return np.pi * 0.25 * size[:, 0] ** 2

    def extent(self, size: np.ndarray) -> np.ndarray:
        return 0.5 * size[:, 0]

    def support(self, theta, size, angle) -> np.ndarray:
        return np.broadcast_to(
            0.5 * size[..., 0], np.broadcast_shapes(np.shape(theta), size.shape[:-1])
        )

    def separation(self, d, size_i, angle_i, size_j, angle_j):
        n = np.hypot(d[:, 0], d[:, 1])
        u = np.where(n[:, None] > 0, d / np.where(n > 0, n, 1.0)[:, None], [1.0, 0.0])
        return n - 0.5 * (size_i[:, 0] + size_j[:, 0]), u

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


def _rotate(p: np.ndarray, angle: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(x, y)`` of points ``p`` (``[m, 2]``) in frames turned by ``angle`` (``[m]`` rad):
    the coordinates along and across each dot's long axis."""
    c, s = np.cos(angle), np.sin(angle)
    return c * p[:, 0] + s * p[:, 1], -s * p[:, 0] + c * p[:, 1]


class Ellipse(Kind):
    """An ellipse of ``length`` (long axis) × ``width`` mm, ``length >= width``."""

    name = "ellipse"
    params = ("length", "width")
    code = 1

    def shape_params(self, size: np.ndarray) -> np.ndarray:
        return np.column_stack([0.5 * size[:, 0], 0.5 * size[:, 1], np.zeros(len(size))])

    def area(self, size: np.ndarray) -> np.ndarray:
        return np.pi * 0.25 * size[:, 0] * size[:, 1]

    def disc(self, size: np.ndarray) -> np.ndarray:
        return np.where(np.abs(size[:, 0] - size[:, 1]) <= DISC_SLACK, size[:, 1], np.nan)

    def extent(self, size: np.ndarray) -> np.ndarray:
        return 0.5 * size[:, 0]

    def support(self, theta: np.ndarray, size: np.ndarray, angle: np.ndarray) -> np.ndarray:
        """The support function (mm) of the ellipses in the directions ``theta`` (rad):
        ``sqrt(a² cos²(θ - φ) + b² sin²(θ - φ))`` (the compiled search, ``_ellipse_h``,
        evaluates it and its derivatives by double angles)."""
        a2, b2 = (0.5 * size[..., 0]) ** 2, (0.5 * size[..., 1]) ** 2
        return np.sqrt(0.5 * (a2 + b2) + 0.5 * (a2 - b2) * np.cos(2.0 * (theta - angle)))

    def separation(self, d, size_i, angle_i, size_j, angle_j):
        """The separation ``max_u <d, u> - h_i(u) - h_j(u)`` over unit directions ``u``
        (both ellipses are centrally symmetric): the edge-to-edge distance when they are
        apart, minus the depth of the shallowest escape when they overlap. Any ``u``
        bounds it from below, so the value returned never exceeds the true distance: the
        best of :func:`gap_samples` directions, then Newton steps in the angle, which
        converge because the function is strictly concave wherever it exceeds minus the
        two ellipses' smallest radii of curvature (``b²/a``)."""
        if not len(d):
            return np.zeros(0), np.zeros((0, 2))
        ratio = np.concatenate([size_i[:, 0] / size_i[:, 1], size_j[:, 0] / size_j[:, 1]])
        samples = gap_samples(float(ratio.max()))
        gap, u = np.empty(len(d)), np.empty((len(d), 2))
        c = np.ascontiguousarray  # one compiled signature, whatever the slices
        _ellipse_gaps(
            c(d, dtype=np.float64),
            c(0.5 * size_i[:, 0]), c(0.5 * size_i[:, 1]), c(angle_i, dtype=np.float64),
            c(0.5 * size_j[:, 0]), c(0.5 * size_j[:, 1]), c(angle_j, dtype=np.float64),
            samples, GAP_NEWTON, gap, u,
        )  # fmt: skip
        return gap, u

    def contains(self, p, size, angle) -> np.ndarray:
        return _contains(packed(self, size, angle), p)

    def outline(self, size, angle, tolerance) -> np.ndarray:
        """Vertices evenly spaced in the ellipse's parameter, as many as a circle of the
        long half-axis needs: the chord error is largest at the ends of the long axis,
        where it equals that circle's."""
        a, b = 0.5 * float(size[0]), 0.5 * float(size[1])
        n = polygon_vertices(a, tolerance)
        t = 2.0 * np.pi * np.arange(n) / n
        return _turned(np.column_stack([a * np.cos(t), b * np.sin(t)]), angle)

    def fit(self, points: np.ndarray, slack: float, share: float = 0.0) -> Fit:
        """Centre: the vertices' mean; axes: the vertices' second moments (vertices evenly
        spaced in the parameter have covariance ``diag(a², b²) / 2``); a fit when every
        vertex lies within ``slack + share a`` of that ellipse."""
        c = points.mean(axis=0)
        q = points - c
        w, v = np.linalg.eigh(q.T @ q / len(q))
        a, b = np.sqrt(2.0 * np.maximum(w[::-1], 0.0))
        ang = _axis_angle(v[:, 1])
        size = np.array([2.0 * a, 2.0 * b])
        if not (len(points) >= MIN_VERTICES and b > 0):
            return Fit(False, c, size, ang, (0.0, 0.0))
        x, y = _rotate(q, np.full(len(q), ang))
        # distance to the ellipse, to first order: the level's excess over its gradient
        lev = np.hypot(x / a, y / b)
        err = np.abs(lev - 1.0) / np.hypot(x / a**2, y / b**2) * lev
        ok = float(err.max()) <= slack + share * a
        rad = np.hypot(*q.T)
        return Fit(ok, c, size, ang, (float(rad.min()), float(rad.max())))


class RoundedRect(Kind):
    """A rectangle of ``length`` × ``width`` mm (``length >= width``) with corners rounded
    to ``corner_radius`` mm (``0 <= corner_radius <= width / 2``): a square when length
    equals width, a capsule when the radius is half the width."""

    name = "rounded_rectangle"
    params = ("length", "width", "corner_radius")
    code = 2

    def shape_params(self, size: np.ndarray) -> np.ndarray:
        return np.column_stack(self._core(size))

    def disc(self, size: np.ndarray) -> np.ndarray:
        w = size[:, 1]
        round_ = (np.abs(size[:, 0] - w) <= DISC_SLACK) & (np.abs(w - 2 * size[:, 2]) <= DISC_SLACK)
        return np.where(round_, w, np.nan)

    def undrawable(self, size: np.ndarray) -> np.ndarray:
        rc = size[:, 2]
        return super().undrawable(size) | ~(rc >= 0) | (rc > 0.5 * size[:, 1])

    def drawable(self, size: np.ndarray) -> np.ndarray:
        # the radius rounded down to 1 nm under half the width: 0.041223 wide, 0.020611
        half = np.floor(np.round(size[:, 1] * 0.5e6, 3)) / 1e6
        out = size.copy()
        out[:, 2] = np.minimum(size[:, 2], half)
        return out

    @staticmethod
    def _core(size: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(hx, hy, rc)``: the half sides of the rectangle the corners round, and the
        radius (the footprint is that rectangle grown by ``rc``)."""
        rc = size[..., 2]
        return 0.5 * size[..., 0] - rc, 0.5 * size[..., 1] - rc, rc

    def area(self, size: np.ndarray) -> np.ndarray:
        return size[:, 0] * size[:, 1] - (4.0 - np.pi) * size[:, 2] ** 2

    def extent(self, size: np.ndarray) -> np.ndarray:
        hx, hy, rc = self._core(size)
        return np.hypot(hx, hy) + rc

    def support(self, theta, size, angle) -> np.ndarray:
        hx, hy, rc = self._core(size)
        return hx * np.abs(np.cos(theta - angle)) + hy * np.abs(np.sin(theta - angle)) + rc

    def separation(self, d, size_i, angle_i, size_j, angle_j):
        """Exact: the two inner rectangles' Minkowski sum is a convex polygon whose edge
        normals are the rectangles' axes and whose vertices are sums of their corners,
        so the separation ``max_u <d, u> - h_i(u) - h_j(u)`` is attained at one of the 8
        axis directions (an edge nearest) or at a direction from one of the 16 corner
        sums to ``d`` (a vertex nearest); the radii add to both."""
        c = np.ascontiguousarray  # one compiled signature, whatever the slices
        ci, cj = self._core(size_i), self._core(size_j)
        gap, u = np.empty(len(d)), np.empty((len(d), 2))
        _rect_gaps(
            c(d, dtype=np.float64), *(c(v) for v in ci), c(angle_i, dtype=np.float64),
            *(c(v) for v in cj), c(angle_j, dtype=np.float64), gap, u,
        )  # fmt: skip
        return gap, u

    def contains(self, p, size, angle) -> np.ndarray:
        return _contains(packed(self, size, angle), p)

    def outline(self, size, angle, tolerance) -> np.ndarray:
        """The four sides and, at each corner, a quarter of the polygon a circle of the
        corner radius needs (one vertex when the corner is sharp)."""
        hx, hy, rc = (float(v) for v in self._core(np.asarray(size, float)))
        q = 0 if rc <= 0 else max(1, -(-polygon_vertices(rc, tolerance) // 4))
        ring = []
        for k, (cx, cy) in enumerate(((hx, hy), (-hx, hy), (-hx, -hy), (hx, -hy))):
            t = 0.5 * np.pi * (k + np.arange(q + 1) / max(q, 1)) if q else np.zeros(1)
            ring.append(np.column_stack([cx + rc * np.cos(t), cy + rc * np.sin(t)]))
        pts = np.concatenate(ring)
        keep = np.ones(len(pts), bool)  # a capsule's or a square's repeated vertices
        keep[1:] = np.hypot(*np.diff(pts, axis=0).T) > 1e-12 * max(hx + rc, 1e-300)
        pts = pts[keep]
        if len(pts) > 1 and np.hypot(*(pts[-1] - pts[0])) <= 1e-12 * (hx + rc):
            pts = pts[:-1]
        return _turned(pts, angle)

    def fit(self, points: np.ndarray, slack: float, share: float = 0.0) -> Fit:
        """Angle: the longest edge's; sides: the vertices' extent along and across it;
        corner radius: the median over the corners' vertices of the arc through each (a
        polygon inscribed in the footprint recovers it to its grid); a fit when every
        vertex lies within ``t = slack + share L`` of that footprint and the polygon's
        area is the footprint's within its perimeter times ``t``."""
        q = points - 0.5 * (points.max(axis=0) + points.min(axis=0))
        e = np.roll(points, -1, axis=0) - points
        k = int(np.argmax(np.hypot(*e.T)))
        ang = _axis_angle(e[k])
        x, y = _rotate(q, np.full(len(q), ang))
        mid = np.array([0.5 * (x.max() + x.min()), 0.5 * (y.max() + y.min())])
        length, width = float(x.max() - x.min()), float(y.max() - y.min())
        if width > length:
            length, width, ang = width, length, _axis_angle(np.array([-e[k, 1], e[k, 0]]))
        c, s = math.cos(ang), math.sin(ang)
        centre = 0.5 * (points.max(axis=0) + points.min(axis=0)) + np.array(
            [c * mid[0] - s * mid[1], s * mid[0] + c * mid[1]]
        )
        # a first radius from the corners' reach along their diagonals (the point at 45°
        # reaches |x| + |y| = L/2 + W/2 - (2 - √2) rc), then each corner vertex's own:
        # at (u, w) in from the sides, a vertex on the arc has rc = u + w + sqrt(2 u w)
        u = 0.5 * length - np.abs(x - mid[0])
        w = 0.5 * width - np.abs(y - mid[1])
        rc0 = float((u + w).min()) / (2.0 - math.sqrt(2.0))
        arc = (u <= 1.01 * rc0) & (w <= 1.01 * rc0) & (u > 0) & (w > 0)
        rc = float(np.median((u + w + np.sqrt(2.0 * u * w))[arc])) if arc.any() else rc0
        size = np.array([length, width, min(max(rc, 0.0), 0.5 * width)])
        rel = points - centre
        x, y = _rotate(rel, np.full(len(rel), ang))
        hx, hy, rc = self._core(size)
        qx, qy = np.abs(x) - hx, np.abs(y) - hy
        dist = np.hypot(np.maximum(qx, 0), np.maximum(qy, 0)) + np.minimum(np.maximum(qx, qy), 0)
        tol = slack + share * length
        # every vertex on the outline, and the outline covered: a trapezoid's or a
        # rhombus's vertices also lie on some rectangle, but enclose less of it
        xs, ys = points[:, 0], points[:, 1]
        area = 0.5 * abs(float(np.dot(xs, np.roll(ys, -1)) - np.dot(ys, np.roll(xs, -1))))
        perimeter = 2.0 * (length + width) - (8.0 - 2.0 * math.pi) * float(rc)
        short = float(self.area(size[None])[0]) - area
        ok = (
            len(points) >= 4
            and width > 0
            and float(np.abs(dist - rc).max()) <= tol
            and abs(short) <= perimeter * tol
        )
        rad = np.hypot(*rel.T)
        return Fit(ok, centre, size, ang, (float(rad.min()), float(rad.max())))


def packed(kind: Kind, size: np.ndarray, angle: np.ndarray | None) -> np.ndarray:
    """``[n, 6]`` footprints as the compiled kernels take them: kind code, the kind's
    three :meth:`Kind.shape_params`, and the cosine and sine of the angle."""
    n = len(size)
    a = np.zeros(n) if angle is None else np.broadcast_to(angle, (n,))
    out = np.empty((n, 6))
    out[:, 0] = kind.code
    out[:, 1:4] = kind.shape_params(size)
    out[:, 4], out[:, 5] = np.cos(a), np.sin(a)
    return out


@nb.njit(cache=True, inline="always")
def on_packed(f, k, dx, dy):  # pragma: no cover - compiled
    """Whether the point ``(dx, dy)`` (mm, from the centre) lies on packed footprint
    ``f[k]`` (:func:`packed`; closed: the edge counts)."""
    code = f[k, 0]
    if code == 0.0:
        return dx * dx + dy * dy <= f[k, 1]
    x = f[k, 4] * dx + f[k, 5] * dy
    y = -f[k, 5] * dx + f[k, 4] * dy
    if code == 1.0:
        u, v = x / f[k, 1], y / f[k, 2]
        return u * u + v * v <= 1.0
    qx, qy = abs(x) - f[k, 1], abs(y) - f[k, 2]
    ox, oy = max(qx, 0.0), max(qy, 0.0)
    return math.sqrt(ox * ox + oy * oy) + min(max(qx, qy), 0.0) <= f[k, 3]


@nb.njit(cache=True)
def _contains(f, p):  # pragma: no cover - compiled
    out = np.empty(p.shape[0], np.bool_)
    for k in range(p.shape[0]):
        out[k] = on_packed(f, k, p[k, 0], p[k, 1])
    return out


@nb.njit(cache=True)
def _rect_gaps(d, hxi, hyi, rci, pi, hxj, hyj, rcj, pj, gap, u):  # pragma: no cover
    """Per pair of rounded rectangles (inner half sides, corner radius, angle): the best of
    the 8 axis directions and the 16 directions from a corner sum to ``d`` (see
    :meth:`RoundedRect.separation`), into ``gap [m]`` and ``u [m, 2]``."""
    cand = np.empty((24, 2))
    for m in range(d.shape[0]):
        dx, dy = d[m, 0], d[m, 1]
        e1x, e1y = math.cos(pi[m]), math.sin(pi[m])
        e2x, e2y = math.cos(pj[m]), math.sin(pj[m])
        axes = ((e1x, e1y), (-e1y, e1x), (e2x, e2y), (-e2y, e2x))
        for k in range(4):
            cand[k, 0], cand[k, 1] = axes[k][0], axes[k][1]
            cand[k + 4, 0], cand[k + 4, 1] = -axes[k][0], -axes[k][1]
        k = 8
        for si in (1.0, -1.0):
            for ti in (1.0, -1.0):
                for sj in (1.0, -1.0):
                    for tj in (1.0, -1.0):
                        vx = si * hxi[m] * e1x - ti * hyi[m] * e1y
                        vy = si * hxi[m] * e1y + ti * hyi[m] * e1x
                        vx += sj * hxj[m] * e2x - tj * hyj[m] * e2y
                        vy += sj * hxj[m] * e2y + tj * hyj[m] * e2x
                        wx, wy = dx - vx, dy - vy
                        n = math.sqrt(wx * wx + wy * wy)
                        if n == 0.0:
                            wx, wy, n = 1.0, 0.0, 1.0
                        cand[k, 0], cand[k, 1] = wx / n, wy / n
                        k += 1
        best, bx, by = -1e300, 1.0, 0.0
        for k in range(24):
            ux, uy = cand[k, 0], cand[k, 1]
            f = (
                dx * ux + dy * uy
                - hxi[m] * abs(ux * e1x + uy * e1y) - hyi[m] * abs(-ux * e1y + uy * e1x)
                - hxj[m] * abs(ux * e2x + uy * e2y) - hyj[m] * abs(-ux * e2y + uy * e2x)
            )  # fmt: skip
            if f > best:
                best, bx, by = f, ux, uy
        gap[m] = best - rci[m] - rcj[m]
        u[m, 0], u[m, 1] = bx, by


def _turned(ring: np.ndarray, angle: float) -> np.ndarray:
    """``ring`` (``[v, 2]``) turned counter-clockwise by ``angle`` rad about the origin."""
    if angle == 0.0:
        return ring
    c, s = math.cos(angle), math.sin(angle)
    return ring @ np.array([[c, s], [-s, c]])


def _axis_angle(v: np.ndarray) -> float:
    """The angle of the axis along ``v`` (``[2]``), rad, in ``(-π/2, π/2]``."""
    a = math.atan2(float(v[1]), float(v[0]))
    if a <= -0.5 * math.pi:
        a += math.pi
    elif a > 0.5 * math.pi:
        a -= math.pi
    return a


#: Fewest directions :meth:`Ellipse.gap` tries before its Newton steps.
GAP_SAMPLES = 16


def gap_samples(aspect: float) -> int:
    """Directions to try for ellipses of up to ``aspect`` (length / width): so many that
    the best lies where the separation is concave (above minus the smallest radius of
    curvature ``b²/a``), the curvature of the pair's support being at most ``2 a²/b``:
    spacing ``sqrt(4 (b/a)³)``, at least :data:`GAP_SAMPLES`."""
    return max(GAP_SAMPLES, math.ceil(2.0 * math.pi / math.sqrt(4.0 * aspect**-3)))


#: Newton steps after them (quadratic convergence: a handful reach machine precision).
GAP_NEWTON = 8
#: Pairs per block of the vectorised search (bounds its memory).
GAP_BLOCK = 1 << 14


@nb.njit(cache=True, inline="always")
def _ellipse_h(c, s, a1, b1, c1, s1, a2, b2, c2, s2, order):  # pragma: no cover - compiled
    """``h_i + h_j`` of two ellipses in the direction ``(c, s)`` = (cos θ, sin θ), each
    given by its half axes and (cos 2φ, sin 2φ) of its angle φ, and for ``order`` 2 the
    first and second derivatives in θ (``Ellipse.support``'s formulas, summed; the
    double angles by addition, so no trigonometry per evaluation)."""
    cc, ss = c * c - s * s, 2.0 * s * c  # cos 2θ, sin 2θ
    h = dh = ddh = 0.0
    for a, b, cp, sp in ((a1, b1, c1, s1), (a2, b2, c2, s2)):
        k = a * a - b * b
        cos2 = cc * cp + ss * sp  # cos 2(θ - φ)
        r = math.sqrt(0.5 * (a * a + b * b) + 0.5 * k * cos2)
        h += r
        if order == 2:
            dq = -k * (ss * cp - cc * sp)  # -k sin 2(θ - φ)
            dh += dq / (2.0 * r)
            ddh += -k * cos2 / r - dq * dq / (4.0 * r * r * r)
    return h, dh, ddh


@nb.njit(cache=True)
def _ellipse_gaps(d, ai, bi, pi, aj, bj, pj, samples, newton, gap, u):  # pragma: no cover
    """Per pair: ``max_θ d·u(θ) - h_i(θ) - h_j(θ)`` by the best of ``samples`` directions
    then ``newton`` safeguarded Newton steps (a step at most the sampling step, a
    gradient step where the curvature is not negative), the best value kept; written
    into ``gap [m]`` and its direction into ``u [m, 2]``."""
    step = 2.0 * math.pi / samples
    tc = np.cos(np.arange(samples) * step)
    ts = np.sin(np.arange(samples) * step)
    for m in range(d.shape[0]):
        dx, dy = d[m, 0], d[m, 1]
        c1, s1 = math.cos(2.0 * pi[m]), math.sin(2.0 * pi[m])
        c2, s2 = math.cos(2.0 * pj[m]), math.sin(2.0 * pj[m])
        a1, b1, a2, b2 = ai[m], bi[m], aj[m], bj[m]
        best, arg = -1e300, 0.0
        for k in range(samples):
            h, _, _ = _ellipse_h(tc[k], ts[k], a1, b1, c1, s1, a2, b2, c2, s2, 0)
            f = dx * tc[k] + dy * ts[k] - h
            if f > best:
                best, arg = f, k * step
        t = arg
        for it in range(newton + 1):  # the value at each step comes with its derivatives
            c, s = math.cos(t), math.sin(t)
            h, dh, ddh = _ellipse_h(c, s, a1, b1, c1, s1, a2, b2, c2, s2, 2)
            f = dx * c + dy * s - h
            if f > best:
                best, arg = f, t
            g1 = -dx * s + dy * c - dh
            g2 = -dx * c - dy * s - ddh
            dt = -g1 / g2 if g2 < 0 else math.copysign(step, g1)
            if it == newton or abs(dt) < 1e-12:  # converged to machine precision
                break
            t += min(max(dt, -step), step)
        gap[m] = best
        u[m, 0], u[m, 1] = math.cos(arg), math.sin(arg)


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
KINDS: dict[str, Kind] = {k.name: k for k in (Circle(), Ellipse(), RoundedRect())}
#: The circle, the kind of every pattern that does not name one.
CIRCLE = KINDS["circle"]


def kind_named(name: str) -> Kind:
    """The registry's kind of ``name`` (what a pickled kind comes back as)."""
    return KINDS[name]


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
        return 0.5 * float(self.size[1])

    @property
    def equivalent_diameter(self) -> float:
        """The diameter of the disc of the same area, mm: what sets the spacing and the
        count (one footprint per ``area / fill``)."""
        return 2.0 * math.sqrt(self.area / math.pi)

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
        return self.size[:, 0] if self.kind is CIRCLE else 2.0 * self.extent()

    def area(self) -> np.ndarray:
        """``[n]`` areas, mm²."""
        return self.kind.area(self.size)

    def extent(self) -> np.ndarray:
        """``[n]`` bounding radii, mm."""
        return self.kind.extent(self.size)

    def equivalent_diameter(self) -> np.ndarray:
        """``[n]`` diameters of the discs of the same areas, mm (a disc's own)."""
        return 2.0 * np.sqrt(self.area() / np.pi)

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
        return self.kind.contains(points - xy[k], self.size[k], self.angles[k])

    def outline(self, k: int, tolerance: float) -> np.ndarray:
        """``[v, 2]`` polygon of dot ``k`` about its centre, within ``tolerance`` mm."""
        return self.kind.outline(self.size[k], float(self.angles[k]), tolerance)


__all__ = [
    "CIRCLE",
    "KINDS",
    "MIN_VERTICES",
    "Circle",
    "DotShape",
    "Ellipse",
    "Fit",
    "Footprints",
    "Kind",
    "RoundedRect",
    "on_packed",
    "packed",
    "polygon_vertices",
]
