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
- **Faces** (by kind, each one module of :mod:`optdot.optics.faces`):

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
- **Walls** (:mod:`optdot.optics.faces.slab_walls`): a slab's walls reflect totally outside its
  escape cone and by Fresnel inside it; what leaves meets the cover, which returns
  ``edge_reflectance`` of it (``specular`` mirrored, ``diffuse`` Lambertian refracted back
  in) and the rest is *lost at the edges*; an ``absorbing`` edge takes everything. In air
  the same rule is the frame's.
- **Bulk absorption**: an optical depth drawn once per ray from ``exp(-tau)``, spent along
  the 3-D path at each layer's absorption coefficient.

Every ray ends in exactly one fate, so injected = extracted + absorbed + lost holds exactly.
Each ray draws from its own counter-based generator (:mod:`optdot.optics.rays`), so the
result does not depend on how rays are shared among threads. The scene's tables and codes
are :mod:`optdot.optics.tables`'s; this module steps a ray from event to event. The edge-lit
guide as this scene draws the same numbers in the same order as the single-slab kernel it
replaced, so it gives the same counts for the same seed.
"""

from __future__ import annotations

import math
from concurrent.futures import ThreadPoolExecutor

import numba as nb
import numpy as np

from .faces import born_among_dots, meet_dots, meet_face, meet_wall, wall_distance
from .marks import BARE, dot_tables, printed
from .rays import fresnel, last_at_most, ray_state, uniform
from .tables import (
    AT_WALL,
    BULK,
    CROSS,
    E_A,
    E_B,
    E_C,
    E_LAYER,
    E_PROF,
    E_SPAN,
    E_START,
    E_T,
    E_W,
    EDGE,
    EXTRACTED,
    F_PRINT,
    F_PROFILE,
    F_TEST,
    L_ABS,
    L_N,
    L_WALL_COS,
    L_WALL_MODE,
    L_WALL_R,
    L_Z0,
    L_Z1,
    NEW_LEG,
    SAME_LEG,
    UNCOUPLED,
    UNFINISHED,
    Scene,
    face_row,
)

#: Rays in a chunk: :func:`trace`'s threads each run every few chunks (:func:`_trace_part`).
RAY_CHUNK = 1024


@nb.njit(cache=True, inline="always")
def _birth(state, k, emit, layer, prof_theta, prof_cdf, prof_mode):  # pragma: no cover
    """A ray of emitter ``k``: a point on its rectangle, a direction in air from its
    profile about its axis, Fresnel transmission into its layer and Snell refraction:
    ``(state, coupled, layer, x, y, z, dx, dy, dz)`` (not coupled: reflected at birth)."""
    li = int(emit[k, E_LAYER])
    z0, z1, n = layer[li, L_Z0], layer[li, L_Z1], layer[li, L_N]
    state, u = uniform(state)
    state, zz = uniform(state)
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
    state, u = uniform(state)
    state, v = uniform(state)
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
    state, w = uniform(state)
    if w < fresnel(math.cos(theta), 1.0, n):
        return state, False, li, x, y, z, 0.0, 0.0, 0.0
    sg = math.sin(theta) / n
    cg_ = math.sqrt(1.0 - sg * sg)
    cp, sp = math.cos(psi), math.sin(psi)
    dxn = emit[k, E_A] * cg_ + emit[k, E_T] * sg * cp + emit[k, E_B] * sg * sp
    dyn = emit[k, E_A + 1] * cg_ + emit[k, E_T + 1] * sg * cp + emit[k, E_B + 1] * sg * sp
    dz = emit[k, E_A + 2] * cg_ + emit[k, E_T + 2] * sg * cp + emit[k, E_B + 2] * sg * sp
    return state, True, li, x, y, z, dxn, dyn, dz


@nb.njit(cache=True, inline="always")
def _enter_layer(layer, li, up, tau):  # pragma: no cover - compiled
    """A ray entering layer ``li`` going up (``up``) or down with optical depth ``tau``
    left to travel: ``(z, z0, z1, n, absorb, budget)``, the face it enters at, the
    layer's faces, index and absorption, and the path (mm) the depth lasts in it."""
    z0, z1, n, absorb = layer[li, L_Z0], layer[li, L_Z1], layer[li, L_N], layer[li, L_ABS]
    budget = tau / absorb if absorb > 0 else np.inf
    return (z0 if up else z1), z0, z1, n, absorb, budget


@nb.njit(cache=True, forceinline=True)
def _among_dots(
    state, li, face, n, x, y, z, z0, dots, walls, run, dxn, dyn, dz
):  # pragma: no cover - compiled
    """A ray in layer ``li`` at ``(x, y, z)`` (mm; the layer's bottom face at ``z0``, its
    index ``n``) going ``d``, off the face: born (or sent back off a wall) going up, or
    coming down onto a wall (``run``: how far, mm, it came on its course): among the
    cavities of a guide's cut dots when in their layer
    (:func:`~.faces.born_among_dots`): ``(state, act, x, y, z, dx, dy, dz)``, ``act`` a
    fate, ``NEW_LEG`` or ``SAME_LEG`` (as it came)."""
    if li != 0 or face[0, F_PROFILE] < 0.5:
        return state, SAME_LEG, x, y, z, dxn, dyn, dz
    state, act, x, y, zc, dxn, dyn, dz = born_among_dots(
        state, face_row(face, 0), n, x, y, z - z0, dots, walls, run, dxn, dyn, dz
    )
    return state, act, x, y, z0 + zc, dxn, dyn, dz


@nb.njit(cache=True, forceinline=True)
def _born_among(state, li, face, n, x, y, z, z0, dots, walls, dxn, dyn, dz):  # pragma: no cover
    """A ray just born (or sent back off a wall) in layer ``li`` at ``(x, y, z)`` going
    ``d``: going up, :func:`_among_dots` (going down, as it came: its path is walked where
    it meets the face or a wall), as ``(state, end, ask, x, y, z, dx, dy, dz)``, ``end`` a
    fate or ``UNFINISHED``, ``ask`` whether a wall it meets coming down asks for a cavity
    before it (not where its walk among the cavities brought it onto a wall, ``AT_WALL``,
    where it now stands)."""
    if dz <= 0:  # going down: its path is walked where it meets the face, or a wall
        return state, UNFINISHED, True, x, y, z, dxn, dyn, dz
    state, act, x, y, z, dxn, dyn, dz = _among_dots(
        state, li, face, n, x, y, z, z0, dots, walls, 0.0, dxn, dyn, dz
    )
    end, ask = _went_on(act)
    return state, end, ask, x, y, z, dxn, dyn, dz


@nb.njit(cache=True, inline="always")
def _went_on(act):  # pragma: no cover - compiled
    """What a ray's ``act`` (a fate, or how it goes on) leaves the tracer: ``(end, ask)``,
    the fate or ``UNFINISHED``, and whether a wall met coming down asks for a cavity before
    it (not after ``AT_WALL``)."""
    return (act if act >= 0 else UNFINISHED), act != AT_WALL


@nb.njit(cache=True, inline="always")
def _off_wall(
    state, layer, li, face, normal, n, x, y, z, dots, walls, run, ask, dxn, dyn, dz
):  # pragma: no cover - compiled
    """A ray meeting a wall of layer ``li`` (index ``n``) at ``(x, y, z)`` (mm; ``normal``
    the wall's into the layer; ``run`` how far, mm, it came on its course) going ``d``:
    coming down in the layer of a guide's cut dots, the cavity its path passes through
    before the wall, if any (:func:`_among_dots`; unless not ``ask``: its walk among the
    cavities brought it here); else :func:`~.faces.meet_wall`, and a ray sent back in
    going up among the cavities, when in their layer (:func:`_born_among`): ``(state, end,
    ask, x, y, z, dx, dy, dz)`` as :func:`_born_among`'s."""
    z0 = layer[li, L_Z0]
    z = min(max(z, z0), layer[li, L_Z1])
    nx_, ny_ = normal[0], normal[1]
    if ask and dz < 0:  # down: a cavity before the wall (x, y nudged off it, into the layer)
        state, act, x2, y2, z2, dx2, dy2, dz2 = _among_dots(
            state, li, face, n, x + nx_ * 1e-9, y + ny_ * 1e-9, z, z0, dots, walls, run,
            dxn, dyn, dz,
        )  # fmt: skip
        if act != SAME_LEG:
            end, ask = _went_on(act)
            return state, end, ask, x2, y2, z2, dx2, dy2, dz2
    cover = (layer[li, L_WALL_MODE], layer[li, L_WALL_COS], layer[li, L_WALL_R])
    state, end, dxn, dyn, dz = meet_wall(state, cover, nx_, ny_, n, dxn, dyn, dz)
    if end >= 0:
        return state, end, True, x, y, z, dxn, dyn, dz
    x, y = x + nx_ * 1e-9, y + ny_ * 1e-9
    return _born_among(state, li, face, n, x, y, z, z0, dots, walls, dxn, dyn, dz)


# A serial loop over a chunk of rays: :func:`trace` runs chunks on several threads (the
# same results: rays draw their own numbers). Not numba's ``prange``: its parallel passes
# analyse the loop's whole body, which a ray's whole life makes compile several times longer.
@nb.njit(cache=True)
def _trace_rays(
    seed, first, lo, hi, emit, emit_start, prof_theta, prof_cdf, prof_mode, layer, face,
    walls, normals, pr_arrays, dots, max_events, fate, ex, ey, ed,
):  # pragma: no cover - compiled  # fmt: skip
    """Rays ``first + lo .. first + hi - 1`` (:func:`trace`'s tables unpacked, ``pr_arrays``
    the :class:`~optdot.optics.tables.Print` as a tuple, ``dots`` its ``dot_tables``), each
    one's fate, end and direction (not for rays turned back at birth) at ``lo .. hi - 1``
    of ``fate``, ``ex``, ``ey``, ``ed``: born, then stepped leg by leg to a wall or face."""
    top = layer.shape[0]  # the top face's index
    for j in range(lo, hi):
        state = ray_state(seed, first + j)
        k = last_at_most(emit_start, first + j, emit.shape[0])
        state, coupled, li, x, y, z, dxn, dyn, dz = _birth(
            state, k, emit, layer, prof_theta, prof_cdf, prof_mode
        )
        fate[j], ex[j], ey[j] = UNCOUPLED, x, y
        if not coupled:
            continue
        state, u = uniform(state)
        tau = -math.log(1.0 - u)  # optical depth the ray will travel
        _, z0, z1, n, absorb, budget = _enter_layer(layer, li, True, tau)
        state, end, ask, x, y, z, dxn, dyn, dz = _born_among(
            state, li, face, n, x, y, z, z0, dots, walls, dxn, dyn, dz
        )
        new_leg, s_wall, wall, h, ux, uy, run = True, np.inf, -1, 1.0, 0.0, 0.0, 0.0
        for _ in range(max_events if end == UNFINISHED else 0):
            if new_leg:  # the horizontal course changed: the wall ahead
                h = math.sqrt(dxn * dxn + dyn * dyn)
                ux, uy = (dxn / h, dyn / h) if h > 1e-12 else (0.0, 0.0)
                s_wall, wall = wall_distance(x, y, ux, uy, walls) if h > 1e-12 else (np.inf, -1)
                new_leg, run = False, 0.0  # run: how far it came on this course
            s_face = (z1 - z) / dz * h if dz > 0 else (z - z0) / (-dz) * h if dz < 0 else np.inf
            at_wall = s_wall <= s_face
            s = s_wall if at_wall else s_face
            if s == np.inf:
                end = EDGE  # a ray parallel to the faces that meets no wall: cannot happen
                break
            path = s / h if h > 1e-12 else abs((z1 if dz > 0 else z0) - z) / abs(dz)
            if path > budget:
                f = budget / path
                x, y, end = x + ux * s * f, y + uy * s * f, BULK
                break
            budget -= path
            x, y, s_wall, run = x + ux * s, y + uy * s, s_wall - s, run + s
            if at_wall:
                state, end, ask, x, y, z, dxn, dyn, dz = _off_wall(
                    state, layer, li, face, normals[wall], n, x, y, z + dz * path, dots, walls,
                    run, ask, dxn, dyn, dz,
                )  # fmt: skip
                if end != UNFINISHED:
                    break
                new_leg = True
                continue
            up = dz > 0  # a face: fi under the layer (going down) or over it (going up)
            fi, z, to = (li + 1, z1, li + 1) if up else (li, z0, li - 1)
            n_to = layer[to, L_N] if 0 <= to < top else 1.0
            on = BARE
            if face[fi, F_TEST] > 0.5:  # the print test: a number drawn, the print looked up
                state, u = uniform(state)
                on = printed(x, y, int(face[fi, F_PRINT]), pr_arrays, u)
            if face[fi, F_PROFILE] > 0.5:  # 3-D dots: they need the print, and move the ray
                state, act, x, y, zc, dxn, dyn, dz = meet_dots(
                    state, face_row(face, fi), n, on, x, y, dots, walls, run, dxn, dyn, dz
                )
                z += zc
            else:
                state, act, dxn, dyn, dz = meet_face(
                    state, face_row(face, fi), up, n, n_to, fi == top, on != BARE, dxn, dyn, dz
                )
            if act >= 0 or (act == CROSS and fi == top):
                end = act if act >= 0 else EXTRACTED
                break
            new_leg, ask = act == NEW_LEG or act == AT_WALL, act != AT_WALL
            if act != CROSS:
                continue
            if absorb > 0:  # through the face into the layer on the other side
                tau = budget * absorb
            li, new_leg = to, True
            z, z0, z1, n, absorb, budget = _enter_layer(layer, li, up, tau)
        fate[j], ex[j], ey[j], ed[j, 0], ed[j, 1], ed[j, 2] = end, x, y, dxn, dyn, dz


@nb.njit(cache=True, nogil=True)
def _trace_part(seed, first, count, scene, part, parts, fate, ex, ey, ed):  # pragma: no cover
    """Chunks ``part, part + parts, ...`` of :data:`RAY_CHUNK` rays of :func:`trace`'s
    ``count`` (its arguments; its outputs filled at the chunks' rays), without the GIL:
    :func:`trace` runs one part a thread."""
    src, st, pr = scene.sources, scene.stack, scene.print
    # the print as a plain tuple, and what a face of 3-D dots reads of it
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
        pr.turn,
    )
    dots = dot_tables(pr_arrays)
    for c in range(part, (count + RAY_CHUNK - 1) // RAY_CHUNK, parts):
        _trace_rays(
            seed, first, c * RAY_CHUNK, min(count, (c + 1) * RAY_CHUNK), src.emit, src.start,
            src.theta, src.cdf, src.mode, st.layer, st.face, st.walls, st.normals, pr_arrays,
            dots, st.max_events, fate, ex, ey, ed,
        )  # fmt: skip


def trace(seed: int, first: int, count: int, scene: Scene) -> tuple:
    """Trace rays ``first .. first + count - 1`` through ``scene``, on numba's threads
    (``numba.get_num_threads()``; each ray draws its own numbers, so the result does not
    depend on how many).

    Args:
        seed: run seed (int). first, count: global index of the first ray, number of rays.
        scene: a :class:`Scene`.

    Returns:
        ``(fate [count] int8, x [count] float32, y [count] float32, d [count, 3]
        float32)``: how and where each ray ended (where it left the top face, for
        extracted rays) and its direction then (in the air above, for those; 0 for a
        ray not coupled at birth).
    """
    fate = np.empty(count, np.int8)
    ex = np.empty(count, np.float32)
    ey = np.empty(count, np.float32)
    ed = np.zeros((count, 3), np.float32)  # rays not coupled leave theirs 0
    parts = max(1, min(nb.get_num_threads(), (count + RAY_CHUNK - 1) // RAY_CHUNK))
    args = (seed, first, count, scene)
    if parts == 1:
        _trace_part(*args, 0, 1, fate, ex, ey, ed)
    else:  # threads, not a compiled parallel loop: its wrapper took a fifth of the compile
        with ThreadPoolExecutor(parts) as pool:
            for done in [
                pool.submit(_trace_part, *args, p, parts, fate, ex, ey, ed) for p in range(parts)
            ]:
                done.result()
    return fate, ex, ey, ed
