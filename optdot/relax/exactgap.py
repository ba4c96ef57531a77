"""The exact-gap penalty for convex shaped dots: each pair of footprints closer than the
gap edge to edge adds ``w (gap - g_ij)²``, ``g_ij`` their exact edge gap
(:meth:`~optdot.geometry.shapes.Footprints.separation`), its gradient along the direction
that widens the gap fastest (Danskin: the gap's gradient in the centres' difference).

A smooth footprint's exact gap is a smooth penalty, where the multi-sphere scheme's
inscribed circles fall short at the flanks; a footprint with corners turns the gap's
direction abruptly there and L-BFGS stalls on it, so such kinds relax with covering
circles (:mod:`.multisphere`; each kind names its term,
:attr:`~optdot.geometry.kinds.base.Kind.relaxation`; ``benchmarks/penalty_choice.py``
measures both on each kind). The angles are held during the relaxation.
"""

from __future__ import annotations

import numba as nb
import numpy as np

from ..geometry.kinds import support_bound
from ..spatial.verlet import append_pair
from .footprint_term import FootprintTerm, factors


class ExactGapTerm(FootprintTerm):
    """The exact-gap penalty of shaped dots at fixed angles over the pair list of
    :class:`~optdot.spatial.verlet.VerletList` (arguments:
    :class:`~.footprint_term.FootprintTerm`)."""

    def setup(self, shape, angle, scale, gap) -> float:
        self.dots = shape.footprints(angle, scale)
        self.bound = np.ascontiguousarray(shape.kind.bound_params(self.dots.size))  # [n, 2]
        self.code = shape.kind.code
        self.cos, self.sin = np.cos(self.dots.angles), np.sin(self.dots.angles)
        return 2.0 * shape.extent * float(factors(len(angle), scale).max(initial=1.0)) + gap

    def __call__(self, xy: np.ndarray, grad: np.ndarray) -> float:
        """Add the term's gradient into ``grad`` (``[n, 2]``) at ``xy``; its value, mm²."""
        p = self.verlet.update(xy)
        i, j = _candidates(
            xy, p.ptr, p.nbr, p.skip, p.ei, p.ej, self.active, self.reach, self.gap,
            self.bound[:, 0], self.bound[:, 1], self.cos, self.sin, self.code,
        )  # fmt: skip
        if not len(i):
            return 0.0
        g, u = self.dots.separation(xy, i, j)
        pen = self.gap - g
        hit = pen > 0
        pen, u, i, j = pen[hit], u[hit], i[hit], j[hit]
        push = (2.0 * self.weight * pen)[:, None] * u
        np.add.at(grad, i, push)
        np.add.at(grad, j, -push)
        return float(self.weight * np.dot(pen, pen))


@nb.njit(cache=True)
def _candidates(
    xy, ptr, nbr, skip, ei, ej, active, reach, gap, a, b, cp, sp, code
):  # pragma: no cover
    """``(i [m], j [m])``: the pairs of the list (its rows, then its extra pairs) of two
    active dots within ``reach`` whose separation along their centres' direction, a lower
    bound of the gap, is under ``gap``: the only ones the exact search must measure."""
    n = xy.shape[0]
    oi = np.empty(1024, np.int64)
    oj = np.empty(1024, np.int64)
    m = 0
    for r in range(n + ei.shape[0]):  # the rows, then each extra pair as a row of one
        if r < n:
            lo, hi = ptr[r], ptr[r + 1]
        else:
            lo, hi = 0, 1
        for q in range(lo, hi):
            if r < n:
                i, j = r, nbr[q]
                if skip[i] or skip[j]:
                    continue
            else:
                i, j = ei[r - n], ej[r - n]
            if not (active[i] and active[j]):
                continue
            dx, dy = xy[j, 0] - xy[i, 0], xy[j, 1] - xy[i, 1]
            dist = np.sqrt(dx * dx + dy * dy)
            if dist >= reach:
                continue
            if dist > 0.0:
                c, s = dx / dist, dy / dist
                hi_ = support_bound(code, c, s, a[i], b[i], cp[i], sp[i])
                hj_ = support_bound(code, c, s, a[j], b[j], cp[j], sp[j])
                lower = dist - hi_ - hj_
                if lower >= gap:
                    continue
            oi, oj = append_pair(oi, oj, m, i, j)
            m += 1
    return oi[:m], oj[:m]
