"""Dots that are 3-D structures on the guide's bottom face: a spherical cap of the guide's
material standing out of the face (a bump, moulded or embossed), or a spherical cap of
air cut into it (a dimple, a laser crater) (compiled).

Where the stepping finds a ray on a dot (the print test at the face's plane), the ray is
followed through the cap's surface exactly, as many times as it meets it: Fresnel and
total internal reflection at the sphere's local normal, Snell through it. A bump's ray
goes down into the cap through the plane of the face, and leaves it back up through that
plane (into the guide) or out through the sphere (into the air under the guide). A
dimple's ray meets the cavity's surface on its way down (the point where its path enters
the sphere, behind the plane's crossing); through it, it crosses the cavity's air and
leaves through the sphere (back into the guide) or down through the cavity's open base
(into the air under the guide). Under the guide, the reflector returns it as it returns
light out of the flat face (:mod:`.reflector`); light going up there meets the flat face.

Where the ray meets the dot is drawn uniformly over its footprint: a cap is the same
shape at any size (its height over its radius), and what moves a ray sideways inside a
dot (at most its diameter) is left out, as is light leaving one structure into another.

Cap coordinates: the footprint's radius 1, the face's plane ``z = 0``, the guide above;
a cap of height ``k`` (its height over the radius, at most 1: a hemisphere) is part of
the sphere of radius ``R = (1 + k²) / (2k)`` centred at ``z = R - k`` (a bump, below the
plane) or ``z = k - R`` (a dimple, above it).
"""

from __future__ import annotations

import math

import numba as nb

from ..rays import fresnel, mirrored, refract, uniform
from ..tables import BOTTOM, DOT, F_PROF_K, F_PROFILE, F_REFL, F_REFL_FINISH, NEW_LEG, SAME_LEG
from .reflector import meet_reflector, sheet_return

#: Profile codes (:data:`optdot.geometry.profile.PROFILES`).
BUMP, DIMPLE = 1, 2
#: Where a ray leaves a dot: back up into the guide, into the air under the guide, caught
#: (after :data:`MAX_BOUNCES` surfaces), or in the guide going down onto the flat face
#: beside a dimple.
INTO_GUIDE, INTO_AIR, CAUGHT, ONTO_FACE = 0, 1, 2, 3
#: Surfaces a ray may meet inside one dot before it counts as absorbed by it. A ray
#: grazing a bump's rim circles it by total reflection along a great circle, advancing
#: twice its grazing angle a meeting, until it reaches the face's plane: 4,096 meetings
#: let out a ray grazing at 0.02° (2 in 10⁶ Lambertian rays outlived 64).
MAX_BOUNCES = 4096


@nb.njit(cache=True)
def trace_cap(state, code, k, n, px, py, dx, dy, dz):  # pragma: no cover - compiled
    """A ray going down (``dz < 0``) in the guide of index ``n`` whose path crosses the
    face's plane at ``(px, py)`` (the footprint's radius 1) on a cap of profile ``code``
    and height ``k``: ``(state, where, dx, dy, dz)``, ``where`` one of
    :data:`INTO_GUIDE`, :data:`INTO_AIR`, :data:`CAUGHT`, :data:`ONTO_FACE`, with the
    direction it goes on in."""
    r_s = (1.0 + k * k) / (2.0 * k)
    bump = code == BUMP
    cz = r_s - k if bump else k - r_s
    n_in, n_out = (n, 1.0) if bump else (1.0, n)  # inside the sphere, outside it
    pz = 0.0
    if not bump:  # back along the path to where it met the cavity, from the guide
        ox, oy, oz = px, py, -cz
        b = dx * ox + dy * oy + dz * oz
        c = ox * ox + oy * oy + oz * oz - r_s * r_s
        t = -b - math.sqrt(max(b * b - c, 0.0))
        px, py, pz = px + t * dx, py + t * dy, t * dz
        mx, my, mz = (px / r_s, py / r_s, (pz - cz) / r_s)  # out of the sphere
        cos_i = -(dx * mx + dy * my + dz * mz)
        state, u = uniform(state)
        if u < fresnel(cos_i, n, 1.0):  # reflected back into the guide
            dx, dy, dz = dx + 2.0 * cos_i * mx, dy + 2.0 * cos_i * my, dz + 2.0 * cos_i * mz
            return state, (INTO_GUIDE if dz > 0 else ONTO_FACE), dx, dy, dz
        dx, dy, dz = _through(dx, dy, dz, -mx, -my, -mz, n, 1.0)
    for _ in range(MAX_BOUNCES):
        leaves = dz > 0 if bump else dz < 0
        t_plane = -pz / dz if leaves else 1e300
        ox, oy, oz = px, py, pz - cz
        b = dx * ox + dy * oy + dz * oz
        c = ox * ox + oy * oy + oz * oz - r_s * r_s
        t_sphere = -b + math.sqrt(max(b * b - c, 0.0))
        if t_plane <= t_sphere:  # out through the face's plane
            return state, (INTO_GUIDE if bump else INTO_AIR), dx, dy, dz
        px, py, pz = px + t_sphere * dx, py + t_sphere * dy, pz + t_sphere * dz
        mx, my, mz = px / r_s, py / r_s, (pz - cz) / r_s  # out of the sphere
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
def meet_profile(state, f, n, dxn, dyn, dz):  # pragma: no cover - compiled
    """A ray going down onto a dot of the bottom face (its row ``f``: the profile's code
    and height, the reflector) from the guide of index ``n``: ``(state, act, dx, dy,
    dz)``, ``NEW_LEG`` back into the guide or a fate (``BOTTOM`` absorbed under it,
    ``DOT`` caught in the dot)."""
    state, u = uniform(state)
    state, v = uniform(state)
    r, phi = math.sqrt(u), 2.0 * math.pi * v
    state, where, dxn, dyn, dz = trace_cap(
        state, int(f[F_PROFILE]), f[F_PROF_K], n, r * math.cos(phi), r * math.sin(phi),
        dxn, dyn, dz,
    )  # fmt: skip
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
