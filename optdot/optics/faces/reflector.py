"""The bottom face over the reflector sheet (face 0): the guide's dots printed on it or
none, the layer's escape cone and Fresnel to the sheet, which returns ``F_REFL`` of the
light: a white sheet Lambertian in air, refracted back in; a mirror film (a metal or a
multilayer) at the angle it left. Outside the cone, total internal reflection
(compiled)."""

from __future__ import annotations

import math

import numba as nb

from ..rays import fresnel, lambert, lambert_in, mirrored, uniform
from ..tables import (
    BOTTOM,
    DOT,
    EXTRACTED,
    F_COS_DOWN,
    F_DOT_R,
    F_EXTRACT,
    F_REFL,
    F_REFL_FINISH,
    NEW_LEG,
    SAME_LEG,
    var_bool,
)


@nb.njit(cache=True, inline="always")
def meet_reflector(state, f, n, ink, dxn, dyn, dz):  # pragma: no cover - compiled
    """A ray going down onto a face (its row ``f``,
    :func:`~optdot.optics.tables.face_row`) from a layer of index ``n``, on the print's
    ink (``ink``: the stepping's print test) or not: ``(state, act, dx, dy, dz)``
    (:data:`~optdot.optics.tables.SAME_LEG`, ``NEW_LEG`` or a fate)."""
    if ink:
        state, u = uniform(state)
        if u >= f[F_DOT_R]:
            return state, DOT, dxn, dyn, dz
        if f[F_EXTRACT] > 0.5:
            return state, EXTRACTED, dxn, dyn, dz
        state, dxn, dyn, dz = lambert(state, var_bool(True))  # back into the slab
        return state, NEW_LEG, dxn, dyn, dz
    if -dz > f[F_COS_DOWN]:
        state, u = uniform(state)
        r_face = fresnel(-dz, n, 1.0)
        if u >= r_face and f[F_REFL_FINISH] > 0.5:  # out to a mirror
            state, ok = mirrored(state, f[F_REFL], r_face)
            if not ok:
                return state, BOTTOM, dxn, dyn, dz
            return state, SAME_LEG, dxn, dyn, -dz  # back in at the angle it left
        if u >= r_face:  # out to the reflector sheet
            return sheet_return(state, f[F_REFL], n, dxn, dyn, dz)
    return state, SAME_LEG, dxn, dyn, -dz


@nb.njit(cache=True, inline="always")
def sheet_return(state, refl, n, dxn, dyn, dz):  # pragma: no cover - compiled
    """A ray out of the guide's bottom onto a white sheet of reflectance ``refl``:
    returned Lambertian in air and refracted back into index ``n`` (drawn again while
    the face reflects it back down), or absorbed: ``(state, NEW_LEG or BOTTOM, dx, dy,
    dz)``."""
    ok = False
    cn = sn = az = 0.0
    while True:
        state, u = uniform(state)
        if u >= refl:
            break
        state, ok, cn, sn, az = lambert_in(state, n)
        if ok:
            break
    if not ok:
        return state, BOTTOM, dxn, dyn, dz
    return state, NEW_LEG, sn * math.cos(az), sn * math.sin(az), cn
