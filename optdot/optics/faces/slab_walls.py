"""The side walls of a layer (the panel's outline straight through the stack): where a ray
meets one, and what the wall does to it. Inside its escape cone a ray leaves by Fresnel to
the cover, which returns ``L_WALL_R`` of it: tape in air Lambertian, refracted back in
(finish 0), a mirror film mirrored (1); black paint in optical contact takes everything
(2). Outside the cone, and what Fresnel reflects, is reflected (compiled)."""

from __future__ import annotations

import math

import numba as nb
import numpy as np

from ..rays import fresnel, lambert_in, uniform
from ..tables import EDGE, NEW_LEG


@nb.njit(cache=True)
def wall_distance(x, y, ux, uy, walls):
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
def meet_wall(state, cover, nx_, ny_, n, dxn, dyn, dz):  # pragma: no cover - compiled
    """A ray of direction ``(dxn, dyn, dz)`` in a layer of index ``n`` at a wall of inward
    normal ``(nx_, ny_)``, the layer's ``cover`` the tuple of its ``L_WALL_MODE``,
    ``L_WALL_COS`` and ``L_WALL_R``: ``(state, act, dx, dy, dz)``, ``act`` the fate
    ``EDGE`` or ``NEW_LEG`` with the direction it goes on in."""
    mode, cos_c, refl = cover
    edge_mode = int(mode)
    if edge_mode == 2:  # black, in optical contact: all of it absorbed
        return state, EDGE, dxn, dyn, dz
    c = dxn * nx_ + dyn * ny_  # < 0: towards the wall
    state, u = uniform(state)
    if -c > cos_c and u >= fresnel(-c, n, 1.0):  # out
        state, u = uniform(state)
        if u >= refl:
            return state, EDGE, dxn, dyn, dz
        if edge_mode == 0:  # tape in air: back Lambertian, refracted in
            ok = False
            cn = sn = az = 0.0
            while True:
                state, ok, cn, sn, az = lambert_in(state, n)
                if ok:
                    break
                state, u = uniform(state)  # back to the tape
                if u >= refl:
                    break
            if not ok:
                return state, EDGE, dxn, dyn, dz
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
    return state, NEW_LEG, dxn, dyn, dz
