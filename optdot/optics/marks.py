"""What is printed where a ray meets a printed face: the job's real dots or its coverage,
a second coverage map (the other printed face of a stack), and the caps over direct-lit
LEDs (compiled; the tables: :class:`optdot.optics.tables.Print`)."""

from __future__ import annotations

import math

import numba as nb

from ..geometry.shapes import half_width_packed, on_packed


@nb.njit(cache=True, inline="always")
def on_dot(x, y, explicit, phi, g, start, dx_, dy_, foot, cg, u):
    """Does the point (x, y) on the bottom face lie on a dot? ``u``: a uniform draw."""
    if not explicit:
        ix = int(math.floor((x - g[0]) / g[2]))
        iy = int(math.floor((y - g[1]) / g[3]))
        if ix < 0 or iy < 0 or ix >= phi.shape[1] or iy >= phi.shape[0]:
            return False
        return u < phi[iy, ix]
    return dot_at(x, y, start, dx_, dy_, foot, cg) >= 0


@nb.njit(cache=True, inline="always")
def dot_at(x, y, start, dx_, dy_, foot, cg):
    """The real dot (its index) the point (x, y) on the bottom face lies on, or -1."""
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
                    return k
    return -1


@nb.njit(cache=True, inline="always")
def on_cap(x, y, cap_start, cap, cap_g, cap_ring):
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


#: What :func:`printed` says where print 1 or 2 has no ink.
BARE = -1
#: What :func:`printed` says where there is ink but no real dot of the job's to name: the
#: coverage's draw, a cap's ring, the second map.
INK = -2


@nb.njit(cache=True, inline="always")
def printed(x, y, mark, pr, u):
    """What of print ``mark`` (1 the job's, 2 the second map, 0 none) lies at (x, y): the index
    of the job's real dot there, :data:`INK` (the coverage's, a cap's or the second
    map's ink) or :data:`BARE`. ``pr``: the :class:`Print`'s fields as a tuple; ``u`` a
    uniform draw (the coverage test). A cap of print 1 is ink whatever ``u``."""
    explicit, phi, g, phi2, g2, start, dx_, dy_, foot, cg, cap_start, cap, cap_g, ring, _ = pr
    if mark == 0:  # a face with no print
        return BARE
    if mark == 2:
        return INK if on_dot(x, y, False, phi2, g2, start, dx_, dy_, foot, cg, u) else BARE
    if cap.shape[0] > 0:
        at = on_cap(x, y, cap_start, cap, cap_g, ring)
        if at == 0:  # within a cap, clear between its rings
            return BARE
        if at == 1:  # on a cap's ink (over a real dot, that dot's frame)
            k = dot_at(x, y, start, dx_, dy_, foot, cg) if explicit else -1
            return k if k >= 0 else INK
    if explicit:
        return dot_at(x, y, start, dx_, dy_, foot, cg)
    return INK if on_dot(x, y, False, phi, g, start, dx_, dy_, foot, cg, u) else BARE


@nb.njit(cache=True, inline="always")
def dot_tables(pr):
    """The print's tables a face of 3-D dots reads, out of the :class:`Print` tuple
    ``pr``: ``(explicit, phi, g, start, x, y, foot, cg, turn)``, as :class:`Print` has
    them. Fewer arrays than the print's to hand down a dot's kernels: numba counts a
    reference to every array of a tuple at each call it is passed to."""
    return (pr[0], pr[1], pr[2], pr[5], pr[6], pr[7], pr[8], pr[9], pr[14])


#: What :func:`dot_frame` says where it cannot tell: the point, the angle and the size
#: unknown.
NO_FRAME = (math.nan, math.nan, math.nan, math.nan, math.nan)


@nb.njit(cache=True, forceinline=True)
def dot_frame(x, y, k, dots):
    """Where on its dot the point (x, y) of the job's print lies, for a 3-D dot (``k``:
    :func:`printed`'s there, the real dot's index or :data:`INK`; ``dots``: the print's
    :func:`dot_tables`): ``(lu,
    lv, c, s, w)``, on a real dot the point in the dot's own frame (mm along its long
    axis and across it), the cosine and sine of its angle and its half width (mm); in
    the coverage, NaN for the point and the cell's angle and half width (``dots``'s
    ``turn``, over the coverage's cells split ``f`` × ``f``: NaN where the dot draws its
    angle, or has the job's one size). Asked only of 3-D dots, where :func:`printed` found
    ink (the ink's own path does not look)."""
    explicit, phi, g, _, dx_, dy_, foot, _, turn = dots
    if explicit:
        if k < 0:
            return NO_FRAME
        c, s = foot[k, 4], foot[k, 5]
        ddx, ddy = x - dx_[k], y - dy_[k]
        return (c * ddx + s * ddy, c * ddy - s * ddx, c, s, half_width_packed(foot, k))
    c, s, w = cell_frame(x, y, phi, g, turn)
    return (math.nan, math.nan, c, s, w)


@nb.njit(cache=True, forceinline=True)
def cell_frame(x, y, phi, g, turn):
    """The coverage's angle and size at ``(x, y)`` (mm; ``phi`` over cells of ``g``, the
    print's ``turn`` over those cells split ``f`` × ``f``): ``(c, s, w)``, the cosine and
    sine of its dots' angle there and their half width (mm), NaN where the dot draws its
    angle, has the job's one size, or off the map."""
    f = int(math.sqrt(turn.shape[0] // phi.size) + 0.5)  # finer cells a coverage cell's side
    nx, ny = phi.shape[1] * f, phi.shape[0] * f
    ix = int(math.floor((x - g[0]) / g[2] * f))
    iy = int(math.floor((y - g[1]) / g[3] * f))
    if turn.shape[0] == nx * ny and 0 <= ix < nx and 0 <= iy < ny:
        k = iy * nx + ix
        return turn[k, 0], turn[k, 1], turn[k, 2]
    return math.nan, math.nan, math.nan
