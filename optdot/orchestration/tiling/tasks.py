"""Tiled generation: the tasks a worker runs, and why they remove seams instead of hiding them.

The problem. A panel of 10⁸ dots does not fit one process (~450 B per dot), and the
relaxation is local: a dot moves at most its container (3.5-4 circle radii) and feels only
dots within two circle radii. So the panel is cut into tiles
(:mod:`optdot.orchestration.tiling.plan`)
that workers relax separately. Cut naively, every tile border is a seam: the dots on each
side were relaxed without the other side, so along the border the pairs are too close
(or too far) and the eye sees a grid of lines.

The design, in nine kinds of task, each a pure function of the job, the plan and the
results it is handed (so any worker count and any schedule give the same bytes):

Every task calls the stages of :mod:`optdot.stages`, the functions the single process
runs over the whole panel; a task only chooses which dots are mobile and which are held.

1. **initial** (:func:`initial_task`). A tile's initial dots are computable from the
   job, the seed and the tile index alone: its quota (the map's dot count over the tile,
   apportioned to the job's dot count by largest remainders: the tiles hold exactly
   ``job.n_dots``), thrown by :func:`optdot.stages.throw` with the tile as the window —
   cell chosen in proportion to ρ × (area of the cell inside the tile), position uniform
   in that part of the cell — with a Sobol sequence scrambled by ``(seed, tile index)``.
   The single-process throw is the window = the panel, so a tile's dots follow ρ exactly
   as the panel's do. When sizes vary, darts follow the dot count (fill over dot area)
   and every dot's rule diameter follows from its start cell, so no task carries sizes
   until the last one fits them.

   **The panel-wide field** (:func:`deposit_task`, :func:`coarse_task`). The relaxation
   keeps its throw's long-wavelength grain, and the correction of step 4 solves over
   windows a tile wide, each with its own mean and walls: it cannot see wavelengths of a
   tile and longer, and two windows disagree about them (notebook crop tiled at 15 mm:
   strongest blob 3.85 JND, 1.16 from one process). So every tile's initial dots are
   deposited on one coarse lattice, one task solves the panel's field from all the
   deposits (summed in tile order: the same bytes on any worker count), and each
   relaxation moves its throw and its halo's along it first
   (:func:`optdot.stages.coarse_shift`; 1.18 JND, p99 0.65 against 1.30 without). Every throw is
   made before any tile relaxes; a resumed run throws every tile again for the field.

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

4. **correct** (:func:`correct_tile`). The long-wavelength correction
   (:mod:`optdot.relax.lowpass`) solves ``∇²φ = e`` over the coverage error of a region;
   corrected tile by tile with the neighbours held still, the error they carried piled up
   on the seams (LED sample: seam bands -1.1 % coverage, 17 JND at a tile corner), and
   with each tile solving over itself plus a margin of its neighbours' dots, the fields of
   two tiles still differed at their seam by a harmonic part (up to 5 µm where the
   correction moves dots ~4 µm: seam bands -0.1 %). So the field is blended: windows
   centred on every tile centre, border midpoint and corner (a tile wide, plus
   ``plan.margin``), each dot displaced by the fields of the four windows around it
   weighted by tents in x and y that sum to one (1 at a window's centre, 0 a tile away).
   Two tiles compute a window they share from the same phase-2 dots, so a dot's
   displacement is the same whichever side of a seam it stands on: no jump, and what the
   blend adds, the weights' gradient times the fields' differences, is spread over a
   tile. The tile deposits its dots and its neighbours' on a lattice all tiles share
   once, and solves each window on its part of it, so two tiles solving one window get one
   field. On the LED sample's phase-2 dots (4 x 2 tiles of 10 mm) this first pass takes
   the blurred coverage error from 0.26 % to 0.086 % RMS, flat across the seams (one pass
   over the whole panel at once: 0.066 %). Windows reach 10 spacings past their
   tile-sized core (``plan.margin``): 4 gave 0.098 %, 30 0.089 % and 40 % more time.

   **The wide pass** (:func:`wide_deposit_task`, :func:`wide_task`, :func:`wide_shift`).
   The single process runs a second pass, 3 spacings wide, off the dots the first moved;
   it is what settles the panel's edges (notebook panel: strongest blob 2.66 JND tiled
   with one pass, 1.48 in one process with two). Its error is a sum of per-dot deposits,
   so it is solved over the whole panel like the throw's field: every tile's corrected
   dots are deposited (:func:`optdot.stages.wide_part`), one task solves the field from
   all of them, and each tile's corrected dots move along it. A barrier: no guarantee
   pass starts before every tile is corrected, so every tile's corrected dots are held
   at once (on a panel large for the workers' memory, their positions alone:
   :func:`first_positions`, the containers thrown again after the barrier,
   :func:`containers`); the merged dots, needed by no task after the corrections, are
   let go instead. Notebook crop tiled at 15 mm: strongest blob 0.51 JND, p99 0.18
   (without the pass 1.18 / 0.65; one process 0.87 / 0.23); led tiled: coverage RMS
   (0.5 mm) 0.029 % (0.065 % without), seams 0.021 % against 0.032 % inside.

5. **guarantee** (:func:`legalize_tile`). The formulation's hard-core iterations (which
   clear the pairs under 60 µm the correction made), then :func:`optdot.stages.finish`:
   sizes fitted to the coverage (when they vary by a rule), then the guarantee pass
   (projection, 1 nm rounding) and its check, with the dots of the 8 neighbouring tiles
   within a halo (:func:`optdot.orchestration.job_settings.halo_width`: the size fit's blur
   reach when sizes are fitted)
   held still, at their final sizes when final, else their rule sizes. Tiles
   are legalised in four checkerboard colours: a tile of colour c waits for its neighbours
   of colours < c and holds their final positions still, so a pair across a border is fixed
   by the later tile, against the earlier's final dots; tiles of one colour never touch, so
   they run in parallel. After the fourth colour every pair across every border has been
   checked against final positions, and each tile's check counts collisions with its
   frozen neighbours as well as inside it.

Dots belong to the tile they were thrown in (their index never changes); a dot may end a
little outside its tile (containers bound it to ~2 circle radii), which the halos allow for.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ... import stages
from ...config.job import Job
from ...geometry.morton import spatial_order
from ...geometry.shapes import Footprints
from ...relax.lowpass import CoarseField, LatticePart
from ...relax.shaped import turned
from ...spatial.window import bounds, grown, in_rect
from ..job_settings import stage_settings
from .plan import TilePlan

#: Salt of a tile's Sobol scrambling seed: ``[seed, SALT, tile index]``.
SALT = 0x711E


@dataclass
class TileDots:
    """The dots of one tile between tasks.

    Attributes:
        tile: ``(i, j)``.
        xy0: ``[n, 2]`` initial positions (container centres, start cells), mm, in Morton
            order.
        xy: ``[n, 2]`` current positions, mm.
    """

    tile: tuple[int, int]
    xy0: np.ndarray
    xy: np.ndarray


@dataclass
class FinalDots:
    """A tile's final dots: ``xy`` ``[n, 2]`` mm (1 nm), ``diameter`` mm (one, or ``[n]``)
    and, for shaped dots, ``dots``: their footprints (sizes and angles, as written)."""

    xy: np.ndarray
    diameter: float | np.ndarray
    dots: Footprints | None = None

    @classmethod
    def read(cls, job: Job, xy: np.ndarray, dots: Footprints) -> FinalDots:
        """Final dots of ``job`` as a part file holds them (``xy [n, 2]`` mm and
        footprints): discs' diameters; shaped dots' footprints and their area-equivalent
        diameters (on the size rule's quantisation, the sizes they were made at)."""
        if dots.kind.round:
            return cls(xy, dots.diameter)
        if job.sizes is None:
            return cls(xy, job.diameter, dots)
        d = job.sizes.quantise(dots.equivalent_diameter())
        return cls(xy, d, dots)

    @property
    def footprints(self) -> Footprints:
        """The footprints of the dots (discs of :attr:`diameter` when not shaped)."""
        if self.dots is not None:
            return self.dots
        return Footprints.circles(self.diameter, len(self.xy))


def _where(i: int, j: int) -> str:
    return f"tile {i},{j}"


def initial_tile(job: Job, plan: TilePlan, i: int, j: int) -> np.ndarray:
    """The initial dots of tile ``(i, j)``: ``[quota, 2]`` positions, mm, generation order."""
    n = int(plan.quotas[j, i])
    if n == 0:
        return np.zeros((0, 2))
    seed = [job.optimize.seed, SALT, plan.index(i, j)]
    return stages.throw(stage_settings(job), n, seed, plan.rect(i, j), _where(i, j))


def initial_task(job: Job, plan: TilePlan, i: int, j: int) -> np.ndarray:
    """The initial dots of tile ``(i, j)`` in Morton order, ``[quota, 2]`` mm."""
    xy = initial_tile(job, plan, i, j)
    return np.ascontiguousarray(xy[spatial_order(xy)])


def relax_tile(
    job: Job,
    plan: TilePlan,
    coarse: CoarseField | None,
    i: int,
    j: int,
    xy0: np.ndarray,
    *around: np.ndarray,
) -> TileDots:
    """Phase 1: tile ``(i, j)``'s initial dots ``xy0`` moved along the panel-wide field
    ``coarse`` (:func:`optdot.stages.coarse_shift`) and relaxed, with the initial dots of
    the tiles ``around`` it within the halo, moved alike, held still (so the border dots
    feel the right density across the border and do not spill into it). The moved
    throw is the tile's containers from here on."""
    s = stage_settings(job)
    xy0 = stages.coarse_shift(s, coarse, xy0)
    if len(xy0) == 0:
        return TileDots((i, j), xy0, xy0.copy())
    box = grown(plan.rect(i, j), plan.halo)
    halo = [stages.coarse_shift(s, coarse, a[in_rect(a, box)]) for a in around]
    halo_xy = np.concatenate(halo) if halo else np.zeros((0, 2))
    n = len(xy0)
    both = np.ascontiguousarray(np.concatenate([xy0, halo_xy]))
    frozen = np.zeros(len(both), bool)
    frozen[n:] = True
    held = frozen if len(halo_xy) else None
    run = stages.relax(s, both, frozen=held, lowpass=False)
    return TileDots((i, j), xy0, np.ascontiguousarray(run.xy[:n]))


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
    run = stages.relax(
        stage_settings(job),
        np.ascontiguousarray(xy0[sel]),
        start=np.ascontiguousarray(xy[sel]),
        frozen=frozen,
        lowpass=False,
    )
    moved = sel[~frozen]
    new_mobile = run.xy[~frozen]
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


def deposit_task(job: Job, xy0: np.ndarray) -> LatticePart:
    """A tile's initial dots ``xy0`` deposited on the panel-wide lattice
    (:func:`optdot.stages.coarse_part`)."""
    return stages.coarse_part(stage_settings(job), xy0)


def coarse_task(job: Job, *parts: LatticePart) -> CoarseField | None:
    """The panel-wide field from every tile's deposit, in the plan's tile order
    (:func:`optdot.stages.coarse_solve`)."""
    return stages.coarse_solve(stage_settings(job), list(parts))


def wide_deposit_task(job: Job, dots: TileDots) -> LatticePart | None:
    """A tile's dots after its first correction pass (:func:`correct_tile`) deposited on
    the wide pass's lattice (:func:`optdot.stages.wide_part`), for :func:`wide_task`."""
    s = stage_settings(job)
    return stages.wide_part(s, dots.xy, s.thrown_areas(dots.xy0))


def wide_task(job: Job, *parts: LatticePart) -> CoarseField | None:
    """The wide pass's field over the panel from every tile's :func:`wide_deposit_task`,
    in the plan's tile order (:func:`optdot.stages.wide_solve`)."""
    return stages.wide_solve(stage_settings(job), list(parts))


def containers(job: Job, plan: TilePlan, coarse: CoarseField | None, i: int, j: int) -> np.ndarray:
    """Tile ``(i, j)``'s containers as its relaxation made them (:func:`relax_tile`): its
    throw moved along the panel-wide field, thrown again (every step a pure function, so
    the same bytes), ``[n, 2]`` mm."""
    return stages.coarse_shift(stage_settings(job), coarse, initial_task(job, plan, i, j))


def first_positions(dots: TileDots) -> np.ndarray:
    """What a run short of memory holds of a tile's first correction pass across the wide
    pass's barrier (:func:`optdot.orchestration.tiling.run.slim_first_passes`): its positions, ``[n,
    2]`` mm (16 B a dot; the containers, 16 B more, are thrown again after the barrier,
    :func:`containers`: on the 55-inch TV the held first passes were 3.6 GB of a 6.75 GiB
    peak)."""
    return dots.xy


def wide_shift(
    job: Job, plan: TilePlan, coarse: CoarseField | None, i: int, j: int,
    first: TileDots | np.ndarray, *fields: CoarseField,
) -> TileDots:  # fmt: skip
    """Tile ``(i, j)``'s dots after its first correction pass (``first``: the pass, or its
    positions alone, :func:`first_positions`) moved along the panel's wide fields
    (:func:`wide_task`), one round after the other: the correction's last pass; with the
    tile's containers (the pass's, or thrown again: :func:`containers`, the panel-wide
    field ``coarse``)."""
    if isinstance(first, TileDots):
        xy0, xy = first.xy0, first.xy.copy()
    else:
        xy0, xy = containers(job, plan, coarse, i, j), first.copy()
    if len(xy):
        for f in fields:
            xy += f.displacement(xy)
    return TileDots((i, j), xy0, xy)


def wide_step(
    job: Job, plan: TilePlan, coarse: CoarseField | None, i: int, j: int,
    first: TileDots | np.ndarray, *fields: CoarseField,
) -> LatticePart | None:  # fmt: skip
    """A round of the wide pass after the first: a tile's first-pass dots moved along the
    rounds' fields before it (:func:`wide_shift`) and deposited for this round's field
    (:func:`wide_deposit_task`)."""
    return wide_deposit_task(job, wide_shift(job, plan, coarse, i, j, first, *fields))


def correct_tile(job: Job, plan: TilePlan, dots: TileDots, *around: TileDots) -> TileDots:
    """Phase 3: tile ``dots`` moved by the first pass of the long-wavelength correction,
    blended across its borders (see the module doc), with the phase-2 dots of the tiles
    ``around`` it."""
    n = len(dots.xy)
    if n == 0:
        return dots
    i, j = dots.tile
    tx, ty = plan.size
    m = plan.margin
    rect = plan.rect(i, j)
    region = (rect[0] - tx / 2 - m, rect[1] - ty / 2 - m,
              rect[2] + tx / 2 + m, rect[3] + ty / 2 + m)  # fmt: skip
    region = grown(region, stages.correction_pad(stage_settings(job)))
    near = [in_rect(a.xy, grown(region, plan.halo)) for a in around]
    xy0 = np.concatenate([dots.xy0] + [a.xy0[k] for a, k in zip(around, near, strict=True)])
    xy = np.concatenate([dots.xy] + [a.xy[k] for a, k in zip(around, near, strict=True)])
    got = stages.correction_region(stage_settings(job), xy0, xy, region)
    if got is None:
        return dots
    err, cap = got
    u = np.zeros((n, 2))
    total = np.zeros(n)
    for cy in (rect[1], 0.5 * (rect[1] + rect[3]), rect[3]):
        wy = np.maximum(0.0, 1.0 - 2.0 * np.abs(dots.xy[:, 1] - cy) / ty)
        for cx in (rect[0], 0.5 * (rect[0] + rect[2]), rect[2]):
            w = wy * np.maximum(0.0, 1.0 - 2.0 * np.abs(dots.xy[:, 0] - cx) / tx)
            own = np.flatnonzero(w > 0)
            if not len(own):
                continue
            window = (cx - tx / 2 - m, cy - ty / 2 - m, cx + tx / 2 + m, cy + ty / 2 + m)
            u[own] += w[own, None] * err.field(window, dots.xy[own], cap)
            total[own] += w[own]
    u /= np.maximum(total, 1e-300)[:, None]
    return TileDots(dots.tile, dots.xy0, np.ascontiguousarray(dots.xy + u))


def held_dots(job: Job, dots: TileDots | FinalDots) -> stages.Held:
    """A neighbour as the guarantee pass holds it: final when it is final, else its
    current positions at their rule sizes (shaped dots: turned by the job's field where
    they stand, as their final angles will be)."""
    if isinstance(dots, FinalDots):
        angle = None if dots.dots is None else dots.dots.angles
        return stages.Held(dots.xy, dots.diameter, angle)
    d = stage_settings(job).rule_diameters(dots.xy0)
    angle = None
    if not job.shape.kind.round:
        angle = turned(job.shape, job.orientation, dots.xy, dots.xy0).angles
    return stages.Held(dots.xy, job.diameter if d is None else d, angle)


def legalize_tile(
    job: Job, plan: TilePlan, dots: TileDots, neighbours: list[stages.Held]
) -> FinalDots:
    """:func:`optdot.stages.hard_core` then :func:`optdot.stages.finish` for one tile;
    ``neighbours``: the dots of the surrounding tiles
    (:func:`held_dots`; final for earlier colours), held still within
    :func:`~optdot.orchestration.job_settings.halo_width` of the tile's dots. The hard core
    runs here, not in
    the correction task, so that every pair across a border is cleared by the later tile
    against the earlier one's final dots, as the guarantee pass settles them.

    Raises:
        GuaranteeError: the tile could not be made legal.
    """
    n = len(dots.xy)
    if n == 0:
        none = None if job.shape.kind.round else job.shape.footprints(np.zeros(0))
        return FinalDots(dots.xy, job.diameter if job.sizes is None else np.zeros(0), none)
    width = stage_settings(job).halo
    window = grown(plan.rect(*dots.tile), width)
    held = stages.Held.near(neighbours, grown(bounds(dots.xy), width))
    xy = stages.hard_core(stage_settings(job), dots.xy0, dots.xy, held)
    done = stages.finish(stage_settings(job), xy, dots.xy0, _where(*dots.tile), held, window)
    return FinalDots(done.xy, done.diameter, done.dots)
