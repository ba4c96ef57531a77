"""A ray's random numbers and the directions it is given: every face and wall of the
tracer (:mod:`optdot.optics.faces`) draws and turns directions with these (compiled).

Each ray draws from its own counter-based generator (SplitMix64 of the run's seed and the
ray's index, :func:`ray_state`), so a result does not depend on how rays are shared among
threads. Directions are unit vectors ``(dx, dy, dz)``, ``z`` up through the stack.

The helpers that take numbers only are plain compiled functions, not numba's
``inline="always"``: LLVM inlines them into the tracer anyway (the same machine speed and
bits), while numba's own inlining types each one again at every call site, a third of the
tracer's first compile. Those handed arrays (:func:`last_at_most`) stay inlined by numba:
a call that passes arrays counts their references.
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

_GOLDEN = np.uint64(0x9E3779B97F4A7C15)
_M1 = np.uint64(0xBF58476D1CE4E5B9)
_M2 = np.uint64(0x94D049BB133111EB)
_S30, _S27, _S31, _S11 = np.uint64(30), np.uint64(27), np.uint64(31), np.uint64(11)
_TO_UNIT = 1.0 / 9007199254740992.0  # 2**-53


@nb.njit(cache=True)
def ray_state(seed, i):  # pragma: no cover - compiled
    """The generator's state for ray ``i`` of a run of ``seed``."""
    return mix(np.uint64(seed) * _M1 ^ np.uint64(i) * _M2 + _GOLDEN)


@nb.njit(cache=True)
def mix(z):
    z = (z ^ (z >> _S30)) * _M1
    z = (z ^ (z >> _S27)) * _M2
    return z ^ (z >> _S31)


@nb.njit(cache=True)
def uniform(state):
    """SplitMix64: ``(new state, u in [0, 1))``."""
    state = state + _GOLDEN
    return state, float(mix(state) >> _S11) * _TO_UNIT


@nb.njit(cache=True)
def fresnel(cos_i, n1, n2):
    """Unpolarised Fresnel reflectance from index n1 into n2 at incidence cosine cos_i."""
    sin_t = n1 / n2 * math.sqrt(max(0.0, 1.0 - cos_i * cos_i))
    if sin_t >= 1.0:
        return 1.0
    cos_t = math.sqrt(1.0 - sin_t * sin_t)
    rs = (n1 * cos_i - n2 * cos_t) / (n1 * cos_i + n2 * cos_t)
    rp = (n1 * cos_t - n2 * cos_i) / (n1 * cos_t + n2 * cos_i)
    return 0.5 * (rs * rs + rp * rp)


@nb.njit(cache=True)
def lambert_in(state, n):
    """A Lambertian direction in air refracted into index n through a face, with the
    Fresnel transmission drawn: ``(state, ok, cos about the normal, sin, azimuth)``."""
    state, u = uniform(state)
    state, v = uniform(state)
    sin_a = math.sqrt(u)
    cos_a = math.sqrt(1.0 - u)
    state, w = uniform(state)
    if w < fresnel(cos_a, 1.0, n):
        return state, False, 0.0, 0.0, 0.0
    sin_g = sin_a / n
    return state, True, math.sqrt(1.0 - sin_g * sin_g), sin_g, 2.0 * math.pi * v


@nb.njit(cache=True)
def mirrored(state, refl, r_face):
    """A ray out through a face of Fresnel reflectance ``r_face`` to a mirror of
    reflectance ``refl`` behind it: bounced between the two until the face lets it back
    through (its transmission is the same both ways) or the mirror absorbs it:
    ``(state, back)``."""
    while True:
        state, u = uniform(state)
        if u >= refl:
            return state, False
        state, u = uniform(state)
        if u >= r_face:
            return state, True


@nb.njit(cache=True)
def lambert(state, up):
    """A Lambertian unit direction about +z (``up``) or -z: ``(state, dx, dy, dz)``."""
    state, u = uniform(state)
    state, v = uniform(state)
    s = math.sqrt(u)
    dz = math.sqrt(1.0 - u)
    return (
        state,
        s * math.cos(2.0 * math.pi * v),
        s * math.sin(2.0 * math.pi * v),
        (dz if up else -dz),
    )


@nb.njit(cache=True)
def tilt(state, dx, dy, dz, sigma):
    """The unit direction turned by a 2-D Gaussian angle of ``sigma`` rad (Rayleigh polar
    angle, uniform azimuth) and kept on its side of the face: redrawn up to 16 times, else
    left as it was. ``(state, dx, dy, dz)``."""
    up = dz > 0
    # an orthonormal pair perpendicular to d
    if abs(dz) < 0.9:
        ax, ay, az = -dy, dx, 0.0
    else:
        ax, ay, az = 0.0, -dz, dy
    a = math.sqrt(ax * ax + ay * ay + az * az)
    ax, ay, az = ax / a, ay / a, az / a
    bx, by, bz = dy * az - dz * ay, dz * ax - dx * az, dx * ay - dy * ax
    for _ in range(16):
        state, u = uniform(state)
        state, v = uniform(state)
        alpha = sigma * math.sqrt(-2.0 * math.log(1.0 - u))
        if alpha >= math.pi:
            continue
        beta = 2.0 * math.pi * v
        ca, sa = math.cos(alpha), math.sin(alpha)
        cb, sb = math.cos(beta), math.sin(beta)
        nx = dx * ca + (ax * cb + bx * sb) * sa
        ny = dy * ca + (ay * cb + by * sb) * sa
        nz = dz * ca + (az * cb + bz * sb) * sa
        if (nz > 1e-9) == up and abs(nz) > 1e-9:
            return state, nx, ny, nz
    return state, dx, dy, dz


@nb.njit(cache=True, inline="always")
def last_at_most(a, value, n):
    """The last ``k < n`` with ``a[k] <= value`` (``a`` non-decreasing, ``a[0] <=
    value``), by bisection: a ray's emitter among ``emit_start`` (an emitter given no rays
    repeats its successor's start; log(LEDs) steps, not one per LED), a draw's bin of a
    cumulative distribution."""
    lo, hi = 0, n
    while hi - lo > 1:
        mid = (lo + hi) // 2
        if a[mid] <= value:
            lo = mid
        else:
            hi = mid
    return lo


@nb.njit(cache=True)
def refract(dxn, dyn, dz, n1, n2):
    """The direction transmitted from index n1 into n2 through a horizontal face (the
    caller has checked it is not totally reflected): ``(dx, dy, dz)``, dz keeping its
    sign."""
    r = n1 / n2
    dxn *= r
    dyn *= r
    c = math.sqrt(max(0.0, 1.0 - dxn * dxn - dyn * dyn))
    return dxn, dyn, (c if dz > 0 else -c)


@nb.njit(cache=True)
def scatter_through(state, dxn, dyn, dz, mode, sigma, n_to):
    """What a hazy face or a sheet does to a direction it transmits (``dz``'s sign: the
    way it goes): ``mode`` 1 a Lambertian direction in air, refracted into ``n_to``; 2 the
    direction tilted by a Gaussian angle ``sigma``; 0 unchanged."""
    if mode == 1:
        state, a, b, c = lambert(state, dz > 0)
        if n_to != 1.0:
            a /= n_to
            b /= n_to
            c = math.copysign(math.sqrt(max(0.0, 1.0 - a * a - b * b)), c)
        return state, a, b, c
    if mode == 2:
        return tilt(state, dxn, dyn, dz, sigma)
    return state, dxn, dyn, dz
