"""The exact-gap penalty for convex shaped dots: each pair of footprints closer than the
gap edge to edge adds ``w (gap - g_ij)²``, ``g_ij`` their exact edge gap
(:meth:`~optdot.geometry.shapes.Footprints.separation`), its gradient along the direction
that widens the gap fastest (Danskin: the gap's gradient in the centres' difference).

Issue 37 asked which relaxes shaped dots better, this or the paper's multi-sphere scheme
(:mod:`.multisphere`); measured with ``benchmarks/penalty_choice.py`` on the edge-lit map
(one process, the same weight, Verlet list and guarantee pass):

* ellipses 80 x 40 µm: 10⁵ dots 2.2 s against 3.1 s (60 evaluations against 84, 740
  pairs left to the guarantee pass against 838), 10⁶ dots 29.3 s against 33.5 s, the
  same close-pair share (0.092-0.094) and ψ6 (0.028-0.030): the exact gap of a smooth
  footprint is a smooth penalty, where the inscribed circles fall short at the flanks;
* prisms 120 x 30 µm: 9.8 s against 3.0 s, 2,544 pairs left against 57, close pairs
  0.39 against 0.31: a rectangle's gap turns its direction abruptly at the corners, and
  L-BFGS stalls on it; the covering circles are smooth.

So ellipses relax with this term and rounded rectangles with the multi-sphere one
(:data:`optdot.relax.optdot.FOOTPRINT_TERMS`), at the multi-sphere term's weight. The
angles are held during the relaxation, as there.
"""

from __future__ import annotations

import numba as nb
import numpy as np

from ..spatial.verlet import append_pair
from .footprint_term import FootprintTerm, factors


class ExactGapTerm(FootprintTerm):
    """The exact-gap penalty of shaped dots at fixed angles over the pair list of
    :class:`~optdot.spatial.verlet.VerletList` (arguments:
    :class:`~.footprint_term.FootprintTerm`)."""

    def setup(self, shape, angle, scale, gap) -> float:
        self.dots = shape.footprints(angle, scale)
        self.half = np.ascontiguousarray(0.5 * self.dots.size[:, :2])  # [n, 2] mm
        self.code = 1 if shape.kind.name == "ellipse" else 2
        self.cos, self.sin = np.cos(self.dots.angles), np.sin(self.dots.angles)
        return 2.0 * shape.extent * float(factors(len(angle), scale).max(initial=1.0)) + gap

    def __call__(self, xy: np.ndarray, grad: np.ndarray) -> float:
        """Add the term's gradient into ``grad`` (``[n, 2]``) at ``xy``; its value, mm²."""
        p = self.verlet.update(xy)
        i, j = _candidates(
            xy, p.ptr, p.nbr, p.skip, p.ei, p.ej, self.active, self.reach, self.gap,
            self.half[:, 0], self.half[:, 1], self.cos, self.sin, self.code,
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


@nb.njit(cache=True, inline="always")
def _h(c, s, a, b, cp, sp, code):  # pragma: no cover - compiled
    """Support of an ellipse (``code`` 1: half axes a, b), exact, or of a rounded
    rectangle's box (2: half sides a, b; at least the rounded one's, so the separation
    it gives still bounds the gap from below) turned by the angle of cosine ``cp`` and
    sine ``sp``, in the direction ``(c, s)``."""
    u, v = c * cp + s * sp, -c * sp + s * cp
    if code == 1:
        return np.sqrt(a * a * u * u + b * b * v * v)
    return a * abs(u) + b * abs(v)


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
                hi_ = _h(c, s, a[i], b[i], cp[i], sp[i], code)
                hj_ = _h(c, s, a[j], b[j], cp[j], sp[j], code)
                lower = dist - hi_ - hj_
                if lower >= gap:
                    continue
            oi, oj = append_pair(oi, oj, m, i, j)
            m += 1
    return oi[:m], oj[:m]
