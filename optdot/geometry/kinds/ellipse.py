"""The ellipse: ``length`` (long axis) × ``width`` mm, its gaps exact by a safeguarded
Newton search over the direction of separation."""

from __future__ import annotations

import math

import numba as nb
import numpy as np

from .base import (
    DISC_SLACK,
    MAX_SPHERES,
    MIN_VERTICES,
    Curve,
    Fit,
    Kind,
    axis_angle,
    polygon_vertices,
    rotate,
    turned,
)


class Ellipse(Kind):
    """An ellipse of ``length`` (long axis) × ``width`` mm, ``length >= width``."""

    name = "ellipse"
    params = ("length", "width")
    code = 1
    curve_form = "ellipse"
    profiles = ("ink", "bump", "dimple")

    def profile_frame(self, size: tuple[float, ...]) -> tuple[float, float, float]:
        return 0.5 * size[0], 0.5 * size[1], 0.0

    def shape_params(self, size: np.ndarray) -> np.ndarray:
        return np.column_stack([0.5 * size[:, 0], 0.5 * size[:, 1], np.zeros(len(size))])

    def area(self, size: np.ndarray) -> np.ndarray:
        return np.pi * 0.25 * size[:, 0] * size[:, 1]

    def disc(self, size: np.ndarray) -> np.ndarray:
        return np.where(np.abs(size[:, 0] - size[:, 1]) <= DISC_SLACK, size[:, 1], np.nan)

    def extent(self, size: np.ndarray) -> np.ndarray:
        return 0.5 * size[:, 0]

    def bound_params(self, size: np.ndarray) -> np.ndarray:
        return 0.5 * size[:, :2]

    def spheres(self, size: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Inscribed circles: the largest centred on the long axis between the centres
        of curvature of its ends (radius ``b sqrt(1 - t²/(a² - b²))`` at ``t``, at least
        the ends' ``b²/a``); their union falls short at the flanks."""
        a, b = 0.5 * size[0], 0.5 * size[1]
        reach = (a * a - b * b) / a  # centre of curvature of each end
        tip = b * b / a
        k = min(MAX_SPHERES, 1 + 2 * math.ceil(reach / max(tip, 1e-12)))
        t = np.linspace(-reach, reach, k) if reach > 0 else np.zeros(1)
        r = b * np.sqrt(np.maximum(1.0 - t * t / max(a * a - b * b, 1e-300), 0.0))
        return t, np.maximum(r, tip)

    def curve(self, size: np.ndarray) -> Curve:
        a, b = 0.5 * float(size[0]), 0.5 * float(size[1])
        return Curve("disc", a, a) if float(size[0]) == float(size[1]) else Curve("ellipse", a, b)

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

    def outline(self, size, angle, tolerance) -> np.ndarray:
        """Vertices evenly spaced in the ellipse's parameter, as many as a circle of the
        long half-axis needs: the chord error is largest at the ends of the long axis,
        where it equals that circle's."""
        a, b = 0.5 * float(size[0]), 0.5 * float(size[1])
        n = polygon_vertices(a, tolerance)
        t = 2.0 * np.pi * np.arange(n) / n
        return turned(np.column_stack([a * np.cos(t), b * np.sin(t)]), angle)

    def perimeter(self, size: np.ndarray) -> np.ndarray:
        """``4 a E(1 - b²/a²)``, the complete elliptic integral of the second kind."""
        from scipy.special import ellipe

        a, b = 0.5 * size[:, 0], 0.5 * size[:, 1]
        return 4.0 * a * ellipe(1.0 - (b / a) ** 2)

    def curvature_floor(self, size: np.ndarray) -> np.ndarray:
        """``b²/a``, at the ends of the long axis."""
        return 0.5 * size[:, 1] ** 2 / size[:, 0]

    def parallel_outline(self, size, g, tolerance) -> np.ndarray:
        """The parallel curve ``p(t) + g n(t)`` (``n`` the outward unit normal) at
        parameters evenly spaced as in :meth:`outline`: not an ellipse. Shrunk (``g <
        0``) by at most ``b²/a`` it is convex and its chords err no more than the
        ellipse's; grown, its ends are flatter by ``1 + g a/b²``, so it takes that many
        more vertices."""
        a, b = 0.5 * float(size[0]), 0.5 * float(size[1])
        n = polygon_vertices(a + max(g, 0.0) * (a / b) ** 2, tolerance)
        t = 2.0 * np.pi * np.arange(n) / n
        c, s = np.cos(t), np.sin(t)
        norm = np.hypot(b * c, a * s)
        return np.column_stack([(a + g * b / norm) * c, (b + g * a / norm) * s])

    def fit_grown(self, points: np.ndarray, g: float, slack: float, share: float = 0.0) -> Fit:
        """Each vertex moved out by ``g`` along the normal there: a parallel curve's
        normals are the ellipse's, so the vertices return onto it; then :meth:`fit`.
        The normals: first the ring's (central differences turned a quarter), then
        twice the fitted ellipse's at each vertex's foot on it (the nearest point, by
        Newton steps in the parameter: a point of a parallel curve is nearest the point
        of the ellipse it was drawn from), each pass fitted by :func:`conic_fit` (a grid
        merges vertices: they need not be evenly spaced); this recovers the axes to the
        vertices' grid."""
        t = np.roll(points, -1, axis=0) - np.roll(points, 1, axis=0)
        xs, ys = points[:, 0], points[:, 1]
        ccw = float(np.dot(xs, np.roll(ys, -1)) - np.dot(ys, np.roll(xs, -1))) > 0
        n = np.column_stack([t[:, 1], -t[:, 0]]) * (1.0 if ccw else -1.0)
        n /= np.maximum(np.hypot(n[:, 0], n[:, 1]), 1e-300)[:, None]
        f = self.fit(points + g * n, slack, share)
        for _ in range(FIT_REFINE):
            if not (len(points) >= MIN_VERTICES and f.size[1] > 0):
                return f
            a, b = 0.5 * float(f.size[0]), 0.5 * float(f.size[1])
            x, y = rotate(points - f.centre, np.full(len(points), f.angle))
            u = np.arctan2(a * y, b * x)  # the foot's parameter: Newton from the normal's
            for _ in range(FOOT_NEWTON):
                c, s = np.cos(u), np.sin(u)
                dx, dy = x - a * c, y - b * s
                d1 = dx * a * s - dy * b * c  # half the derivative of the squared distance
                d2 = a * a * s * s + b * b * c * c + dx * a * c + dy * b * s
                u = u - d1 / np.where(d2 > 0, d2, 1.0)
            c, s = np.cos(u), np.sin(u)
            m = np.column_stack([b * c, a * s])
            m /= np.hypot(m[:, 0], m[:, 1])[:, None]
            ca, sa = math.cos(f.angle), math.sin(f.angle)
            n = np.column_stack([ca * m[:, 0] - sa * m[:, 1], sa * m[:, 0] + ca * m[:, 1]])
            # the points a grid merged are unevenly spaced: the moments would be biased
            conic = conic_fit(points + g * n)
            if conic is None or not conic[1][1] > 0:
                return self.fit(points + g * n, slack, share)
            f = _judged(points + g * n, *conic, slack, share)
        # the vertices alone can sit on an ellipse that is not the outline (a rectangle's
        # corners): the polygon grown by g (Steiner) must cover the ellipse's area too
        xs, ys = points[:, 0], points[:, 1]
        area = 0.5 * abs(float(np.dot(xs, np.roll(ys, -1)) - np.dot(ys, np.roll(xs, -1))))
        rim = float(np.hypot(*(np.roll(points, -1, axis=0) - points).T).sum())
        grown = area + rim * g + math.pi * g * g
        want, per = float(self.area(f.size[None])[0]), float(self.perimeter(f.size[None])[0])
        if abs(grown - want) > per * (slack + share * 0.5 * float(f.size[0])):
            return Fit(False, f.centre, f.size, f.angle, f.radii)
        return f

    def fit(self, points: np.ndarray, slack: float, share: float = 0.0) -> Fit:
        """Centre: the vertices' mean; axes: the vertices' second moments (vertices evenly
        spaced in the parameter have covariance ``diag(a², b²) / 2``); a fit when every
        vertex lies within ``slack + share a`` of that ellipse."""
        c = points.mean(axis=0)
        q = points - c
        w, v = np.linalg.eigh(q.T @ q / len(q))
        a, b = np.sqrt(2.0 * np.maximum(w[::-1], 0.0))
        ang = axis_angle(v[:, 1])
        size = np.array([2.0 * a, 2.0 * b])
        if not (len(points) >= MIN_VERTICES and b > 0):
            return Fit(False, c, size, ang, (0.0, 0.0))
        return _judged(points, c, size, ang, slack, share)


def _judged(points, c, size, ang, slack, share) -> Fit:
    """The ellipse ``(c, size, ang)`` as a :class:`Fit` of ``points``: one when every
    point lies within ``slack + share a`` of it."""
    a, b = 0.5 * float(size[0]), 0.5 * float(size[1])
    q = points - c
    x, y = rotate(q, np.full(len(q), ang))
    # distance to the ellipse, to first order: the level's excess over its gradient
    lev = np.hypot(x / a, y / b)
    err = np.abs(lev - 1.0) / np.hypot(x / a**2, y / b**2) * lev
    ok = float(err.max()) <= slack + share * a
    rad = np.hypot(*q.T)
    return Fit(ok, c, size, ang, (float(rad.min()), float(rad.max())))


def conic_fit(points: np.ndarray) -> tuple[np.ndarray, np.ndarray, float] | None:
    """``(centre [2], size [2], angle)`` of the ellipse nearest ``points`` (``[v, 2]``)
    in the algebraic sense (Fitzgibbon's direct fit, in Halíř and Flusser's stable
    form): unlike the moments of :meth:`Ellipse.fit`, it does not need the points evenly
    spaced. None when the points lie on no ellipse."""
    c0 = points.mean(axis=0)
    k = float(np.abs(points - c0).max()) or 1.0
    x, y = ((points - c0) / k).T
    d1 = np.column_stack([x * x, x * y, y * y])
    d2 = np.column_stack([x, y, np.ones_like(x)])
    s1, s2, s3 = d1.T @ d1, d1.T @ d2, d2.T @ d2
    try:
        t = -np.linalg.solve(s3, s2.T)
    except np.linalg.LinAlgError:
        return None
    m = s1 + s2 @ t
    m = np.array([m[2] / 2.0, -m[1], m[0] / 2.0])
    w, v = np.linalg.eig(m)
    v = np.real(v)
    cond = 4.0 * v[0] * v[2] - v[1] ** 2
    if not np.any(cond > 0):
        return None
    a1 = v[:, int(np.argmax(cond))]
    A, B, C = a1
    D, E, F = t @ a1
    den = B * B - 4.0 * A * C
    if den >= 0:
        return None
    cx = (2.0 * C * D - B * E) / den
    cy = (2.0 * A * E - B * D) / den
    f0 = A * cx * cx + B * cx * cy + C * cy * cy + D * cx + E * cy + F
    lam = np.linalg.eigvalsh(np.array([[A, B / 2.0], [B / 2.0, C]]))
    if not (np.all(-f0 / lam > 0)):
        return None
    semi = np.sqrt(-f0 / lam)  # along the eigenvectors of the smaller, then larger, eigenvalue
    ang = 0.5 * math.atan2(B, A - C) + (0.5 * math.pi if abs(lam[0]) < abs(lam[1]) else 0.0)
    u = np.array([math.cos(ang), math.sin(ang)])
    q = np.array([[A, B / 2.0], [B / 2.0, C]])
    along = math.sqrt(-f0 / float(u @ q @ u))
    long_first = along >= float(semi.min()) * (1 + 1e-12)
    if not long_first:
        ang += 0.5 * math.pi
    size = 2.0 * k * np.array([float(semi.max()), float(semi.min())])
    return c0 + k * np.array([cx, cy]), size, axis_angle(np.array([math.cos(ang), math.sin(ang)]))


#: Passes of :meth:`Ellipse.fit_grown` with the fitted ellipse's normals, and Newton
#: steps to each vertex's foot on it.
FIT_REFINE, FOOT_NEWTON = 2, 6
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


@nb.njit(cache=True, inline="always")
def inside(f, k, dx, dy):  # pragma: no cover - compiled
    """Whether ``(dx, dy)`` (mm, from the centre) lies on packed ellipse ``f[k]`` (half
    axes ``f[k, 1:3]``, the angle's cosine and sine ``f[k, 4:6]``; closed)."""
    x = f[k, 4] * dx + f[k, 5] * dy
    y = -f[k, 5] * dx + f[k, 4] * dy
    u, v = x / f[k, 1], y / f[k, 2]
    return u * u + v * v <= 1.0


@nb.njit(cache=True, inline="always")
def half_width(f, k):  # pragma: no cover - compiled
    """Packed ellipse ``f[k]``'s half width: its short half axis, mm."""
    return f[k, 2]


@nb.njit(cache=True, inline="always")
def support_bound(c, s, a, b, cp, sp):  # pragma: no cover - compiled
    """The support (exact) of an ellipse of half axes ``a``, ``b`` turned by the angle of
    cosine ``cp`` and sine ``sp``, in the direction ``(c, s)``."""
    u, v = c * cp + s * sp, -c * sp + s * cp
    return np.sqrt(a * a * u * u + b * b * v * v)
