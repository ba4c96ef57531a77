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
under the guide); :mod:`.cavities` follows a cut dot's light among the cavities its
path passes and the reflector under them. Every dot is convex: light reflected off one
from outside does not meet it again.

On real dots the ray meets the dot where the stepping found it, in the dot's own frame
(turned by its angle), and goes on in the guide from where it comes back through the
face; in a coverage trace the point is drawn uniformly over the footprint, the angle is
the orientation's at that cell (drawn, for random angles), and the ray goes on from
where it met the dot.

Light out in the air under the guide, from a raised dot or through the bare face between
raised dots, meets the raised dots beside it (:func:`among_dots`: the real dots, found
along its course by :func:`next_dot`; :func:`among_twins`: the coverage's twins on a
hexagonal lattice of the cell's fill), each met from outside by Fresnel, and entered,
as many as it reaches, before it goes on up onto the bare face or down to the
reflector. The reflector sheet lies on the tallest raised dots' tips (``F_PROF_H`` under
the face), and what it returns comes up among the dots again (:func:`under_dots`):
into them from the air, or onto the bare face between them.

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
from ...geometry.shapes import half_width_packed
from ..marks import INK, cell_frame, dot_frame
from ..rays import _M1, _M2, fresnel, lambert, mix, refract, uniform
from ..tables import (
    BOTTOM,
    DOT,
    EDGE,
    F_COS_DOWN,
    F_PROF_C,
    F_PROF_H,
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
    var_bool,
    var_int,
)
from .slab_walls import wall_distance

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
#: Dots a ray leaving one raised dot may meet in turn before it counts as absorbed.
MAX_DOTS = 256
#: The least distance a ray goes before it meets a dot it is leaving, in the dot's units:
#: a ray reflected off a dot, or leaving it, starts on its surface.
EPS = 1e-12


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
    g = 1.0 / math.sqrt(gx * gx + gy * gy + oz * oz)
    return gx * g, gy * g, oz * g


@nb.njit(cache=True)
def trace_cap(state, code, k, e, n, px, py, dx, dy, dz):  # pragma: no cover - compiled
    """A ray going down (``dz < 0``) in the guide of index ``n`` whose path crosses the
    face's plane at ``(px, py)`` (the footprint's half width 1, ``x`` along its long
    axis) on a cap of profile ``code``, height ``k`` and elongation ``e``: ``(state,
    where, px, py, pz, dx, dy, dz)``, ``where`` one of :data:`INTO_GUIDE`,
    :data:`INTO_AIR`, :data:`CAUGHT`, :data:`ONTO_FACE`, the point it leaves the dot at
    (cap coordinates) and the direction it goes on in."""
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
            return state, (INTO_GUIDE if dz > 0 else ONTO_FACE), px, py, pz, dx, dy, dz
        dx, dy, dz = _through(dx, dy, dz, -mx, -my, -mz, n, 1.0)
    return _cap_walk(state, bump, q, r_s, cz, n_in, n_out, px, py, pz, dx, dy, dz)


@nb.njit(cache=True)
def _cap_walk(state, bump, q, r_s, cz, n_in, n_out, px, py, pz, dx, dy, dz):  # pragma: no cover
    """A ray inside a cap's body (the guide's material in a bump, air in a dimple; cap
    coordinates, the sphere's radius ``r_s`` and centre height ``cz``, ``q = 1/e²``) at
    ``p`` going ``d``, followed through the cap's surface until it leaves: as
    :func:`trace_cap`'s."""
    for _ in range(MAX_BOUNCES):
        leaves = dz > 0 if bump else dz < 0
        t_plane = -pz / dz if leaves else 1e300
        a, b, c = _quadric(q, px, py, pz - cz, dx, dy, dz, r_s)
        t_cap = (-b + math.sqrt(max(b * b - a * c, 0.0))) / a
        if t_plane <= t_cap:  # out through the face's plane
            px, py = px + t_plane * dx, py + t_plane * dy
            return state, (INTO_GUIDE if bump else INTO_AIR), px, py, 0.0, dx, dy, dz
        px, py, pz = px + t_cap * dx, py + t_cap * dy, pz + t_cap * dz
        mx, my, mz = _normal(q, px, py, pz - cz)
        cos_i = dx * mx + dy * my + dz * mz
        state, u = uniform(state)
        if u < fresnel(cos_i, n_in, n_out):  # reflected, inside again
            dx, dy, dz = dx - 2.0 * cos_i * mx, dy - 2.0 * cos_i * my, dz - 2.0 * cos_i * mz
            continue
        dx, dy, dz = _through(dx, dy, dz, mx, my, mz, n_in, n_out)
        if bump:
            return state, INTO_AIR, px, py, pz, dx, dy, dz
        return state, (INTO_GUIDE if dz > 0 else ONTO_FACE), px, py, pz, dx, dy, dz
    return state, CAUGHT, px, py, pz, dx, dy, dz


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
    ``t2``), raised or ``cut``: ``(state, where, pu, pv, pz, du, dv, dz)`` as
    :func:`trace_cap`'s (``pz`` mm, up from the face's plane)."""
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
            return state, (INTO_GUIDE if ds > 0 else ONTO_FACE), pu, pv, ps, du, dv, ds
        du, dv, ds = _through(du, dv, ds, -mu, -mv, -ms, n, 1.0)
    state, where, pu, pv, ps, du, dv, ds = _prism_walk(
        state, cut, hu, hv, rc, t1, t2, n_in, n_out, pu, pv, ps, du, dv, ds
    )
    return state, where, pu, pv, (ps if cut else -ps), du, dv, (ds if cut else -ds)


@nb.njit(cache=True)
def _prism_walk(
    state, cut, hu, hv, rc, t1, t2, n_in, n_out, pu, pv, ps, du, dv, ds
):  # pragma: no cover
    """A ray inside a prism's body (prism coordinates) at ``p`` going ``d``, followed
    through its surfaces until it leaves: ``(state, where, pu, pv, ps, du, dv, ds)`` as
    :func:`trace_cap`'s, in prism coordinates."""
    for _ in range(MAX_BOUNCES):
        t, mu, mv, ms, base = prism_exit(pu, pv, ps, du, dv, ds, hu, hv, rc, t1, t2)
        if base:  # out through the face's plane
            pu, pv = pu + t * du, pv + t * dv
            return state, (INTO_AIR if cut else INTO_GUIDE), pu, pv, 0.0, du, dv, ds
        pu, pv, ps = pu + t * du, pv + t * dv, ps + t * ds
        cos_i = du * mu + dv * mv + ds * ms
        state, x = uniform(state)
        if x < fresnel(cos_i, n_in, n_out):  # reflected, inside again
            du, dv, ds = du - 2.0 * cos_i * mu, dv - 2.0 * cos_i * mv, ds - 2.0 * cos_i * ms
            continue
        du, dv, ds = _through(du, dv, ds, mu, mv, ms, n_in, n_out)
        if not cut:
            return state, INTO_AIR, pu, pv, ps, du, dv, ds
        return state, (INTO_GUIDE if ds > 0 else ONTO_FACE), pu, pv, ps, du, dv, ds
    return state, CAUGHT, pu, pv, ps, du, dv, ds


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


@nb.njit(cache=True, inline="always")
def _sized(hu, hv, rc, k, half):  # pragma: no cover - compiled
    """A row's dot frame ``(hu, hv, rc, k)`` for a dot of half width ``half`` (mm; NaN:
    the row's size): the footprint scaled, under a cap of the same height."""
    if half == half and half != hv:
        m = half / hv
        return hu * m, half, rc * m, k / m
    return hu, hv, rc, k


@nb.njit(cache=True)
def footprint_span(pu, pv, du, dv, hu, hv, rc):  # pragma: no cover - compiled
    """Where the line through ``(pu, pv)`` going ``(du, dv)`` (horizontal parts, not
    unit) is over a rounded rectangle of half sides ``hu``, ``hv`` and corner radius
    ``rc`` (mm, about the origin): ``(t_in, t_out, mu, mv)``, its parameters in and out
    (``t_in >= t_out`` when it misses; ``-inf``, ``inf`` for a vertical line over it)
    and the edge's outward unit normal where it comes in."""
    t_in, t_out, mu, mv = -np.inf, np.inf, 0.0, 0.0
    if du != 0:
        iu = 1.0 / du
        a, b = (-hu - pu) * iu, (hu - pu) * iu
        t_in, t_out, mu = min(a, b), max(a, b), (-1.0 if du > 0 else 1.0)
    elif abs(pu) > hu:
        return np.inf, -np.inf, 0.0, 0.0
    if dv != 0:
        iv = 1.0 / dv
        a, b = (-hv - pv) * iv, (hv - pv) * iv
        if min(a, b) > t_in:
            t_in, mu, mv = min(a, b), 0.0, (-1.0 if dv > 0 else 1.0)
        t_out = min(t_out, max(a, b))
    elif abs(pv) > hv:
        return np.inf, -np.inf, 0.0, 0.0
    if t_in >= t_out or rc <= 0 or t_in == -np.inf:
        return t_in, t_out, mu, mv
    cu, cv = hu - rc, hv - rc
    for end in range(2):  # a corner's square where it comes in, or goes out: its arc
        t = t_in if end == 0 else t_out
        qu, qv = pu + t * du, pv + t * dv
        if abs(qu) > cu and abs(qv) > cv:
            ou, ov = pu - math.copysign(cu, qu), pv - math.copysign(cv, qv)
            a = du * du + dv * dv
            b = ou * du + ov * dv
            disc = b * b - a * (ou * ou + ov * ov - rc * rc)
            if disc <= 0:  # past the corner's arc: off the footprint
                return np.inf, -np.inf, 0.0, 0.0
            if end == 0:
                t_in = (-b - math.sqrt(disc)) / a
                mu, mv = (ou + t_in * du) / rc, (ov + t_in * dv) / rc
            else:
                t_out = (-b + math.sqrt(disc)) / a
    return t_in, t_out, mu, mv


@nb.njit(cache=True)
def enter_prism(hu, hv, rc, t1, t2, pu, pv, ps, du, dv, ds):  # pragma: no cover - compiled
    """Where a ray from outside a raised prism's body (prism coordinates, ``s > 0`` below
    the face) first meets it: ``(t, mu, mv, ms)``, its parameter (inf if it misses) and
    the surface's outward unit normal there."""
    t_in, t_out, mu, mv = footprint_span(pu, pv, du, dv, hu, hv, rc)
    ms = 0.0
    for i in range(3):  # the face's plane s >= 0 and the two facets, as a . p <= b
        au, a_s = (0.0, -1.0) if i == 0 else ((-t1, 1.0) if i == 1 else (t2, 1.0))
        b = 0.0 if i == 0 else (t1 * hu if i == 1 else t2 * hu)
        ad, ap = au * du + a_s * ds, au * pu + a_s * ps
        if ad == 0:
            if ap > b:
                return np.inf, 0.0, 0.0, 0.0
            continue
        t = (b - ap) / ad
        if ad > 0:
            t_out = min(t_out, t)
        elif t > t_in:
            g = 1.0 / math.sqrt(au * au + a_s * a_s)
            t_in, mu, mv, ms = t, au * g, 0.0, a_s * g
    if t_in >= t_out or t_in <= EPS:
        return np.inf, 0.0, 0.0, 0.0
    return t_in, mu, mv, ms


@nb.njit(cache=True)
def enter_cap(k, e, ox, oy, oz, dx, dy, dz):  # pragma: no cover - compiled
    """Where a ray from outside a bump (cap coordinates: ``o`` its start under the face,
    ``d`` unit) first meets it: ``(t, mx, my, mz)``, its parameter (inf if it misses)
    and the cap's outward unit normal there."""
    r_s = (1.0 + k * k) / (2.0 * k)
    q = 1.0 if e == 1.0 else 1.0 / (e * e)
    cz = r_s - k
    a, b, c = _quadric(q, ox, oy, oz - cz, dx, dy, dz, r_s)
    disc = b * b - a * c
    if disc <= 0:
        return np.inf, 0.0, 0.0, 0.0
    t = (-b - math.sqrt(disc)) / a
    if t <= EPS or oz + t * dz > 0:  # behind, or the sphere over the face: not the cap
        return np.inf, 0.0, 0.0, 0.0
    mx, my, mz = _normal(q, ox + t * dx, oy + t * dy, oz + t * dz - cz)
    return t, mx, my, mz


@nb.njit(cache=True, forceinline=True)
def _meet_body(f, hu, hv, rc, k, c, s, rx, ry, z, dx, dy, dz):  # pragma: no cover
    """Where a ray from outside a raised dot of row ``f``'s profile (its frame ``hu``,
    ``hv``, ``rc``, ``k``, turned by ``(c, s)``) first meets it: from ``(rx, ry, z)`` (mm,
    from its centre) going ``d``, both in the frame it stands turned in: ``(t, mx, my,
    mz)``, the distance (mm, inf if it misses) and the outward unit normal there."""
    ru, rv = c * rx + s * ry, c * ry - s * rx
    du, dv = c * dx + s * dy, c * dy - s * dx
    if int(f[F_PROFILE]) >= PRISM:
        t, mu, mv, ms = enter_prism(hu, hv, rc, f[F_PROF_T1], f[F_PROF_T2], ru, rv, -z, du, dv, -dz)
        mz = -ms
    else:
        ih = 1.0 / hv
        t, mu, mv, mz = enter_cap(k, hu * ih, ru * ih, rv * ih, z * ih, du, dv, dz)
        t *= hv
    return t, c * mu - s * mv, s * mu + c * mv, mz


@nb.njit(cache=True)
def _into_body(
    state, f, n, hu, hv, rc, k, c, s, rx, ry, z, dx, dy, dz, mx, my, mz
):  # pragma: no cover
    """A ray meeting a dot from outside (a raised dot from the air under the face, a cut
    one's cavity from the glass; as :func:`_meet_body`'s, at ``(rx, ry, z)`` from its
    centre where the normal is ``m``): Fresnel's reflection off it, or in and through it
    (:func:`_walk_body`): ``(state, where, rx, ry, z, dx, dy, dz)``. Reflected, a raised
    dot's ray is :data:`INTO_AIR` again, a cut dot's in the glass (:data:`INTO_GUIDE`
    going up, :data:`ONTO_FACE` down)."""
    code = int(f[F_PROFILE])
    cut = code == DIMPLE or code == PRISM_CUT
    n_out, n_in = (n, 1.0) if cut else (1.0, n)  # the media outside the dot and in it
    cos_i = -(dx * mx + dy * my + dz * mz)
    state, u = uniform(state)
    if u < fresnel(cos_i, n_out, n_in):  # reflected off it, on outside it
        dx, dy, dz = dx + 2.0 * cos_i * mx, dy + 2.0 * cos_i * my, dz + 2.0 * cos_i * mz
        where = (INTO_GUIDE if dz > 0 else ONTO_FACE) if cut else INTO_AIR
        return state, where, rx, ry, z, dx, dy, dz
    dx, dy, dz = _through(dx, dy, dz, -mx, -my, -mz, n_out, n_in)
    return _walk_body(state, f, n, hu, hv, rc, k, c, s, rx, ry, z, dx, dy, dz)


@nb.njit(cache=True)
def _walk_body(state, f, n, hu, hv, rc, k, c, s, rx, ry, z, dx, dy, dz):  # pragma: no cover
    """A ray inside a dot of row ``f``'s profile (its frame ``hu``, ``hv``, ``rc``, ``k``,
    turned by ``(c, s)``) at ``(rx, ry, z)`` (mm from its centre, ``z`` up from the
    face's plane) going ``d``, followed through its surfaces until it leaves:
    ``(state, where, rx, ry, z, dx, dy, dz)``, where and how it leaves
    (:func:`trace_cap`'s ``where``: a raised dot's :data:`INTO_AIR` out through its
    surface or :data:`INTO_GUIDE` up through its base; a cut dot's :data:`INTO_GUIDE` or
    :data:`ONTO_FACE` out through its surface, :data:`INTO_AIR` down through its open
    base), or :data:`CAUGHT`."""
    code = int(f[F_PROFILE])
    cut = code == DIMPLE or code == PRISM_CUT
    n_in, n_out = (1.0, n) if cut else (n, 1.0)
    pu, pv = c * rx + s * ry, c * ry - s * rx
    du, dv = c * dx + s * dy, c * dy - s * dx
    if code >= PRISM:
        sg = 1.0 if cut else -1.0  # prism coordinates: s into the structure from the face
        state, where, pu, pv, ps, du, dv, ds = _prism_walk(
            state, cut, hu, hv, rc, f[F_PROF_T1], f[F_PROF_T2], n_in, n_out, pu, pv, sg * z,
            du, dv, sg * dz,
        )  # fmt: skip
        z, dz = sg * ps, sg * ds
    else:
        r_s = (1.0 + k * k) / (2.0 * k)
        state, where, pu, pv, pz, du, dv, dz = _cap_walk(
            state, not cut, (hv / hu) ** 2, r_s, (k - r_s) if cut else (r_s - k), n_in, n_out,
            pu / hv, pv / hv, z / hv, du, dv, dz,
        )  # fmt: skip
        pu, pv, z = pu * hv, pv * hv, pz * hv
    rx, ry = c * pu - s * pv, s * pu + c * pv
    z = max(z, 0.0) if cut else min(z, 0.0)
    return state, where, rx, ry, z, c * du - s * dv, s * du + c * dv, dz


@nb.njit(cache=True, inline="always")
def tallest(f, hu, hv, k):  # pragma: no cover - compiled
    """How far the tallest of row ``f``'s dots stands out of the face (or sinks into it),
    mm: a prism of half length ``hu``, a cap ``k`` on half width ``hv`` (mm)."""
    if int(f[F_PROFILE]) >= PRISM:
        t1, t2 = f[F_PROF_T1], f[F_PROF_T2]
        return 2.0 * hu * t1 * t2 / (t1 + t2)
    return k * hv


@nb.njit(cache=True, inline="always")
def _layer_end(f, hu, hv, k, z, dz):  # pragma: no cover - compiled
    """How far a ray at height ``z`` (mm, under the face) going up or down by ``dz`` (a
    unit direction's) goes before it leaves the layer of raised dots whose tallest has
    half length ``hu`` (a prism's) or cap ``k`` on half width ``hv`` (mm)."""
    tall = tallest(f, hu, hv, k)
    return (-tall - z) / dz if dz < 0 else (-z / dz if dz > 0 else np.inf)


@nb.njit(cache=True, inline="always")
def _off_line(rx, ry, ux, uy, reach):  # pragma: no cover - compiled
    """Whether a dot centred ``(rx, ry)`` (mm) from a ray's start lies farther than
    ``reach`` (its extent, mm) from the ray's course, whose horizontal unit direction is
    ``(ux, uy)`` (``(0, 0)`` for a vertical ray): the ray cannot meet it."""
    if ux == 0.0 and uy == 0.0:
        return rx * rx + ry * ry > reach * reach
    return abs(rx * uy - ry * ux) > reach


@nb.njit(cache=True)
def next_dot(f, start, dx_, dy_, foot, cg, x, y, z, dx, dy, dz, fold):  # pragma: no cover
    """The first of the real raised dots (row ``f``'s profile; the print's cells ``start``,
    centres ``dx_``, ``dy_``, footprints ``foot``, grid ``cg``) a ray in the air under
    the face meets, from ``(x, y, z)`` (mm, ``z <= 0``) going ``d`` (unit), before it
    leaves their layer: ``(k, t, mx, my, mz, after)``, the dot (-1 for none), the distance
    to it (mm) and its surface's outward unit normal there. The cells are walked along the
    ray's course a cell at a time, each widened by the largest dot's extent; a step tries
    the dots whose centres project onto its own span of the course (each dot once) and lie
    within the largest extent of it, and a long footprint only where the course passes
    within its own support across it.

    With ``fold`` (a ray going up, ``dz > 0``, that the face will reflect totally), the
    path goes on mirrored off the face's plane, down out of the layer: its horizontal
    course is the same line, so one walk finds the dot met on either leg. A dot met
    going up is returned with ``after`` false; else the dot met after the face (``after``
    true, ``t`` from the point the path meets the face's plane, ``k`` -1 for none)."""
    hu0, hv0, rc0, k0 = f[F_PROF_U], f[F_PROF_V], f[F_PROF_C], f[F_PROF_K]
    x0, y0, cell, nx, ny, rmax = cg[0], cg[1], cg[2], int(cg[4]), int(cg[5]), cg[6]
    t_end = _layer_end(f, rmax, hv0, k0, z, dz)  # a prism no longer than the largest extent
    t_face = t_end if fold else 0.0  # a rising ray's first leg ends on the face's plane
    xf, yf = x + t_face * dx, y + t_face * dy
    t_end2 = _layer_end(f, rmax, hv0, k0, -0.0, -dz) if fold else 0.0
    t_all = t_face + t_end2 if fold else t_end
    hs = math.sqrt(dx * dx + dy * dy)
    flat = hs > 1e-12  # a course over the face (not a vertical ray)
    ih = 1.0 / hs if flat else np.inf
    step, lag, inv = cell * ih, rmax * ih, 1.0 / cell  # lag: a dot met before its span
    ux, uy = (dx * ih, dy * ih) if flat else (0.0, 0.0)
    lean = flat and hu0 != hv0  # long footprints: their support across the course
    r2 = rmax * rmax if flat else np.inf  # (a vertical ray: every dot in its cells tried)
    far = t_all * hs + rmax  # the farthest a dot met stands along its course (mm)
    best, bk, bx, by, bz = t_end, -1, 0.0, 0.0, 0.0
    best2, bk2, bx2, by2, bz2 = t_end2, -1, 0.0, 0.0, 0.0  # after the face
    ta = 0.0
    for _ in range(2 * (nx + ny) + 4):
        tb = min(ta + step, t_all)
        last = tb >= t_all
        lo, hi = (ta * hs if ta > 0 else -rmax), (far if last else tb * hs)  # its span
        xa, xb = x + ta * dx, x + (tb if tb < np.inf else ta) * dx
        ya, yb = y + ta * dy, y + (tb if tb < np.inf else ta) * dy
        ax = int(math.floor((min(xa, xb) - rmax - x0) * inv))
        bx_ = int(math.floor((max(xa, xb) + rmax - x0) * inv))
        ay = int(math.floor((min(ya, yb) - rmax - y0) * inv))
        by_ = int(math.floor((max(ya, yb) + rmax - y0) * inv))
        if bx_ < 0 or by_ < 0 or ax >= nx or ay >= ny:  # past the grid: no dots ahead
            break
        for jy in range(max(ay, 0), min(by_ + 1, ny)):
            for jx in range(max(ax, 0), min(bx_ + 1, nx)):
                cc = jy * nx + jx
                for j in range(start[cc], start[cc + 1]):
                    rx, ry = dx_[j] - x, dy_[j] - y
                    p, q = rx * ux + ry * uy, rx * uy - ry * ux  # along its course, across
                    if (q * q > r2) | (p < lo) | (p > hi):  # one branch: bitwise, not or
                        continue  # off its course, or not over this step's span of it
                    hu, hv, rc, kk = _sized(hu0, hv0, rc0, k0, half_width_packed(foot, j))
                    c, s = foot[j, 4], foot[j, 5]
                    if lean:  # its support across the course: hu |sin| + hv |cos| of its turn
                        across = hu * abs(ux * s - uy * c) + hv * abs(ux * c + uy * s)
                        if abs(q) > across * (1.0 + 1e-9):
                            continue  # its course passes beside it
                    t, mx, my, mz = _meet_body(
                        f, hu, hv, rc, kk, c, s, x - dx_[j], y - dy_[j], z, dx, dy, dz
                    )
                    if t < best:
                        best, bk, bx, by, bz = t, j, mx, my, mz
                    if fold and bk < 0:  # on the leg after the face
                        t, mx, my, mz = _meet_body(
                            f, hu, hv, rc, kk, c, s, xf - dx_[j], yf - dy_[j], -0.0, dx, dy, -dz
                        )
                        if t < best2:
                            best2, bk2, bx2, by2, bz2 = t, j, mx, my, mz
        # every dot over the course short of tb tried: none further on is met before tb - lag
        met = bk >= 0 and best <= tb - lag
        if last or met or (fold and bk < 0 and t_face + best2 <= tb - lag):
            break
        ta = tb
    if fold and bk < 0:
        return bk2, best2, bx2, by2, bz2, True
    return bk, best, bx, by, bz, False


@nb.njit(cache=True)
def among_dots(state, f, n, pr, x, y, z, dxn, dyn, dz):  # pragma: no cover - compiled
    """A ray that left a real raised dot (or the bare face between them) into the air
    under the guide at ``(x, y, z)`` (mm) going ``d``, followed among the dots
    (:func:`next_dot`, :func:`_into_body`): ``(state, where, x, y, z, dxn, dyn, dz)``,
    :data:`INTO_GUIDE` up through a dot's base (there), :data:`CAUGHT`, or
    :data:`INTO_AIR` out of the dots' layer (down to the reflector, or up onto the bare
    face), from the point it last left a dot at (or its start). ``pr``: the print's
    :func:`~optdot.optics.marks.dot_tables`."""
    start, dx_, dy_, foot, cg = pr[3], pr[4], pr[5], pr[6], pr[7]
    for _ in range(MAX_DOTS):
        k, t, mx, my, mz, _ = next_dot(
            f, start, dx_, dy_, foot, cg, x, y, z, dxn, dyn, dz, var_bool(False)
        )
        if k < 0:
            return state, INTO_AIR, x, y, z, dxn, dyn, dz
        hu, hv, rc, kk = _sized(
            f[F_PROF_U], f[F_PROF_V], f[F_PROF_C], f[F_PROF_K], half_width_packed(foot, k)
        )
        rx, ry, z = x + t * dxn - dx_[k], y + t * dyn - dy_[k], min(z + t * dz, 0.0)
        state, where, rx, ry, z, dxn, dyn, dz = _into_body(
            state, f, n, hu, hv, rc, kk, foot[k, 4], foot[k, 5], rx, ry, z, dxn, dyn, dz, mx,
            my, mz,
        )  # fmt: skip
        x, y = dx_[k] + rx, dy_[k] + ry
        if where != INTO_AIR:
            return state, where, x, y, z, dxn, dyn, dz
    return state, CAUGHT, x, y, z, dxn, dyn, dz


@nb.njit(cache=True, inline="always")
def _fill_at(x, y, phi, g):  # pragma: no cover - compiled
    """The coverage's fill at ``(x, y)`` (mm; ``phi`` over cells of ``g``), 0 off it."""
    ix = int(math.floor((x - g[0]) / g[2]))
    iy = int(math.floor((y - g[1]) / g[3]))
    if ix < 0 or iy < 0 or ix >= phi.shape[1] or iy >= phi.shape[0]:
        return 0.0
    return phi[iy, ix]


@nb.njit(cache=True, forceinline=True)
def fill_along(x, y, ux, uy, lo, hi, phi, g):  # pragma: no cover - compiled
    """The most fill the coverage (``phi`` over cells of ``g``) has in the cells the course
    from ``(x, y) + lo u`` to ``(x, y) + hi u`` crosses (mm; ``u = (ux, uy)`` a unit
    direction, ``lo <= hi``), every one of them (a walk over the grid's lines, one cell at
    a time); 0 off the map."""
    nx, ny = phi.shape[1], phi.shape[0]
    fx, fy = (x + lo * ux - g[0]) / g[2], (y + lo * uy - g[1]) / g[3]
    ix, iy = int(math.floor(fx)), int(math.floor(fy))
    vx, vy = ux / g[2], uy / g[3]  # cells a millimetre along the course
    sx, sy = (1 if vx > 0 else -1), (1 if vy > 0 else -1)
    # how far along the course (mm from its start) it crosses the next line of cells
    nxt_x = ((ix + 1 - fx) / vx if vx > 0 else (ix - fx) / vx) if vx != 0 else np.inf
    nxt_y = ((iy + 1 - fy) / vy if vy > 0 else (iy - fy) / vy) if vy != 0 else np.inf
    dx_, dy_ = (abs(1.0 / vx) if vx != 0 else np.inf), (abs(1.0 / vy) if vy != 0 else np.inf)
    length = hi - lo
    top = phi[iy, ix] if 0 <= ix < nx and 0 <= iy < ny else 0.0
    for _ in range(int(length * (abs(vx) + abs(vy))) + 3):
        if nxt_x < nxt_y:
            t, ix, nxt_x = nxt_x, ix + sx, nxt_x + dx_
        else:
            t, iy, nxt_y = nxt_y, iy + sy, nxt_y + dy_
        if not t <= length:
            break
        if 0 <= ix < nx and 0 <= iy < ny:
            top = max(top, phi[iy, ix])
    return top


@nb.njit(cache=True, forceinline=True)
def _site_angle(key, i, j, turn):  # pragma: no cover - compiled
    """A twin's own angle (rad, ``0 .. turn``) at lattice site ``(i, j)`` of the ray whose
    draw is ``key``: the same every time the ray meets the site."""
    z = mix(key ^ (np.uint64(i + (1 << 31)) * _M1 + np.uint64(j + (1 << 31)) * _M2))
    return turn * float(z >> np.uint64(11)) * 2.0**-53


@nb.njit(cache=True, inline="always")
def _turn(f):  # pragma: no cover - compiled
    """The turn a random angle of row ``f``'s dots is drawn over (rad): π, or 2π for a
    prism whose facets differ (turned half a turn, it is another dot)."""
    if int(f[F_PROFILE]) >= PRISM and f[F_PROF_T1] != f[F_PROF_T2]:
        return 2.0 * math.pi
    return math.pi


#: :func:`twin_lattice`'s ``turn`` for twins each at the print's angle where it stands
#: (:func:`_twin_at`): the coverage's angles turn from cell to cell (toward the LEDs).
FIELD = -1.0


@nb.njit(cache=True, forceinline=True)
def twins_turn(f, hu, hv, c):  # pragma: no cover - compiled
    """How the twins of a coverage dot of row ``f`` (half sides ``hu``, ``hv``, mm) stand
    turned where the print's cell angle has cosine ``c`` (NaN where the dot draws its
    angle): :func:`twin_lattice`'s ``turn``, 0 for a disc (any angle), :data:`FIELD` at
    the print's angles, else drawn (:func:`_turn`)."""
    if int(f[F_PROFILE]) < PRISM and hu == hv:
        return 0.0
    return FIELD if c == c else _turn(f)


@nb.njit(cache=True, forceinline=True)
def _site(lat, i, j):  # pragma: no cover - compiled
    """Lattice ``lat``'s site ``(i, j)``: its centre ``(cu, cv)`` (mm, the dot's frame)
    and its twin's angle ``(c, s)`` in that frame (the frame's own in a :data:`FIELD`:
    :func:`_twin_at` looks it up)."""
    e, _, b1u, b1v, b2u, b2v, key, turn, _, _ = lat
    c, s = 1.0, 0.0
    if turn > 0:
        g = _site_angle(key, i, j, turn)
        c, s = math.cos(g), math.sin(g)
    return (i * b1u + j * b2u) * e, i * b1v + j * b2v, c, s


@nb.njit(cache=True, forceinline=True)
def _twin_at(lat, i, j, place):  # pragma: no cover - compiled
    """:func:`_site`'s centre and angle of lattice ``lat``'s twin ``(i, j)``, in a
    :data:`FIELD` at the print's angle where its centre stands on the face (``place``:
    the frame's origin and turn there, ``(ox, oy, c, s)`` mm, the coverage ``phi`` over
    cells ``g``, the print's ``turn``; :func:`~optdot.optics.marks.cell_frame`), turned
    into the frame: a ray's walk may cross a millimetre of a field that turns toward an
    LED beside it. The twin at ``(0, 0)``, the one the ray came to, keeps the frame's
    angle, as a twin where the print has none."""
    cu, cv, c, s = _site(lat, i, j)
    if lat[7] < 0 and (i != 0 or j != 0):
        ox, oy, c0, s0, phi, g, turn = place
        gc, gs, _ = cell_frame(ox + c0 * cu - s0 * cv, oy + s0 * cu + c0 * cv, phi, g, turn)
        if gc == gc and (gc != c0 or gs != s0):  # (the frame's own: exactly)
            c, s = gc * c0 + gs * s0, gs * c0 - gc * s0
    return cu, cv, c, s


@nb.njit(cache=True, forceinline=True)
def _twin_area(hu, hv, rc, prism):  # pragma: no cover - compiled
    """A twin's footprint area (mm²): a rounded rectangle of half sides ``hu``, ``hv`` and
    corner ``rc`` (mm) for a ``prism``, else an ellipse of half axes ``hu``, ``hv``."""
    return 4.0 * hu * hv - (4.0 - math.pi) * rc * rc if prism else math.pi * hu * hv


@nb.njit(cache=True, forceinline=True)
def _lattice_fill(lat, hu, hv, rc, prism):  # pragma: no cover - compiled
    """The fill lattice ``lat`` of twins (half sides ``hu``, ``hv``, corner ``rc``, mm;
    ``prism`` as :func:`_twin_area`'s) was packed for: one twin a cell of its basis."""
    e, a = lat[0], lat[1]
    return 2.0 * _twin_area(hu, hv, rc, prism) / (e * math.sqrt(3.0) * a * a)


#: The salt of the draw that thins a lattice's twins (:func:`_stands`), apart from their
#: angles' (:func:`_site_angle`).
_THIN = np.uint64(0x5851F42D4C957F2D)


@nb.njit(cache=True, forceinline=True)
def _stands(lat, i, j, fill, there):  # pragma: no cover - compiled
    """Whether lattice ``lat``'s twin ``(i, j)`` stands where the coverage's fill is
    ``there``, the lattice packed for ``fill``: not where the map has no dots; where it has
    fewer than the lattice, with the chance ``there / fill`` (drawn by the site, the same
    every time the ray meets it). The twin at ``(0, 0)`` of a lattice about a dot the ray
    came to (``lat``'s ``own``) stands wherever the map has dots; about a point drawn on the
    bare face between them (:func:`bare_point`) it is thinned as any other: a lattice
    packed for a denser cell along the ray's path than where it met the face stands no
    denser there than the map."""
    if there <= 0:
        return False
    if there >= fill or (lat[9] and i == 0 and j == 0):
        return True
    return _site_angle(lat[6] ^ _THIN, i, j, 1.0) * fill < there


@nb.njit(cache=True)
def twin_lattice(state, hu, hv, rc, prism, turn, fill, own):  # pragma: no cover - compiled
    """The twins of a coverage dot (half sides ``hu``, ``hv``, corner ``rc``, mm) where
    the cell's ``fill`` (> 0) puts them: a hexagonal lattice of the fill's density turned
    at random, stretched along ``u`` by the dot's elongation when the twins stand at its
    angle (``turn`` 0) or at the print's angles where they stand (:data:`FIELD`, which
    turns slowly from one twin to the next: :func:`_twin_at`), each at its own angle
    otherwise, drawn over ``turn`` (π, or 2π for a prism whose facets differ;
    :func:`_site_angle`): ``(state, lat)``, ``lat = (e,
    a, b1u, b1v, b2u, b2v, key, turn, m, own)``, the stretch, the spacing (mm), the basis
    (mm, stretched coordinates ``u / e, v``), the sites' key, how many sites about the
    nearest one a twin over a point may stand, and whether the twin at ``(0, 0)`` is the
    dot the ray came to (``own``: it stands wherever the map has dots, :func:`_stands`)
    or the lattice is placed about a point on the bare face between them."""
    e = hu / hv if turn <= 0 else 1.0
    a = math.sqrt(2.0 * _twin_area(hu, hv, rc, prism) / (e * math.sqrt(3.0) * min(fill, 1.0)))
    state, w = uniform(state)
    state, key_u = uniform(state)
    ca, sa = math.cos(math.pi / 3.0 * w), math.sin(math.pi / 3.0 * w)
    h = 0.8660254037844386  # sin 60°
    reach = math.sqrt(hu * hu + hv * hv) / e  # a twin's extent, stretched coordinates
    m = int(math.ceil(reach / (h * a) + 1.3))  # the nearest site by rounding: 0.87 a off
    lat = (
        e, a, a * ca, a * sa, a * (0.5 * ca - h * sa), a * (0.5 * sa + h * ca),
        np.uint64(key_u * 2.0**53), turn, m, var_bool(own),
    )  # fmt: skip
    return state, lat


@nb.njit(cache=True, forceinline=True)
def _lattice_at(lat, pu, pv):  # pragma: no cover - compiled
    """``(pu, pv)`` (mm, the dot's frame) in lattice ``lat``'s basis (fractional)."""
    e, _, b1u, b1v, b2u, b2v, _, _, _, _ = lat
    det = b1u * b2v - b1v * b2u
    qu = pu / e
    return (qu * b2v - pv * b2u) / det, (b1u * pv - b1v * qu) / det


@nb.njit(cache=True, forceinline=True)
def _nearest_site(lat, pu, pv):  # pragma: no cover - compiled
    """The lattice site nearest ``(pu, pv)`` (mm, the dot's frame) in the basis's
    coordinates (rounded)."""
    fi, fj = _lattice_at(lat, pu, pv)
    return int(math.floor(fi + 0.5)), int(math.floor(fj + 0.5))


@nb.njit(cache=True, forceinline=True)
def _j_span(i, form, lo, hi, ja, jb):  # pragma: no cover - compiled
    """The ``j`` of ``ja .. jb`` for which ``i a + j b + c`` (``form = (a, b, c)``) may lie
    within ``lo .. hi`` (either may be infinite), a little generously: ``(ja, jb)``, empty
    when ``ja > jb``. The sites it leaves out are those :func:`next_twin`'s own tests
    would pass by."""
    a, b, c = form
    w = i * a + c
    if abs(b) < 1e-12:  # the same for every j
        return (ja, jb) if lo - 1e-9 <= w <= hi + 1e-9 else (ja, ja - 1)
    x1, x2 = (lo - w) / b, (hi - w) / b
    if x1 > x2:
        x1, x2 = x2, x1
    if x1 - 1e-7 > jb or x2 + 1e-7 < ja:
        return ja, ja - 1
    if x1 > ja:
        ja = int(math.ceil(x1 - 1e-7))
    if x2 < jb:
        jb = int(math.floor(x2 + 1e-7))
    return ja, jb


@nb.njit(cache=True)
def next_twin(
    f, hu, hv, rc, k, lat, skip0, place, pu, pv, pz, du, dv, dz, fold
):  # pragma: no cover
    """:func:`next_dot` over lattice ``lat``'s twins (the dot at site ``(0, 0)`` left
    out when ``skip0``; ``fold`` as :func:`next_dot`'s): ``(i, j, t, mu, mv, mz, after)``,
    the site (``t`` inf for none), the distance (mm) and the normal, in the dot's frame. A
    twin stands only where the coverage has dots (``place``: the frame's origin and turn
    on the face, ``(ox, oy, c, s)`` mm, and the coverage ``phi`` over cells ``g``): none
    past the panel's edge or in its holes, and where the map has fewer than the lattice
    (packed for the fill where the ray met the face, a cut dot's for the densest cell
    along its path), as many fewer (:func:`_stands`):
    a walk a millimetre long toward an LED crosses the map's cells. The path is walked a
    spacing at a time, each step trying the sites within a twin's reach of it whose
    centres lie along it, so each site is tried once."""
    ox, oy, c0, s0, phi, g, _ = place
    a = lat[1]
    t_end = _layer_end(f, hu, hv, k, pz, dz)
    t_face = t_end if fold else 0.0  # a rising ray's first leg ends on the face's plane
    fu, fv = pu + t_face * du, pv + t_face * dv
    t_end2 = _layer_end(f, hu, hv, k, -0.0, -dz) if fold else 0.0
    t_all = t_face + t_end2 if fold else t_end
    hs = math.sqrt(du * du + dv * dv)
    step = a * min(lat[0], 1.0) / hs if hs > 1e-12 else np.inf  # a spacing along
    ux, uy = (du / hs, dv / hs) if hs > 1e-12 else (0.0, 0.0)
    e, b1u, b1v, b2u, b2v = lat[0], lat[2], lat[3], lat[4], lat[5]
    fill = _lattice_fill(lat, hu, hv, rc, int(f[F_PROFILE]) >= PRISM)
    reach = math.sqrt(hu * hu + hv * hv)  # a twin's extent
    wide = reach * max(1.0, 1.0 / e) / (0.8660254037844386 * a)  # in the basis's units
    lag = reach / hs if hs > 1e-12 else np.inf  # a twin ahead is met this much before it
    t_scan = t_all + lag  # the twins past it are not met
    # a site's offset across the course and along it, linear in (i, j): i a + j b + c
    across = (b1u * e * uy - b1v * ux, b2u * e * uy - b2v * ux, pv * ux - pu * uy)
    along = (b1u * e * ux + b1v * uy, b2u * e * ux + b2v * uy, -pu * ux - pv * uy)
    best, bi, bj, bu, bv, bz = t_end, 0, 0, 0.0, 0.0, 0.0
    best2, bi2, bj2, bu2, bv2, bz2 = t_end2, 0, 0, 0.0, 0.0, 0.0  # after the face
    ta = 0.0
    for _ in range(4096):
        tb = ta + step
        last = tb >= t_scan
        lo = ta * hs if ta > 0 else -np.inf  # the step's share of the sites along the path
        hi = np.inf if last else tb * hs
        tc = tb if tb < np.inf else ta
        fi0, fj0 = _lattice_at(lat, pu + ta * du, pv + ta * dv)
        fi1, fj1 = _lattice_at(lat, pu + tc * du, pv + tc * dv)
        i0 = int(math.floor(min(fi0, fi1) - wide))
        j0 = int(math.floor(min(fj0, fj1) - wide))
        i1 = int(math.ceil(max(fi0, fi1) + wide))
        j1 = int(math.ceil(max(fj0, fj1) + wide))
        for i in range(i0, i1 + 1):  # the sites within a twin's reach of the step
            ja, jb = j0, j1
            if hs > 1e-12:  # only those whose offsets may pass the tests below
                ja, jb = _j_span(i, across, -reach, reach, ja, jb)
                ja, jb = _j_span(i, along, lo, hi, ja, jb)
            for j in range(ja, jb + 1):
                if skip0 and i == 0 and j == 0:
                    continue  # the dot the ray left
                ru, rv = (i * b1u + j * b2u) * e - pu, i * b1v + j * b2v - pv
                if not lo <= ru * ux + rv * uy < hi or _off_line(ru, rv, ux, uy, reach):
                    continue  # another step's, or off the path
                cu, cv, c, s = _twin_at(lat, i, j, place)
                there = _fill_at(ox + c0 * cu - s0 * cv, oy + s0 * cu + c0 * cv, phi, g)
                if not _stands(lat, i, j, fill, there):
                    continue  # no dots there, or fewer than the lattice packs
                t, mu, mv, mz = _meet_body(f, hu, hv, rc, k, c, s, pu - cu, pv - cv, pz, du, dv, dz)
                if t < best:
                    best, bi, bj, bu, bv, bz = t, i, j, mu, mv, mz
                if fold and best >= t_end:  # on the leg after the face
                    t, mu, mv, mz = _meet_body(
                        f, hu, hv, rc, k, c, s, fu - cu, fv - cv, -0.0, du, dv, -dz
                    )
                    if t < best2:
                        best2, bi2, bj2, bu2, bv2, bz2 = t, i, j, mu, mv, mz
        met = best < t_end  # on the way up: no twin farther along can come before it
        if last or (met and best <= tb - lag) or (fold and not met and t_face + best2 <= tb - lag):
            break
        ta = tb
    if fold and best >= t_end:
        return bi2, bj2, (best2 if best2 < t_end2 else np.inf), bu2, bv2, bz2, True
    return bi, bj, (best if best < t_end else np.inf), bu, bv, bz, False


@nb.njit(cache=True)
def _on_twin(lat, hu, hv, rc, pu, pv, place):  # pragma: no cover - compiled
    """Whether ``(pu, pv)`` (mm, the dot's frame) lies on a twin's footprint (an ellipse
    for ``rc < 0``; ``place`` as :func:`_twin_at`'s), of the twins that stand
    (:func:`_stands`: none where the map has no dots, fewer where it has fewer than the
    lattice was packed for)."""
    ox, oy, c0, s0, phi, g, _ = place
    e, _, b1u, b1v, b2u, b2v, _, _, _, _ = lat
    fill = _lattice_fill(lat, hu, hv, max(rc, 0.0), rc >= 0)
    r2 = (hu * hu + hv * hv) * (1.0 + 1e-9)  # a twin's extent, squared: sites farther off pass
    i0, j0 = _nearest_site(lat, pu, pv)
    for i in range(i0 - lat[8], i0 + lat[8] + 1):
        for j in range(j0 - lat[8], j0 + lat[8] + 1):
            du, dv = pu - (i * b1u + j * b2u) * e, pv - (i * b1v + j * b2v)
            if du * du + dv * dv > r2:
                continue
            cu, cv, c, s = _twin_at(lat, i, j, place)
            there = _fill_at(ox + c0 * cu - s0 * cv, oy + s0 * cu + c0 * cv, phi, g)
            if not _stands(lat, i, j, fill, there):
                continue
            ru, rv = c * (pu - cu) + s * (pv - cv), c * (pv - cv) - s * (pu - cu)
            if rc < 0:
                if (ru / hu) ** 2 + (rv / hv) ** 2 <= 1.0:
                    return True
            elif abs(ru) <= hu and abs(rv) <= hv:
                qu, qv = abs(ru) - (hu - rc), abs(rv) - (hv - rc)
                if qu <= 0 or qv <= 0 or qu * qu + qv * qv <= rc * rc:
                    return True
    return False


@nb.njit(cache=True)
def bare_point(state, lat, hu, hv, rc, prism, spot):  # pragma: no cover - compiled
    """A point drawn uniformly over lattice ``lat``'s cell off the footprints of its
    twins that stand (:func:`_on_twin`; half sides ``hu``, ``hv``, corner ``rc``;
    ellipses unless ``prism``), the point on the face ``spot = (x, y, c, s, phi, g,
    turn)``: its place (mm), the frame's turn there, the coverage and its angles (twins in
    a :data:`FIELD` at theirs, :func:`_twin_at`): ``(state, pu, pv)``, mm in the dot's
    frame: where a ray out through the bare face between the coverage's dots leaves it
    (the lattice's origin on the face ``(x, y) - R (pu, pv)``)."""
    e, _, b1u, b1v, b2u, b2v, _, _, _, _ = lat
    x, y, c, s, phi, g, turn = spot
    pu = pv = 0.0
    for _ in range(64):
        state, wa = uniform(state)
        state, wb = uniform(state)
        pu, pv = (wa * b1u + wb * b2u) * e, wa * b1v + wb * b2v
        place = (x - c * pu + s * pv, y - s * pu - c * pv, c, s, phi, g, turn)
        if not _on_twin(lat, hu, hv, rc if prism else -1.0, pu, pv, place):
            break
    return state, pu, pv


@nb.njit(cache=True)
def among_twins(
    state, f, n, hu, hv, rc, k, lat, skip0, place, pu, pv, pz, du, dv, dz
):  # pragma: no cover
    """The coverage's counterpart of :func:`among_dots`: a ray in the air under the face
    at ``(pu, pv, pz)`` (mm, a coverage dot's frame: half sides ``hu``, ``hv``, corner
    ``rc``, cap height ``k``) going ``d`` meets the dot's twins (lattice ``lat``,
    :func:`twin_lattice`; the dot itself at site ``(0, 0)`` left out when ``skip0``:
    the ray has just left it), found by :func:`next_twin` (``place`` its). The relaxed
    patterns ``generate`` makes place a dot's neighbours about the hexagonal spacing of
    the local fill apart, so the twins stand about where the real dots' nearest
    neighbours do. ``(state, where, pu, pv, pz, du, dv, dz)`` as :func:`among_dots`', in
    the dot's frame."""
    for _ in range(MAX_DOTS):
        i, j, t, mu, mv, mz, _ = next_twin(
            f, hu, hv, rc, k, lat, skip0, place, pu, pv, pz, du, dv, dz, var_bool(False)
        )
        if t == np.inf:
            return state, INTO_AIR, pu, pv, pz, du, dv, dz
        cu, cv, c, s = _twin_at(lat, i, j, place)
        ru, rv, pz = pu + t * du - cu, pv + t * dv - cv, min(pz + t * dz, 0.0)
        state, where, ru, rv, pz, du, dv, dz = _into_body(
            state, f, n, hu, hv, rc, k, c, s, ru, rv, pz, du, dv, dz, mu, mv, mz
        )
        pu, pv = cu + ru, cv + rv
        if where != INTO_AIR:
            return state, where, pu, pv, pz, du, dv, dz
        skip0 = False  # the lattice's own dot may be met now
    return state, CAUGHT, pu, pv, pz, du, dv, dz


@nb.njit(cache=True, inline="always")
def _no_lattice():  # pragma: no cover - compiled
    """The lattice :func:`under_dots` takes among real dots (unused there)."""
    return (1.0, 1.0, 1.0, 0.0, 0.0, 1.0, np.uint64(0), 0.0, var_int(0), var_bool(False))


@nb.njit(cache=True)
def under_dots(
    state, f, n, real, pr, walls, x, y, frame, lat, skip0, place, pu, pv, pz, du, dv, dz
):  # pragma: no cover
    """A ray in the air under a face of raised dots (row ``f``; the guide's index ``n``)
    that met the face at ``(x, y)`` (mm), now at ``(pu, pv, pz)`` going ``d``: among the
    real dots (``real``: :func:`among_dots`, the print's ``dot_tables`` ``pr``, face coordinates)
    or the coverage's twins (:func:`among_twins` over ``lat`` in the dot's frame,
    ``frame = (hu, hv, rc, k)``, ``skip0`` as its; ``place``'s origin and turn take the
    frame to the face), up onto the bare face between them (Fresnel: into the guide, or
    down again) and down to the reflector sheet, which lies on the tallest dots
    (``F_PROF_H`` under the face) and returns ``F_REFL`` of the light up among them again
    (Lambertian in air, or at the angle it came for a mirror), until the ray is back in
    the guide: ``(state, act, x, y, dx, dy, dz)``, ``NEW_LEG`` from where it comes in
    (through a dot's base, or the bare face), or the fate ``BOTTOM`` (the reflector
    absorbed it), ``DOT`` (caught in a dot, or after :data:`MAX_DOTS` passes) or
    ``EDGE`` (out past the panel's ``walls`` under the guide: beside it). A dot hanging
    over the panel's edge (a coverage dot drawn there) lets its light in where the ray
    met it."""
    hu, hv, rc, k = frame
    ox, oy, c, s, _, _, _ = place
    floor = f[F_PROF_H]
    for _ in range(MAX_DOTS):
        if real:
            state, where, pu, pv, pz, du, dv, dz = among_dots(
                state, f, n, pr, pu, pv, pz, du, dv, dz
            )
        else:
            state, where, pu, pv, pz, du, dv, dz = among_twins(
                state, f, n, hu, hv, rc, k, lat, skip0, place, pu, pv, pz, du, dv, dz
            )
        skip0 = False
        if where == CAUGHT:
            break
        bare = where == INTO_AIR
        if bare:  # out of the dots' layer: down to the reflector, or up onto the bare face
            if dz == 0:
                break
            t = (-floor - pz) / dz if dz < 0 else -pz / dz
            pu, pv, pz = pu + t * du, pv + t * dv, (-floor if dz < 0 else 0.0)
            ex, ey = ox + c * pu - s * pv, oy + s * pu + c * pv
            state, u = uniform(state)
            if dz < 0 and u >= f[F_REFL]:  # into the sheet, or out of the guide's bottom
                return state, BOTTOM, x, y, c * du - s * dv, s * du + c * dv, dz
            if _past_wall(x, y, ex, ey, walls):  # out sideways, beside the guide
                return state, EDGE, x, y, c * du - s * dv, s * du + c * dv, dz
            if dz < 0:  # the reflector sheet returns it
                if f[F_REFL_FINISH] > 0.5:  # a mirror: back up at the angle it came
                    dz = -dz
                else:
                    state, du, dv, dz = lambert(state, var_bool(True))
                continue
            if u < fresnel(dz, 1.0, n):  # the face: Fresnel, into the guide or down again
                dz = -dz
                continue
            du, dv, dz = refract(du, dv, dz, 1.0, n)
            return state, NEW_LEG, ex, ey, c * du - s * dv, s * du + c * dv, dz
        ex, ey = ox + c * pu - s * pv, oy + s * pu + c * pv  # in through a dot's base
        if _past_wall(x, y, ex, ey, walls):  # a dot over the panel's edge: where it met it
            ex, ey = x, y
        return state, NEW_LEG, ex, ey, c * du - s * dv, s * du + c * dv, dz
    return state, DOT, x, y, c * du - s * dv, s * du + c * dv, dz


# inlined into the tracer's loop: numba counts a reference to each of the print's
# tables at every call they are handed to (a tenth of a raised dot's time)
@nb.njit(cache=True, forceinline=True)
def meet_profile(state, f, n, at, x, y, pr, walls, dxn, dyn, dz):  # pragma: no cover - compiled
    """A ray going down onto a raised dot of the bottom face (its row ``f``: the profile's
    code, its body, the reflector) from the guide of index ``n``, where the print test found
    it (``at``, :func:`~optdot.optics.marks.dot_frame`'s: the point in the dot's frame, its
    angle and its half width, NaN where unknown; ``(x, y)`` the point, mm; ``pr`` the
    print's :func:`~optdot.optics.marks.dot_tables`): ``(state, act, x, y, dx, dy, dz)``,
    ``NEW_LEG`` back into the guide (from where it leaves the dot's base, or the base of the
    dot it passed into, or meets the face coming up) or a fate (``BOTTOM`` absorbed under
    it, ``DOT`` caught in a dot, ``EDGE`` out past the panel's ``walls``). A dot of another
    size than the row's is its footprint scaled, under a cap of the same height (a prism's
    facets keep their angles). Light leaving a raised dot into the air meets the dots beside
    it, and what the reflector returns meets them again (:func:`under_dots`: the real dots,
    or the coverage's twins)."""
    code = int(f[F_PROFILE])
    lu, lv, c, s, half = at
    hu, hv, rc, k = _sized(f[F_PROF_U], f[F_PROF_V], f[F_PROF_C], f[F_PROF_K], half)
    lt = twins_turn(f, hu, hv, c)
    if lt > 0:  # a random angle, drawn
        state, w = uniform(state)
        c, s = math.cos(lt * w), math.sin(lt * w)
    if c != c:
        c, s = 1.0, 0.0
    du, dv = c * dxn + s * dyn, c * dyn - s * dxn
    real = lu == lu
    if not real:  # where on the dot, drawn
        state, lu, lv = _on_footprint(state, code, hu, hv, rc)
    if code >= PRISM:
        state, where, pu, pv, pz, du, dv, dz = trace_prism(
            state, code == PRISM_CUT, hu, hv, rc, f[F_PROF_T1], f[F_PROF_T2], n, lu, lv,
            du, dv, dz,
        )  # fmt: skip
    else:
        state, where, pu, pv, pz, du, dv, dz = trace_cap(
            state, code, k, hu / hv, n, lu / hv, lv / hv, du, dv, dz
        )
        pu, pv, pz = pu * hv, pv * hv, pz * hv
    ox, oy = x - c * lu + s * lv, y - s * lu - c * lv  # the dot's centre
    if where == INTO_AIR and (code == BUMP or code == PRISM):  # among the raised dots
        frame = (hu, hv, rc, k)
        if real:
            return under_dots(
                state, f, n, real, pr, walls, x, y, frame, _no_lattice(), var_bool(False),
                (0.0, 0.0, 1.0, 0.0, pr[1], pr[2], pr[8]), ox + c * pu - s * pv,
                oy + s * pu + c * pv, min(pz, 0.0), c * du - s * dv, s * du + c * dv, dz,
            )  # fmt: skip
        fill = _fill_at(x, y, pr[1], pr[2])
        state, lat = twin_lattice(
            state, hu, hv, rc, code == PRISM, lt, max(fill, 1e-9), var_bool(True)
        )
        return under_dots(
            state, f, n, real, pr, walls, x, y, frame, lat, var_bool(True),
            (ox, oy, c, s, pr[1], pr[2], pr[8]), pu, pv, min(pz, 0.0), du, dv, dz,
        )  # fmt: skip
    dxn, dyn = c * du - s * dv, s * du + c * dv
    if where == INTO_GUIDE:  # on from where it left the dot
        ex = x + c * (pu - lu) - s * (pv - lv)
        ey = y + s * (pu - lu) + c * (pv - lv)
        if _past_wall(x, y, ex, ey, walls):  # a dot over the panel's edge: where it met it
            ex, ey = x, y
        return state, NEW_LEG, ex, ey, dxn, dyn, dz
    return state, DOT, x, y, dxn, dyn, dz  # caught


@nb.njit(cache=True, forceinline=True)
def _past_wall(x, y, x2, y2, walls):  # pragma: no cover - compiled
    """Whether the step from ``(x, y)`` to ``(x2, y2)`` (mm) crosses one of the panel's
    ``walls``: a coverage dot drawn over the edge, or light out of a dot by the edge that
    comes up past the guide's side."""
    gx, gy = x2 - x, y2 - y
    g = math.sqrt(gx * gx + gy * gy)
    return g > 0 and wall_distance(x, y, gx / g, gy / g, walls)[0] < g


# inlined into the tracer's loop: numba counts a reference to each of the print's
# tables at every call they are handed to (a tenth of a raised dot's time)
@nb.njit(cache=True, forceinline=True)
def leave_between(state, f, n, x, y, pr, walls, dxn, dyn, dz):  # pragma: no cover - compiled
    """A ray going down onto the bare face between raised dots (row ``f``) from the
    guide of index ``n`` at ``(x, y)`` (mm; ``pr`` the print's ``dot_tables``): totally
    reflected outside the escape cone, else Fresnel; what goes out into the air meets
    the dots beside it, the reflector under them, and the dots again
    (:func:`under_dots`: the real ones, or the coverage's twins at the cell's angle and
    size from a point drawn off them, :func:`bare_point`): ``(state, act, x, y, dx, dy,
    dz)`` as :func:`meet_profile`'s, or ``SAME_LEG`` reflected at the face."""
    if -dz <= f[F_COS_DOWN]:
        return state, SAME_LEG, x, y, dxn, dyn, -dz
    state, u = uniform(state)
    if u < fresnel(-dz, n, 1.0):
        return state, SAME_LEG, x, y, dxn, dyn, -dz
    dxn, dyn, dz = refract(dxn, dyn, dz, n, 1.0)
    if pr[0]:  # real dots
        return under_dots(
            state, f, n, pr[0], pr, walls, x, y, (0.0, 0.0, 0.0, 0.0), _no_lattice(),
            var_bool(False), (0.0, 0.0, 1.0, 0.0, pr[1], pr[2], pr[8]), x, y, 0.0, dxn, dyn, dz,
        )  # fmt: skip
    _, _, c, s, half = dot_frame(x, y, INK, pr)  # the coverage cell's angle and size
    hu, hv, rc, k = _sized(f[F_PROF_U], f[F_PROF_V], f[F_PROF_C], f[F_PROF_K], half)
    prism = int(f[F_PROFILE]) >= PRISM
    lt = twins_turn(f, hu, hv, c)
    if c != c:
        c, s = 1.0, 0.0
    fill = _fill_at(x, y, pr[1], pr[2])
    state, lat = twin_lattice(state, hu, hv, rc, prism, lt, max(fill, 1e-9), var_bool(False))
    state, pu, pv = bare_point(state, lat, hu, hv, rc, prism, (x, y, c, s, pr[1], pr[2], pr[8]))
    ox, oy = x - c * pu + s * pv, y - s * pu - c * pv  # the lattice's origin on the face
    return under_dots(
        state, f, n, pr[0], pr, walls, x, y, (hu, hv, rc, k), lat, var_bool(False),
        (ox, oy, c, s, pr[1], pr[2], pr[8]), pu, pv, 0.0, c * dxn + s * dyn, c * dyn - s * dxn, dz,
    )  # fmt: skip
