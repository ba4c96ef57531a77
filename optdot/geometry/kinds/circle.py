"""The circle: a disc of ``diameter`` mm, the paper's dot and the kind of every pattern
that does not name one."""

from __future__ import annotations

import math

import numba as nb
import numpy as np

from .base import MIN_VERTICES, Curve, Fit, Kind, polygon_vertices


class Circle(Kind):
    """A disc of ``diameter`` mm."""

    name = "circle"
    params = ("diameter",)
    round = True
    code = 0
    curve_form = "disc"
    profiles = ("ink", "bump", "dimple")

    def profile_frame(self, size: tuple[float, ...]) -> tuple[float, float, float]:
        return 0.5 * size[0], 0.5 * size[0], 0.0

    def shape_params(self, size: np.ndarray) -> np.ndarray:
        r = 0.5 * size[:, 0]
        return np.column_stack([r * r, np.zeros((len(r), 2))])

    def undrawable(self, size: np.ndarray) -> np.ndarray:
        return ~(size[:, 0] > 0)

    def disc(self, size: np.ndarray) -> np.ndarray:
        return size[:, 0].astype(np.float64, copy=True)

    def bound_params(self, size: np.ndarray) -> np.ndarray:
        r = 0.5 * size[:, 0]
        return np.column_stack([r, r])

    def spheres(self, size: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return np.zeros(1), np.array([0.5 * float(size[0])])

    def curve(self, size: np.ndarray) -> Curve:
        return Curve("disc", 0.5 * float(size[0]), 0.5 * float(size[0]))

    def area(self, size: np.ndarray) -> np.ndarray:
        return np.pi * 0.25 * size[:, 0] ** 2

    def extent(self, size: np.ndarray) -> np.ndarray:
        return 0.5 * size[:, 0]

    def equivalent_diameter(self, size: np.ndarray) -> np.ndarray:
        return size[:, 0].astype(np.float64, copy=True)

    def inradius(self, size: np.ndarray) -> np.ndarray:
        return 0.5 * size[:, 0]

    def aspect(self, size: np.ndarray) -> np.ndarray:
        return np.ones(len(size))

    def narrowest(self, size: np.ndarray) -> np.ndarray:
        return size[:, 0].astype(np.float64, copy=True)

    def support(self, theta, size, angle) -> np.ndarray:
        return np.broadcast_to(
            0.5 * size[..., 0], np.broadcast_shapes(np.shape(theta), size.shape[:-1])
        )

    def separation(self, d, size_i, angle_i, size_j, angle_j):
        n = np.hypot(d[:, 0], d[:, 1])
        u = np.where(n[:, None] > 0, d / np.where(n > 0, n, 1.0)[:, None], [1.0, 0.0])
        return n - 0.5 * (size_i[:, 0] + size_j[:, 0]), u

    def perimeter(self, size: np.ndarray) -> np.ndarray:
        return np.pi * size[:, 0]

    def curvature_floor(self, size: np.ndarray) -> np.ndarray:
        return 0.5 * size[:, 0]

    def parallel(self, size: np.ndarray, g: float) -> np.ndarray | None:
        return size + 2.0 * g

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

    def fit_grown(self, points: np.ndarray, g: float, slack: float, share: float = 0.0) -> Fit:
        """The circle through the vertices by least squares (a grid's snapping can merge
        or crowd them, which pulls their mean off the centre), grown by ``g``; a fit when
        their distances from its centre spread by at most ``slack + share r``."""
        x, y = points[:, 0], points[:, 1]
        m = np.column_stack([x, y, np.ones_like(x)])
        sol, *_ = np.linalg.lstsq(m, x * x + y * y, rcond=None)
        c = 0.5 * sol[:2]
        rad = np.hypot(*(points - c).T)
        r = float(np.sqrt(max(sol[2] + c @ c, 0.0)))
        ok = len(points) >= MIN_VERTICES and float(np.ptp(rad)) <= slack + share * r
        size = np.array([2.0 * (r + g)])
        return Fit(ok, c, size, 0.0, (float(rad.min()) + g, float(rad.max()) + g))


@nb.njit(cache=True, inline="always")
def inside(f, k, dx, dy):  # pragma: no cover - compiled
    """Whether ``(dx, dy)`` (mm, from the centre) lies on packed disc ``f[k]`` (``f[k,
    1]``: its radius squared; closed)."""
    return dx * dx + dy * dy <= f[k, 1]


@nb.njit(cache=True, inline="always")
def half_width(f, k):  # pragma: no cover - compiled
    """Packed disc ``f[k]``'s half width: its radius, mm."""
    return math.sqrt(f[k, 1])


@nb.njit(cache=True, inline="always")
def support_bound(c, s, a, b, cp, sp):  # pragma: no cover - compiled
    """The disc's support (its radius ``a``) in any direction."""
    return a
