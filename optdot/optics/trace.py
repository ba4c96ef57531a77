"""The Monte Carlo ray tracer of a backlight stack (compiled): each ray from an LED to its end.

A backlight is a **scene** (:class:`Scene`): sources, a stack of horizontal layers inside the
panel's side walls, the faces between them, and the dots printed on one face. The edge-lit
guide is the scene of one slab whose bottom face carries the dots and has the reflector sheet
under it; a direct-lit backlight is an air cavity over a reflector carrying LEDs, the printed
film, and diffuser sheets above (:mod:`optdot.optics.scene` builds both from a job).

**Layers** ``0 .. L - 1`` bottom to top, each ``z0 <= z <= z1`` with an index, a bulk
absorption and what covers its side walls. **Faces** ``0 .. L``: face ``i`` lies under
layer ``i`` (face ``L`` is the top, where light leaves to the viewer). A ray is followed
event by event:

- **Birth**: an emitter chosen by ray index (rays are shared out in proportion to power
  before tracing), a point on its rectangle, a direction in air from its profile
  (inverse-CDF of ``I(theta) sin(theta)``) about its axis, Fresnel transmission into its
  layer (rays it reflects are *not coupled* and not counted as injected), Snell
  refraction. An edge emitter is an LED on a slab's side wall; a face emitter an LED on the
  reflector, shining up into the cavity.
- **Layers**: between events a ray's horizontal direction is fixed, so the distance to the
  next wall is found once per leg and the faces are stepped one at a time.
- **Faces** (by kind):

  - ``BOTTOM`` (face 0): the reflector sheet under layer 0, in contact (no gap): the dot
    test if the face is printed, then the layer's escape cone and Fresnel lead to the
    sheet, which returns ``reflector`` of the light (or absorbs it: *lost at the bottom*):
    a diffuse sheet Lambertian in air, refracted back in; a specular one (a metal or
    multilayer mirror film) mirrored, so the ray comes back at the angle it left, after as
    many bounces between the sheet and the face's Fresnel reflection as it takes.
  - ``INTERFACE``: a dielectric face between two layers (Fresnel, total internal
    reflection, Snell). If printed, the dots sit on the bottom of the layer above it: a dot
    met from either side reflects ``dot R`` of the light Lambertian back, transmits ``dot
    T`` Lambertian to the other side, and absorbs the rest (*absorbed in dots*). A hazy
    face sends what it transmits on in a scattered direction (Lambertian, or tilted by a
    Gaussian angle).
  - ``SHEET``: a thin diffuser between two air layers: ``T`` transmitted to the other side
    (Lambertian or Gaussian spread), ``R`` reflected Lambertian (recycled), the rest
    *absorbed in sheets*.
  - the top face (index ``L``, any kind): what crosses it is *extracted*, binned where it
    leaves.
- **Walls**: a slab's walls reflect totally outside its escape cone and by Fresnel inside
  it; what leaves meets the cover, which returns ``edge_reflectance`` of it (``specular``
  mirrored, ``diffuse`` Lambertian refracted back in) and the rest is *lost at the edges*;
  an ``absorbing`` edge takes everything. In air the same rule is the frame's.
- **Bulk absorption**: an optical depth drawn once per ray from ``exp(-tau)``, spent along
  the 3-D path at each layer's absorption coefficient.

Every ray ends in exactly one fate, so injected = extracted + absorbed + lost holds exactly.
Each ray draws from its own counter-based generator (SplitMix64 of the seed and the ray's
index), so the result does not depend on how rays are shared among threads. The edge-lit
guide as this scene draws the same numbers in the same order as the single-slab kernel it
replaced, so it gives the same counts for the same seed.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numba as nb
import numpy as np

from ..geometry.shapes import on_packed

#: Fates of a ray (``trace`` output).
EXTRACTED, BULK, DOT, EDGE, BOTTOM, UNCOUPLED, UNFINISHED, SHEET = range(8)
FATES = (
    "extracted",
    "absorbed_bulk",
    "absorbed_dots",
    "lost_edges",
    "lost_bottom",
    "not_coupled",
    "unfinished",
    "absorbed_sheets",
)
#: Events (reflections, scatterings) after which a ray is given up (``unfinished``;
#: reported, never silently dropped).
MAX_EVENTS = 1 << 16

# -- the scene's tables: column indices ------------------------------------------------
#: Emitter ``[e, 17]``: centre (3), axis (3, unit), tangent (3), second tangent (3), width
#: along the tangent, span and start along the second tangent (a point is centre +
#: tangent (u - 1/2) width + second (v span + start)), profile index, layer.
E_C, E_A, E_T, E_B, E_W, E_SPAN, E_START, E_PROF, E_LAYER = 0, 3, 6, 9, 12, 13, 14, 15, 16
E_COLS = 17
#: Layer ``[L, 7]``: z0, z1 (mm), index, absorption (1/mm), wall cover's reflectance, its
#: finish (0 diffuse, 1 specular, 2 absorbing), the walls' critical cosine (0 when none).
L_Z0, L_Z1, L_N, L_ABS, L_WALL_R, L_WALL_MODE, L_WALL_COS = range(7)
L_COLS = 7
#: Face ``[L + 1, 15]``: kind, printed (0 no, 1 the job's print, 2 the second map), dot
#: R, dot T, reflector (BOTTOM), dot extract (0/1), haze (0 none, 1 Lambertian, 2
#: Gaussian), haze sigma (rad), sheet T, sheet R, sheet spread (0 Lambertian, 1 Gaussian),
#: its sigma (rad), critical cosine going up, going down (0 when there is none), the
#: reflector's finish (BOTTOM: 0 diffuse, 1 specular).
(F_KIND, F_PRINT, F_DOT_R, F_DOT_T, F_REFL, F_EXTRACT, F_HAZE, F_HAZE_SIG, F_SHEET_T) = range(9)
F_SHEET_R, F_SPREAD, F_SPREAD_SIG, F_COS_UP, F_COS_DOWN, F_REFL_FINISH = range(9, 15)
F_COLS = 15
#: Face kinds.
BOTTOM_FACE, INTERFACE, SHEET_FACE = 0, 1, 2


class Sources(NamedTuple):
    """The emitters and their angular profiles.

    Attributes:
        emit: ``[e, E_COLS]`` emitters (see ``E_*``), mm.
        start: ``[e + 1]`` int64 first global ray of each emitter (the last = the total).
        theta: ``[K]`` angles in air, rad, of the profiles' CDFs.
        cdf: ``[p, K]`` the CDF of ``I(theta) sin(theta)`` per profile.
        mode: ``[p, 2]`` (0 table / 1 collimated, the collimated tilt in rad).
    """

    emit: np.ndarray
    start: np.ndarray
    theta: np.ndarray
    cdf: np.ndarray
    mode: np.ndarray


class Stack(NamedTuple):
    """Layers, faces and walls (see ``L_*``, ``F_*``).

    Attributes:
        layer: ``[L, L_COLS]``. face: ``[L + 1, F_COLS]``.
        walls: ``[m, 4]`` wall segments (ax, ay, bx, by), mm. normals: ``[m, 2]`` inward.
        max_events: events after which a ray is given up (``unfinished``).
    """

    layer: np.ndarray
    face: np.ndarray
    walls: np.ndarray
    normals: np.ndarray
    max_events: int


class Print(NamedTuple):
    """What is printed: on faces marked 1 the job's map (its coverage) or its real dots; on
    faces marked 2 a second coverage map (the other printed face of a stack).

    Attributes:
        explicit: trace real dots (True) or the coverage map ``phi``.
        phi: ``[ny, nx]`` coverage; g: ``[4]`` its x0, y0, dx, dy, mm.
        start: ``[cells + 1]`` CSR of dots by cell; x, y: ``[n]`` centres, mm; foot:
            ``[n, 6]`` their footprints (:func:`optdot.geometry.shapes.packed`); cg:
            ``[7]`` cell grid x0, y0, dx, dy, nx, ny and the largest dot extent (cells
            at least that wide).
        phi2, g2: the second coverage map and its grid (as ``phi``, ``g``).
        cap_start, cap: the caps of print 1 (solid ink discs, tested before the dots or
            the coverage, so ``phi`` is the coverage where no cap is): ``[cells + 1]``
            CSR by cell and ``[m, 3]`` rows ``(x, y, r^2)``, mm; cap_g: ``[7]`` their
            cell grid (as ``cg``).
        cap_ring: ``[k, 2]`` the rings each cap prints, ``(r_in^2, r_out^2)`` mm^2 about
            its centre (a solid cap: ``[[0, inf]]``; graded caps:
            :func:`optdot.geometry.caps.ring_table`).
    """

    explicit: bool
    phi: np.ndarray
    g: np.ndarray
    start: np.ndarray
    x: np.ndarray
    y: np.ndarray
    foot: np.ndarray
    cg: np.ndarray
    phi2: np.ndarray
    g2: np.ndarray
    cap_start: np.ndarray
    cap: np.ndarray
    cap_g: np.ndarray
    cap_ring: np.ndarray


class Scene(NamedTuple):
    """Everything :func:`trace` reads."""

    sources: Sources
    stack: Stack
    print: Print


_GOLDEN = np.uint64(0x9E3779B97F4A7C15)
_M1 = np.uint64(0xBF58476D1CE4E5B9)
_M2 = np.uint64(0x94D049BB133111EB)
_S30, _S27, _S31, _S11 = np.uint64(30), np.uint64(27), np.uint64(31), np.uint64(11)
_TO_UNIT = 1.0 / 9007199254740992.0  # 2**-53
#: Rays a task of :func:`trace`'s parallel loop traces (:func:`_trace_rays`).
RAY_CHUNK = 1024


@nb.njit(cache=True, inline="always")
def _mix(z):
    z = (z ^ (z >> _S30)) * _M1
    z = (z ^ (z >> _S27)) * _M2
    return z ^ (z >> _S31)


@nb.njit(cache=True, inline="always")
def _uniform(state):
    """SplitMix64: ``(new state, u in [0, 1))``."""
    state = state + _GOLDEN
    return state, float(_mix(state) >> _S11) * _TO_UNIT


@nb.njit(cache=True, inline="always")
def _fresnel(cos_i, n1, n2):
    """Unpolarised Fresnel reflectance from index n1 into n2 at incidence cosine cos_i."""
    sin_t = n1 / n2 * math.sqrt(max(0.0, 1.0 - cos_i * cos_i))
    if sin_t >= 1.0:
        return 1.0
    cos_t = math.sqrt(1.0 - sin_t * sin_t)
    rs = (n1 * cos_i - n2 * cos_t) / (n1 * cos_i + n2 * cos_t)
    rp = (n1 * cos_t - n2 * cos_i) / (n1 * cos_t + n2 * cos_i)
    return 0.5 * (rs * rs + rp * rp)


@nb.njit(cache=True, inline="always")
def _lambert_in(state, n):
    """A Lambertian direction in air refracted into index n through a face, with the
    Fresnel transmission drawn: ``(state, ok, cos about the normal, sin, azimuth)``."""
    state, u = _uniform(state)
    state, v = _uniform(state)
    sin_a = math.sqrt(u)
    cos_a = math.sqrt(1.0 - u)
    state, w = _uniform(state)
    if w < _fresnel(cos_a, 1.0, n):
        return state, False, 0.0, 0.0, 0.0
    sin_g = sin_a / n
    return state, True, math.sqrt(1.0 - sin_g * sin_g), sin_g, 2.0 * math.pi * v


@nb.njit(cache=True, inline="always")
def _mirrored(state, refl, r_face):
    """A ray out through a face of Fresnel reflectance ``r_face`` to a mirror of
    reflectance ``refl`` behind it: bounced between the two until the face lets it back
    through (its transmission is the same both ways) or the mirror absorbs it:
    ``(state, back)``."""
    while True:
        state, u = _uniform(state)
        if u >= refl:
            return state, False
        state, u = _uniform(state)
        if u >= r_face:
            return state, True


@nb.njit(cache=True, inline="always")
def _lambert(state, up):
    """A Lambertian unit direction about +z (``up``) or -z: ``(state, dx, dy, dz)``."""
    state, u = _uniform(state)
    state, v = _uniform(state)
    s = math.sqrt(u)
    dz = math.sqrt(1.0 - u)
    return (
        state,
        s * math.cos(2.0 * math.pi * v),
        s * math.sin(2.0 * math.pi * v),
        (dz if up else -dz),
    )


@nb.njit(cache=True)
def _tilt(state, dx, dy, dz, sigma):
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
        state, u = _uniform(state)
        state, v = _uniform(state)
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
def _wall_distance(x, y, ux, uy, walls):
    """Horizontal distance along (ux, uy) to the first wall, and the wall's index."""
    best = np.inf
    hit = -1
    for k in range(walls.shape[0]):
        ax, ay, bx, by = walls[k, 0], walls[k, 1], walls[k, 2], walls[k, 3]
        ex, ey = bx - ax, by - ay
        den = ux * ey - uy * ex
        if den == 0.0:
            continue
        px, py = ax - x, ay - y
        s = (px * ey - py * ex) / den
        w = (px * uy - py * ux) / den
        if s > 1e-12 and -1e-12 <= w <= 1.0 + 1e-12 and s < best:
            best = s
            hit = k
    return best, hit


@nb.njit(cache=True, inline="always")
def _on_dot(x, y, explicit, phi, g, start, dx_, dy_, foot, cg, u):
    """Does the point (x, y) on the bottom face lie on a dot? ``u``: a uniform draw."""
    if not explicit:
        ix = int(math.floor((x - g[0]) / g[2]))
        iy = int(math.floor((y - g[1]) / g[3]))
        if ix < 0 or iy < 0 or ix >= phi.shape[1] or iy >= phi.shape[0]:
            return False
        return u < phi[iy, ix]
    nx, ny, rmax = int(cg[4]), int(cg[5]), cg[6]
    # the cells the disc of the largest dot radius around (x, y) overlaps (1 to 4)
    ax = int(math.floor((x - rmax - cg[0]) / cg[2]))
    bx = int(math.floor((x + rmax - cg[0]) / cg[2]))
    ay = int(math.floor((y - rmax - cg[1]) / cg[3]))
    by = int(math.floor((y + rmax - cg[1]) / cg[3]))
    for jy in range(max(ay, 0), min(by + 1, ny)):
        for jx in range(max(ax, 0), min(bx + 1, nx)):
            c = jy * nx + jx
            for k in range(start[c], start[c + 1]):
                ddx = x - dx_[k]
                ddy = y - dy_[k]
                if on_packed(foot, k, ddx, ddy):
                    return True
    return False


@nb.njit(cache=True, inline="always")
def _on_cap(x, y, cap_start, cap, cap_g, cap_ring):
    """Where the point (x, y) lies among the caps (``cap`` rows ``(x, y, r^2)``, by
    cell; ``cap_ring`` the rings each prints, squared radii): 1 on a cap's ink, 0 within
    a cap but between its rings (clear: no dot is there either), -1 outside every cap."""
    nx, ny = int(cap_g[4]), int(cap_g[5])
    jx = int(math.floor((x - cap_g[0]) / cap_g[2]))
    jy = int(math.floor((y - cap_g[1]) / cap_g[3]))
    # cells are at least a cap's diameter wide: the 2 x 2 cells nearest the point
    ax = jx - 1 if x - cap_g[0] - jx * cap_g[2] < 0.5 * cap_g[2] else jx
    ay = jy - 1 if y - cap_g[1] - jy * cap_g[3] < 0.5 * cap_g[3] else jy
    for iy in range(max(ay, 0), min(ay + 2, ny)):
        for ix in range(max(ax, 0), min(ax + 2, nx)):
            c = iy * nx + ix
            for k in range(cap_start[c], cap_start[c + 1]):
                ddx = x - cap[k, 0]
                ddy = y - cap[k, 1]
                d2 = ddx * ddx + ddy * ddy
                if d2 <= cap[k, 2]:  # caps do not overlap: this one or none
                    for i in range(cap_ring.shape[0]):
                        if cap_ring[i, 0] <= d2 <= cap_ring[i, 1]:
                            return 1
                    return 0
    return -1


@nb.njit(cache=True, inline="always")
def _marked(x, y, mark, pr, u):
    """Is there a dot of print ``mark`` (1 the job's, 2 the second map) at (x, y)? ``pr``:
    the :class:`Print`'s fields as a tuple; ``u`` a uniform draw (the coverage test). A
    cap of print 1 is ink whatever ``u``."""
    explicit, phi, g, phi2, g2, start, dx_, dy_, foot, cg, cap_start, cap, cap_g, ring = pr
    if mark == 2:
        return _on_dot(x, y, False, phi2, g2, start, dx_, dy_, foot, cg, u)
    if cap.shape[0] > 0:
        at = _on_cap(x, y, cap_start, cap, cap_g, ring)
        if at >= 0:  # on a cap's ink, or clear between its rings
            return at == 1
    return _on_dot(x, y, explicit, phi, g, start, dx_, dy_, foot, cg, u)


@nb.njit(cache=True, inline="always")
def _refract(dxn, dyn, dz, n1, n2):
    """The direction transmitted from index n1 into n2 through a horizontal face (the
    caller has checked it is not totally reflected): ``(dx, dy, dz)``, dz keeping its
    sign."""
    r = n1 / n2
    dxn *= r
    dyn *= r
    c = math.sqrt(max(0.0, 1.0 - dxn * dxn - dyn * dyn))
    return dxn, dyn, (c if dz > 0 else -c)


@nb.njit(cache=True)
def _scatter_through(state, dxn, dyn, dz, mode, sigma, n_to):
    """What a hazy face or a sheet does to a direction it transmits (``dz``'s sign: the
    way it goes): ``mode`` 1 a Lambertian direction in air, refracted into ``n_to``; 2 the
    direction tilted by a Gaussian angle ``sigma``; 0 unchanged."""
    if mode == 1:
        state, a, b, c = _lambert(state, dz > 0)
        if n_to != 1.0:
            a /= n_to
            b /= n_to
            c = math.copysign(math.sqrt(max(0.0, 1.0 - a * a - b * b)), c)
        return state, a, b, c
    if mode == 2:
        return _tilt(state, dxn, dyn, dz, sigma)
    return state, dxn, dyn, dz


@nb.njit(cache=True)
def _trace_rays(
    seed, first, lo, hi, emit, emit_start, prof_theta, prof_cdf, prof_mode, layer, face,
    walls, normals, pr_arrays, max_events, fate, ex, ey,
):  # pragma: no cover - compiled  # fmt: skip
    """Rays ``first + lo .. first + hi - 1`` (:func:`trace`'s tables unpacked,
    ``pr_arrays`` the :class:`Print` as a tuple), each one's fate and end written at
    ``lo .. hi - 1`` of ``fate``, ``ex``, ``ey``.

    A serial loop of its own, which :func:`trace` runs in parallel over chunks: numba's
    parallel passes analyse the whole body of a ``prange`` loop, and a ray's whole life
    there makes a first run's compile several times longer; split so, it runs at the
    same speed with the same results (every ray draws from its own generator)."""
    top = layer.shape[0]  # the top face's index
    n_emit = emit.shape[0]
    for j in range(lo, hi):
        i = first + j
        state = _mix(np.uint64(seed) * _M1 ^ np.uint64(i) * _M2 + _GOLDEN)
        # -- birth
        k = last_at_most(emit_start, i, n_emit)
        li = int(emit[k, E_LAYER])
        z0, z1, n, absorb = layer[li, L_Z0], layer[li, L_Z1], layer[li, L_N], layer[li, L_ABS]
        state, u = _uniform(state)
        state, zz = _uniform(state)
        off = (u - 0.5) * emit[k, E_W]
        off2 = zz * emit[k, E_SPAN] + emit[k, E_START]
        x = emit[k, E_C] + emit[k, E_T] * off + emit[k, E_B] * off2 + emit[k, E_A] * 1e-9
        y = (
            emit[k, E_C + 1]
            + emit[k, E_T + 1] * off
            + emit[k, E_B + 1] * off2
            + emit[k, E_A + 1] * 1e-9
        )
        z = (
            emit[k, E_C + 2]
            + emit[k, E_T + 2] * off
            + emit[k, E_B + 2] * off2
            + emit[k, E_A + 2] * 1e-9
        )
        z = min(max(z, z0), z1)
        p = int(emit[k, E_PROF])
        state, u = _uniform(state)
        state, v = _uniform(state)
        if prof_mode[p, 0] > 0.5:
            theta = prof_mode[p, 1]
            psi = 0.5 * math.pi if v < 0.5 else -0.5 * math.pi
        else:
            cdf = prof_cdf[p]
            lo = last_at_most(cdf, u, cdf.shape[0] - 1)
            hi = lo + 1
            span = cdf[hi] - cdf[lo]
            f = (u - cdf[lo]) / span if span > 0 else 0.0
            theta = prof_theta[lo] + f * (prof_theta[hi] - prof_theta[lo])
            psi = 2.0 * math.pi * v
        state, w = _uniform(state)
        if w < _fresnel(math.cos(theta), 1.0, n):
            fate[j] = UNCOUPLED
            ex[j] = x
            ey[j] = y
            continue
        sg = math.sin(theta) / n
        cg_ = math.sqrt(1.0 - sg * sg)
        cp, sp = math.cos(psi), math.sin(psi)
        dxn = emit[k, E_A] * cg_ + emit[k, E_T] * sg * cp + emit[k, E_B] * sg * sp
        dyn = emit[k, E_A + 1] * cg_ + emit[k, E_T + 1] * sg * cp + emit[k, E_B + 1] * sg * sp
        dz = emit[k, E_A + 2] * cg_ + emit[k, E_T + 2] * sg * cp + emit[k, E_B + 2] * sg * sp
        state, u = _uniform(state)
        tau = -math.log(1.0 - u)  # optical depth the ray will travel
        budget = tau / absorb if absorb > 0 else np.inf  # in mm, in this layer
        end = UNFINISHED
        new_leg = True
        s_wall = np.inf
        wall = -1
        h = 1.0
        ux = uy = 0.0
        for _ in range(max_events):
            if new_leg:
                h = math.sqrt(dxn * dxn + dyn * dyn)
                if h > 1e-12:
                    ux, uy = dxn / h, dyn / h
                    s_wall, wall = _wall_distance(x, y, ux, uy, walls)
                else:
                    ux = uy = 0.0
                    s_wall, wall = np.inf, -1
                new_leg = False
            if dz > 0:
                s_face = (z1 - z) / dz * h
            elif dz < 0:
                s_face = (z - z0) / (-dz) * h
            else:
                s_face = np.inf
            at_wall = s_wall <= s_face
            s = s_wall if at_wall else s_face
            if s == np.inf:
                end = EDGE  # a ray parallel to the faces that meets no wall: cannot happen
                break
            path = s / h if h > 1e-12 else abs((z1 if dz > 0 else z0) - z) / abs(dz)
            if path > budget:
                f = budget / path
                x += ux * s * f
                y += uy * s * f
                end = BULK
                break
            budget -= path
            x += ux * s
            y += uy * s
            s_wall -= s
            if at_wall:
                z = min(max(z + dz * path, z0), z1)
                edge_mode = int(layer[li, L_WALL_MODE])
                if edge_mode == 2:  # black, in optical contact: all of it absorbed
                    end = EDGE
                    break
                nx_, ny_ = normals[wall, 0], normals[wall, 1]
                c = dxn * nx_ + dyn * ny_  # < 0: towards the wall
                state, u = _uniform(state)
                if -c > layer[li, L_WALL_COS] and u >= _fresnel(-c, n, 1.0):  # out
                    state, u = _uniform(state)
                    if u >= layer[li, L_WALL_R]:
                        end = EDGE
                        break
                    if edge_mode == 0:  # tape in air: back Lambertian, refracted in
                        ok = False
                        cn = sn = az = 0.0
                        while True:
                            state, ok, cn, sn, az = _lambert_in(state, n)
                            if ok:
                                break
                            state, u = _uniform(state)  # back to the tape
                            if u >= layer[li, L_WALL_R]:
                                break
                        if not ok:
                            end = EDGE
                            break
                        # tangent of the wall: (-ny, nx)
                        dxn = nx_ * cn - ny_ * sn * math.cos(az)
                        dyn = ny_ * cn + nx_ * sn * math.cos(az)
                        dz = sn * math.sin(az)
                    else:  # a mirror film: the way back is the mirror image
                        dxn -= 2.0 * c * nx_
                        dyn -= 2.0 * c * ny_
                else:  # total internal or Fresnel reflection at the edge
                    dxn -= 2.0 * c * nx_
                    dyn -= 2.0 * c * ny_
                x += nx_ * 1e-9
                y += ny_ * 1e-9
                new_leg = True
                continue
            # -- a face: fi under the layer (going down) or over it (going up)
            up = dz > 0
            fi = li + 1 if up else li
            z = z1 if up else z0
            kind = int(face[fi, F_KIND])
            to = li + 1 if up else li - 1  # the layer on the other side (top: none)
            n_to = layer[to, L_N] if 0 <= to < top else 1.0
            cross = False  # the ray goes through to the other side
            if kind == SHEET_FACE:
                state, u = _uniform(state)
                if u < face[fi, F_SHEET_T]:
                    spread = 1 + int(face[fi, F_SPREAD])
                    state, dxn, dyn, dz = _scatter_through(
                        state, dxn, dyn, dz, spread, face[fi, F_SPREAD_SIG], 1.0
                    )
                    cross = True
                elif u < face[fi, F_SHEET_T] + face[fi, F_SHEET_R]:
                    state, dxn, dyn, dz = _lambert(state, not up)
                    new_leg = True
                    continue
                else:
                    end = SHEET
                    break
            elif kind == BOTTOM_FACE:  # the reflector sheet under layer 0
                state, u = _uniform(state)
                mark = int(face[fi, F_PRINT])
                if mark > 0 and _marked(x, y, mark, pr_arrays, u):
                    state, u = _uniform(state)
                    if u >= face[fi, F_DOT_R]:
                        end = DOT
                        break
                    if face[fi, F_EXTRACT] > 0.5:
                        end = EXTRACTED
                        break
                    state, dxn, dyn, dz = _lambert(state, True)  # back into the slab
                    new_leg = True
                    continue
                if -dz > face[fi, F_COS_DOWN]:
                    state, u = _uniform(state)
                    r_face = _fresnel(-dz, n, 1.0)
                    if u >= r_face and face[fi, F_REFL_FINISH] > 0.5:  # out to a mirror
                        state, ok = _mirrored(state, face[fi, F_REFL], r_face)
                        if not ok:
                            end = BOTTOM
                            break
                        dz = -dz  # back in at the angle it left
                        continue
                    if u >= r_face:  # out to the reflector sheet
                        ok = False
                        cn = sn = az = 0.0
                        while True:
                            state, u = _uniform(state)
                            if u >= face[fi, F_REFL]:
                                break
                            state, ok, cn, sn, az = _lambert_in(state, n)
                            if ok:
                                break
                        if not ok:
                            end = BOTTOM
                            break
                        dz = cn
                        dxn = sn * math.cos(az)
                        dyn = sn * math.sin(az)
                        new_leg = True
                        continue
                dz = -dz
                continue
            else:  # INTERFACE (the top face too)
                mark = int(face[fi, F_PRINT])
                if mark > 0:
                    state, u = _uniform(state)
                    if _marked(x, y, mark, pr_arrays, u):
                        # the dots lie on the bottom of the layer above the face
                        state, u = _uniform(state)
                        if u < face[fi, F_DOT_R]:
                            if face[fi, F_EXTRACT] > 0.5:
                                end = EXTRACTED
                                break
                            state, dxn, dyn, dz = _lambert(state, not up)
                            new_leg = True
                            continue
                        if u >= face[fi, F_DOT_R] + face[fi, F_DOT_T]:
                            end = DOT
                            break
                        state, dxn, dyn, dz = _lambert(state, up)
                        cross = True
                if not cross:
                    cos_c = face[fi, F_COS_UP] if up else face[fi, F_COS_DOWN]
                    if abs(dz) > cos_c:
                        state, u = _uniform(state)
                        if u >= _fresnel(abs(dz), n, n_to):
                            if fi == top:
                                end = EXTRACTED
                                break
                            dxn, dyn, dz = _refract(dxn, dyn, dz, n, n_to)
                            if face[fi, F_HAZE] > 0.5:
                                state, dxn, dyn, dz = _scatter_through(
                                    state,
                                    dxn,
                                    dyn,
                                    dz,
                                    int(face[fi, F_HAZE]),
                                    face[fi, F_HAZE_SIG],
                                    n_to,
                                )
                            cross = True
                    if not cross:  # total internal or Fresnel reflection
                        dz = -dz
                        continue
            # -- through the face into the layer on the other side
            if fi == top:
                end = EXTRACTED
                break
            if absorb > 0:
                tau = budget * absorb
            li = to
            z0, z1, n, absorb = layer[li, L_Z0], layer[li, L_Z1], layer[li, L_N], layer[li, L_ABS]
            budget = tau / absorb if absorb > 0 else np.inf
            z = z0 if up else z1
            new_leg = True
        fate[j] = end
        ex[j] = x
        ey[j] = y


@nb.njit(cache=True, parallel=True)
def trace(seed, first, count, scene):  # pragma: no cover - compiled
    """Trace rays ``first .. first + count - 1`` through ``scene``.

    Args:
        seed: run seed (int). first, count: global index of the first ray, number of rays.
        scene: a :class:`Scene`.

    Returns:
        ``(fate [count] int8, x [count] float32, y [count] float32)``: how and where each
        ray ended (where it left the top face, for extracted rays).
    """
    src, st, pr = scene.sources, scene.stack, scene.print
    emit, emit_start, prof_theta, prof_cdf, prof_mode = (
        src.emit,
        src.start,
        src.theta,
        src.cdf,
        src.mode,
    )
    layer, face, walls, normals = st.layer, st.face, st.walls, st.normals
    # the print as a plain tuple (numba's parallel loop cannot carry a record inside it)
    pr_arrays = (
        pr.explicit,
        pr.phi,
        pr.g,
        pr.phi2,
        pr.g2,
        pr.start,
        pr.x,
        pr.y,
        pr.foot,
        pr.cg,
        pr.cap_start,
        pr.cap,
        pr.cap_g,
        pr.cap_ring,
    )
    max_events = st.max_events
    fate = np.empty(count, np.int8)
    ex = np.empty(count, np.float32)
    ey = np.empty(count, np.float32)
    for c in nb.prange((count + RAY_CHUNK - 1) // RAY_CHUNK):
        _trace_rays(
            seed, first, c * RAY_CHUNK, min(count, (c + 1) * RAY_CHUNK), emit, emit_start,
            prof_theta, prof_cdf, prof_mode, layer, face, walls, normals, pr_arrays,
            max_events, fate, ex, ey,
        )  # fmt: skip
    return fate, ex, ey
