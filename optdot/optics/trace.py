"""The Monte Carlo ray tracer of an edge-lit slab (compiled): each ray from an LED to its end.

A ray is followed event by event through the slab ``0 <= z <= t`` bounded by side walls:

- **Birth**: an emitter (one LED) chosen by ray index (rays are shared out in proportion
  to power before tracing), a point on its face, a direction in air from its profile
  (inverse-CDF of ``I(theta) sin(theta)``), Fresnel transmission into the edge (rays it
  reflects are *not coupled* and not counted as injected), Snell refraction inside.
- **Faces**: between events a ray's horizontal direction is fixed, so the distance to
  the next wall is found once per leg and the faces are stepped one bounce at a time.
  Top face: inside the escape cone Fresnel decides (escape = *extracted*, binned at the
  exit point), outside it total internal reflection. Bottom face: first the dot test (the
  map's coverage as a probability, or the real dots through a cell grid); a dot reflects
  with the albedo (Lambertian into the slab, or straight out in ``extract`` mode) or
  absorbs; between dots the escape cone leads to the reflector sheet, which returns light
  Lambertian in air, refracted back in (or absorbs it: *lost at the bottom*).
- **Walls**: total internal reflection outside the escape cone, Fresnel inside it; what
  leaves the edge meets the cover, which returns ``edge_reflectance`` of it, mirrored
  (``specular``) or Lambertian refracted back in (``diffuse``); the rest is *lost at the
  edges*. An ``absorbing`` edge (black paint in optical contact) takes everything.
- **Bulk absorption**: a free path drawn once per ray from ``exp(-a s)``, spent along the
  3-D path.

Every ray ends in exactly one fate, so injected = extracted + absorbed + lost holds exactly.
Each ray draws from its own counter-based generator (SplitMix64 of the seed and the ray's
index), so the result does not depend on how rays are shared among threads.
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

from ..geometry.shapes import on_packed

#: Fates of a ray (``trace`` output).
EXTRACTED, BULK, DOT, EDGE, BOTTOM, UNCOUPLED, UNFINISHED = range(7)
FATES = (
    "extracted",
    "absorbed_bulk",
    "absorbed_dots",
    "lost_edges",
    "lost_bottom",
    "not_coupled",
    "unfinished",
)
#: Events (reflections, scatterings) after which a ray is given up (``unfinished``;
#: reported, never silently dropped).
MAX_EVENTS = 1 << 16

_GOLDEN = np.uint64(0x9E3779B97F4A7C15)
_M1 = np.uint64(0xBF58476D1CE4E5B9)
_M2 = np.uint64(0x94D049BB133111EB)
_S30, _S27, _S31, _S11 = np.uint64(30), np.uint64(27), np.uint64(31), np.uint64(11)
_TO_UNIT = 1.0 / 9007199254740992.0  # 2**-53


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


@nb.njit(cache=True, parallel=True)
def trace(
    seed,
    first,
    count,
    emit,
    emit_start,
    prof_theta,
    prof_cdf,
    prof_mode,
    walls,
    normals,
    phys,
    explicit,
    phi,
    g,
    start,
    dx_,
    dy_,
    foot,
    cg,
):  # pragma: no cover - compiled
    """Trace rays ``first .. first + count - 1``.

    Args:
        seed: run seed (int). first, count: global index of the first ray, number of rays.
        emit: ``[e, 8]`` emitters: centre x, y; tangent tx, ty; inward normal nx, ny;
            width, mm; profile index.
        emit_start: ``[e + 1]`` int64 first global ray of each emitter (the last = total).
        prof_theta: ``[K]`` angles in air, rad. prof_cdf: ``[p, K]`` their CDFs.
        prof_mode: ``[p, 2]`` (0 table / 1 collimated, tilt in rad).
        walls: ``[m, 4]`` segments (ax, ay, bx, by), mm. normals: ``[m, 2]`` inward.
        phys: ``[9]`` thickness mm, index, absorption 1/mm, dot albedo, extract (0/1),
            reflector, edge reflectance, edge finish (0 diffuse, 1 specular,
            2 absorbing), events after which a ray is given up (``unfinished``).
        explicit: trace real dots (True) or the coverage map ``phi``.
        phi: ``[ny, nx]`` coverage; g: ``[4]`` its x0, y0, dx, dy, mm.
        start: ``[cells + 1]`` CSR of dots by cell; dx_, dy_: ``[n]`` centres; foot:
            ``[n, 6]`` their footprints (:func:`optdot.geometry.shapes.packed`); cg:
            ``[7]`` cell grid x0, y0, dx, dy, nx, ny and the largest dot extent (cells
            at least that wide).

    Returns:
        ``(fate [count] int8, x [count] float32, y [count] float32)``: how and where each
        ray ended (where it left the top face, for extracted rays).
    """
    fate = np.empty(count, np.int8)
    ex = np.empty(count, np.float32)
    ey = np.empty(count, np.float32)
    t, n, absorb, albedo = phys[0], phys[1], phys[2], phys[3]
    extract_mode, refl, edge_r, edge_mode = phys[4] > 0.5, phys[5], phys[6], int(phys[7])
    max_events = int(phys[8])
    cos_c = math.sqrt(1.0 - 1.0 / (n * n))  # cosine of the critical angle
    n_emit = emit.shape[0]
    for j in nb.prange(count):
        i = first + j
        state = _mix(np.uint64(seed) * _M1 ^ np.uint64(i) * _M2 + _GOLDEN)
        # -- birth
        k = last_at_most(emit_start, i, n_emit)
        state, u = _uniform(state)
        state, zz = _uniform(state)
        off = (u - 0.5) * emit[k, 6]
        x = emit[k, 0] + emit[k, 2] * off + emit[k, 4] * 1e-9
        y = emit[k, 1] + emit[k, 3] * off + emit[k, 5] * 1e-9
        z = t * zz
        p = int(emit[k, 7])
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
        dxn = emit[k, 4] * cg_ + emit[k, 2] * sg * math.cos(psi)
        dyn = emit[k, 5] * cg_ + emit[k, 3] * sg * math.cos(psi)
        dz = sg * math.sin(psi)
        state, u = _uniform(state)
        budget = -math.log(1.0 - u) / absorb if absorb > 0 else np.inf
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
                s_face = (t - z) / dz * h
            elif dz < 0:
                s_face = z / (-dz) * h
            else:
                s_face = np.inf
            at_wall = s_wall <= s_face
            s = s_wall if at_wall else s_face
            if s == np.inf:
                end = EDGE  # a ray parallel to the faces that meets no wall: cannot happen
                break
            path = s / h if h > 1e-12 else abs((t if dz > 0 else 0.0) - z) / abs(dz)
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
                z = min(max(z + dz * path, 0.0), t)
                if edge_mode == 2:  # black, in optical contact: all of it absorbed
                    end = EDGE
                    break
                nx_, ny_ = normals[wall, 0], normals[wall, 1]
                c = dxn * nx_ + dyn * ny_  # < 0: towards the wall
                state, u = _uniform(state)
                if -c > cos_c and u >= _fresnel(-c, n, 1.0):  # out through the edge
                    state, u = _uniform(state)
                    if u >= edge_r:
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
                            if u >= edge_r:
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
            if dz > 0:  # top face
                z = t
                if dz > cos_c:
                    state, u = _uniform(state)
                    if u >= _fresnel(dz, n, 1.0):
                        end = EXTRACTED
                        break
                dz = -dz
                continue
            z = 0.0  # bottom face
            state, u = _uniform(state)
            if _on_dot(x, y, explicit, phi, g, start, dx_, dy_, foot, cg, u):
                state, u = _uniform(state)
                if u >= albedo:
                    end = DOT
                    break
                if extract_mode:
                    end = EXTRACTED
                    break
                state, u = _uniform(state)
                state, v = _uniform(state)
                sin_a = math.sqrt(u)
                dz = math.sqrt(1.0 - u)
                dxn = sin_a * math.cos(2.0 * math.pi * v)
                dyn = sin_a * math.sin(2.0 * math.pi * v)
                new_leg = True
                continue
            if -dz > cos_c:
                state, u = _uniform(state)
                if u >= _fresnel(-dz, n, 1.0):  # out to the reflector sheet
                    ok = False
                    cn = sn = az = 0.0
                    while True:
                        state, u = _uniform(state)
                        if u >= refl:
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
        fate[j] = end
        ex[j] = x
        ey[j] = y
    return fate, ex, ey
