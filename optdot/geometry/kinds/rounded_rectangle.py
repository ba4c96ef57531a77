"""The rounded rectangle: ``length`` × ``width`` mm with corners rounded to
``corner_radius`` (a micro-prism's base; a square, a capsule), its gaps exact over the
24 directions its inner rectangles' Minkowski sum can be nearest in."""

from __future__ import annotations

import math

import numba as nb
import numpy as np

from .base import (
    DISC_SLACK,
    MAX_SPHERES,
    Curve,
    Fit,
    Kind,
    axis_angle,
    polygon_vertices,
    rotate,
    turned,
    unit_toward,
)


class RoundedRect(Kind):
    """A rectangle of ``length`` × ``width`` mm (``length >= width``) with corners rounded
    to ``corner_radius`` mm (``0 <= corner_radius <= width / 2``): a square when length
    equals width, a capsule when the radius is half the width."""

    name = "rounded_rectangle"
    params = ("length", "width", "corner_radius")
    code = 2
    zero_params = ("corner_radius",)
    relaxation = "spheres"
    arc_param = 2
    profiles = ("ink", "prism")

    def profile_frame(self, size: tuple[float, ...]) -> tuple[float, float, float]:
        return 0.5 * size[0], 0.5 * size[1], size[2]

    def shape_params(self, size: np.ndarray) -> np.ndarray:
        return np.column_stack(self._core(size))

    def disc(self, size: np.ndarray) -> np.ndarray:
        w = size[:, 1]
        round_ = (np.abs(size[:, 0] - w) <= DISC_SLACK) & (np.abs(w - 2 * size[:, 2]) <= DISC_SLACK)
        return np.where(round_, w, np.nan)

    def bound_params(self, size: np.ndarray) -> np.ndarray:
        return 0.5 * size[:, :2]  # the box: its support bounds the rounded one's

    def problem(self, size: tuple[float, ...]) -> str | None:
        width = size[1]
        if size[2] > 0.5 * width:
            return (
                f"dots.corner_radius = {size[2]:g} cannot be drawn on a dot {width:g} mm wide "
                f"(at most width / 2 = {0.5 * width:g}: a capsule)"
            )
        return None

    def spheres(self, size: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Covering circles along the straight part, as wide as the corners need (they
        reach past the flat sides by up to ``(√2 - 1)(w/2 - r)``)."""
        length, width, rc = size[0], size[1], size[2]
        half = 0.5 * (length - width)
        k = min(MAX_SPHERES, 1 + math.ceil(2.0 * half / (0.5 * width)))
        t = np.linspace(-half, half, k) if half > 0 else np.zeros(1)
        # covering: the end circles reach the rounded corners, each the slab between centres
        step = 2.0 * half / (k - 1) if k > 1 else 0.0
        cover = max(
            math.hypot(0.5 * width - rc, 0.5 * width - rc) + rc,
            math.hypot(0.5 * width, 0.5 * step),
        )
        return t, np.full(len(t), cover)

    def curve(self, size: np.ndarray) -> Curve:
        """A disc when it is one, else its sides and, at each corner, an arc of a quarter
        turn (bulge ``tan(π/8)``; none when the corner is sharp)."""
        if float(size[0]) == float(size[1]) and float(size[-1]) >= 0.5 * float(size[1]):
            return Curve("disc", 0.5 * float(size[0]), 0.5 * float(size[0]))
        hx, hy, rc = 0.5 * float(size[0]) - size[2], 0.5 * float(size[1]) - size[2], size[2]
        bulge = math.tan(math.pi / 8) if rc > 0 else 0.0  # a quarter circle
        pts = []
        for cx, cy, t in ((hx, hy, 0), (-hx, hy, 1), (-hx, -hy, 2), (hx, -hy, 3)):
            c0, s0 = math.cos(t * math.pi / 2), math.sin(t * math.pi / 2)
            c1, s1 = math.cos((t + 1) * math.pi / 2), math.sin((t + 1) * math.pi / 2)
            pts.append((cx + rc * c0, cy + rc * s0, bulge))
            if rc > 0:
                pts.append((cx + rc * c1, cy + rc * s1, 0.0))
        # a side of length 0 (a capsule's ends, a disc): its two ends are one vertex, the
        # one that starts the next arc
        keep = [
            tuple(float(v) for v in p)
            for p, q in zip(pts, pts[1:] + pts[:1], strict=True)
            if math.hypot(p[0] - q[0], p[1] - q[1]) > 1e-12 * float(size[0])
        ]
        return Curve("bulged", ring=tuple(keep))

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

    def perimeter(self, size: np.ndarray) -> np.ndarray:
        return 2.0 * (size[:, 0] + size[:, 1]) - (8.0 - 2.0 * np.pi) * size[:, 2]

    def curvature_floor(self, size: np.ndarray) -> np.ndarray:
        return size[:, 2].astype(np.float64, copy=True)

    def parallel(self, size: np.ndarray, g: float) -> np.ndarray | None:
        """Exact both ways: the sides grow by ``2 g`` and the corners by ``g``; shrunk
        by more than its corner radius, the corners come out sharp (0), and grown back
        they are of radius ``g``, not the radius they had."""
        out = size + np.array([2.0 * g, 2.0 * g, g])
        out[:, 2] = np.maximum(out[:, 2], 0.0)
        return out

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
        return turned(pts, angle)

    def fit(self, points: np.ndarray, slack: float, share: float = 0.0) -> Fit:
        """Angle: the longest edge's; sides: the vertices' extent along and across it;
        corner radius: the median over the corners' vertices of the arc through each (a
        polygon inscribed in the footprint recovers it to its grid); a fit when every
        vertex lies within ``t = slack + share L`` of that footprint and the polygon's
        area is the footprint's within its perimeter times ``t``."""
        q = points - 0.5 * (points.max(axis=0) + points.min(axis=0))
        e = np.roll(points, -1, axis=0) - points
        k = int(np.argmax(np.hypot(*e.T)))
        ang = axis_angle(e[k])
        x, y = rotate(q, np.full(len(q), ang))
        mid = np.array([0.5 * (x.max() + x.min()), 0.5 * (y.max() + y.min())])
        length, width = float(x.max() - x.min()), float(y.max() - y.min())
        if width > length:
            length, width, ang = width, length, axis_angle(np.array([-e[k, 1], e[k, 0]]))
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
        x, y = rotate(rel, np.full(len(rel), ang))
        hx, hy, rc = self._core(size)
        qx, qy = np.abs(x) - hx, np.abs(y) - hy
        dist = np.hypot(np.maximum(qx, 0), np.maximum(qy, 0)) + np.minimum(np.maximum(qx, qy), 0)
        tol = slack + share * length
        # every vertex on the outline, and the outline covered: a trapezoid's or a
        # rhombus's vertices also lie on some rectangle, but enclose less of it
        xs, ys = points[:, 0], points[:, 1]
        area = 0.5 * abs(float(np.dot(xs, np.roll(ys, -1)) - np.dot(ys, np.roll(xs, -1))))
        perimeter = float(self.perimeter(size[None])[0])
        short = float(self.area(size[None])[0]) - area
        ok = (
            len(points) >= 4
            and width > 0
            and float(np.abs(dist - rc).max()) <= tol
            and abs(short) <= perimeter * tol
        )
        rad = np.hypot(*rel.T)
        return Fit(ok, centre, size, ang, (float(rad.min()), float(rad.max())))


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
                        cand[k, 0], cand[k, 1] = unit_toward(dx - vx, dy - vy)
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


@nb.njit(cache=True, inline="always")
def inside(f, k, dx, dy):  # pragma: no cover - compiled
    """Whether ``(dx, dy)`` (mm, from the centre) lies on packed rounded rectangle
    ``f[k]`` (inner half sides ``f[k, 1:3]``, corner radius ``f[k, 3]``, the angle's
    cosine and sine ``f[k, 4:6]``; closed)."""
    x = f[k, 4] * dx + f[k, 5] * dy
    y = -f[k, 5] * dx + f[k, 4] * dy
    qx, qy = abs(x) - f[k, 1], abs(y) - f[k, 2]
    ox, oy = max(qx, 0.0), max(qy, 0.0)
    return math.sqrt(ox * ox + oy * oy) + min(max(qx, qy), 0.0) <= f[k, 3]


@nb.njit(cache=True, inline="always")
def half_width(f, k):  # pragma: no cover - compiled
    """Packed rounded rectangle ``f[k]``'s half width (its inner half side plus the
    corner radius), mm."""
    return f[k, 2] + f[k, 3]


@nb.njit(cache=True, inline="always")
def support_bound(c, s, a, b, cp, sp):  # pragma: no cover - compiled
    """The support of the box of half sides ``a``, ``b`` (at least the rounded
    rectangle's, so a separation it gives bounds the gap from below) turned by the angle
    of cosine ``cp`` and sine ``sp``, in the direction ``(c, s)``."""
    u, v = c * cp + s * sp, -c * sp + s * cp
    return a * abs(u) + b * abs(v)
