"""The multi-sphere penalty for shaped dots (Imamichi and Nagamochi 2007, the scheme the
paper names for non-circular scatterers): each footprint as a row of circles along its
long axis (:meth:`~optdot.geometry.kinds.base.Kind.spheres`: an ellipse's inscribed, a
rounded rectangle's covering, which leave the guarantee pass far fewer pairs), and penalty
(3) on the circles of different dots. A pair of circles ``(m, n)`` of dots ``(i, j)``
adds ``w max(r_m + r_n + gap - |c_im - c_jn|, 0)²``; the angles are held for the
relaxation (the dots move by a fraction of a spacing, and the orientation fields change
over millimetres). The penalty is an approximation: the exact guarantee pass
(:mod:`optdot.relax.shaped`) fixes the pairs it leaves too close.
"""

from __future__ import annotations

import numba as nb
import numpy as np

from .footprint_term import FootprintTerm, factors

#: Weight ``w`` of the term (the spacing circles' overlap has 1, the hard core 15).
#: Measured on 10⁵ dots of the edge-lit map (benchmarks/shapes.py): 15 took ellipses
#: 118 iterations, 3.3 s of relaxation; 5 took 84, 2.4 s; 1 took 57, 1.6 s but left
#: prisms 427 pairs for the guarantee pass (5: 57) and 0.33 of them in close pairs (5:
#: 0.31, 15: 0.28). Uniform fills of 0.5 (prisms) and 0.54 (ellipses) hold at each.
MULTISPHERE_WEIGHT = 5.0


class MultiSphereTerm(FootprintTerm):
    """The multi-sphere penalty of shaped dots at fixed angles, over the pair list of
    :class:`~optdot.spatial.verlet.VerletList` (rebuilt only when many dots have moved
    far; the few that have are searched afresh at each evaluation); arguments:
    :class:`~.footprint_term.FootprintTerm`, each dot's circles scaled with it."""

    def setup(self, shape, angle, scale, gap) -> float:
        t, radius = shape.kind.spheres(np.asarray(shape.size, np.float64))
        f = factors(len(angle), scale)
        c, s = np.cos(angle) * f, np.sin(angle) * f
        self.offset = np.stack([c[:, None] * t, s[:, None] * t], axis=2)  # [n, k, 2]
        self.radius = np.ascontiguousarray(f[:, None] * radius)  # [n, k]
        top = float(f.max(initial=1.0))
        return 2.0 * float(np.abs(t).max() + radius.max()) * top + gap

    def __call__(self, xy: np.ndarray, grad: np.ndarray) -> float:
        """Add the term's gradient into ``grad`` (``[n, 2]``) at ``xy``; its value, mm²."""
        if int(self.active.sum()) < 2:
            return 0.0
        p = self.verlet.update(xy)
        args = (self.offset, self.radius, self.gap, self.weight, self.reach, self.active, grad)
        return _penalty(xy, p.ptr, p.nbr, p.skip, p.ei, p.ej, *args)


@nb.njit(cache=True, inline="always")
def _pair(xy, i, j, off, rad, gap, w, reach, active, grad):  # pragma: no cover - compiled
    if not (active[i] and active[j]):
        return 0.0
    ex, ey = xy[i, 0] - xy[j, 0], xy[i, 1] - xy[j, 1]
    if ex * ex + ey * ey >= reach * reach:
        return 0.0
    e = 0.0
    k = rad.shape[1]
    far = 0.5 * reach  # the reach of j's circles from its centre, plus half the gap
    for a in range(k):
        xa, ya = xy[i, 0] + off[i, a, 0], xy[i, 1] + off[i, a, 1]
        fx, fy = xa - xy[j, 0], ya - xy[j, 1]
        lim = rad[i, a] + far + 0.5 * gap
        if fx * fx + fy * fy >= lim * lim:  # circle a meets none of j's
            continue
        for b in range(k):
            dx = xa - xy[j, 0] - off[j, b, 0]
            dy = ya - xy[j, 1] - off[j, b, 1]
            t = rad[i, a] + rad[j, b] + gap
            d2 = dx * dx + dy * dy
            if d2 >= t * t:
                continue
            d = np.sqrt(d2)
            pen = t - d
            e += w * pen * pen
            if d > 1e-15:
                g = -2.0 * w * pen / d
                grad[i, 0] += g * dx
                grad[i, 1] += g * dy
                grad[j, 0] -= g * dx
                grad[j, 1] -= g * dy
    return e


@nb.njit(cache=True)
def _penalty(xy, ptr, nbr, skip, ei, ej, off, rad, gap, w, reach, active, grad):  # pragma: no cover
    """The term over a :class:`~optdot.spatial.blocks.PairList`: the listed pairs of dots
    not marked ``skip``, then the extra pairs (those of the skipped dots)."""
    e = 0.0
    for i in range(xy.shape[0]):
        if skip[i]:
            continue
        for k in range(ptr[i], ptr[i + 1]):
            j = nbr[k]
            if not skip[j]:
                e += _pair(xy, i, j, off, rad, gap, w, reach, active, grad)
    for p in range(ei.shape[0]):
        e += _pair(xy, ei[p], ej[p], off, rad, gap, w, reach, active, grad)
    return e
