"""The guarantee pass for shaped dots: exact edge gaps between oriented footprints.

Discs are legal when their centres keep one diameter + gap apart; shaped dots when their
footprints do, whatever their angles. The pass alternates two projections until neither
moves a dot:

1. the disc pass of :mod:`optdot.relax.legalize` with the footprint's bounding disc
   against the panel and zero cells (a footprint inside its bounding disc cannot
   protrude), and its inscribed disc + gap between centres (a necessary condition: two
   footprints nearer than that overlap at any angles);
2. every pair whose exact edge gap (:meth:`~optdot.geometry.shapes.Footprints.separation`)
   is under the gap is pushed apart along the direction that widens it fastest, each
   dot by :data:`PUSH` of the deficit plus a few nm (a dot held still leaves it to its
   partner), the angles of the dots that moved taken again from the orientation field
   where they now stand; only pairs with a dot that moved are measured again, and the
   pushes repeat until no pair is too close before the disc pass runs again.

Then the positions are rounded to 1 nm, the angles computed where they ended (and
rounded as files store them), and every pair checked again exactly.
"""

from __future__ import annotations

import numpy as np

from ..errors import GuaranteeError
from ..geometry.density import DensityMap
from ..geometry.domain import Domain
from ..geometry.orientation import Orientation, degrees
from ..geometry.shapes import DotShape, Footprints
from ..spatial.cellgrid import pairs_within
from .legalize import MARGIN, RESOLUTION, LegalizeResult, check_guarantee, legalize

#: Most alternations of the two projections.
MAX_ROUNDS = 3000
#: Each dot of a pair too close moves this share of the deficit (over-relaxed: chains of
#: pairs in dense regions settle in fewer rounds than with the exact half).
PUSH = 0.75
#: Extra reach of the pair list, as a share of the footprint's bounding radius.
SKIN = 0.25
#: A dot the disc pass sends back this many times (into the panel, or out of a zero
#: cell, against its pushes away from dots held still: wedged between a wall and held
#: dots, which alternate projections cannot leave) is moved to a place it fits instead
#: (:func:`_relocate`).
STUCK = 20
#: Where :func:`_relocate` looks: rings every quarter of the bounding radius, out to
#: this many bounding radii.
RELOCATE_REACH = 4.0


def turned(
    shape: DotShape,
    field: Orientation,
    xy: np.ndarray,
    thrown: np.ndarray,
    scale: np.ndarray | None = None,
) -> Footprints:
    """The footprints of dots at ``xy`` (``[n, 2]`` mm) thrown at ``thrown``, turned by
    ``field``, their angles rounded to 1e-6° (what every file holds); scaled by
    ``scale`` (``[n]``) when sizes vary."""
    return shape.footprints(np.radians(degrees(field.at(xy, thrown))), scale)


def shape_conflicts(
    xy: np.ndarray, dots: Footprints, gap: float, frozen: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Pairs whose exact edge gap is under ``gap`` (mm): ``(pairs [m, 2], gap [m], u [m,
    2])``, pairs of two frozen dots left out."""
    return _conflicts(xy, dots, gap, _pairs(xy, dots, gap, 0.0, frozen))


def _pairs(xy, dots: Footprints, gap: float, skin: float, frozen) -> np.ndarray:
    """``[m, 2]`` pairs whose bounding discs come within ``gap + skin`` (mm)."""
    pr = pairs_within(xy, 2.0 * float(dots.extent().max(initial=0.0)) + gap + skin)
    if frozen is not None and len(pr):
        pr = pr[~(frozen[pr[:, 0]] & frozen[pr[:, 1]])]
    return pr


def _conflicts(xy, dots: Footprints, gap: float, pr: np.ndarray):
    if not len(pr):
        return pr, np.zeros(0), np.zeros((0, 2))
    g, u = dots.separation(xy, pr[:, 0], pr[:, 1])
    bad = g < gap
    return pr[bad], g[bad], u[bad]


def _relocate(
    k: int,
    xy: np.ndarray,
    thrown: np.ndarray,
    sized: Footprints,
    angle: np.ndarray,
    still: np.ndarray,
    field: Orientation,
    gap: float,
    density: DensityMap,
    domain: Domain,
    extent: float,
) -> np.ndarray | None:
    """A place for dot ``k`` out of a wedge: among points on rings every quarter of its
    bounding radius ``extent`` (out to :data:`RELOCATE_REACH` of them), those in a lit
    cell with the bounding disc inside the panel and the footprint (turned by ``field``
    there) the gap and rounding margin clear of every dot held still, the one farthest
    by the exact gap from the dots that may move (the pushes then settle those; nearest
    first among equals). ``[2]`` mm (1 nm), or None when no point qualifies."""
    step = 0.25 * extent
    cand = [xy[k][None]]
    for m in range(1, int(RELOCATE_REACH / 0.25) + 1):
        t = np.linspace(0.0, 2.0 * np.pi, 8 * m, endpoint=False)
        cand.append(xy[k] + m * step * np.column_stack([np.cos(t), np.sin(t)]))
    cand = np.round(np.concatenate(cand) / RESOLUTION) * RESOLUTION
    cand = cand[(density.at(cand) > 0) & ~domain.protruding(cand, extent)]
    if not len(cand):
        return None
    reach = (RELOCATE_REACH + 1.0) * extent + 2.0 * float(sized.extent().max()) + gap
    others = np.flatnonzero(np.hypot(*(xy - xy[k]).T) < reach)
    others = others[others != k]
    if not len(others):
        return cand[0]
    turn = np.radians(degrees(field.at(cand, np.broadcast_to(thrown, cand.shape))))
    c, o = np.repeat(np.arange(len(cand)), len(others)), np.tile(others, len(cand))
    g, _ = sized.kind.separation(
        xy[o] - cand[c], sized.size[np.full(len(c), k)], turn[c], sized.size[o], angle[o]
    )
    g = g.reshape(len(cand), len(others))
    held = still[others]
    clear = np.all(g[:, held] >= gap + 2.0 * MARGIN, axis=1)
    if not clear.any():
        return None
    room = np.min(np.where(held[None], np.inf, g), axis=1, initial=np.inf)
    room[~clear] = -np.inf
    return cand[int(np.argmax(room))]


def make_legal_shapes(
    xy: np.ndarray,
    thrown: np.ndarray,
    density: DensityMap,
    home_cell: np.ndarray,
    domain: Domain,
    shape: DotShape,
    field: Orientation,
    gap: float,
    where: str,
    frozen: np.ndarray | None = None,
    fixed: np.ndarray | None = None,
    scale: np.ndarray | None = None,
) -> tuple[LegalizeResult, Footprints]:
    """Legal positions for shaped dots and their footprints where they end.

    Args:
        xy: ``[n, 2]`` relaxed positions, mm. thrown: ``[n, 2]`` where they were thrown.
        home_cell: ``[n]`` the map cell each returns to if it drifts into a zero cell.
        shape, field: the job's dot and orientation field. gap: smallest edge gap, mm.
        frozen: ``[n]`` bool, dots held still (a tile's halo).
        fixed: ``[frozen.sum()]`` the held dots' angles, rad, in order (a neighbour's
            final angles, or its field's where it stands); without, they are taken from
            ``field`` at their positions and ``thrown``.

    Raises:
        GuaranteeError: a violation is left after :data:`MAX_ROUNDS` rounds.
    """
    extent, core = shape.extent, 2.0 * shape.inner_radius + gap
    if scale is not None:  # per dot: the bounding disc and the inscribed disc + gap
        extent, core = shape.extent * scale, 2.0 * shape.inner_radius * scale + gap
    sized = shape.footprints(np.zeros(len(xy)), scale)  # the sizes, 1 nm, as written
    still = np.zeros(len(xy), bool) if frozen is None else frozen
    sweeps = pair_fixes = dot_fixes = 0
    skin = SKIN * float(np.max(extent, initial=0.0))
    pr_all, built = None, None
    moved = np.ones(len(xy), bool)
    angle = np.zeros(len(xy))
    turns = np.ones(len(xy), bool)  # whose angle the field gives
    if fixed is not None:  # held dots keep theirs (the disc pass may round their
        angle[still] = fixed  # positions to 1 nm: their pairs are measured again, but
        turns &= ~still  # they do not turn)
    walls = True  # the disc pass is due: at the start, and once the pairs are clean
    sent_back = np.zeros(len(xy), np.int64)
    for _ in range(MAX_ROUNDS):
        if walls:
            leg = legalize(xy, density, home_cell, domain, extent, core, frozen=frozen)
            sweeps, pair_fixes, dot_fixes = (
                sweeps + leg.sweeps,
                pair_fixes + leg.pair_fixes,
                dot_fixes + leg.dot_fixes,
            )
            moved |= np.any(leg.xy != xy, axis=1)
            sent_back += np.abs(leg.xy - xy).max(axis=1) > 2.0 * RESOLUTION
            xy = leg.xy
            for k in np.flatnonzero((sent_back >= STUCK) & ~still):
                ext = float(np.broadcast_to(extent, (len(xy),))[k])
                at = _relocate(
                    k, xy, thrown[k], sized, angle, still, field, gap, density, domain, ext
                )
                sent_back[k] = 0
                if at is not None:
                    xy = xy.copy()
                    xy[k], moved[k] = at, True
                    dot_fixes += 1
        if built is None or np.max(np.abs(xy - built)) > 0.5 * skin:
            pr_all, built = _pairs(xy, sized, gap, skin, frozen), xy
        # the field where the dots that moved now stand (the others' angles hold)
        turn = moved & turns
        angle[turn] = np.radians(degrees(field.at(xy[turn], thrown[turn])))
        dots = Footprints(shape.kind, sized.size, angle)
        near = pr_all[moved[pr_all[:, 0]] | moved[pr_all[:, 1]]]  # only pairs that changed
        pr, g, u = _conflicts(xy, dots, gap + MARGIN, near)
        if not len(pr):
            if walls:
                break  # the disc pass moved nothing into a conflict: done
            walls, moved = True, np.zeros(len(xy), bool)
            continue
        walls = False
        pair_fixes += len(pr)
        share = PUSH * (gap + 2.0 * MARGIN - g)
        i, j = pr[:, 0], pr[:, 1]
        wi = np.where(still[i], 0.0, np.where(still[j], 2.0, 1.0)) * share
        wj = np.where(still[j], 0.0, np.where(still[i], 2.0, 1.0)) * share
        step = np.zeros_like(xy)
        np.add.at(step, i, -wi[:, None] * u)
        np.add.at(step, j, wj[:, None] * u)
        new = np.round((xy + step) / RESOLUTION) * RESOLUTION
        moved = np.any(new != xy, axis=1)
        xy = new
    else:
        raise GuaranteeError(
            f"{where}: could not meet the guarantee for {shape.kind.name} dots after "
            f"{MAX_ROUNDS} rounds: {len(pr)} pairs closer than {gap * 1e3:g} µm edge to edge"
        )
    dots = turned(shape, field, xy, thrown, scale)  # every angle afresh for the final check
    if fixed is not None:
        dots.angle[still] = fixed
    viol = check_guarantee(xy, density, domain, extent, core, frozen)
    left, _, _ = shape_conflicts(xy, dots, gap, frozen)
    if not viol.ok or len(left):
        raise GuaranteeError(
            f"{where}: could not meet the guarantee for {shape.kind.name} dots: "
            + (viol.text(core) if not viol.ok else f"{len(left)} pairs under the gap")
        )
    return LegalizeResult(xy, sweeps, pair_fixes, dot_fixes), dots
