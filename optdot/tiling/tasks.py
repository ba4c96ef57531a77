"""Tiled generation: the tasks a worker runs, and why they remove seams instead of hiding them.

The problem. A panel of 10⁸ dots does not fit one process (~450 B per dot), and the
relaxation is local: a dot moves at most its container (3.5-4 circle radii) and feels only
dots within two circle radii. So the panel is cut into tiles (:mod:`optdot.tiling.plan`)
that workers relax separately. Cut naively, every tile border is a seam: the dots on each
side were relaxed without the other side, so along the border the pairs are too close
(or too far) and the eye sees a grid of lines.

The design, in four kinds of task, each a pure function of the job, the plan and the
results it is handed (so any worker count and any schedule give the same bytes):

1. **initial** (:func:`initial_task`). A tile's initial dots are computable from the
   job, the seed and the tile index alone: its quota (the map's integral over the tile,
   apportioned to the job's dot count by largest remainders: the tiles hold exactly
   ``job.n_dots``), thrown by the paper's dart throwing (§2.1) restricted to the tile —
   cell chosen in proportion to ρ × (area of the cell inside the tile), position uniform
   in that part of the cell — with a Sobol sequence scrambled by ``(seed, tile index)``.
   The single-process throw is the special case "one tile = the panel" (same cumulative
   law), so a tile's dots follow ρ exactly as the panel's do.

2. **relax** (:func:`relax_tile`, phase 1). Each tile relaxes its own dots with the job's
   formulation (all stages, ``max_iter`` iterations), containers on the initial dots, the
   panel's real edges, outline and zero cells as penalties. Across its borders it sees the
   neighbours' *initial* dots within the halo, frozen: without them the border dots, free
   on one side, spilled into the border and left +0.6 % coverage along every seam (led
   sample, 4 x 2 tiles); with them the density across the border is right, but its
   arrangement is not relaxed: the seam is still there.

3. **seams** (:func:`relax_seams`, phase 2). The tiling shifted by half a tile puts every
   phase-1 seam in the middle of a shifted square. Each square relaxes again, with every
   dot within ``band`` (6 hexagonal spacings at the lowest fill) of a seam line mobile and
   the dots in a ``halo`` (3 spacings) beyond them frozen: the seam is relaxed as interior,
   from both sides at once, by the same kernels, same containers (still on the initial
   dots), same iterations. Only the bands are relaxed (~25 % extra work at 150k-dot tiles),
   not whole shifted tiles: farther from a seam, phase 1 already saw every neighbour. Two
   shifted squares meet at the middle of each phase-1 border, where a band crosses from
   one square into the next; there the band is relaxed from one side per square, over a
   patch of ~band² — a few dozen dots per tile border, which the guarantee pass then makes
   legal and which the seam metrics of QA measure.

4. **guarantee** (:func:`legalize_tile`). The guarantee pass (projection, then 1 nm
   rounding) per tile, with the dots of the 8 neighbouring tiles within a halo frozen. Tiles
   are legalised in four checkerboard colours: a tile of colour c waits for its neighbours
   of colours < c and holds their final positions still, so a pair across a border is fixed
   by the later tile, against the earlier's final dots; tiles of one colour never touch, so
   they run in parallel. After the fourth colour every pair across every border has been
   checked against final positions, and each tile's check (:func:`check_tile`) counts
   collisions with its frozen neighbours as well as inside it.

Dots belong to the tile they were thrown in (their index never changes); a dot may end a
little outside its tile (containers bound it to ~2 circle radii), which the halos allow for.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..config.job import Job
from ..errors import GeometryError, GuaranteeError
from ..geometry.density import axis_overlap
from ..geometry.domain import box_protruding
from ..geometry.morton import spatial_order
from ..relax.legalize import legalize
from ..relax.optdot import relax_staged
from ..sampling.sobol import sobol_points
from ..spatial.cellgrid import pairs_within
from .plan import TilePlan
from .steps import formulation_for, problem_of, settings_for

#: Salt of a tile's Sobol scrambling seed: ``[seed, SALT, tile index]``.
SALT = 0x711E


@dataclass
class TileDots:
    """The dots of one tile between tasks.

    Attributes:
        tile: ``(i, j)``.
        xy0: ``[n, 2]`` initial positions (container centres), mm, in Morton order.
        xy: ``[n, 2]`` current positions, mm.
    """

    tile: tuple[int, int]
    xy0: np.ndarray
    xy: np.ndarray


def initial_tile(job: Job, plan: TilePlan, i: int, j: int) -> np.ndarray:
    """The initial dots of tile ``(i, j)``: ``[quota, 2]`` positions, mm, generation order."""
    n = int(plan.quotas[j, i])
    if n == 0:
        return np.zeros((0, 2))
    d = job.density
    x0, y0, x1, y1 = plan.rect(i, j)
    cw, ch = d.cell_size
    fx = axis_overlap(np.array([x0, x1]), d.x0, cw, d.shape[1])[0]
    fy = axis_overlap(np.array([y0, y1]), d.y0, ch, d.shape[0])[0]
    cols = np.flatnonzero(fx > 0)
    rows = np.flatnonzero(fy > 0)
    w = (d.grid[np.ix_(rows, cols)] * fy[rows, None] * fx[None, cols]).ravel()
    if not (w > 0).any():
        raise GeometryError(f"tile {i},{j}: quota of {n} dots but the map is zero there")
    cum = np.cumsum(w)
    cum /= cum[-1]
    last = int(np.flatnonzero(w > 0)[-1])
    seed = [job.optimize.seed, SALT, plan.index(i, j)]
    m = n
    while True:
        u = sobol_points(m, seed)
        k = np.minimum(np.searchsorted(cum, u[:, 0], side="right"), last)
        r, c = np.divmod(k, len(cols))
        ax = np.maximum(d.x0 + cols[c] * cw, x0)
        bx = np.minimum(d.x0 + (cols[c] + 1) * cw, x1)
        ay = np.maximum(d.y0 + rows[r] * ch, y0)
        by = np.minimum(d.y0 + (rows[r] + 1) * ch, y1)
        xy = np.column_stack([ax + u[:, 1] * (bx - ax), ay + u[:, 2] * (by - ay)])
        if job.domain.rectangle:
            return xy
        keep = xy[job.domain.contains(xy)]
        if len(keep) >= n:
            return keep[:n]
        if m > 64 * max(n, 16):
            raise GeometryError(
                f"tile {i},{j}: could only place {len(keep)} of {n} dots inside the outline"
            )
        m = int(m * 1.25 * n / max(len(keep), 1)) + 16


def initial_task(job: Job, plan: TilePlan, i: int, j: int) -> np.ndarray:
    """The initial dots of tile ``(i, j)`` in Morton order, ``[quota, 2]`` mm."""
    xy = initial_tile(job, plan, i, j)
    return np.ascontiguousarray(xy[spatial_order(xy)])


def _near_rect(xy: np.ndarray, rect: tuple[float, float, float, float], h: float) -> np.ndarray:
    x0, y0, x1, y1 = rect
    return (xy[:, 0] >= x0 - h) & (xy[:, 0] <= x1 + h) & (xy[:, 1] >= y0 - h) & (xy[:, 1] <= y1 + h)


def relax_tile(
    job: Job, plan: TilePlan, i: int, j: int, xy0: np.ndarray, *around: np.ndarray
) -> TileDots:
    """Phase 1: tile ``(i, j)``'s initial dots ``xy0`` relaxed, with the initial dots of
    the tiles ``around`` it within the halo held still (so the border dots feel the right
    density across the border and do not spill into it)."""
    if len(xy0) == 0:
        return TileDots((i, j), xy0, xy0.copy())
    rect = plan.rect(i, j)
    halo = [a[_near_rect(a, rect, plan.halo)] for a in around]
    halo_xy = np.concatenate(halo) if halo else np.zeros((0, 2))
    n = len(xy0)
    both = np.ascontiguousarray(np.concatenate([xy0, halo_xy]))
    frozen = np.zeros(len(both), bool)
    frozen[n:] = True
    rho = job.density.at(both)
    xy, _, _ = relax_staged(
        problem_of(job),
        formulation_for(job),
        both,
        rho,
        settings_for(job),
        frozen=frozen if len(halo_xy) else None,
    )
    return TileDots((i, j), xy0, np.ascontiguousarray(xy[:n]))


def _gather(parts: list[TileDots]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Concatenate tiles: ``(xy0 [n, 2], xy [n, 2], owner [n] part index)``."""
    xy0 = np.concatenate([p.xy0 for p in parts]) if parts else np.zeros((0, 2))
    xy = np.concatenate([p.xy for p in parts]) if parts else np.zeros((0, 2))
    owner = np.concatenate([np.full(len(p.xy), k) for k, p in enumerate(parts)])
    return xy0, xy, owner.astype(np.int64)


@dataclass
class SeamMoves:
    """Phase-2 result of one shifted square: new positions of some dots of some tiles.

    Attributes:
        moves: ``{tile: (local indices [k] int64, positions [k, 2] mm)}``.
    """

    moves: dict[tuple[int, int], tuple[np.ndarray, np.ndarray]]


def relax_seams(job: Job, plan: TilePlan, i: int, j: int, parts: list[TileDots]) -> SeamMoves:
    """Phase 2 for the shifted square around grid point ``(i, j)``: relax the seam bands
    in it with a frozen halo. ``parts``: the (up to 4) phase-1 tiles meeting there."""
    xy0, xy, owner = _gather(parts)
    si, sj = plan.square_of(xy)
    here = (si == i) & (sj == j)
    mobile = here & plan.in_band(xy, i, j, plan.band)
    if not mobile.any():
        return SeamMoves({})
    # frozen shell: within the halo of the mobile set (band + halo of the lines, and of
    # the square's sides)
    mx = 0.5 * (plan.xs[:-1] + plan.xs[1:])
    my = 0.5 * (plan.ys[:-1] + plan.ys[1:])
    lo_x = mx[i - 1] if i > 0 else -np.inf
    hi_x = mx[i] if i < plan.nx else np.inf
    lo_y = my[j - 1] if j > 0 else -np.inf
    hi_y = my[j] if j < plan.ny else np.inf
    h = plan.halo
    near = (
        plan.in_band(xy, i, j, plan.band + h)
        & (xy[:, 0] >= lo_x - h)
        & (xy[:, 0] < hi_x + h)
        & (xy[:, 1] >= lo_y - h)
        & (xy[:, 1] < hi_y + h)
    )
    sel = np.flatnonzero(near | mobile)
    frozen = ~mobile[sel]
    rho = job.density.at(xy0[sel])
    new, _, _ = relax_staged(
        problem_of(job),
        formulation_for(job),
        np.ascontiguousarray(xy0[sel]),
        rho,
        settings_for(job),
        start=np.ascontiguousarray(xy[sel]),
        frozen=frozen,
    )
    moved = sel[~frozen]
    new_mobile = new[~frozen]
    starts = np.cumsum([0] + [len(p.xy) for p in parts])
    moves = {}
    for k, p in enumerate(parts):
        mine = owner[moved] == k
        if mine.any():
            moves[p.tile] = (moved[mine] - starts[k], np.ascontiguousarray(new_mobile[mine]))
    return SeamMoves(moves)


def apply_seams(dots: TileDots, results: list[SeamMoves]) -> TileDots:
    """The tile after phase 2: its dots moved by the squares that relaxed its borders."""
    xy = dots.xy.copy()
    for res in results:
        if dots.tile in res.moves:
            idx, pos = res.moves[dots.tile]
            xy[idx] = pos
    return TileDots(dots.tile, dots.xy0, xy)


def _halo_of(dots: TileDots, neighbours: list[np.ndarray], width: float) -> np.ndarray:
    """Neighbour positions within ``width`` of the tile's own dots' bounding box."""
    if len(dots.xy) == 0 or not neighbours:
        return np.zeros((0, 2))
    lo = dots.xy.min(axis=0) - width
    hi = dots.xy.max(axis=0) + width
    out = [n[np.all((n >= lo) & (n <= hi), axis=1)] for n in neighbours]
    return np.concatenate(out) if out else np.zeros((0, 2))


def legalize_tile(job: Job, plan: TilePlan, dots: TileDots, neighbours: list[np.ndarray]):
    """The guarantee pass for one tile; ``neighbours``: positions ``[k, 2]`` of the dots of
    the surrounding tiles (final for earlier colours), held still.

    Returns:
        ``[n, 2]`` final positions of the tile's dots, mm, rounded to 1 nm.

    Raises:
        GuaranteeError: the tile could not be made legal.
    """
    r0 = 0.5 * job.diameter
    dmin = job.min_distance
    halo = _halo_of(dots, neighbours, 2.0 * dmin)
    n = len(dots.xy)
    if n == 0:
        return dots.xy
    xy = np.concatenate([dots.xy, halo])
    frozen = np.zeros(len(xy), bool)
    frozen[n:] = True
    home = np.zeros(len(xy), np.int64)
    home[:n] = job.density.cell_index(dots.xy0)
    leg = legalize(xy, job.density, home, job.domain, r0, dmin, frozen=frozen)
    final = np.ascontiguousarray(leg.xy[:n])
    bad = check_tile(job, final, np.round(halo, 6))
    if bad:
        i, j = dots.tile
        raise GuaranteeError(
            f"tile {i},{j}: could not meet the guarantee after {leg.sweeps} sweeps: {bad}"
        )
    return final


def check_tile(job: Job, xy: np.ndarray, halo: np.ndarray) -> str:
    """What is wrong with a tile's final dots (empty if nothing): pairs closer than the
    minimum distance among them or with the halo, dots out of the panel, dots in zero
    cells."""
    r0 = 0.5 * job.diameter
    both = np.concatenate([xy, halo])
    pairs = pairs_within(both, job.min_distance)
    n = len(xy)
    collisions = int((pairs[:, 0] < n).sum()) if len(pairs) else 0
    dom = job.domain
    if dom.rectangle:
        out = int(box_protruding(xy, dom.box, r0 + dom.edge_margin).sum())
    else:
        out = int(dom.protruding(xy, r0).sum())
    empty = int(job.density.empty_mask(xy).sum())
    if collisions or out or empty:
        return (
            f"{collisions} pairs closer than {job.min_distance * 1e3:.1f} um, "
            f"{out} dots protruding, {empty} dots in zero-density cells"
        )
    return ""
