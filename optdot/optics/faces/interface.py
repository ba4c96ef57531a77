"""A dielectric face between two layers, the top face too (where what crosses it is
extracted): Fresnel, total internal reflection and Snell; printed, the dots on the bottom
of the layer above it, which reflect ``F_DOT_R`` Lambertian back, transmit ``F_DOT_T``
Lambertian through and absorb the rest; hazy, what it transmits scattered on
(compiled)."""

from __future__ import annotations

import numba as nb

from ..rays import fresnel, lambert, refract, scatter_through, uniform
from ..tables import (
    CROSS,
    DOT,
    EXTRACTED,
    F_COS_DOWN,
    F_COS_UP,
    F_DOT_R,
    F_DOT_T,
    F_EXTRACT,
    F_HAZE,
    F_HAZE_SIG,
    NEW_LEG,
    SAME_LEG,
)


@nb.njit(cache=True, inline="always")
def meet_interface(state, f, up, n, n_to, is_top, ink, dxn, dyn, dz):  # pragma: no cover - compiled
    """A ray meeting a face (its row ``f``, :func:`~optdot.optics.tables.face_row`) going
    up (``up``) or down, from index ``n`` toward ``n_to`` (``is_top``: the top face), on
    the print's ink (``ink``: the stepping's print test) or not: ``(state, act, dx, dy,
    dz)`` (``SAME_LEG``, ``NEW_LEG``, ``CROSS`` with the direction it crosses in, out of
    the top the direction it leaves in, or a fate). A ray's fate and place are decided
    before a draw the top face's haze makes: it ends there."""
    if ink:  # the dots lie on the bottom of the layer above the face
        state, u = uniform(state)
        if u < f[F_DOT_R]:
            if f[F_EXTRACT] > 0.5:
                return state, EXTRACTED, dxn, dyn, dz
            state, dxn, dyn, dz = lambert(state, not up)
            return state, NEW_LEG, dxn, dyn, dz
        if u >= f[F_DOT_R] + f[F_DOT_T]:
            return state, DOT, dxn, dyn, dz
        state, dxn, dyn, dz = lambert(state, up)
        return state, CROSS, dxn, dyn, dz
    cos_c = f[F_COS_UP] if up else f[F_COS_DOWN]
    if abs(dz) > cos_c:
        state, u = uniform(state)
        if u >= fresnel(abs(dz), n, n_to):  # through (out of the top: into the air)
            dxn, dyn, dz = refract(dxn, dyn, dz, n, n_to)
            if f[F_HAZE] > 0.5:
                state, dxn, dyn, dz = scatter_through(
                    state, dxn, dyn, dz, int(f[F_HAZE]), f[F_HAZE_SIG], n_to
                )
            return state, CROSS, dxn, dyn, dz
    return state, SAME_LEG, dxn, dyn, -dz  # total internal or Fresnel reflection
