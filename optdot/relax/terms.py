"""The penalty's terms, one small compiled function each (paper eq. 3 and optdot's hard terms).

Each term adds its value to ``f`` and its gradient to the accumulators it is given, in
a fixed order, so the composed kernel (:mod:`optdot.relax.penalty`) sums exactly as one
hand-written loop would. Every term also has a numpy-facing form over all dots
(``*_penalty(xy, ...) -> (f, grad)``) that the tests check against finite differences.
All lengths in mm, f in mm².

=============  ============================================================================
term           value for one dot (or pair)
=============  ============================================================================
pair           ``max(s - d, 0)² + w max(c - d, 0)²``, d the centre distance (overlap and
               hard core)
box            ``Σ_axes max(rad + m - (v - lo), 0)² + max(v + rad + m - hi, 0)²`` (panel
               rectangle, times ``weight``)
edge           ``weight · max(rad + m - sd, 0)²``, sd the signed distance to the outline
container      ``Σ_axes max(|v - c| + r - h, 0)²``
empty          ``max(rp - dist(x, Z), 0)²``, Z the zero-density cells (inside Z: rp plus
               the distance to the cell's nearest side)
=============  ============================================================================

"""

from __future__ import annotations

import numba as nb
import numpy as np

from ..geometry.edges import edge_signed_distance


@nb.njit(cache=True, inline="always")
def pair_grad(dx, dy, s, dmin, w, i_first):  # pragma: no cover - compiled
    """Overlap + hard-core term of a pair at offset (dx, dy) = x_i - x_j.

    Returns ``(f, gx, gy)``: the pair's f and the gradient for x_j (x_i gets minus it);
    all zero beyond ``max(s, dmin)``. Branch-free but for coincident centres (never in
    practice): computing the zeros costs less than a mispredicted branch on the ~30 % of
    listed pairs that do not touch.
    """
    if dx * dx + dy * dy < 1e-24:
        # coincident centres: separate along x, deterministically by index
        dx = 1e-12 if i_first else -1e-12
        dy = 0.0
    d = np.sqrt(dx * dx + dy * dy)
    dl = max(s - d, 0.0)
    dh = max(dmin - d, 0.0)  # weighted by w: nothing when the hard terms are off
    q = (2.0 * dl + 2.0 * w * dh) / d
    return dl * dl + w * dh * dh, q * dx, q * dy


@nb.njit(cache=True, inline="always")
def box_axis_term(v, lo, hi, rad, margin, weight, f, g):  # pragma: no cover - compiled
    """Panel term along one axis: coordinate ``v`` in ``[lo, hi]`` keeps ``rad + margin``
    from both ends. Returns ``(f, g)`` with the term's value and derivative added."""
    p = rad + margin - (v - lo)
    if p > 0.0:
        f += weight * p * p
        g -= 2.0 * weight * p
    p = v + rad + margin - hi
    if p > 0.0:
        f += weight * p * p
        g += 2.0 * weight * p
    return f, g


@nb.njit(cache=True, inline="always")
def container_axis_term(u, r, h, f, g):  # pragma: no cover - compiled
    """Container term along one axis: offset ``u`` from the container centre, circle
    radius ``r``, half side ``h``. Returns ``(f, g)`` with the term added."""
    p = abs(u) + r - h
    if p > 0.0:
        f += p * p
        g += 2.0 * p * (1.0 if u >= 0.0 else -1.0)
    return f, g


@nb.njit(cache=True, inline="always")
def edge_term(sd, ux, uy, rad, margin, weight, f, g0, g1):  # pragma: no cover - compiled
    """Outline term from the signed distance ``sd`` (> 0 inside) and its gradient
    ``(ux, uy)``: the circle of radius ``rad`` keeps ``margin`` inside the edges."""
    e = rad + margin - sd
    if e > 0.0:
        f += weight * e * e
        g0 -= 2.0 * weight * e * ux
        g1 -= 2.0 * weight * e * uy
    return f, g0, g1


@nb.njit(cache=True)
def empty_depth(x, y, rp, empty, gx0, gy0, cw, ch):  # pragma: no cover - compiled
    """Penetration of a circle (x, y, rp) into the zero cells: (depth, dir_x, dir_y).

    dir is the unit direction that *increases* the depth (gradient of depth wrt x).
    """
    ny, nx = empty.shape
    ix = int(np.floor((x - gx0) / cw))
    iy = int(np.floor((y - gy0) / ch))
    if 0 <= ix < nx and 0 <= iy < ny and empty[iy, ix]:
        # inside a zero cell: leave through the nearest side
        lo_x = x - (gx0 + ix * cw)
        hi_x = gx0 + (ix + 1) * cw - x
        lo_y = y - (gy0 + iy * ch)
        hi_y = gy0 + (iy + 1) * ch - y
        best = lo_x
        ux, uy = 1.0, 0.0
        if hi_x < best:
            best, ux, uy = hi_x, -1.0, 0.0
        if lo_y < best:
            best, ux, uy = lo_y, 0.0, 1.0
        if hi_y < best:
            best, ux, uy = hi_y, 0.0, -1.0
        return rp + best, ux, uy
    best2 = rp * rp
    bx = 0.0
    by = 0.0
    found = False
    for cy in range(max(int(np.floor((y - rp - gy0) / ch)), 0), min(iy + int(rp / ch) + 2, ny)):
        for cx in range(max(int(np.floor((x - rp - gx0) / cw)), 0), min(ix + int(rp / cw) + 2, nx)):
            if not empty[cy, cx]:
                continue
            px = min(max(x, gx0 + cx * cw), gx0 + (cx + 1) * cw)
            py = min(max(y, gy0 + cy * ch), gy0 + (cy + 1) * ch)
            d2 = (x - px) ** 2 + (y - py) ** 2
            if d2 < best2:
                best2, bx, by, found = d2, px, py, True
    if not found:
        return 0.0, 0.0, 0.0
    d = np.sqrt(best2)
    if d < 1e-15:
        return rp, 0.0, 0.0
    return rp - d, (bx - x) / d, (by - y) / d


@nb.njit(cache=True, inline="always")
def empty_term(x, y, rp, empty, gbox, f, g0, g1):  # pragma: no cover - compiled
    """Zero-density term of the circle ``(x, y, rp)``; ``empty`` ``[ny, nx]`` uint8 mask,
    ``gbox`` ``(x0, y0, cell_w, cell_h)``."""
    e, ux, uy = empty_depth(x, y, rp, empty, gbox[0], gbox[1], gbox[2], gbox[3])
    if e > 0.0:
        f += e * e
        g0 += 2.0 * e * ux
        g1 += 2.0 * e * uy
    return f, g0, g1


# ------------------------------------------------------------------ numpy-facing forms


@nb.njit(cache=True)
def _box_all(xy, rad, box, margin, weight, grad):  # pragma: no cover - compiled
    f = 0.0
    for i in range(xy.shape[0]):
        for a in range(2):
            g = 0.0
            f, g = box_axis_term(xy[i, a], box[a], box[a + 2], rad[i], margin, weight, f, g)
            grad[i, a] = g
    return f


def box_penalty(xy, rad, box, margin=0.0, weight=1.0) -> tuple[float, np.ndarray]:
    """Panel-rectangle term over all dots: ``xy`` ``[n, 2]``, ``rad`` ``[n]`` (mm), ``box``
    ``(xmin, ymin, xmax, ymax)``. Returns ``(f, grad [n, 2])``."""
    xy = np.ascontiguousarray(xy, dtype=np.float64)
    grad = np.zeros_like(xy)
    rad = np.broadcast_to(np.asarray(rad, np.float64), (len(xy),)).copy()
    f = _box_all(xy, rad, np.asarray(box, np.float64), float(margin), float(weight), grad)
    return f, grad


@nb.njit(cache=True)
def _container_all(xy, r, center, half, grad):  # pragma: no cover - compiled
    f = 0.0
    for i in range(xy.shape[0]):
        for a in range(2):
            g = 0.0
            f, g = container_axis_term(xy[i, a] - center[i, a], r[i], half[i], f, g)
            grad[i, a] = g
    return f


def container_penalty(xy, r, center, half) -> tuple[float, np.ndarray]:
    """Container term over all dots: circles ``r`` ``[n]`` in squares of half side
    ``half`` ``[n]`` centred on ``center`` ``[n, 2]`` (mm). Returns ``(f, grad)``."""
    xy = np.ascontiguousarray(xy, dtype=np.float64)
    grad = np.zeros_like(xy)
    f = _container_all(
        xy,
        np.ascontiguousarray(r, dtype=np.float64),
        np.ascontiguousarray(center, dtype=np.float64),
        np.ascontiguousarray(half, dtype=np.float64),
        grad,
    )
    return f, grad


@nb.njit(cache=True)
def _edge_all(xy, rad, ed, margin, weight, grad):  # pragma: no cover - compiled
    f = 0.0
    for i in range(xy.shape[0]):
        sd, ux, uy = edge_signed_distance(xy[i, 0], xy[i, 1], ed)
        f, grad[i, 0], grad[i, 1] = edge_term(sd, ux, uy, rad[i], margin, weight, f, 0.0, 0.0)
    return f


def edge_penalty(xy, rad, edge_arrays, margin=0.0, weight=1.0) -> tuple[float, np.ndarray]:
    """Outline term over all dots; ``edge_arrays`` is :func:`optdot.geometry.edges.edge_args`
    of the outline's index. Returns ``(f, grad [n, 2])``."""
    xy = np.ascontiguousarray(xy, dtype=np.float64)
    grad = np.zeros_like(xy)
    rad = np.broadcast_to(np.asarray(rad, np.float64), (len(xy),)).copy()
    f = _edge_all(xy, rad, edge_arrays, float(margin), float(weight), grad)
    return f, grad


@nb.njit(cache=True)
def _empty_all(xy, rp, empty, gbox, grad):  # pragma: no cover - compiled
    f = 0.0
    for i in range(xy.shape[0]):
        f, grad[i, 0], grad[i, 1] = empty_term(xy[i, 0], xy[i, 1], rp[i], empty, gbox, f, 0.0, 0.0)
    return f


def empty_penalty(xy, rp, empty, grid_box) -> tuple[float, np.ndarray]:
    """Zero-density term over all dots: radii ``rp`` ``[n]``, mask ``empty`` ``[ny, nx]``
    over the grid ``grid_box`` ``(x0, y0, cell_w, cell_h)``. Returns ``(f, grad)``."""
    xy = np.ascontiguousarray(xy, dtype=np.float64)
    grad = np.zeros_like(xy)
    rp = np.broadcast_to(np.asarray(rp, np.float64), (len(xy),)).copy()
    f = _empty_all(
        xy, rp, np.ascontiguousarray(empty, dtype=np.uint8), np.asarray(grid_box, np.float64), grad
    )
    return f, grad


@nb.njit(cache=True)
def _pairs_all(xy, r, core, w, pi, pj, grad):  # pragma: no cover - compiled
    f = 0.0
    for k in range(pi.shape[0]):
        i = pi[k]
        j = pj[k]
        fp, gx, gy = pair_grad(
            xy[i, 0] - xy[j, 0], xy[i, 1] - xy[j, 1], r[i] + r[j], core[i] + core[j], w, i < j
        )
        f += fp
        grad[i, 0] -= gx
        grad[i, 1] -= gy
        grad[j, 0] += gx
        grad[j, 1] += gy
    return f


def pair_penalty(xy, r, core, w, pairs) -> tuple[float, np.ndarray]:
    """Overlap + hard-core term over explicit ``pairs`` ``[K, 2]``: circles ``r`` ``[n]``,
    core radii ``core`` ``[n]`` (mm) with weight ``w``. Returns ``(f, grad [n, 2])``."""
    xy = np.ascontiguousarray(xy, dtype=np.float64)
    grad = np.zeros_like(xy)
    pairs = np.asarray(pairs, np.int64).reshape(-1, 2)
    f = _pairs_all(
        xy,
        np.ascontiguousarray(r, dtype=np.float64),
        np.ascontiguousarray(core, dtype=np.float64),
        float(w),
        pairs[:, 0].copy(),
        pairs[:, 1].copy(),
        grad,
    )
    return f, grad
