"""The boundary of a :class:`~optdot.geometry.domain.Domain` as an index the compiled
kernels query: :class:`EdgeIndex` holds the segments (interior on the left) bucketed in a
grid, and :func:`signed_distance` gives a point's distance to the nearest edge, positive
inside, with its gradient, in O(1) per point.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numba as nb
import numpy as np
from scipy.ndimage import distance_transform_cdt

from .domain import Domain


@dataclass(frozen=True, eq=False)
class EdgeIndex:
    """The domain boundary as segments bucketed in a grid, for :func:`signed_distance`.

    Attributes:
        seg: ``[S, 4]`` segments ``(ax, ay, bx, by)``, interior on the left, mm.
        prev, next: ``[S]`` int64 neighbouring segment on the same loop.
        x0, y0, cell: bucket grid origin and cell side, mm.
        nx, ny: bucket grid shape.
        start, items: CSR of the segments within ``cell`` of each bucket.
        inside: ``[nx * ny]`` int8, 1 if the bucket's centre is inside.
        clear: ``[nx * ny]`` int32, how many buckets (chessboard) from the nearest one
            that lists a segment (0: it lists one): every segment is at least ``clear
            cell`` from the bucket.
        reach: distances below it come out exact (by default: :func:`signed_distance`).
    """

    seg: np.ndarray
    prev: np.ndarray
    next: np.ndarray
    x0: float
    y0: float
    cell: float
    nx: int
    ny: int
    start: np.ndarray
    items: np.ndarray
    inside: np.ndarray
    clear: np.ndarray
    reach: float

    @classmethod
    def build(cls, domain: Domain, reach: float) -> EdgeIndex:
        """Index ``domain``'s edges; distances below ``reach`` (mm) come out exact.

        Buckets are ``reach`` wide, but no wider than :data:`SEGMENTS_A_CELL` typical
        segments (and no finer than 1/2048 of the panel): a bucket then lists a few
        segments even where an outline is finely curved (a cap's keep-out, a flattened
        arc) and ``reach`` is long (the phantoms' two radii at a sparse fill); a point
        farther than a bucket from the edges is found by rings of buckets."""
        segs, prev, nxt = [], [], []
        for ring in domain.rings():
            k = len(ring)
            base = len(segs)
            for i in range(k):
                a, b = ring[i], ring[(i + 1) % k]
                segs.append((a[0], a[1], b[0], b[1]))
                prev.append(base + (i - 1) % k)
                nxt.append(base + (i + 1) % k)
        seg = np.asarray(segs, dtype=np.float64)
        bx0, by0, bx1, by1 = domain.box
        span = max(bx1 - bx0, by1 - by0)
        length = float(np.median(np.hypot(seg[:, 2] - seg[:, 0], seg[:, 3] - seg[:, 1])))
        cell = max(min(reach, SEGMENTS_A_CELL * length), span / 2048.0, 1e-9)
        x0, y0 = bx0 - reach - cell, by0 - reach - cell
        nx = int((bx1 + reach + cell - x0) / cell) + 1
        ny = int((by1 + reach + cell - y0) / cell) + 1
        start, items = _bucket_segments(seg, x0, y0, cell, nx, ny, cell)
        iy, ix = np.divmod(np.arange(nx * ny), nx)
        centres = np.stack([x0 + (ix + 0.5) * cell, y0 + (iy + 0.5) * cell], axis=1)
        inside = domain.contains(centres).astype(np.int8)
        listed = (np.diff(start) > 0).reshape(ny, nx)
        if listed.any():
            clear = distance_transform_cdt(~listed, metric="chessboard").astype(np.int32)
        else:
            clear = np.full((ny, nx), max(nx, ny), np.int32)
        return cls(
            seg,
            np.asarray(prev),
            np.asarray(nxt),
            x0,
            y0,
            cell,
            nx,
            ny,
            start,
            items,
            inside,
            np.ascontiguousarray(clear.ravel()),
            float(reach),
        )


#: A bucket is at most this many typical segment lengths wide (see :meth:`EdgeIndex.build`).
SEGMENTS_A_CELL = 4.0


@nb.njit(cache=True)
def _bucket_segments(seg, x0, y0, cell, nx, ny, reach):  # pragma: no cover - compiled
    counts = np.zeros(nx * ny + 1, np.int64)
    for pass_ in range(2):
        if pass_ == 1:
            start = np.cumsum(counts)
            fill = start[:-1].copy()
            items = np.empty(start[-1], np.int64)
        for s in range(seg.shape[0]):
            lo_x = min(seg[s, 0], seg[s, 2]) - reach
            hi_x = max(seg[s, 0], seg[s, 2]) + reach
            lo_y = min(seg[s, 1], seg[s, 3]) - reach
            hi_y = max(seg[s, 1], seg[s, 3]) + reach
            for cy in range(
                max(int((lo_y - y0) / cell), 0), min(int((hi_y - y0) / cell), ny - 1) + 1
            ):
                for cx in range(
                    max(int((lo_x - x0) / cell), 0), min(int((hi_x - x0) / cell), nx - 1) + 1
                ):
                    c = cy * nx + cx
                    if pass_ == 0:
                        counts[c + 1] += 1
                    else:
                        items[fill[c]] = s
                        fill[c] += 1
    return start, items


@nb.njit(cache=True, inline="always")
def _left(ax, ay, bx, by, px, py):  # pragma: no cover - compiled
    return (bx - ax) * (py - ay) - (by - ay) * (px - ax) > 0.0


@nb.njit(cache=True)
def _nearest(x, y, seg, prev, nxt, cand, lo, hi):  # pragma: no cover - compiled
    """Nearest boundary point among segments ``cand[lo:hi]``: (d, px, py, inside)."""
    best = np.inf
    bs = -1
    bt = 0.0
    for q in range(lo, hi):
        s = cand[q]
        ax, ay, bx, by = seg[s, 0], seg[s, 1], seg[s, 2], seg[s, 3]
        dx, dy = bx - ax, by - ay
        L2 = dx * dx + dy * dy
        t = 0.0 if L2 == 0.0 else min(max(((x - ax) * dx + (y - ay) * dy) / L2, 0.0), 1.0)
        px, py = ax + t * dx, ay + t * dy
        d2 = (x - px) ** 2 + (y - py) ** 2
        if d2 < best:
            best, bs, bt = d2, s, t
    s = bs
    ax, ay, bx, by = seg[s, 0], seg[s, 1], seg[s, 2], seg[s, 3]
    px, py = ax + bt * (bx - ax), ay + bt * (by - ay)
    if 0.0 < bt < 1.0:
        inside = _left(ax, ay, bx, by, x, y)
    else:
        # nearest point is a vertex: decide with both edges meeting there
        e1 = prev[s] if bt == 0.0 else s
        e2 = s if bt == 0.0 else nxt[s]
        l1 = _left(seg[e1, 0], seg[e1, 1], seg[e1, 2], seg[e1, 3], x, y)
        l2 = _left(seg[e2, 0], seg[e2, 1], seg[e2, 2], seg[e2, 3], x, y)
        ux1, uy1 = seg[e1, 2] - seg[e1, 0], seg[e1, 3] - seg[e1, 1]
        ux2, uy2 = seg[e2, 2] - seg[e2, 0], seg[e2, 3] - seg[e2, 1]
        convex = ux1 * uy2 - uy1 * ux2 > 0.0
        inside = (l1 and l2) if convex else (l1 or l2)
    return np.sqrt(best), px, py, inside


@nb.njit(cache=True)
def _nearest_around(
    x, y, ix, iy, k0, seg, prev, nxt, nx, ny, cell, start, items, need
):  # pragma: no cover - compiled
    """The nearest boundary point from the buckets in square rings around bucket ``(ix,
    iy)``, from ring ``k0`` out (the rings inside hold no segment): ``(d, px, py,
    inside)``. A segment at distance ``D`` has its nearest point in a bucket within
    ``ceil(D / cell)`` rings, and every bucket lists the segments within ``cell`` of it,
    so rings ``0 .. k - 1`` hold every segment closer than ``k cell``: the search stops
    before ring ``k`` once it has a candidate that close (exact) or ``k cell`` reaches
    ``need``, or past the grid; ``d`` = inf when nothing is closer than ``need``."""
    best, bpx, bpy, bins = np.inf, 0.0, 0.0, False
    for k in range(k0, max(nx, ny) + 1):
        if best <= k * cell or k * cell >= need:
            break
        for jy in range(max(iy - k, 0), min(iy + k, ny - 1) + 1):
            step = 1 if (jy == iy - k or jy == iy + k) else 2 * k
            jx = ix - k
            while jx <= ix + k:
                if 0 <= jx < nx:
                    c = jy * nx + jx
                    if start[c] < start[c + 1]:
                        d, px, py, ins = _nearest(
                            x, y, seg, prev, nxt, items, start[c], start[c + 1]
                        )
                        if d < best:
                            best, bpx, bpy, bins = d, px, py, ins
                jx += step
    if best >= need:
        return np.inf, 0.0, 0.0, False
    return best, bpx, bpy, bins


@nb.njit(cache=True)
def signed_distance(
    x, y, seg, prev, nxt, x0, y0, cell, nx, ny, start, items, inside, clear, far, need_in, need_out
):  # pragma: no cover
    """Signed distance of (x, y) to the boundary (> 0 inside) and its gradient (ux, uy),
    exact when it is under ``need_in`` inside or ``need_out`` outside; beyond, inside
    returns ``far`` and outside ``-far`` (nothing a caller measures there), with a zero
    gradient.

    Each bucket lists every segment within ``cell`` of it, so a nearest listed segment
    closer than ``cell`` is the true nearest. Otherwise the point is at least ``cell``
    (and at least ``clear`` buckets) from the boundary, on the same side as its bucket's
    centre (half a diagonal away), and the buckets in rings around its own are searched
    (:func:`_nearest_around`) as far as the side's need. A point off the grid is
    outside: all segments are measured, unless it is farther off than ``need_out``.
    """
    ix = int(np.floor((x - x0) / cell))
    iy = int(np.floor((y - y0) / cell))
    d = np.inf
    if 0 <= ix < nx and 0 <= iy < ny:
        c = iy * nx + ix
        if start[c] < start[c + 1]:
            d, px, py, ins = _nearest(x, y, seg, prev, nxt, items, start[c], start[c + 1])
        if d >= cell:
            need = need_in if inside[c] else need_out
            k0 = max(1, clear[c])
            d, px, py, ins = _nearest_around(
                x, y, ix, iy, k0, seg, prev, nxt, nx, ny, cell, start, items, need
            )
            if d == np.inf:
                return (far, 0.0, 0.0) if inside[c] else (-far, 0.0, 0.0)
    else:  # off the grid: outside the panel, at least this far from the grid's edge
        gx = max(x0 - x, x - (x0 + nx * cell), 0.0)
        gy = max(y0 - y, y - (y0 + ny * cell), 0.0)
        if max(gx, gy) >= need_out:
            return -far, 0.0, 0.0
    if d == np.inf:
        every = np.arange(seg.shape[0])  # (lo as a variable: a literal 0 compiled _nearest again)
        d, px, py, ins = _nearest(x, y, seg, prev, nxt, every, every.shape[0] * 0, seg.shape[0])
    if d < 1e-15:
        return 0.0, 0.0, 0.0
    ux, uy = (x - px) / d, (y - py) / d
    if ins:
        return d, ux, uy
    return -d, -ux, -uy


#: The kernels' stand-in for "no outline" (a rectangle panel).
NO_EDGES = (
    np.zeros((0, 4)),
    np.zeros(0, np.int64),
    np.zeros(0, np.int64),
    np.zeros(1, np.int64),
    np.zeros(0, np.int64),
    np.zeros(0, np.int8),
    np.zeros(0, np.int32),
    np.zeros(6),
)


def edge_args(edges: EdgeIndex | None) -> tuple:
    """The edge index as one tuple of arrays for the kernel (empty: rectangle)."""
    if edges is None:
        return NO_EDGES
    geo = np.array(
        [edges.x0, edges.y0, edges.cell, edges.nx, edges.ny, edges.reach], dtype=np.float64
    )
    return (
        edges.seg,
        edges.prev,
        edges.next,
        edges.start,
        edges.items,
        edges.inside,
        edges.clear,
        geo,
    )


@nb.njit(cache=True, inline="always")
def edge_signed_distance(x, y, ed):  # pragma: no cover - compiled
    """:func:`signed_distance` with the index packed by :func:`edge_args`: exact within
    the index's reach inside, and everywhere outside."""
    return edge_signed_distance_within(x, y, ed, ed[7][5], np.inf)


@nb.njit(cache=True, inline="always")
def edge_signed_distance_within(x, y, ed, need_in, need_out):  # pragma: no cover - compiled
    """:func:`signed_distance` with the index packed by :func:`edge_args`, exact within
    ``need_in`` inside and ``need_out`` outside (``need_in`` at most the index's
    reach); beyond, ``inf`` inside and ``-inf`` outside."""
    seg, prev, nxt, start, items, inside, clear, geo = ed
    return signed_distance(
        x,
        y,
        seg,
        prev,
        nxt,
        geo[0],
        geo[1],
        geo[2],
        int(geo[3]),
        int(geo[4]),
        start,
        items,
        inside,
        clear,
        np.inf,
        need_in,
        need_out,
    )


def signed_distances(
    index: EdgeIndex, xy: np.ndarray, far: float = math.inf
) -> tuple[np.ndarray, np.ndarray]:
    """Vectorised :func:`signed_distance`: ``[n]`` distances and ``[n, 2]`` gradients,
    exact within the index's reach inside (``far`` beyond) and everywhere outside."""
    return _signed_many(np.ascontiguousarray(xy, dtype=np.float64), edge_args(index), far)


@nb.njit(cache=True)
def _signed_many(xy, ed, far):  # pragma: no cover - compiled
    n = xy.shape[0]
    d = np.empty(n)
    u = np.empty((n, 2))
    for i in range(n):
        d[i], u[i, 0], u[i, 1] = edge_signed_distance(xy[i, 0], xy[i, 1], ed)
        if d[i] == np.inf:
            d[i] = far
    return d, u
