"""Reference implementations: slow, obviously correct, and written independently of the
fast code they check. The tests hold the compiled kernels to them (neighbour search
against all pairs, the penalty and its gradient against numpy over explicit pairs and
shapely's distances, QA's pair counts against GEOS); benchmarks use :func:`close_pairs`
as the independent count. Nothing in the pipeline imports this module.
"""

from __future__ import annotations

import numpy as np
import shapely

from .relax.penalty import PHANTOM_WEIGHT, PenaltyTerms


def pairs_brute_force(xy: np.ndarray, radius: np.ndarray | float, skin: float = 0.0) -> np.ndarray:
    """O(n²) reference of :func:`neighbor_pairs`, as sorted ``[K, 2]`` int64 pairs, i < j."""
    xy = np.asarray(xy, dtype=np.float64)
    n = len(xy)
    r = np.broadcast_to(np.asarray(radius, np.float64), (n,))
    d2 = ((xy[:, None, :] - xy[None, :, :]) ** 2).sum(-1)
    lim = (r[:, None] + r[None, :]) * (1.0 + skin)
    i, j = np.nonzero(np.triu(d2 < lim * lim, k=1))
    return np.stack([i, j], axis=1).astype(np.int64)


def close_pairs(xy: np.ndarray, distance: float) -> np.ndarray:
    """Pairs of centres strictly closer than ``distance``, via shapely STRtree.

    Returns:
        ``[K, 2]`` int64, i < j, sorted.
    """
    pts = shapely.points(xy)
    tree = shapely.STRtree(pts)
    i, j = tree.query(pts, predicate="dwithin", distance=distance)
    keep = i < j
    i, j = i[keep], j[keep]
    d = np.hypot(*(xy[i] - xy[j]).T)
    keep = d < distance
    p = np.stack([i[keep], j[keep]], axis=1).astype(np.int64)
    return p[np.lexsort((p[:, 1], p[:, 0]))] if len(p) else p


def penalty_reference(
    xy: np.ndarray, terms: PenaltyTerms, pairs: np.ndarray, outline=None
) -> tuple[float, np.ndarray]:
    """Slow numpy penalty over explicit pairs (``[K, 2]``, e.g. all i < j); returns (f, grad).

    With ``terms.edges`` set, ``outline`` is the domain's shapely geometry: the edge
    terms are then measured by shapely (nearest points), independently of the index.
    """
    xy = np.asarray(xy, dtype=np.float64)
    r = terms.radius
    w = terms.w_hard
    g = np.zeros_like(xy)
    f = 0.0
    ph = np.zeros(len(xy), bool) if terms.phantom is None else np.asarray(terms.phantom, bool)
    real = (~ph).astype(np.float64)
    if len(pairs):
        i, j = pairs[:, 0], pairs[:, 1]
        diff = xy[i] - xy[j]
        d = np.sqrt((diff**2).sum(1))
        unit = diff / d[:, None]
        dl = np.maximum(r[i] + r[j] - d, 0.0)
        cr = terms.core_radius
        dh = np.maximum(cr[i] + cr[j] - d, 0.0) if w > 0 else np.zeros_like(d)
        f += float((dl**2).sum() + w * (dh**2).sum())
        coef = (2 * dl + 2 * w * dh)[:, None] * unit
        np.add.at(g, i, -coef)
        np.add.at(g, j, coef)
    lo = np.array(terms.box[:2])
    hi = np.array(terms.box[2:])
    m = terms.margin
    if terms.edges is not None:
        sd, u = _outline_reference(xy, outline)
        sd_u = u
    for rad, weight in ((terms.panel_radius[:, None], 1.0), (terms.dot_radius, w)):
        if weight == 0:
            continue
        if terms.edges is not None:
            e = np.maximum(np.broadcast_to(rad, (len(xy), 1))[:, 0] + m - sd, 0.0) * real
            f += weight * float((e**2).sum())
            g -= weight * 2 * e[:, None] * u
            continue
        p_lo = np.maximum(rad + m - (xy - lo), 0.0) * real[:, None]
        p_hi = np.maximum(xy + rad + m - hi, 0.0) * real[:, None]
        f += weight * float((p_lo**2).sum() + (p_hi**2).sum())
        g += weight * (-2 * p_lo + 2 * p_hi)
    if terms.empty.any():
        e, u = _empty_reference(xy, terms)
        e = e * real
        f += float((e**2).sum())
        g += 2 * e[:, None] * u
    if ph.any():
        on_edge = terms.edges is not None
        depth, u = _phantom_reference(
            xy[ph], r[ph], terms, sd[ph] if on_edge else None, sd_u[ph] if on_edge else None
        )
        depth = np.maximum(depth, 0.0)
        f += PHANTOM_WEIGHT * float((depth**2).sum())
        g[ph] += 2 * PHANTOM_WEIGHT * depth[:, None] * u
    u = xy - terms.center
    p = np.maximum(np.abs(u) + r[:, None] - terms.half_side[:, None], 0.0)
    f += float((p**2).sum())
    g += 2 * p * np.where(u >= 0, 1.0, -1.0)
    return f, g


def _phantom_reference(xy, r, terms: PenaltyTerms, sd, sd_u) -> tuple[np.ndarray, np.ndarray]:
    """How far each phantom stands inside the allowed region (``[m]``, <= 0 outside)
    and the gradient of that depth (``[m, 2]``), brute force."""
    m = terms.margin
    if sd is not None:
        depth, u = sd - m, sd_u.copy()
    else:
        x0, y0, x1, y1 = terms.box
        sides = np.stack([xy[:, 0] - x0, x1 - xy[:, 0], xy[:, 1] - y0, y1 - xy[:, 1]], axis=1)
        k = np.argmin(sides, axis=1)
        depth = sides[np.arange(len(xy)), k] - m
        u = np.array([(1.0, 0.0), (-1.0, 0.0), (0.0, 1.0), (0.0, -1.0)])[k]
    if terms.empty.any():
        gx0, gy0, cw, ch = terms.grid_box
        iy, ix = np.nonzero(terms.empty)
        lo = np.stack([gx0 + ix * cw, gy0 + iy * ch], axis=1)
        near = np.clip(xy[:, None, :], lo[None], (lo + np.array([cw, ch]))[None])
        diff = xy[:, None, :] - near
        d = np.sqrt((diff**2).sum(-1))
        k = np.argmin(d, axis=1)
        dz = d[np.arange(len(xy)), k]
        use = (dz < 2 * r) & (dz < depth) & (depth > 0)
        depth = np.where(use, dz, depth)
        with np.errstate(invalid="ignore", divide="ignore"):
            uz = np.where(dz[:, None] > 0, diff[np.arange(len(xy)), k] / dz[:, None], 0.0)
        u = np.where(use[:, None], uz, u)
    return depth, u


def _outline_reference(xy: np.ndarray, outline) -> tuple[np.ndarray, np.ndarray]:
    """Signed distance to the outline's edges (> 0 inside) and its gradient, by shapely."""
    import shapely

    pts = shapely.points(xy)
    near = shapely.get_coordinates(shapely.shortest_line(pts, outline.boundary))[1::2]
    diff = xy - near
    d = np.hypot(diff[:, 0], diff[:, 1])
    sign = np.where(shapely.contains_xy(outline, xy[:, 0], xy[:, 1]), 1.0, -1.0)
    u = np.where(d[:, None] > 0, diff / np.maximum(d, 1e-300)[:, None], 0.0) * sign[:, None]
    return sign * d, u


def _empty_reference(xy: np.ndarray, terms: PenaltyTerms) -> tuple[np.ndarray, np.ndarray]:
    """Brute-force depth ``[n]`` and gradient direction ``[n, 2]`` of the zero-cell term."""
    gx0, gy0, cw, ch = terms.grid_box
    iy, ix = np.nonzero(terms.empty)
    lo = np.stack([gx0 + ix * cw, gy0 + iy * ch], axis=1)  # [Z, 2]
    hi = lo + np.array([cw, ch])
    near = np.clip(xy[:, None, :], lo[None], hi[None])  # [n, Z, 2]
    diff = near - xy[:, None, :]
    d = np.sqrt((diff**2).sum(-1))
    inside = np.all((xy[:, None, :] >= lo[None]) & (xy[:, None, :] < hi[None]), axis=-1)
    k = np.argmin(d, axis=1)
    rows = np.arange(len(xy))
    dist = d[rows, k]
    depth = np.maximum(terms.panel_radius - dist, 0.0)
    with np.errstate(invalid="ignore", divide="ignore"):
        u = np.where(dist[:, None] > 0, diff[rows, k] / dist[:, None], 0.0)
    for i in np.nonzero(inside.any(axis=1))[0]:
        z = int(np.argmax(inside[i]))
        sides = [xy[i, 0] - lo[z, 0], hi[z, 0] - xy[i, 0], xy[i, 1] - lo[z, 1], hi[z, 1] - xy[i, 1]]
        s = int(np.argmin(sides))
        depth[i] = terms.panel_radius[i] + sides[s]
        u[i] = [(1.0, 0.0), (-1.0, 0.0), (0.0, 1.0), (0.0, -1.0)][s]
    return depth, u
