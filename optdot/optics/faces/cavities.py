"""Dots cut into the guide's bottom face (compiled): the light in the glass among their
cavities (a dimple's cap of air, a cut prism), and under them.

A cavity stands above its footprint, inside the glass: a ray coming down onto the face
meets a cavity wherever its path passes through one, not only where it crosses the
face's plane on a footprint. A ray coming down at 30° from the face passes over a
cavity 15 µm deep along 26 µm before it crosses the plane: a shallow ray meets a dimple
beyond its rim, and is turned by its wall. So the ray is followed from where it comes
down into the layer of the cavities (the deepest one's depth over the face), among the
cavities (:func:`~.dot_profile.next_dot` over the real dots, or
:func:`~.dot_profile.next_twin` over the coverage's twins, with ``z`` turned over: a
cavity in the glass is a raised dot in the air seen from below), through each it meets
(:func:`~.dot_profile._into_body`: Fresnel and total internal reflection off its wall,
or in, across the air and out through its wall or its open base), onto the bare face
between them (Fresnel, total internal reflection, the reflector sheet under it), until
it leaves the layer going up, into the guide. What leaves a cavity's open base goes
down onto the reflector sheet, which lies against the face: it returns the light up
into that cavity (Lambertian, or at the angle it came for a mirror), through the
cavity's wall into the glass or out of its base again.

In a coverage trace the cavities are the coverage's twins about the point the print test
drew: on a dot (where on it drawn over its footprint) or on the bare face between them
(drawn off the twins, :func:`~.dot_profile.bare_point`), on the hexagonal lattice of the
cell's fill (:func:`~.dot_profile.twin_lattice`), so a shallow ray meets a twin beyond
its rim as it meets a real dot.
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

from ...geometry.profile import PRISM
from ...geometry.shapes import half_width_packed
from ..marks import BARE, INK, dot_frame
from ..rays import lambert, uniform
from ..tables import (
    AT_WALL,
    BOTTOM,
    DOT,
    F_COS_DOWN,
    F_PROF_C,
    F_PROF_K,
    F_PROF_U,
    F_PROF_V,
    F_PROFILE,
    F_REFL,
    F_REFL_FINISH,
    NEW_LEG,
    SAME_LEG,
    var_bool,
)
from .dot_profile import (
    CAUGHT,
    INTO_AIR,
    MAX_DOTS,
    _fill_at,
    _into_body,
    _no_lattice,
    _on_footprint,
    _past_wall,
    _site,
    _sized,
    _twin_at,
    _walk_body,
    bare_point,
    fill_along,
    next_dot,
    next_twin,
    tallest,
    twin_lattice,
    twins_turn,
)
from .reflector import meet_reflector
from .slab_walls import wall_distance

__all__ = ["among_cavities", "meet_cut", "packed_for"]

#: The farthest along a ray's course, either way from where it meets the face, that the
#: coverage's fill is looked at to pack its twins (mm): a course nearly parallel to the
#: face crosses the cavities' layer over a long way.
_REACH = 2.0


@nb.njit(cache=True, forceinline=True)
def _sheet_back(state, f, du, dv, dz):  # pragma: no cover - compiled
    """A ray going down out of a cavity's open base onto the reflector sheet against the
    face (row ``f``'s ``F_REFL``, ``F_REFL_FINISH``): ``(state, back, du, dv, dz)``,
    whether the sheet returns it and the direction it comes up in (Lambertian in air, or
    at the angle it came for a mirror)."""
    state, u = uniform(state)
    if u >= f[F_REFL]:
        return state, False, du, dv, dz
    if f[F_REFL_FINISH] > 0.5:
        return state, True, du, dv, -dz
    state, du, dv, dz = lambert(state, var_bool(True))
    return state, True, du, dv, dz


@nb.njit(cache=True, forceinline=True)
def _at_wall(x, y, z0, lx, ly, lz, ex, ey, ez, walls):  # pragma: no cover - compiled
    """Where a ray leaving the cavities' layer (or coming down onto the face) at ``(ex, ey,
    ez)`` (mm, face coordinates, ``z`` over the face) on a straight leg from ``(lx, ly,
    lz)`` meets the panel's ``walls`` first: ``(met, x, y, z)``, on that leg a nanometre
    short of the wall; where the leg began past a wall already (seen from ``(x, y)``,
    where the ray met the face or the wall), not met: ``(x, y, z0)``."""
    if _past_wall(x, y, lx, ly, walls):
        return False, x, y, z0
    gx, gy = ex - lx, ey - ly
    g = math.sqrt(gx * gx + gy * gy)
    f = min(max(wall_distance(lx, ly, gx / g, gy / g, walls)[0] - 1e-9, 0.0) / g, 1.0)
    return True, lx + f * gx, ly + f * gy, lz + f * (ez - lz)


@nb.njit(cache=True, forceinline=True)
def _next_cavity(f, real, pr, frame, lat, place, pu, pv, pz, du, dv, dz):  # pragma: no cover
    """The first cavity a ray in the glass at ``(pu, pv)``, ``pz`` mm over the face of cut
    dots (row ``f``), going ``d`` (unit) meets before it leaves their layer: a real dot
    (``real``: :func:`~.dot_profile.next_dot` over the print's ``pr``) or a twin
    (:func:`~.dot_profile.next_twin` over ``lat``; ``frame``, ``place`` as
    :func:`among_cavities`'), ``z`` turned over: ``(met, i, j, t, mx, my, mz, after)``,
    whether it meets one, which (the dot ``i``, or the site ``(i, j)``), how far on (mm)
    and the normal there. A ray going down that the face will reflect totally is followed
    on past it, up: ``after``, when it meets none on the way down (then the one it meets
    after the face, ``t`` from there)."""
    fold = dz < 0 and -dz <= f[F_COS_DOWN]
    if real:
        i, t, mx, my, mz, after = next_dot(
            f, pr[3], pr[4], pr[5], pr[6], pr[7], pu, pv, -pz, du, dv, -dz, fold
        )
        return i >= 0, i, 0, t, mx, my, mz, after
    hu, hv, rc, k = frame
    i, j, t, mx, my, mz, after = next_twin(
        f, hu, hv, rc, k, lat, var_bool(False), place, pu, pv, -pz, du, dv, -dz, fold
    )
    return t < np.inf, i, j, t, mx, my, mz, after


@nb.njit(cache=True)
def among_cavities(
    state, f, n, real, pr, walls, x, y, z0, deep, frame, lat, place, pu, pv, pz, du, dv, dz, met
):  # pragma: no cover
    """A ray in the glass of index ``n`` over a face of cut dots (row ``f``), at ``(pu, pv,
    pz)`` going ``d`` (unit; ``pz`` mm over the face), followed among the cavities until it
    leaves their layer going up: the real dots' (``real``: the print's
    :func:`~optdot.optics.marks.dot_tables` ``pr``, face coordinates) or the coverage's
    twins (lattice ``lat`` of :func:`~.dot_profile.twin_lattice`, all of them met, in the
    frame ``place = (ox, oy, c, s, phi, g, turn)`` puts on the face; every twin's frame
    ``frame = (hu, hv, rc, k)``). ``(x, y, z0)``: where the ray met the face or was born
    (mm, ``z0`` over the face); ``deep``: the layer's depth (mm, the deepest cavity's).
    Returns ``(state, act, x, y, z, dx, dy, dz)``: ``NEW_LEG`` up into the guide from where
    it leaves the layer (face coordinates, ``z`` mm over the face), ``SAME_LEG`` from ``(x,
    y, z0)`` when a ray coming down met nothing but the flat face, which reflected it (its
    course the same, turned up), ``AT_WALL`` where a leg going down meets the panel's
    ``walls`` before the face (the tracer turns it off the wall), or the fate ``BOTTOM``
    (the reflector absorbed it), ``DOT`` (caught in a cavity, or after
    :data:`~.dot_profile.MAX_DOTS` events). A ray that would leave the layer past the
    walls goes on from where its last leg meets the wall (:func:`_at_wall`; from ``(x, y,
    z0)`` when that leg began past it). ``met``: the first cavity on its path
    (:func:`_next_cavity`'s)."""
    ox, oy, c0, s0, _, _, _ = place
    hu, hv, rc, k = frame
    cu, cv, c, s = 0.0, 0.0, 1.0, 0.0
    plain = dz < 0  # met nothing but the flat face, and that as a mirror, yet
    looked = True  # the first cavity on its path, found by the caller
    for _ in range(MAX_DOTS):
        if not looked:
            met = _next_cavity(f, real, pr, frame, lat, place, pu, pv, pz, du, dv, dz)
        found, i, j, t, mx, my, mz, after = met
        looked = after  # none on the way down: the one met on the way up, kept
        met = (found, i, j, t, mx, my, mz, False)
        found = found and not after
        if found and real:
            hu, hv, rc, k = _sized(
                f[F_PROF_U], f[F_PROF_V], f[F_PROF_C], f[F_PROF_K], half_width_packed(pr[6], i)
            )
            cu, cv, c, s = pr[4][i], pr[5][i], pr[6][i, 4], pr[6][i, 5]
        elif found:
            cu, cv, c, s = _twin_at(lat, i, j, place)
        if found:  # into the cavity (z turned back: its normal out into the glass)
            plain = False
            rx, ry, z = pu + t * du - cu, pv + t * dv - cv, max(pz + t * dz, 0.0)
            state, where, rx, ry, z, du, dv, dz = _into_body(
                state, f, n, hu, hv, rc, k, c, s, rx, ry, z, du, dv, dz, mx, my, -mz
            )
            for _ in range(MAX_DOTS):
                if where != INTO_AIR:
                    break
                state, back, du, dv, dz = _sheet_back(state, f, du, dv, dz)
                if not back:  # out of its open base, and the sheet absorbed it
                    return state, BOTTOM, x, y, 0.0, c0 * du - s0 * dv, s0 * du + c0 * dv, dz
                state, where, rx, ry, z, du, dv, dz = _walk_body(
                    state, f, n, hu, hv, rc, k, c, s, rx, ry, 0.0, du, dv, dz
                )
            if where == CAUGHT or where == INTO_AIR:
                break
            pu, pv, pz = cu + rx, cv + ry, z
            continue
        if dz >= 0 and plain:  # reflected by the face alone: on up from where it met it
            return state, SAME_LEG, x, y, z0, c0 * du - s0 * dv, s0 * du + c0 * dv, dz
        if dz >= 0:  # out of the cavities' layer, up into the guide
            t = max(deep - pz, 0.0) / dz if dz > 0 else 0.0
            lx, ly = ox + c0 * pu - s0 * pv, oy + s0 * pu + c0 * pv  # its last leg's start
            pu, pv = pu + t * du, pv + t * dv
            ex, ey = ox + c0 * pu - s0 * pv, oy + s0 * pu + c0 * pv
            if _past_wall(x, y, ex, ey, walls):
                _, ex, ey, pz = _at_wall(x, y, z0, lx, ly, pz, ex, ey, max(pz, deep), walls)
            else:
                pz = max(pz, deep)
            return state, NEW_LEG, ex, ey, pz, c0 * du - s0 * dv, s0 * du + c0 * dv, dz
        t = -pz / dz  # onto the bare face between the cavities
        lx, ly = ox + c0 * pu - s0 * pv, oy + s0 * pu + c0 * pv  # its leg's start
        fu, fv = pu + t * du, pv + t * dv
        ex, ey = ox + c0 * fu - s0 * fv, oy + s0 * fu + c0 * fv
        if _past_wall(x, y, ex, ey, walls):  # the panel's wall comes first: onto it
            met, ex, ey, pz = _at_wall(x, y, z0, lx, ly, pz, ex, ey, 0.0, walls)
            act = AT_WALL if met else NEW_LEG  # (its leg began past it: from where it met)
            return state, act, ex, ey, pz, c0 * du - s0 * dv, s0 * du + c0 * dv, dz
        pu, pv, pz = fu, fv, 0.0
        state, act, du, dv, dz = meet_reflector(state, f, n, False, du, dv, dz)
        if act >= 0:
            return state, act, x, y, 0.0, c0 * du - s0 * dv, s0 * du + c0 * dv, dz
        plain = plain and act == SAME_LEG
    return state, DOT, x, y, 0.0, c0 * du - s0 * dv, s0 * du + c0 * dv, dz


@nb.njit(cache=True, forceinline=True)
def packed_for(x, y, dxn, dyn, dz, z0, back, deep, reach, phi, g):  # pragma: no cover
    """The fill the coverage (``phi`` over cells of ``g``) has where a ray going ``d``
    (unit) meets a face of cut dots at ``(x, y)`` (mm; ``z0`` mm over it, where it was
    born or met a wall), and the fill the twins it meets are packed for: the most of the
    cells its path crosses in the cavities' layer, ``deep`` mm (from ``back`` back along
    it, its length in the layer before it met the face, to where it leaves the layer after;
    at most :data:`_REACH` each way over the face), and a twin's ``reach`` (mm) past either
    end: ``(fill, top)``. Thinned where the map has fewer (:func:`~.dot_profile._stands`),
    the twins along a walk toward the map's denser cells stand as densely as its dots do
    there."""
    fill = _fill_at(x, y, phi, g)
    hs = math.sqrt(dxn * dxn + dyn * dyn)
    ahead = (z0 + deep) / -dz if dz < 0 else (deep - z0) / dz if dz > 0 else np.inf
    ux, uy = (dxn / hs, dyn / hs) if hs > 1e-12 else (0.0, 0.0)
    lo, hi = -min(back * hs, _REACH) - reach, min(ahead * hs, _REACH) + reach
    return fill, max(fill, fill_along(x, y, ux, uy, lo, hi, phi, g))


# inlined into the tracer's loop: numba counts a reference to each of the print's
# tables at every call they are handed to (called instead, dimples took ~20 % longer a ray)
@nb.njit(cache=True, forceinline=True)
def meet_cut(state, f, n, on, x, y, z, pr, walls, dxn, dyn, dz, run):  # pragma: no cover
    """A ray in the guide of index ``n`` over a face of cut dots (row ``f``): going down, its
    path crossing the face's plane at ``(x, y)`` (mm), on a dot or not (``on``:
    :func:`~optdot.optics.marks.printed`'s there; the real dots are found along the path
    whatever it says), followed from where its path comes down into the cavities' layer (or
    from the panel's wall behind it, where a ray born or turned there began); or going up
    from ``(x, y)``, ``z`` mm over the face (a ray born there), followed from there if that
    is within the layer (else returned as it came, ``SAME_LEG``); or going down onto the
    panel's wall at ``(x, y)``, ``z > 0`` mm over the face, followed among the cavities if
    its path meets one before the wall (else returned as it came, ``SAME_LEG`` with ``dz``
    still down: on to the wall). ``run``: how far (mm)
    its course has come over the face since it last turned (the panel's walls are
    looked up behind it only past that; 0 if not known). ``pr``: the print's
    :func:`~optdot.optics.marks.dot_tables`. Among the cavities (:func:`among_cavities`):
    ``(state, act, x, y, z, dx, dy, dz)``, ``NEW_LEG`` back into the guide from where it
    leaves the layer (``z`` mm over the face) or a fate."""
    real = pr[0]
    code = int(f[F_PROFILE])
    hu, hv, rc, k = f[F_PROF_U], f[F_PROF_V], f[F_PROF_C], f[F_PROF_K]
    c = s = 0.0
    if real:
        deep = max(tallest(f, pr[7][6], hv, k), tallest(f, hu, hv, k))
    else:
        _, _, c, s, half = dot_frame(x, y, INK, pr)  # the coverage cell's angle and size
        hu, hv, rc, k = _sized(hu, hv, rc, k, half)
        deep = tallest(f, hu, hv, k)
    deep *= 1.0 + 1e-9  # over the deepest cavity's apex: a ray from there meets it
    at_wall = dz < 0 and z > 0  # coming down onto the panel's wall over the face
    if (dz >= 0 or at_wall) and z >= deep:  # over the cavities
        return state, SAME_LEG, x, y, z, dxn, dyn, dz
    back = (deep - z) / -dz if dz < 0 else 0.0  # back along the path to the layer's top
    hs = math.sqrt(dxn * dxn + dyn * dyn)
    if back > 0 and back * hs > run:  # or to the panel's wall behind it, where its path began
        back = min(back, wall_distance(x, y, -dxn / hs, -dyn / hs, walls)[0] / hs)
    z0, z = z, z - back * dz
    if real:  # face coordinates
        lat, c, s, ox, oy, pu, pv = _no_lattice(), 1.0, 0.0, 0.0, 0.0, x, y
    else:  # the coverage's twins, in the frame of the dot drawn at the lattice's origin
        lt = twins_turn(f, hu, hv, c)
        if c != c:
            c, s = 1.0, 0.0
        reach = math.hypot(hu, hv)
        fill, top = packed_for(x, y, dxn, dyn, dz, z0, back, deep, reach, pr[1], pr[2])
        if at_wall:  # the wall's point over a twin with the fill's chance, as at the face
            state, u = uniform(state)
            on = INK if u < fill else BARE
        state, lat = twin_lattice(state, hu, hv, rc, code >= PRISM, lt, max(top, 1e-9), on != BARE)
        if on != BARE:  # on the twin at the lattice's origin: where on it, drawn
            state, lu, lv = _on_footprint(state, code, hu, hv, rc)
            _, _, c1, s1 = _site(lat, 0, 0)  # its own angle in the lattice's frame
            pu, pv = c1 * lu - s1 * lv, s1 * lu + c1 * lv
        else:
            spot = (x, y, c, s, pr[1], pr[2], pr[8])
            state, pu, pv = bare_point(state, lat, hu, hv, rc, code >= PRISM, spot)
        ox, oy = x - c * pu + s * pv, y - s * pu - c * pv  # the lattice's origin on the face
    du, dv = c * dxn + s * dyn, c * dyn - s * dxn
    pu, pv = pu - back * du, pv - back * dv
    frame, place = (hu, hv, rc, k), (ox, oy, c, s, pr[1], pr[2], pr[8])
    met = _next_cavity(f, real, pr, frame, lat, place, pu, pv, z, du, dv, dz)
    if at_wall and not (met[0] and not met[7] and met[3] < back):  # none before the wall
        return state, SAME_LEG, x, y, z0, dxn, dyn, dz
    if not met[0] and met[7]:  # no cavity on its path down to the face and back up, which
        return state, SAME_LEG, x, y, z0, c * du - s * dv, s * du + c * dv, -dz  # reflects it
    return among_cavities(
        state, f, n, real, pr, walls, x, y, z0, deep, frame, lat, place, pu, pv, z, du, dv, dz,
        met,
    )  # fmt: skip
