"""Penalty (3) of the paper and its analytic gradient, plus optdot's hard terms.

For circles S_i (centre x_i, radius r_i) the objective is

    f = sum_{pairs} max(r_i + r_j - |x_i - x_j|, 0)^2              circle overlap
      + sum_i  dx_i^2 + dy_i^2   with dx = max(rp_i - x, 0) + max(x + rp_i - W, 0)
                                                                  panel protrusion
      + sum_i  cx_i^2 + cy_i^2   with cx = max(|x - c_x| + r_i - h_i, 0)
                                                                  container protrusion
      + sum_i  e_i^2             with e_i = max(rp_i - dist(x_i, Z), 0), Z the union of
                                 the map's zero-density cells (inside Z: rp_i + the
                                 distance to the cell's nearest side)
      + w_hard * [ sum_{pairs} max(c_i + c_j - |x_i - x_j|, 0)^2
                   + sum_i max(r0 - x, 0)^2 + max(x + r0 - W, 0)^2 (and y) ]

The last line is optdot's hard-core term (zero in the paper formulation): it only acts on
dots closer than the minimum distance or protruding from the panel. All lengths in mm,
f in mm². Each term is a small compiled function in :mod:`optdot.relax.terms`; this
module composes them. ``penalty_fast`` is the compiled kernel over a CSR Verlet list;
:func:`optdot.testing.penalty_reference` is the slow, obviously-correct numpy version over
an explicit pair list the tests hold it to.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property

import numba as nb
import numpy as np

from ..geometry.edges import EdgeIndex, edge_args, edge_signed_distance_within
from ..spatial.blocks import BLOCK, PairList
from .terms import (
    box_axis_term,
    container_axis_term,
    edge_term,
    empty_depth,
    empty_term,
    pair_grad,
)


@dataclass(frozen=True, eq=False)
class PenaltyTerms:
    """Everything the penalty needs besides the positions.

    Attributes:
        radius: ``[n]`` circle radii r_i, mm.
        panel_radius: ``[n]`` radius used against the panel edges, mm.
        center: ``[n, 2]`` container centres (initial positions), mm.
        half_side: ``[n]`` container half sides, mm.
        box: ``(xmin, ymin, xmax, ymax)`` of the panel, mm.
        dmin: minimum centre distance of the hard-core term, mm.
        core: optional ``[n]`` per-dot hard-core radii c_i (pair target c_i + c_j), mm;
            default ``dmin / 2`` for every dot.
        margin: edge margin, mm: the panel terms keep ``rp + margin`` (soft) and
            ``r0 + margin`` (hard) from the edges.
        edges: a polygon outline's :class:`~optdot.geometry.edges.EdgeIndex`; the panel terms
            then use the signed distance to its edges instead of ``box``.
        dot_radius: r0, mm (hard panel limit).
        w_hard: weight of the hard terms (0 = paper).
        empty: ``[ny, nx]`` uint8 mask of zero-density cells (all 0 = no term).
        grid_box: ``(x0, y0, cell_w, cell_h)`` of that mask, mm.
        phantom: ``[n]`` bool, dots that stand beyond a wall
            (:mod:`optdot.sampling.phantoms`): they keep out of the allowed region
            (``margin`` inside the edges, out of zero cells) and have no hard core.
    """

    radius: np.ndarray
    panel_radius: np.ndarray
    center: np.ndarray
    half_side: np.ndarray
    box: tuple[float, float, float, float]
    dmin: float
    dot_radius: float
    w_hard: float = 0.0
    empty: np.ndarray = field(default_factory=lambda: np.zeros((1, 1), np.uint8))
    grid_box: tuple[float, float, float, float] = (0.0, 0.0, 1.0, 1.0)
    core: np.ndarray | None = None
    margin: float = 0.0
    edges: EdgeIndex | None = None
    phantom: np.ndarray | None = None

    @cached_property
    def core_radius(self) -> np.ndarray:
        """``[n]`` hard-core radii c_i, mm (phantoms: none)."""
        if self.core is not None:
            core = np.asarray(self.core, dtype=np.float64)
        else:
            core = np.full(len(self.radius), 0.5 * self.dmin)
        if self.phantom is not None:
            core = np.where(self.phantom, NO_CORE, core)
        return np.ascontiguousarray(core)

    @cached_property
    def scratch(self) -> np.ndarray:
        """``[n, 4]`` work array the kernel packs positions and radii into (one per terms
        object, so an evaluation allocates nothing)."""
        return np.empty((len(self.radius), 4))

    @cached_property
    def kernel_constants(self) -> tuple:
        """What the kernel needs besides radii and pairs, packed once per terms object:
        (box array, has zero cells, grid box array, edge-index tuple, phantom flags:
        ``[n]`` uint8 or ``[0]`` without phantoms)."""
        ph = np.zeros(0, np.uint8) if self.phantom is None else self.phantom.astype(np.uint8)
        return (
            np.asarray(self.box, dtype=np.float64),
            bool(self.empty.any()),
            np.asarray(self.grid_box, dtype=np.float64),
            edge_args(self.edges),
            np.ascontiguousarray(ph),
        )

    @property
    def reach(self) -> np.ndarray:
        """``[n]`` radius within which dot i interacts: pairs closer than reach_i + reach_j."""
        return np.maximum(self.radius, self.core_radius) if self.w_hard > 0 else self.radius


@nb.njit(cache=True, inline="always")
def _pair_term(xy, r, cr, i, j, w, grad):  # pragma: no cover - compiled
    """Add pair (i, j)'s overlap and hard-core gradient to ``grad``; returns its f."""
    f, gx, gy = pair_grad(
        xy[i, 0] - xy[j, 0], xy[i, 1] - xy[j, 1], r[i] + r[j], cr[i] + cr[j], w, i < j
    )
    grad[i, 0] -= gx
    grad[i, 1] -= gy
    grad[j, 0] += gx
    grad[j, 1] += gy
    return f


@nb.njit(cache=True, inline="always")
def _single_terms(
    i, xy, r, rp, c, h, box, r0, w, margin, empty, has_empty, gbox, ed, ph, grad
):  # pragma: no cover
    """Set ``grad[i]`` to dot i's zero-cell, outline or panel, and container terms;
    returns their f. The terms are added in this fixed order. A phantom (``ph[i]``)
    has its own term and its container."""
    if ph.shape[0] > 0 and ph[i]:
        f, g0, g1 = _phantom_terms(i, xy, r, box, margin, empty, has_empty, gbox, ed)
        f, g0 = container_axis_term(xy[i, 0] - c[i, 0], r[i], h[i], f, g0)
        f, g1 = container_axis_term(xy[i, 1] - c[i, 1], r[i], h[i], f, g1)
        grad[i, 0] = g0
        grad[i, 1] = g1
        return f
    f = 0.0
    g0 = 0.0
    g1 = 0.0
    if has_empty:
        f, g0, g1 = empty_term(xy[i, 0], xy[i, 1], rp[i], empty, gbox, f, g0, g1)
    outline = ed[0].shape[0] > 0
    if outline:
        # exact where a term acts (the dot's radius and the hard core's, plus the margin)
        need = (max(rp[i], r0) if w > 0.0 else rp[i]) + margin
        sd, ux, uy = edge_signed_distance_within(xy[i, 0], xy[i, 1], ed, need, np.inf)
        f, g0, g1 = edge_term(sd, ux, uy, rp[i], margin, 1.0, f, g0, g1)
        if w > 0.0:
            f, g0, g1 = edge_term(sd, ux, uy, r0, margin, w, f, g0, g1)
    for a in range(2):
        v = xy[i, a]
        g = 0.0
        if not outline:
            f, g = box_axis_term(v, box[a], box[a + 2], rp[i], margin, 1.0, f, g)
            if w > 0.0:
                f, g = box_axis_term(v, box[a], box[a + 2], r0, margin, w, f, g)
        f, g = container_axis_term(v - c[i, a], r[i], h[i], f, g)
        if a == 0:
            g0 += g
        else:
            g1 += g
    grad[i, 0] = g0
    grad[i, 1] = g1
    return f


#: Core radius of a phantom: every pair target with it is negative (no hard core).
NO_CORE = -1e300
#: Weight of the term that keeps phantoms out of the allowed region.
PHANTOM_WEIGHT = 15.0


@nb.njit(cache=True, inline="always")
def _phantom_terms(i, xy, r, box, margin, empty, has_empty, gbox, ed):  # pragma: no cover
    """A phantom's term: ``PHANTOM_WEIGHT · depth²`` where ``depth > 0`` is how far it
    stands inside the allowed region (``margin`` inside the panel or outline, outside
    the zero cells). Returns ``(f, g0, g1)``."""
    x = xy[i, 0]
    y = xy[i, 1]
    if ed[0].shape[0] > 0:
        # outside, only the side matters (no term); inside, exact within the index's
        # reach, and further inside (inf) never: a phantom's container keeps it within
        # 0.75 r of where it was thrown, beyond the wall
        sd, ux, uy = edge_signed_distance_within(x, y, ed, ed[7][5], 0.0)
        depth = sd - margin if sd < np.inf else 0.0
    else:
        depth = x - box[0]
        ux, uy = 1.0, 0.0
        if box[2] - x < depth:
            depth, ux, uy = box[2] - x, -1.0, 0.0
        if y - box[1] < depth:
            depth, ux, uy = y - box[1], 0.0, 1.0
        if box[3] - y < depth:
            depth, ux, uy = box[3] - y, 0.0, -1.0
        depth -= margin
    if depth > 0.0 and has_empty:
        reach = 2.0 * r[i]
        e, zx, zy = empty_depth(x, y, reach, empty, gbox[0], gbox[1], gbox[2], gbox[3])
        if e > 0.0 and reach - e < depth:
            depth, ux, uy = reach - e, -zx, -zy
    if depth <= 0.0:
        return 0.0, 0.0, 0.0
    return (
        PHANTOM_WEIGHT * depth * depth,
        2.0 * PHANTOM_WEIGHT * depth * ux,
        2.0 * PHANTOM_WEIGHT * depth * uy,
    )


#: Radius given to a mover in the packed array: its listed pairs then contribute exactly 0
#: (s - d < 0), so the pair loop needs no per-partner test of ``skip``.
_GONE = -1e300


@nb.njit(cache=True, inline="always")
def row_pairs(i, lo, hi, packed, nbr, skip, check, w, grad, f, gxi, gyi):  # pragma: no cover
    """Dot i's pairs with its partners ``nbr[lo:hi]`` read from the ``packed`` rows
    ``[n, 4]`` (x, y, r, c): each pair's f added to ``f``, its gradient subtracted from
    ``(gxi, gyi)`` (dot i's, kept in registers over the row) and added to ``grad[j]``;
    partners that are movers are passed over when ``check`` (a packed mover's radius
    makes its pairs zero anyway). Returns ``(f, gxi, gyi)``."""
    xi, yi, ri, ci = packed[i, 0], packed[i, 1], packed[i, 2], packed[i, 3]
    for k in range(lo, hi):
        j = nbr[k]
        if check and skip[j]:
            continue
        dx = xi - packed[j, 0]
        dy = yi - packed[j, 1]
        fp, gx, gy = pair_grad(dx, dy, ri + packed[j, 2], ci + packed[j, 3], w, i < j)
        f += fp
        gxi -= gx
        gyi -= gy
        grad[j, 0] += gx
        grad[j, 1] += gy
    return f, gxi, gyi


@nb.njit(parallel=True, cache=True)
def _penalty_kernel(
    xy,
    r,
    rp,
    c,
    h,
    box,
    cr,
    r0,
    w,
    margin,
    ptr,
    mid,
    nbr,
    skip,
    cross,
    ei,
    ej,
    empty,
    has_empty,
    gbox,
    ed,
    ph,
    packed,
    grad,
):  # pragma: no cover - compiled
    """Blocks of BLOCK dots in parallel (pack the block, single terms, then pairs inside
    the block), then the rows with cross-block partners and the extra pairs, serially,
    in a fixed order. ``packed`` is ``[n, 4]`` scratch: (x, y, r, c) with movers' radii
    set to ``_GONE``."""
    n = xy.shape[0]
    nblock = (n + BLOCK - 1) // BLOCK
    part = np.zeros(nblock)
    for b in nb.prange(nblock):
        lo = b * BLOCK
        hi = min(lo + BLOCK, n)
        f = 0.0
        for i in range(lo, hi):
            packed[i, 0] = xy[i, 0]
            packed[i, 1] = xy[i, 1]
            packed[i, 2] = _GONE if skip[i] else r[i]
            packed[i, 3] = _GONE if skip[i] else cr[i]
            f += _single_terms(
                i, xy, r, rp, c, h, box, r0, w, margin, empty, has_empty, gbox, ed, ph, grad
            )
        for i in range(lo, hi):
            if skip[i]:
                continue
            f, gxi, gyi = row_pairs(
                i, ptr[i], mid[i], packed, nbr, skip, False, w, grad, f, 0.0, 0.0
            )
            grad[i, 0] += gxi
            grad[i, 1] += gyi
        part[b] = f
    f = 0.0
    for b in range(nblock):
        f += part[b]
    for a in range(cross.shape[0]):
        i = cross[a]
        if skip[i]:
            continue
        # the packed rows (one cache line a dot) hold the same values as xy, r and cr
        # for dots that are not movers
        g0, g1 = grad[i, 0], grad[i, 1]
        f, grad[i, 0], grad[i, 1] = row_pairs(
            i, mid[i], ptr[i + 1], packed, nbr, skip, True, w, grad, f, g0, g1
        )
    for k in range(ei.shape[0]):
        f += _pair_term(xy, r, cr, ei[k], ej[k], w, grad)
    return f


def penalty_fast(xy: np.ndarray, terms: PenaltyTerms, pairs: PairList, grad: np.ndarray) -> float:
    """Penalty and gradient over a prepared pair list (see :mod:`optdot.spatial`).

    Args:
        xy: ``[n, 2]`` positions, mm (C-contiguous float64).
        terms: radii, containers, panel.
        pairs: holds at least every pair closer than ``reach_i + reach_j``, once.
        grad: ``[n, 2]`` output, overwritten with df/dxy (mm).

    Returns:
        f, mm².
    """
    box, has_empty, grid_box, edges, ph = terms.kernel_constants
    return _penalty_kernel(
        xy,
        terms.radius,
        terms.panel_radius,
        terms.center,
        terms.half_side,
        box,
        terms.core_radius,
        terms.dot_radius,
        terms.w_hard,
        terms.margin,
        pairs.ptr,
        pairs.mid,
        pairs.nbr,
        pairs.skip,
        pairs.cross,
        pairs.ei,
        pairs.ej,
        terms.empty,
        has_empty,
        grid_box,
        edges,
        ph,
        terms.scratch,
        grad,
    )
