"""The convex polygon: a job's own vertices (a hexagonal dot, a triangular prism's base),
scaled to ``length`` × ``width`` mm, its gaps exact over the directions its Minkowski
difference can be nearest in.

Unlike the other kinds, a polygon kind is made per job: its vertices are the job's
(``[dots] vertices``), about the polygon's area centroid (the dot's centre) and rounded
to 1 nm, counter-clockwise. ``length`` and ``width`` are their extents along x and y; a
footprint of ``size = (L, W)`` is the vertices scaled by ``L / L0`` along x and ``W / W0``
along y (a job scales both alike). The registry holds a polygon without vertices, which
names the kind and recognises no footprint.
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

from .base import Curve, Fit, Kind, turned, unit_toward

#: Most vertices a polygon dot may have (each is two numbers of every packed footprint
#: the tracer tests, and a term of every pair's exact gap).
MAX_POLYGON_VERTICES = 12
#: Sine of the smallest turn between two edges a polygon's vertex may have (a vertex on a
#: straight side is no corner: drawn, it would read back as a side).
MIN_TURN = 1e-3
#: Shortest side of a polygon dot, mm (a mask's grid draws none shorter).
MIN_SIDE = 1e-4


def polygon_problem(vertices) -> str | None:
    """Why ``vertices`` (a job's ``[dots] vertices``: ``[[x, y], ...]`` mm) are not a
    convex polygon optdot draws, or None."""
    ok = isinstance(vertices, list | tuple) and all(
        isinstance(v, list | tuple)
        and len(v) == 2
        and all(isinstance(c, int | float) and not isinstance(c, bool) for c in v)
        for v in vertices
    )
    if not ok:
        return "must be a list of [x, y] pairs in mm"
    try:
        v = np.asarray(vertices, np.float64).reshape(-1, 2)
    except OverflowError:
        return "holds a number that is not finite"
    if not np.isfinite(v).all():
        return "holds a number that is not finite"
    if not 3 <= len(v) <= MAX_POLYGON_VERTICES:
        return f"has {len(v)} vertices; a polygon dot has 3 to {MAX_POLYGON_VERTICES}"
    e = np.roll(v, -1, axis=0) - v
    short = np.hypot(*e.T) < MIN_SIDE
    if short.any():
        k = int(np.argmax(short))
        return (
            f"repeats a vertex (vertices {k + 1} and {(k + 1) % len(v) + 1} are under "
            f"{MIN_SIDE * 1e3:g} µm apart)"
        )
    f = np.roll(e, -1, axis=0)  # the side after each
    turn = (e[:, 0] * f[:, 1] - e[:, 1] * f[:, 0]) / (np.hypot(*e.T) * np.hypot(*f.T))
    if not ((turn > MIN_TURN).all() or (turn < -MIN_TURN).all()):
        k = int(np.argmin(np.abs(turn)) if (np.abs(turn) <= MIN_TURN).any() else 0)
        return (
            f"is not a convex polygon in order (at vertex {(k + 1) % len(v) + 1}: "
            "a straight or reflex corner, or the vertices out of order)"
        )
    angles = np.arctan2(e[:, 1], e[:, 0])
    total = np.sum(np.mod(np.diff(np.append(angles, angles[0])) + np.pi, 2 * np.pi) - np.pi)
    if abs(abs(total) - 2 * np.pi) > 1e-6:
        return "crosses itself (its edges turn more than once around)"
    return None


def canonical(vertices) -> np.ndarray:
    """``[v, 2]`` the checked ``vertices`` (:func:`polygon_problem` None) counter-clockwise
    from the lowest-leftmost, about their area centroid, rounded to 1 nm (mm): the same
    polygon however it was written down."""
    v = np.asarray(vertices, np.float64).reshape(-1, 2)
    c = _centroid(v if _signed_area(v) > 0 else v[::-1])
    return _in_order(np.round(v - c, 6) + 0.0)


def _in_order(v: np.ndarray) -> np.ndarray:
    """``v`` (``[m, 2]``) counter-clockwise, from its lowest-leftmost vertex."""
    if _signed_area(v) < 0:
        v = v[::-1]
    first = int(np.lexsort((v[:, 1], v[:, 0]))[0])
    return np.roll(v, -first, axis=0)


def narrowest(v: np.ndarray) -> tuple[float, float]:
    """``(width, diameter)`` of the convex polygon ``v`` (``[m, 2]``): its least width
    between two parallel lines (attained across one of its sides) and its largest,
    between its two farthest vertices."""
    e = np.roll(v, -1, axis=0) - v
    cross = e[:, None, 0] * (v[None, :, 1] - v[:, None, 1]) - e[:, None, 1] * (
        v[None, :, 0] - v[:, None, 0]
    )
    width = float((np.abs(cross).max(axis=1) / np.hypot(*e.T)).min())
    diameter = float(np.hypot(*(v[:, None, :] - v[None, :, :]).transpose(2, 0, 1)).max())
    return width, diameter


def _signed_area(v: np.ndarray) -> float:
    """Twice the signed area of the polygon ``v`` (``[m, 2]``; > 0 counter-clockwise)."""
    x, y = v[:, 0], v[:, 1]
    return float(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1)))


def _centroid(v: np.ndarray) -> np.ndarray:
    """``[2]`` the area centroid of the polygon ``v`` (``[m, 2]``)."""
    x, y = v[:, 0], v[:, 1]
    x1, y1 = np.roll(x, -1), np.roll(y, -1)
    cross = x * y1 - x1 * y
    a2 = float(cross.sum())
    return np.array([((x + x1) * cross).sum(), ((y + y1) * cross).sum()]) / (3.0 * a2)


class Polygon(Kind):
    """A convex polygon of the job's ``vertices`` (``[v, 2]`` mm about the area centroid,
    counter-clockwise, :func:`canonical`), scaled to ``length`` × ``width`` mm (its
    extents along x and y; either may be the larger)."""

    name = "polygon"
    params = ("length", "width")
    code = 3
    #: ``[dots]`` keys the kind reads besides its size parameters, which it derives.
    keys = {"vertices": (list,)}
    derived = True
    made_otherwise = " of other vertices"

    def __init__(self, vertices=None):
        self.base = None if vertices is None else np.asarray(vertices, np.float64)
        if self.base is not None:
            self.base.setflags(write=False)
            self.l0, self.w0 = (float(v) for v in np.ptp(self.base, axis=0))
            self.a0 = 0.5 * _signed_area(self.base)
            self.period = _period(self.base)

    # a kind made per job: equal when its vertices are, pickled with them

    def __eq__(self, other) -> bool:
        if not isinstance(other, Polygon):
            return NotImplemented
        if self.base is None or other.base is None:
            return self.base is None and other.base is None
        return self.base.shape == other.base.shape and bool((self.base == other.base).all())

    def __hash__(self) -> int:
        return hash(("polygon", None if self.base is None else self.base.tobytes()))

    def __reduce__(self):
        if self.base is None:  # the registry's own
            return super().__reduce__()
        return (Polygon, (self.base.tolist(),))

    def __repr__(self) -> str:
        return "Polygon()" if self.base is None else f"Polygon({self.base.tolist()})"

    def from_job(self, dots: dict, where: str) -> tuple[Kind, tuple[float, ...]]:
        """The job's polygon and its size from ``[dots] vertices``.

        Raises:
            ValueError: the vertices are not a convex polygon (the message names why).
        """
        if "vertices" not in dots:
            raise ValueError('dots.shape = "polygon" needs dots.vertices = [[x, y], ...] (mm)')
        problem = polygon_problem(dots["vertices"])
        if problem is not None:
            raise ValueError(f"dots.vertices {problem}")
        v = canonical(dots["vertices"])
        problem = polygon_problem(v.tolist())  # a side or a corner the 1 nm rounding took
        if problem is not None:
            raise ValueError(f"dots.vertices, rounded to 1 nm, {problem}")
        kind = Polygon(v)
        return kind, (kind.l0, kind.w0)

    def from_spec(self, spec: dict) -> Polygon:
        """The polygon of a file's ``vertices_mm`` (as written: about the dot's centre),
        counter-clockwise.

        Raises:
            ValueError: no vertices, or not a convex polygon.
        """
        if not isinstance(spec, dict) or "vertices_mm" not in spec:
            raise ValueError("a polygon's vertices_mm are missing")
        problem = polygon_problem(spec["vertices_mm"])
        if problem is not None:
            raise ValueError(f"vertices_mm {problem}")
        return Polygon(_in_order(np.asarray(spec["vertices_mm"], np.float64)))

    def spec(self) -> dict:
        """What a file holds to name this kind besides its name: the vertices, mm."""
        return {"vertices_mm": self.base.tolist()}

    def _scaled(self, size: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(sx [n], sy [n])``: each footprint's scale of the vertices along x and y."""
        return size[:, 0] / self.l0, size[:, 1] / self.w0

    def vertices(self, size: np.ndarray) -> np.ndarray:
        """``[v, 2]`` the vertices of one footprint of ``size`` (``[2]`` mm) at angle 0."""
        return self.base * (np.asarray(size, np.float64)[:2] / (self.l0, self.w0))

    def shape_params(self, size: np.ndarray) -> np.ndarray:
        sx, sy = self._scaled(size)
        return np.column_stack([sx, sy, np.full(len(size), float(len(self.base)))])

    def packed_extra(self, size: np.ndarray) -> np.ndarray:
        """``[n, 2v]`` the vertices (x, y in turn), the same for every footprint: what the
        compiled :func:`inside` tests a point against after undoing the scale."""
        return np.broadcast_to(self.base.ravel(), (len(size), self.base.size))

    def bound_params(self, size: np.ndarray) -> np.ndarray:
        sx, sy = self._scaled(size)  # the box symmetric about the centre
        bx, by = np.abs(self.base).max(axis=0)
        return np.column_stack([sx * bx, sy * by])

    def undrawable(self, size: np.ndarray) -> np.ndarray:
        return ~(size[:, 0] > 0) | ~(size[:, 1] > 0)

    def aspect(self, size: np.ndarray) -> np.ndarray:
        """Its largest width over its least (across a side), whichever way it is turned."""
        out = [narrowest(self.vertices(row)) for row in np.asarray(size, np.float64)]
        return np.array([d / w for w, d in out])

    def narrowest(self, size: np.ndarray) -> np.ndarray:
        """``[n]`` its least width between two parallel lines, mm."""
        return np.array([narrowest(self.vertices(row))[0] for row in np.asarray(size)])

    def inradius(self, size: np.ndarray) -> np.ndarray:
        """``[n]`` the distance from the centre to the nearest side, mm."""
        sx, sy = self._scaled(size)
        b, e = self.base, np.roll(self.base, -1, axis=0) - self.base
        # side k's line through s b_k along s e_k: distance |cross(s b_k, s e_k)| / |s e_k|
        cross = np.abs(b[:, 0] * e[:, 1] - b[:, 1] * e[:, 0])  # [v]
        length = np.hypot(sx[:, None] * e[None, :, 0], sy[:, None] * e[None, :, 1])
        return ((sx * sy)[:, None] * cross[None, :] / length).min(axis=1)

    def spheres(self, size: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """One circle about the centre: inscribed while the polygon relaxes by its exact
        gap, through the farthest vertex (covering) when it relaxes by circles."""
        size = np.asarray(size, np.float64)[None, :2]
        if self.relaxation == "spheres":
            return np.zeros(1), self.extent(size)
        return np.zeros(1), self.inradius(size)

    def curve(self, size: np.ndarray) -> Curve:
        ring = tuple((float(x), float(y), 0.0) for x, y in self.vertices(size))
        return Curve("bulged", ring=ring)

    def area(self, size: np.ndarray) -> np.ndarray:
        sx, sy = self._scaled(size)
        return self.a0 * sx * sy

    def perimeter(self, size: np.ndarray) -> np.ndarray:
        sx, sy = self._scaled(size)
        e = np.roll(self.base, -1, axis=0) - self.base
        return np.hypot(sx[:, None] * e[None, :, 0], sy[:, None] * e[None, :, 1]).sum(axis=1)

    def fill_share(self, size: np.ndarray) -> np.ndarray:
        """Sharp corners lower the fill polygons are dealt at, by their roundness ``q =
        4π area / perimeter²`` (1 for a disc): 1 from a square's 0.785 up, 0.88 at a
        triangle's 0.6, on a line between and beyond. Measured (uniform 3 × 3 mm maps, 5
        µm gap, random angles, effective fill): hexagons and squares hold at 0.66; an
        equilateral triangle at 0.58; a scalene triangle (q 0.598) holds at 0.58 and
        fails at 0.62."""
        q = 4.0 * np.pi * self.area(size) / self.perimeter(size) ** 2
        return np.clip(0.88 + (q - 0.6) * (0.12 / 0.185), 0.1, 1.0)

    def curvature_floor(self, size: np.ndarray) -> np.ndarray:
        """0: every vertex is a sharp corner."""
        return np.zeros(len(size))

    def angle_lever(self, size: np.ndarray) -> float:
        """The farthest vertex's distance, mm: a turn of δ moves it by this times δ."""
        return float(self.extent(np.asarray(size, np.float64)[None, :2])[0])

    def extent(self, size: np.ndarray) -> np.ndarray:
        sx, sy = self._scaled(size)
        x, y = sx[:, None] * self.base[None, :, 0], sy[:, None] * self.base[None, :, 1]
        return np.hypot(x, y).max(axis=1)

    def support(self, theta, size, angle) -> np.ndarray:
        """``max_k <R(angle) S b_k, u(θ)>`` over the scaled, turned vertices."""
        sx, sy = self._scaled(np.atleast_2d(size))
        t = np.asarray(theta) - np.asarray(angle)
        c, s = np.cos(t)[..., None], np.sin(t)[..., None]
        x = np.asarray(sx)[..., None] * self.base[:, 0]
        y = np.asarray(sy)[..., None] * self.base[:, 1]
        return (x * c + y * s).max(axis=-1)

    def separation(self, d, size_i, angle_i, size_j, angle_j):
        """Exact: the gap ``max_u <d, u> - h_i(u) - h_j(-u)`` (a polygon need not be
        symmetric) is the signed distance from ``d`` to the Minkowski difference of the
        two polygons, which is attained along one of its edge normals (the two polygons'
        outward normals, j's turned back) or along the direction from one of its vertices
        (differences of the two polygons' vertices) to ``d``."""
        c = np.ascontiguousarray
        sxi, syi = self._scaled(size_i)
        sxj, syj = self._scaled(size_j)
        gap, u = np.empty(len(d)), np.empty((len(d), 2))
        _polygon_gaps(
            c(d, dtype=np.float64), c(self.base), c(sxi), c(syi), c(angle_i, dtype=np.float64),
            c(sxj), c(syj), c(angle_j, dtype=np.float64), gap, u,
        )  # fmt: skip
        return gap, u

    def outline(self, size, angle, tolerance) -> np.ndarray:
        """The vertices themselves (exact)."""
        return turned(self.vertices(size), angle)

    def parallel_outline(self, size, g, tolerance) -> np.ndarray:
        """Shrunk (``g < 0``): its sides moved in, a polygon; grown: its sides moved out
        and its corners rounded to ``g``, arcs inscribed within ``tolerance``."""
        import shapely

        poly = shapely.Polygon(self.vertices(size))
        if g < 0:
            out = poly.buffer(g, join_style="mitre", mitre_limit=1e6)
        else:
            seg = max(1, math.ceil(0.5 * math.pi / math.acos(max(1.0 - tolerance / g, -1.0))))
            out = poly.buffer(g, quad_segs=seg) if g > 0 else poly
        ring = np.asarray(shapely.get_coordinates(shapely.normalize(out).exterior))[:-1]
        return ring[::-1] if _signed_area(ring) < 0 else ring

    def fit_grown(self, points: np.ndarray, g: float, slack: float, share: float = 0.0) -> Fit:
        """:meth:`fit` of the polygon grown by ``g`` (its sides moved out; shrunk when
        negative): a mask drawn for a print that moves every side by ``g``. Shrunk, the
        mask's sides are its longest edges and its corners arcs of radius ``-g`` about the
        print's corners: each corner is the centre of its arc's vertices (two nearly
        parallel sides would place a sharp tip many times less well)."""
        import shapely

        pts = np.asarray(points, np.float64)
        v = len(self.base) if self.base is not None else 0
        if g < 0 and v and len(pts) > v:
            ring = pts if _signed_area(pts) > 0 else pts[::-1]
            e = np.roll(ring, -1, axis=0) - ring
            length = np.hypot(*e.T)
            order = np.argsort(length)[::-1]
            if length[order[v - 1]] > 2.0 * length[order[v]]:  # the sides stand out
                k = np.sort(order[:v])
                n = np.column_stack([e[k, 1], -e[k, 0]]) / length[k, None]  # outward
                p = ring[k] + g * n
                d = e[k]
                corners = np.empty((v, 2))
                for i in range(v):  # the arc from side i's end to side i + 1's start
                    j = (i + 1) % v
                    arc = ring[np.arange(k[i] + 1, k[j] + 1 + (len(ring) if j == 0 else 0))
                               % len(ring)]  # fmt: skip
                    guess = _meet(p[i], d[i], p[j], d[j])
                    corners[i] = _arc_centre(arc, -g, guess)
                return self.fit(corners, slack, share)
        poly = shapely.Polygon(pts)
        grown = poly.buffer(g, join_style="round", quad_segs=16) if g else poly
        if grown.is_empty or grown.geom_type != "Polygon":
            return self.fit(points, slack, share)
        ring = np.asarray(shapely.get_coordinates(grown.exterior))[:-1]
        return self.fit(ring, slack, share)

    def fit(self, points: np.ndarray, slack: float, share: float = 0.0) -> Fit:
        """The scale, angle and centre that lay the vertices on the polygon ``points``
        (``[m, 2]``, any unit; at least one point near each vertex): the angle from the
        support functions' correlation, then the least-squares similarity of the
        vertices to the points nearest them. A fit when every point lies within ``t =
        slack + share L`` of the fitted outline and the areas agree within its
        perimeter times ``t``. The angle is the least of the polygon's symmetric turns."""
        pts = np.asarray(points, np.float64)
        a2 = _signed_area(pts) if len(pts) >= 3 else 0.0
        if self.base is None or len(pts) < len(self.base) or a2 == 0.0:
            centre = pts.mean(axis=0) if len(pts) else np.zeros(2)
            rad = np.hypot(*(pts - centre).T) if len(pts) else np.zeros(1)
            return Fit(False, centre, np.zeros(2), 0.0, (float(rad.min()), float(rad.max())))
        if a2 < 0:
            pts = pts[::-1]
        centre = _centroid(pts)
        q = pts - centre
        s = math.sqrt(abs(0.5 * a2) / self.a0)
        theta = _coarse_turn(q, s * self.base)
        b = self.base[:, 0] + 1j * self.base[:, 1]
        p = q[:, 0] + 1j * q[:, 1]
        near = np.abs(p[None, :] - (s * np.exp(1j * theta) * b)[:, None]).argmin(axis=1)
        pm, bm = p[near], b
        z = np.vdot(bm - bm.mean(), pm - pm.mean()) / np.vdot(bm - bm.mean(), bm - bm.mean())
        shift = pm.mean() - z * bm.mean()
        s, theta = abs(z), math.atan2(z.imag, z.real)
        centre = centre + np.array([shift.real, shift.imag])
        size = np.array([s * self.l0, s * self.w0])
        ring = turned(self.vertices(size), theta)
        rel = pts - centre
        tol = slack + share * max(size)
        dist = _ring_distance(rel, ring)
        area = self.area(size[None])[0]
        rad = np.hypot(*rel.T)
        ok = bool(
            dist.max() <= tol and abs(abs(0.5 * a2) - area) <= self.perimeter(size[None])[0] * tol
        )
        per = self.period
        theta = theta - per * math.floor((theta + 0.5 * per) / per)  # in [-per/2, per/2)
        return Fit(ok, centre, size, theta, (float(rad.min()), float(rad.max())))


def _arc_centre(arc: np.ndarray, r: float, guess: np.ndarray) -> np.ndarray:
    """``[2]`` the centre of the circle of radius ``r`` nearest the points ``arc`` (``[m,
    2]``) in least squares, by Gauss-Newton steps from ``guess`` (the guess itself for
    fewer than 3 points)."""
    c = np.asarray(guess, np.float64).copy()
    if len(arc) < 3:
        return c
    for _ in range(8):
        w = c - arc
        dist = np.hypot(*w.T)
        jac = w / dist[:, None]
        step, *_ = np.linalg.lstsq(jac, r - dist, rcond=None)
        c += step
        if np.hypot(*step) <= 1e-12 * abs(r):
            break
    return c


def _meet(p: np.ndarray, d: np.ndarray, q: np.ndarray, e: np.ndarray) -> np.ndarray:
    """``[2]`` where the line through ``p`` along ``d`` meets the one through ``q`` along
    ``e``."""
    den = d[0] * e[1] - d[1] * e[0]
    t = ((q[0] - p[0]) * e[1] - (q[1] - p[1]) * e[0]) / den
    return p + t * d


def _period(base: np.ndarray) -> float:
    """The least turn (rad) that maps the polygon ``base`` (about its centroid) onto
    itself: 2π/k for a k-fold symmetric one, 2π for none."""
    v = len(base)
    scale = float(np.hypot(*base.T).max())
    b = base[:, 0] + 1j * base[:, 1]
    for k in range(v, 1, -1):
        if v % k:
            continue
        r = b * np.exp(2j * np.pi / k)
        # the vertices are rounded to 1 nm: equal within 2 nm
        if np.abs(r[:, None] - b[None, :]).min(axis=1).max() <= max(1e-6 * scale, 2e-6):
            return 2.0 * math.pi / k
    return 2.0 * math.pi


#: Directions the fit's coarse angle compares support functions in (0.5°: the vertices'
#: matching needs it within half the least turn between two of them).
FIT_DIRECTIONS = 720


def _coarse_turn(q: np.ndarray, base: np.ndarray) -> float:
    """The turn (rad, to 0.5°) that best lays ``base``'s support function on ``q``'s
    (both ``[m, 2]`` about their centroids): their circular correlation's peak."""
    phi = 2.0 * np.pi * np.arange(FIT_DIRECTIONS) / FIT_DIRECTIONS
    u = np.column_stack([np.cos(phi), np.sin(phi)])
    hq, hb = (q @ u.T).max(axis=0), (base @ u.T).max(axis=0)
    corr = np.fft.irfft(np.fft.rfft(hq) * np.conj(np.fft.rfft(hb)), FIT_DIRECTIONS)
    return float(phi[int(np.argmax(corr))])


def _ring_distance(p: np.ndarray, ring: np.ndarray) -> np.ndarray:
    """``[m]`` each point's distance to the closed polyline ``ring`` (``[v, 2]``)."""
    a = ring[None, :, :]
    e = np.roll(ring, -1, axis=0)[None, :, :] - a
    w = p[:, None, :] - a
    t = np.clip((w * e).sum(-1) / (e * e).sum(-1), 0.0, 1.0)
    return np.hypot(*(w - t[..., None] * e).transpose(2, 0, 1)).min(axis=1)


@nb.njit(cache=True)
def _polygon_gaps(d, base, sxi, syi, pi, sxj, syj, pj, gap, u):  # pragma: no cover
    """Per pair of polygons (the vertices ``base [v, 2]`` scaled by ``sx``, ``sy`` and
    turned by ``p``): the best of the edge normals and vertex directions of their
    Minkowski difference (see :meth:`Polygon.separation`), into ``gap [m]`` and ``u [m,
    2]``."""
    v = base.shape[0]
    a = np.empty((v, 2))
    b = np.empty((v, 2))
    cand = np.empty((2 * v + v * v, 2))
    for m in range(d.shape[0]):
        ci, si = math.cos(pi[m]), math.sin(pi[m])
        cj, sj = math.cos(pj[m]), math.sin(pj[m])
        for k in range(v):
            x, y = sxi[m] * base[k, 0], syi[m] * base[k, 1]
            a[k, 0], a[k, 1] = ci * x - si * y, si * x + ci * y
            x, y = sxj[m] * base[k, 0], syj[m] * base[k, 1]
            b[k, 0], b[k, 1] = cj * x - sj * y, sj * x + cj * y
        n = 0
        for k in range(v):  # outward normals of i's sides, and of j's turned back
            k1 = (k + 1) % v
            for poly, sign in ((a, 1.0), (b, -1.0)):
                ex, ey = poly[k1, 0] - poly[k, 0], poly[k1, 1] - poly[k, 1]
                le = math.sqrt(ex * ex + ey * ey)
                cand[n, 0], cand[n, 1] = sign * ey / le, -sign * ex / le
                n += 1
        dx, dy = d[m, 0], d[m, 1]
        for k in range(v):  # from each vertex difference to d
            for q in range(v):
                w = unit_toward(dx - (a[k, 0] - b[q, 0]), dy - (a[k, 1] - b[q, 1]))
                cand[n, 0], cand[n, 1] = w
                n += 1
        best, bx, by = -1e300, 1.0, 0.0
        for c in range(n):
            ux, uy = cand[c, 0], cand[c, 1]
            hi, hj = -1e300, -1e300
            for k in range(v):
                hi = max(hi, a[k, 0] * ux + a[k, 1] * uy)
                hj = max(hj, -(b[k, 0] * ux + b[k, 1] * uy))
            f = dx * ux + dy * uy - hi - hj
            if f > best:
                best, bx, by = f, ux, uy
        gap[m] = best
        u[m, 0], u[m, 1] = bx, by


@nb.njit(cache=True, inline="always")
def inside(f, k, dx, dy):  # pragma: no cover - compiled
    """Whether ``(dx, dy)`` (mm, from the centre) lies on packed polygon ``f[k]`` (scale
    along x and y ``f[k, 1:3]``, vertex count ``f[k, 3]``, the angle's cosine and sine
    ``f[k, 4:6]``, the vertices from ``f[k, 6]``; closed): left of every side, in the
    unscaled frame (a scale keeps which side a point is on)."""
    x = (f[k, 4] * dx + f[k, 5] * dy) / f[k, 1]
    y = (-f[k, 5] * dx + f[k, 4] * dy) / f[k, 2]
    v = int(f[k, 3])
    for q in range(v):
        q1 = (q + 1) % v
        ax, ay = f[k, 6 + 2 * q], f[k, 7 + 2 * q]
        ex, ey = f[k, 6 + 2 * q1] - ax, f[k, 7 + 2 * q1] - ay
        if ex * (y - ay) - ey * (x - ax) < 0.0:
            return False
    return True


@nb.njit(cache=True, inline="always")
def support_bound(c, s, a, b, cp, sp):  # pragma: no cover - compiled
    """The support of the box of half sides ``a``, ``b`` about the centre (at least the
    polygon's, either way along ``(c, s)``) turned by the angle of cosine ``cp`` and
    sine ``sp``."""
    u, v = c * cp + s * sp, -c * sp + s * cp
    return a * abs(u) + b * abs(v)
