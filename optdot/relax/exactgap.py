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

import numpy as np

from .footprint_term import FootprintTerm, factors


class ExactGapTerm(FootprintTerm):
    """The exact-gap penalty of shaped dots at fixed angles over the pair list of
    :class:`~optdot.spatial.verlet.VerletList` (arguments:
    :class:`~.footprint_term.FootprintTerm`)."""

    def setup(self, shape, angle, scale, gap) -> float:
        self.dots = shape.footprints(angle, scale)
        return 2.0 * shape.extent * float(factors(len(angle), scale).max(initial=1.0)) + gap

    def __call__(self, xy: np.ndarray, grad: np.ndarray) -> float:
        """Add the term's gradient into ``grad`` (``[n, 2]``) at ``xy``; its value, mm²."""
        p = self.verlet.update(xy)
        rows = np.repeat(np.arange(len(p.ptr) - 1, dtype=np.int64), np.diff(p.ptr))
        listed = ~(p.skip[rows] | p.skip[p.nbr])
        i = np.concatenate([rows[listed], p.ei.astype(np.int64)])
        j = np.concatenate([p.nbr[listed].astype(np.int64), p.ej.astype(np.int64)])
        keep = self.active[i] & self.active[j]
        d = xy[j[keep]] - xy[i[keep]]
        near = np.einsum("ij,ij->i", d, d) < self.reach * self.reach
        i, j = i[keep][near], j[keep][near]
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
