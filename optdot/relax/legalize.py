"""The guarantee pass: after relaxation, no collision, no protrusion, no dot where rho = 0.

Every penalty of the paper is soft, so a converged layout can still hold a few pairs
closer than one diameter and dots poking out of the panel. This pass fixes them by
projection (Gauss-Seidel): clamp each dot into the panel (and back into its own start
cell if it drifted into a zero-density cell), then push every pair closer than the
minimum distance apart symmetrically to exactly that distance plus a few nm, and repeat
until a whole sweep changes nothing. Positions are then rounded to 1 nm (the resolution
of every output format) and checked again.
"""

from __future__ import annotations

from dataclasses import dataclass

import numba as nb
import numpy as np

from ..errors import GuaranteeError
from ..geometry.density import DensityMap
from ..geometry.domain import Domain, box_protruding
from ..geometry.edges import NO_EDGES, EdgeIndex, edge_args, edge_signed_distance
from ..spatial.cellgrid import neighbor_pairs, pairs_within

#: Output resolution, mm (1 nm): positions are rounded to this.
RESOLUTION = 1e-6
#: Margin kept beyond each limit so rounding to RESOLUTION cannot break it, mm.
MARGIN = 3e-6


@nb.njit(cache=True)
def _push_pairs(xy, ptr, nbr, half, slack, still):  # pragma: no cover - compiled
    moved = 0
    for i in range(xy.shape[0]):
        for k in range(ptr[i], ptr[i + 1]):
            j = nbr[k]
            target = half[i] + half[j]
            dx = xy[i, 0] - xy[j, 0]
            dy = xy[i, 1] - xy[j, 1]
            d2 = dx * dx + dy * dy
            if d2 >= target * target or (still[i] and still[j]):
                continue
            d = np.sqrt(d2)
            if d < 1e-12:
                dx, dy, d = (1.0, 0.0, 1.0) if i < j else (-1.0, 0.0, 1.0)
            p = 0.5 * (target + slack - d) / d
            # a dot held still (a tile's halo) leaves the whole push to its partner
            pi = 0.0 if still[i] else (2.0 * p if still[j] else p)
            pj = 0.0 if still[j] else (2.0 * p if still[i] else p)
            xy[i, 0] += pi * dx
            xy[i, 1] += pi * dy
            xy[j, 0] -= pj * dx
            xy[j, 1] -= pj * dy
            moved += 1
    return moved


@nb.njit(cache=True)
def _fix_dots(xy, box, grid, x0, y0, cw, ch, home, eps, needs, ed, still):  # pragma: no cover
    ny, nx = grid.shape
    fixed = 0
    for i in range(xy.shape[0]):
        if still[i]:
            continue
        need = needs[i]
        lo0, lo1 = box[0] + need + eps, box[1] + need + eps
        hi0, hi1 = box[2] - need - eps, box[3] - need - eps
        x = min(max(xy[i, 0], lo0), hi0)
        y = min(max(xy[i, 1], lo1), hi1)
        if ed[0].shape[0] > 0:
            # outline: move along the edge normal until ``need`` (+ eps) inside
            for _ in range(8):
                sd, ux, uy = edge_signed_distance(x, y, ed)
                if sd >= need + eps:
                    break
                step = need + 2.0 * eps - sd
                x += step * ux
                y += step * uy
        # the cell of the position as it will be written (rounded to 1 nm)
        xr = np.floor(x * 1e6 + 0.5) / 1e6
        yr = np.floor(y * 1e6 + 0.5) / 1e6
        ix = min(max(int(np.floor((xr - x0) / cw)), 0), nx - 1)
        iy = min(max(int(np.floor((yr - y0) / ch)), 0), ny - 1)
        if grid[iy, ix] <= 0.0:
            hy, hx = home[i] // nx, home[i] % nx
            x = min(max(x, x0 + hx * cw + eps), x0 + (hx + 1) * cw - eps)
            y = min(max(y, y0 + hy * ch + eps), y0 + (hy + 1) * ch - eps)
            x = min(max(x, lo0), hi0)
            y = min(max(y, lo1), hi1)
        if x != xy[i, 0] or y != xy[i, 1]:
            xy[i, 0] = x
            xy[i, 1] = y
            fixed += 1
    return fixed


@dataclass
class LegalizeResult:
    """Outcome of :func:`legalize`: positions ``[n, 2]`` mm, sweeps run, dots moved."""

    xy: np.ndarray
    sweeps: int
    pair_fixes: int
    dot_fixes: int


def legalize(
    xy: np.ndarray,
    density: DensityMap,
    home_cell: np.ndarray,
    domain: Domain,
    dot_radius: float | np.ndarray,
    dmin: float | np.ndarray,
    max_sweeps: int = 1000,
    frozen: np.ndarray | None = None,
) -> LegalizeResult:
    """Project ``xy`` onto the feasible set and round it to :data:`RESOLUTION`.

    Args:
        xy: ``[n, 2]`` positions, mm (copied).
        density: the map; dots may not sit in its zero cells.
        home_cell: ``[n]`` flat index of each dot's start cell (a non-zero cell).
        domain: the panel; centres keep ``r0 + edge_margin`` from its edges.
        dot_radius: r0, mm, or ``[n]`` per dot.
        dmin: minimum centre distance, mm; or ``[n]`` per dot (its diameter + gap),
            a pair then keeping the mean of its two.
        max_sweeps: give up (the caller raises) after this many sweeps.
        frozen: ``[n]`` bool, dots that stay where they are (a tile's halo: a pair with
            one of them is fixed by moving the other the whole way).

    Returns:
        :class:`LegalizeResult`; ``sweeps == max_sweeps`` means it did not settle.
    """
    xy = np.array(xy, dtype=np.float64, order="C")
    n = len(xy)
    box = np.asarray(domain.box, dtype=np.float64)
    need = np.ascontiguousarray(np.broadcast_to(dot_radius + domain.edge_margin, (n,)))
    reach = float(need.max(initial=0.0)) + 4 * MARGIN
    ed = NO_EDGES if domain.rectangle else edge_args(EdgeIndex.build(domain, reach))
    cw, ch = density.cell_size
    half = 0.5 * (dmin + MARGIN)  # a pair keeps half_i + half_j
    half_n = np.ascontiguousarray(np.broadcast_to(half, (n,)))
    pair_fixes = dot_fixes = 0
    home = np.asarray(home_cell, dtype=np.int64)
    still = np.zeros(len(xy), np.uint8) if frozen is None else frozen.astype(np.uint8)
    sweeps = 0
    while sweeps < max_sweeps:
        sweeps += 1
        fixed = _fix_dots(
            xy, box, density.grid, density.x0, density.y0, cw, ch, home, MARGIN, need, ed, still
        )
        ptr, nbr = neighbor_pairs(xy, half, 0.02)
        moved = _push_pairs(xy, ptr, nbr, half_n, 0.5 * MARGIN, still)
        pair_fixes += moved
        dot_fixes += fixed
        if moved == 0 and fixed == 0:
            break
    xy = np.round(xy, 6)  # = nearest double to the 1 nm decimal, as the CSV parses back
    return LegalizeResult(xy=xy, sweeps=sweeps, pair_fixes=pair_fixes, dot_fixes=dot_fixes)


@dataclass(frozen=True)
class Violations:
    """Counts of guarantee violations: pairs closer than dmin, dots out of the panel,
    dots in zero-density cells."""

    collisions: int
    protruding: int
    in_empty: int

    @property
    def ok(self) -> bool:
        return self.collisions == 0 and self.protruding == 0 and self.in_empty == 0

    def text(self, dmin: float | np.ndarray) -> str:
        """The counts in words (``dmin`` as in :func:`check_guarantee`)."""
        if np.ndim(dmin) == 0:
            closer = f"closer than {float(dmin) * 1e3:.1f} um"
        else:
            closer = "closer than their radii + gap"
        return (
            f"{self.collisions} pairs {closer}, {self.protruding} dots protruding, "
            f"{self.in_empty} dots in zero-density cells"
        )


def check_guarantee(
    xy: np.ndarray,
    density: DensityMap,
    domain: Domain,
    dot_radius: float | np.ndarray,
    dmin: float | np.ndarray,
    frozen: np.ndarray | None = None,
) -> Violations:
    """Count violations of the final positions (``dot_radius``, ``dmin`` and ``frozen``
    as in :func:`legalize`: pairs of two frozen dots, and frozen dots themselves, are
    someone else's to check).

    Pairs come from the cell-grid search (property-tested against brute force); the
    independent cross-check is QA's shapely/GEOS count, which ``optdot export`` and
    ``optdot qa`` run on every pattern before it reaches a mask.
    """
    if np.ndim(dmin) == 0:
        pr = pairs_within(xy, float(dmin))
    else:
        pr = pairs_within(xy, float(np.max(dmin, initial=0.0)))
        dist = np.hypot(*(xy[pr[:, 0]] - xy[pr[:, 1]]).T)
        pr = pr[dist < 0.5 * (dmin[pr[:, 0]] + dmin[pr[:, 1]])]
    own = slice(None)
    if frozen is not None:
        pr = pr[~(frozen[pr[:, 0]] & frozen[pr[:, 1]])]
        own = ~frozen
    radius = dot_radius if np.ndim(dot_radius) == 0 else dot_radius[own]
    mine = xy[own]
    if domain.rectangle:
        out = box_protruding(mine, domain.box, radius + domain.edge_margin)
    else:
        out = domain.protruding(mine, radius)
    empty = density.empty_mask(mine)
    return Violations(len(pr), int(out.sum()), int(empty.sum()))


def make_legal(
    xy: np.ndarray,
    density: DensityMap,
    home_cell: np.ndarray,
    domain: Domain,
    dot_radius: float | np.ndarray,
    dmin: float | np.ndarray,
    where: str,
    frozen: np.ndarray | None = None,
) -> LegalizeResult:
    """:func:`legalize`, then :func:`check_guarantee` of its result (arguments as there).

    Raises:
        GuaranteeError: a violation is left; the message starts with ``where`` (the job,
            or a tile of it).
    """
    leg = legalize(xy, density, home_cell, domain, dot_radius, dmin, frozen=frozen)
    viol = check_guarantee(leg.xy, density, domain, dot_radius, dmin, frozen)
    if not viol.ok:
        raise GuaranteeError(
            f"{where}: could not meet the guarantee after {leg.sweeps} sweeps: {viol.text(dmin)}"
        )
    return leg
