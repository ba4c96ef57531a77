"""A prism sheet (a brightness enhancement film, BEF) between two air layers: a flat base
under a row of straight prisms (compiled).

The sheet is traced as a thin face: the prisms' pitch (tens of µm) is far below anything
the stack resolves, so where a ray meets the sheet, its place within the prisms' period
is drawn uniformly and the ray is followed through the prisms' cross-section, exactly,
as many times as it meets a surface: the flat base (Fresnel), the facets (Fresnel and
total internal reflection at each facet's normal), the next prism's facet for a ray that
leaves one and meets its neighbour. It ends leaving the sheet upwards (above the apexes,
in air) or downwards (through the base). What moves a ray sideways inside the sheet (at
most its thickness) is left out, and the sheet absorbs nothing.

Cross-section coordinates: ``u`` across the grooves (period 1), ``z`` up from the base
(the valleys); a prism of apex angle ``A`` rises to ``H = 1 / (2 tan(A / 2))``, its left
facet ``z = 2 H u`` (``0 <= u <= 1/2``), its right ``z = 2 H (1 - u)``. A direction's
component along the grooves is kept by every facet (their normals lie across them).

Face row: ``F_SHEET_T`` the prisms' index, ``F_SPREAD`` the grooves' axis (0 along x,
1 along y), ``F_SPREAD_SIG`` half the apex angle, radians.
"""

from __future__ import annotations

import math

import numba as nb

from ..rays import fresnel, uniform
from ..tables import CROSS, F_SHEET_T, F_SPREAD, F_SPREAD_SIG, NEW_LEG, SHEET

#: Surfaces a ray may meet inside one sheet before it counts as absorbed. Light near 30°
#: across the grooves can skim from prism to prism, out of a facet, into the next, totally
#: reflected by the base: 0.28 % of such rays outlived 64 surfaces (an independent tracer
#: let them all out within 200 legs); none of 10⁶ at 28°, 30° or 32° outlives 4,096.
MAX_BOUNCES = 4096


@nb.njit(cache=True)
def meet_prism(state, f, up, dxn, dyn, dz):  # pragma: no cover - compiled
    """A ray meeting the prism sheet (its face row ``f``) going up (``up``) or down:
    ``(state, act, dx, dy, dz)``: ``CROSS`` through it, ``NEW_LEG`` sent back, or the fate
    ``SHEET`` after :data:`MAX_BOUNCES` surfaces."""
    n = f[F_SHEET_T]
    along_y = f[F_SPREAD] > 0.5
    h = 0.5 / math.tan(f[F_SPREAD_SIG])
    p, q = (dxn, dyn) if along_y else (dyn, dxn)  # across, along the grooves
    w = dz
    state, u = uniform(state)
    inside = False
    z = 0.0
    if up:  # from below: the flat base first
        state, v = uniform(state)
        if v < fresnel(abs(w), 1.0, n):
            return state, NEW_LEG, dxn, dyn, -dz
        p, q, w = p / n, q / n, math.sqrt(max(0.0, 1.0 - (p * p + q * q) / (n * n)))
        inside = True
    else:  # from above: the plane of the apexes
        z = h
    for _ in range(MAX_BOUNCES):
        state, done, u, z, p, q, w, inside = _step(state, n, h, u, z, p, q, w, inside)
        if done:
            dx2, dy2 = (p, q) if along_y else (q, p)
            went_up = w > 0
            act = CROSS if went_up == up else NEW_LEG
            return state, act, dx2, dy2, w
    return state, SHEET, dxn, dyn, dz


@nb.njit(cache=True, inline="always")
def _step(state, n, h, u, z, p, q, w, inside):  # pragma: no cover - compiled
    """One leg in the cross-section from ``(u, z)`` along ``(p, q, w)`` to the next
    surface and what it does there: ``(state, done, u, z, p, q, w, inside)``; ``done``
    when the ray has left the sheet (up in air above the apexes, or down through the
    base)."""
    k = 2.0 * h  # the facets' slope
    big = 1e300
    t_left = (k * u - z) / (w - k * p) if w - k * p != 0.0 else big
    t_right = (k * (1.0 - u) - z) / (w + k * p) if w + k * p != 0.0 else big
    if t_left <= 1e-12 or not 0.0 <= u + p * t_left <= 0.5:
        t_left = big
    if t_right <= 1e-12 or not 0.5 <= u + p * t_right <= 1.0:
        t_right = big
    if inside:
        t_base = -z / w if w < 0 else big
        t = min(t_left, t_right, t_base)
        if t == t_base:  # the flat base: out into the air below, or back up
            u = u + p * t
            state, v = uniform(state)
            if v < fresnel(-w, n, 1.0):
                return state, False, u, 0.0, p, q, -w, True
            p, q = p * n, q * n
            return state, True, u, 0.0, p, q, -math.sqrt(max(0.0, 1.0 - p * p - q * q)), False
    else:
        t_top = (h - z) / w if w > 0 else big
        t_wall = -u / p if p < 0 else (1.0 - u) / p if p > 0 else big
        t = min(t_left, t_right, t_top, t_wall)
        if t == t_top:
            return state, True, u + p * t, h, p, q, w, False
        if t == t_wall:  # into the next period, in air above its valley
            return state, False, (0.0 if p > 0 else 1.0), z + w * t, p, q, w, False
    if t >= big:  # nothing ahead (rounding at an apex or a valley): it has left
        return state, True, u, z, p, q, w, inside
    u, z = u + p * t, z + w * t
    s = 1.0 / math.sqrt(1.0 + k * k)  # the facet's normal, out into the air
    nu, nz = (-k * s, s) if t == t_left else (k * s, s)
    c = p * nu + w * nz  # > 0 leaving the prism, < 0 entering it
    n1, n2 = (n, 1.0) if inside else (1.0, n)
    state, v = uniform(state)
    if v < fresnel(abs(c), n1, n2):  # reflected, on the same side
        return state, False, u, z, p - 2.0 * c * nu, q, w - 2.0 * c * nz, inside
    eta = n1 / n2
    cos_t = math.sqrt(max(0.0, 1.0 - eta * eta * (1.0 - c * c)))
    g = eta * abs(c) - cos_t  # along the normal pointing back at the incoming side
    sign = -1.0 if c > 0 else 1.0
    p, q, w = eta * p + g * sign * nu, eta * q, eta * w + g * sign * nz
    return state, False, u, z, p, q, w, not inside
