"""Dots that are 3-D structures on the guide's bottom face (compiled): a cap of the
guide's material standing out of the face (a bump, moulded or embossed) or a cap of air
cut into it (a dimple, a laser crater), spherical on a circle and stretched along an
ellipse's long axis; a micro-prism on a rectangle, standing out or cut in
(:mod:`optdot.geometry.profile`).

Where the stepping finds a ray on a dot (the print test at the face's plane), the ray is
followed through the dot's surfaces exactly, as many times as it meets them: Fresnel and
total internal reflection at the local normal, Snell through it. A raised dot's ray
goes down into it through the plane of the face, and leaves it back up through that
plane (into the guide) or out through its surface (into the air under the guide). A cut
dot's ray meets the cavity's surface on its way down (where its path enters the cavity,
behind the plane's crossing); through it, it crosses the cavity's air and leaves through
the surface (back into the guide) or down through the cavity's open base (into the air
under the guide). Under the guide, the reflector returns it as it returns light out of
the flat face (:mod:`.reflector`); light going up there meets the flat face. Every dot
is convex: light reflected off one from outside does not meet it again.

On real dots the ray meets the dot where the stepping found it, in the dot's own frame
(turned by its angle); in a coverage trace the point is drawn uniformly over the
footprint and the angle is the orientation's at that cell (drawn, for random angles).
What moves a ray sideways inside a dot (at most its length) is left out, as is light
leaving one structure into another.

Cap coordinates: the footprint's half width 1, the face's plane ``z = 0``, the guide
above; a cap of height ``k`` (its height over the half width, at most 1: a hemisphere
across the short axis) on an ellipse ``e`` times longer than wide is the surface
``x²/e² + y² + (z - c)² = R²`` with ``R = (1 + k²) / (2k)``, ``c = R - k`` (a bump,
below the plane) or ``k - R`` (a dimple, above it): a sphere for ``e = 1``.

Prism coordinates: mm, ``u`` along the dot's length, ``v`` across it, ``s`` from the
face into the structure (down for a raised prism, up into the guide for a cut one); the
body is ``0 <= s <= t1 (u + L/2)``, ``s <= t2 (L/2 - u)`` over its footprint (vertical
sides), ``t1``, ``t2`` the facets' slopes.
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

from ...geometry.profile import BUMP, DIMPLE, PRISM, PRISM_CUT
from ..rays import fresnel, mirrored, refract, uniform
from ..tables import (
    BOTTOM,
    DOT,
    F_PROF_C,
    F_PROF_K,
    F_PROF_T1,
    F_PROF_T2,
    F_PROF_U,
    F_PROF_V,
    F_PROFILE,
    F_REFL,
    F_REFL_FINISH,
    NEW_LEG,
    SAME_LEG,
)
from .reflector import meet_reflector, sheet_return

__all__ = ["BUMP", "DIMPLE", "PRISM", "PRISM_CUT", "meet_profile", "trace_cap", "trace_prism"]

#: Where a ray leaves a dot: back up into the guide, into the air under the guide, caught
#: (after :data:`MAX_BOUNCES` surfaces), or in the guide going down onto the flat face
#: beside a dimple.
INTO_GUIDE, INTO_AIR, CAUGHT, ONTO_FACE = 0, 1, 2, 3
#: Surfaces a ray may meet inside one dot before it counts as absorbed by it. A ray
#: grazing a bump's rim circles it by total reflection along a great circle, advancing
#: twice its grazing angle a meeting, until it reaches the face's plane: 4,096 meetings
#: let out a ray grazing at 0.02° (2 in 10⁶ Lambertian rays outlived 64).
MAX_BOUNCES = 4096


@nb.njit(cache=True, inline="always")
def _quadric(q, ox, oy, oz, dx, dy, dz, r):  # pragma: no cover - compiled
    """``(a, b, c)`` of the cap surface's equation ``a t² + 2 b t + c = 0`` along the ray
    from ``o`` (relative to the surface's centre) going ``d``; ``q = 1/e²``."""
    a = q * dx * dx + dy * dy + dz * dz
    b = q * ox * dx + oy * dy + oz * dz
    c = q * ox * ox + oy * oy + oz * oz - r * r
    return a, b, c


@nb.njit(cache=True, inline="always")
def _normal(q, ox, oy, oz):  # pragma: no cover - compiled
    """The cap surface's outward unit normal at ``o`` (relative to its centre)."""
    gx, gy = q * ox, oy
    g = math.sqrt(gx * gx + gy * gy + oz * oz)
    return gx / g, gy / g, oz / g


@nb.njit(cache=True)
def trace_cap(state, code, k, e, n, px, py, dx, dy, dz):  # pragma: no cover - compiled
    """A ray going down (``dz < 0``) in the guide of index ``n`` whose path crosses the
    face's plane at ``(px, py)`` (the footprint's half width 1, ``x`` along its long
    axis) on a cap of profile ``code``, height ``k`` and elongation ``e``: ``(state,
    where, dx, dy, dz)``, ``where`` one of :data:`INTO_GUIDE`, :data:`INTO_AIR`,
    :data:`CAUGHT`, :data:`ONTO_FACE`, with the direction it goes on in."""
    r_s = (1.0 + k * k) / (2.0 * k)
    q = 1.0 / (e * e)
    bump = code == BUMP
    cz = r_s - k if bump else k - r_s
    n_in, n_out = (n, 1.0) if bump else (1.0, n)  # inside the surface, outside it
    pz = 0.0
    if not bump:  # back along the path to where it met the cavity, from the guide
        a, b, c = _quadric(q, px, py, -cz, dx, dy, dz, r_s)
        t = (-b - math.sqrt(max(b * b - a * c, 0.0))) / a
        px, py, pz = px + t * dx, py + t * dy, t * dz
        mx, my, mz = _normal(q, px, py, pz - cz)  # out of the cap
        cos_i = -(dx * mx + dy * my + dz * mz)
        state, u = uniform(state)
        if u < fresnel(cos_i, n, 1.0):  # reflected back into the guide
            dx, dy, dz = dx + 2.0 * cos_i * mx, dy + 2.0 * cos_i * my, dz + 2.0 * cos_i * mz
            return state, (INTO_GUIDE if dz > 0 else ONTO_FACE), dx, dy, dz
        dx, dy, dz = _through(dx, dy, dz, -mx, -my, -mz, n, 1.0)
    for _ in range(MAX_BOUNCES):
        leaves = dz > 0 if bump else dz < 0
        t_plane = -pz / dz if leaves else 1e300
        a, b, c = _quadric(q, px, py, pz - cz, dx, dy, dz, r_s)
        t_cap = (-b + math.sqrt(max(b * b - a * c, 0.0))) / a
        if t_plane <= t_cap:  # out through the face's plane
            return state, (INTO_GUIDE if bump else INTO_AIR), dx, dy, dz
        px, py, pz = px + t_cap * dx, py + t_cap * dy, pz + t_cap * dz
        mx, my, mz = _normal(q, px, py, pz - cz)
        cos_i = dx * mx + dy * my + dz * mz
        state, u = uniform(state)
        if u < fresnel(cos_i, n_in, n_out):  # reflected, inside again
            dx, dy, dz = dx - 2.0 * cos_i * mx, dy - 2.0 * cos_i * my, dz - 2.0 * cos_i * mz
            continue
        dx, dy, dz = _through(dx, dy, dz, mx, my, mz, n_in, n_out)
        if bump:
            return state, INTO_AIR, dx, dy, dz
        return state, (INTO_GUIDE if dz > 0 else ONTO_FACE), dx, dy, dz
    return state, CAUGHT, dx, dy, dz


@nb.njit(cache=True)
def wall_exit(pu, pv, du, dv, hu, hv, rc):  # pragma: no cover - compiled
    """Where a ray at ``(pu, pv)`` going ``(du, dv)`` (horizontal parts, not unit) leaves
    a rounded rectangle of half sides ``hu``, ``hv`` and corner radius ``rc`` (mm, about
    the origin), from inside: ``(t, mu, mv)``, the ray's parameter there (inf if it
    does not move) and the edge's outward unit normal."""
    t, mu, mv = np.inf, 0.0, 0.0
    if du > 0:
        t, mu = (hu - pu) / du, 1.0
    elif du < 0:
        t, mu = (-hu - pu) / du, -1.0
    if dv != 0:
        tv = ((hv if dv > 0 else -hv) - pv) / dv
        if tv < t:
            t, mu, mv = tv, 0.0, (1.0 if dv > 0 else -1.0)
    if rc > 0 and t < np.inf:
        qu, qv = pu + t * du, pv + t * dv
        cu, cv = hu - rc, hv - rc
        if abs(qu) > cu and abs(qv) > cv:  # in a corner's square: out through its arc
            ou, ov = pu - math.copysign(cu, qu), pv - math.copysign(cv, qv)
            a = du * du + dv * dv
            b = ou * du + ov * dv
            c = ou * ou + ov * ov - rc * rc
            t = (-b + math.sqrt(max(b * b - a * c, 0.0))) / a
            wu, wv = ou + t * du, ov + t * dv
            w = math.sqrt(wu * wu + wv * wv)
            mu, mv = wu / w, wv / w
    return t, mu, mv


@nb.njit(cache=True)
def prism_exit(pu, pv, ps, du, dv, ds, hu, hv, rc, t1, t2):  # pragma: no cover - compiled
    """Where a ray inside a prism's body (prism coordinates) leaves it: ``(t, mu, mv, ms,
    base)``, the ray's parameter (>= 0), the surface's outward unit normal, and whether
    that is the open base on the face's plane."""
    t, mu, mv, ms, base = np.inf, 0.0, 0.0, 0.0, False
    if ds < 0:
        t, ms, base = -ps / ds, -1.0, True
    dn = ds - t1 * du  # the first facet, s - t1 u <= t1 hu
    if dn > 0:
        tf = (t1 * (hu + pu) - ps) / dn
        if tf < t:
            g = 1.0 / math.sqrt(1.0 + t1 * t1)
            t, mu, mv, ms, base = tf, -t1 * g, 0.0, g, False
    dn = ds + t2 * du  # the second, s + t2 u <= t2 hu
    if dn > 0:
        tf = (t2 * (hu - pu) - ps) / dn
        if tf < t:
            g = 1.0 / math.sqrt(1.0 + t2 * t2)
            t, mu, mv, ms, base = tf, t2 * g, 0.0, g, False
    tw, wu, wv = wall_exit(pu, pv, du, dv, hu, hv, rc)
    if tw < t:
        t, mu, mv, ms, base = tw, wu, wv, 0.0, False
    return max(t, 0.0), mu, mv, ms, base


@nb.njit(cache=True)
def trace_prism(state, cut, hu, hv, rc, t1, t2, n, pu, pv, du, dv, dz):  # pragma: no cover
    """A ray going down (``dz < 0``) in the guide of index ``n`` whose path crosses the
    face's plane at ``(pu, pv)`` (mm, the dot's frame: ``u`` along its length) on a prism
    (half length ``hu``, half width ``hv``, corner radius ``rc``, facet slopes ``t1``,
    ``t2``), raised or ``cut``: ``(state, where, du, dv, dz)`` as :func:`trace_cap`'s."""
    ds = dz if cut else -dz  # prism coordinates: s from the face into the structure
    ps = 0.0
    n_in, n_out = (1.0, n) if cut else (n, 1.0)
    if cut:  # back along the path to where it entered the cavity, from the guide
        t, mu, mv, ms, _ = prism_exit(pu, pv, 0.0, -du, -dv, -ds, hu, hv, rc, t1, t2)
        pu, pv, ps = pu - t * du, pv - t * dv, -t * ds
        cos_i = -(du * mu + dv * mv + ds * ms)
        state, x = uniform(state)
        if x < fresnel(cos_i, n, 1.0):  # reflected back into the guide
            du, dv, ds = du + 2.0 * cos_i * mu, dv + 2.0 * cos_i * mv, ds + 2.0 * cos_i * ms
            return state, (INTO_GUIDE if ds > 0 else ONTO_FACE), du, dv, ds
        du, dv, ds = _through(du, dv, ds, -mu, -mv, -ms, n, 1.0)
    for _ in range(MAX_BOUNCES):
        t, mu, mv, ms, base = prism_exit(pu, pv, ps, du, dv, ds, hu, hv, rc, t1, t2)
        if base:  # out through the face's plane
            return state, (INTO_AIR if cut else INTO_GUIDE), du, dv, (ds if cut else -ds)
        pu, pv, ps = pu + t * du, pv + t * dv, ps + t * ds
        cos_i = du * mu + dv * mv + ds * ms
        state, x = uniform(state)
        if x < fresnel(cos_i, n_in, n_out):  # reflected, inside again
            du, dv, ds = du - 2.0 * cos_i * mu, dv - 2.0 * cos_i * mv, ds - 2.0 * cos_i * ms
            continue
        du, dv, ds = _through(du, dv, ds, mu, mv, ms, n_in, n_out)
        if not cut:
            return state, INTO_AIR, du, dv, -ds
        return state, (INTO_GUIDE if ds > 0 else ONTO_FACE), du, dv, ds
    return state, CAUGHT, du, dv, (ds if cut else -ds)


@nb.njit(cache=True, inline="always")
def _through(dx, dy, dz, mx, my, mz, n1, n2):  # pragma: no cover - compiled
    """The direction transmitted from index ``n1`` into ``n2`` through a surface whose
    unit normal ``m`` points into ``n2`` (not totally reflected: the caller drew
    Fresnel's share, 1 under total reflection)."""
    eta = n1 / n2
    cos_i = dx * mx + dy * my + dz * mz
    cos_t = math.sqrt(max(0.0, 1.0 - eta * eta * (1.0 - cos_i * cos_i)))
    g = cos_t - eta * cos_i
    return eta * dx + g * mx, eta * dy + g * my, eta * dz + g * mz


@nb.njit(cache=True)
def _on_footprint(state, code, hu, hv, rc):  # pragma: no cover - compiled
    """A point drawn uniformly over a footprint (the dot's frame, mm): an ellipse of half
    axes ``hu``, ``hv`` for a cap, a rounded rectangle (half sides, corner ``rc``) for a
    prism (drawn over its box until on it)."""
    if code < PRISM:
        state, u = uniform(state)
        state, v = uniform(state)
        r, phi = math.sqrt(u), 2.0 * math.pi * v
        return state, hu * r * math.cos(phi), hv * r * math.sin(phi)
    for _ in range(64):
        state, u = uniform(state)
        state, v = uniform(state)
        pu, pv = (2.0 * u - 1.0) * hu, (2.0 * v - 1.0) * hv
        qu, qv = abs(pu) - (hu - rc), abs(pv) - (hv - rc)
        if qu <= 0 or qv <= 0 or qu * qu + qv * qv <= rc * rc:
            return state, pu, pv
    return state, 0.0, 0.0


@nb.njit(cache=True)
def meet_profile(state, f, n, at, dxn, dyn, dz):  # pragma: no cover - compiled
    """A ray going down onto a dot of the bottom face (its row ``f``: the profile's code,
    its body, the reflector) from the guide of index ``n``, where the print test found it
    (``at``, :func:`~optdot.optics.marks.dot_frame`'s: the point in the dot's frame, its
    angle and its half width, NaN where unknown): ``(state, act, dx, dy, dz)``,
    ``NEW_LEG`` back into the guide or a fate (``BOTTOM`` absorbed under it, ``DOT``
    caught in the dot). A dot of another size than the row's is its footprint scaled,
    under a cap of the same height (a prism's facets keep their angles)."""
    code = int(f[F_PROFILE])
    hu, hv, rc, k = f[F_PROF_U], f[F_PROF_V], f[F_PROF_C], f[F_PROF_K]
    lu, lv, c, s, half = at
    if half == half and half != hv:  # this dot's size
        m = half / hv
        hu, hv, rc, k = hu * m, half, rc * m, k / m
    turned = code >= PRISM or hu != hv  # the dot looks different turned
    if turned and c != c:  # a random angle, drawn
        state, w = uniform(state)
        c, s = math.cos(math.pi * w), math.sin(math.pi * w)
    if c != c:
        c, s = 1.0, 0.0
    du, dv = c * dxn + s * dyn, c * dyn - s * dxn
    if lu != lu:  # where on the dot, drawn
        state, lu, lv = _on_footprint(state, code, hu, hv, rc)
    if code >= PRISM:
        state, where, du, dv, dz = trace_prism(
            state, code == PRISM_CUT, hu, hv, rc, f[F_PROF_T1], f[F_PROF_T2], n, lu, lv,
            du, dv, dz,
        )  # fmt: skip
    else:
        state, where, du, dv, dz = trace_cap(
            state, code, k, hu / hv, n, lu / hv, lv / hv, du, dv, dz
        )
    dxn, dyn = c * du - s * dv, s * du + c * dv
    if where == INTO_GUIDE:
        return state, NEW_LEG, dxn, dyn, dz
    if where == CAUGHT:
        return state, DOT, dxn, dyn, dz
    if where == ONTO_FACE:  # the bare face beside the dot
        state, act, dxn, dyn, dz = meet_reflector(state, f, n, False, dxn, dyn, dz)
        return state, (NEW_LEG if act == SAME_LEG else act), dxn, dyn, dz
    if dz > 0:  # in the air under the guide, up onto its flat face
        state, u = uniform(state)
        if u >= fresnel(dz, 1.0, n):
            dxn, dyn, dz = refract(dxn, dyn, dz, 1.0, n)
            return state, NEW_LEG, dxn, dyn, dz
        dz = -dz
    if f[F_REFL_FINISH] > 0.5:  # a mirror: back up at the angle it came, through the face
        state, back = mirrored(state, f[F_REFL], fresnel(-dz, 1.0, n))
        if not back:
            return state, BOTTOM, dxn, dyn, dz
        dxn, dyn, dz = refract(dxn, dyn, -dz, 1.0, n)
        return state, NEW_LEG, dxn, dyn, dz
    return sheet_return(state, f[F_REFL], n, dxn, dyn, dz)
