"""The baseline: molecular-dynamics redistribution of Idé et al. (2003), paper §2.2.

The paper gives the pair force (1) and the difference equation (2) tersely; this is our
reading, stated so that it can be argued with:

* **Force (1).** ``f_ij = u_ij * g(d_ij)`` with ``u_ij = (x_i - x_j) / d_ij`` (repulsive),
  ``g(d) = 1`` for ``d < b_ij`` (the constant-magnitude core) and
  ``g(d) = exp(-(d - b_ij) / L)`` for ``d >= b_ij`` (the exponential tail), and no force
  beyond a cut-off ``D_ij``. The paper writes the case split as "b_ij < D"; read
  literally both sides are parameters, which cannot be meant. We read ``b_ij`` as the
  collision distance of the pair (the dot diameter plus the job's gap: a pair in the core
  collides and gets the largest force) and ``D`` as the interaction cut-off, which the
  paper says grows as 1/sqrt(rho): "D and the square root of the density are inversely
  proportional".
* **Length scales.** ``L_ij = decay * (a_i + a_j) / 2`` where ``a_i = 2 r'_i`` is the
  centre distance of a hexagonal packing at dot i's fill fraction (eq. 4), taken at the
  dot's start position (the rho OptDot's circles use); ``D_ij = b_ij + cutoff * L_ij``.
  With the defaults (decay 0.25, cutoff 3) the tail is cut at 5 % of the core force, at
  ~1.3 hexagonal spacings, and D grows as 1/sqrt(rho). (We first tried b_ij = the
  hexagonal spacing itself: then almost every pair sits in the constant core, the unit
  forces balance regardless of distance and collisions never resolve; 30,666 of the
  initial 50,016 collisions were left on "tsuno" after 200 steps.)
* **Motion (2).** Overdamped (m = 0) explicit Euler: ``x_i += (dt / c) * sum_j f_ij``.
  The forces are dimensionless, so ``dt / c`` is a length: ``step * b`` (a fraction of
  the collision distance): a colliding pair separates by ``2 * step * b`` per step, and a
  dot boxed in by k colliding neighbours moves at most ``k * step * b``, so the step is
  stable. One global step, as in the paper.
* **Boundaries.** No containers (the point of the paper's Figure 4) and no knowledge of
  zero-density cells: only the panel is enforced, by clamping each centre to
  ``[r0, W - r0] x [r0, H - r0]`` after every step, so no dot leaves the panel.

Pairs come from the same :class:`~optdot.spatial.verlet.VerletList` OptDot uses, with the
per-dot interaction radius ``R_i = b / 2 + cutoff * decay * a_i / 2`` so that
``R_i + R_j = D_ij``.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numba as nb
import numpy as np

from ..spatial.blocks import BLOCK, PairList
from ..spatial.verlet import VerletList
from .result import RelaxResult


@nb.njit(cache=True, inline="always")
def _pair_force(xy, a, i, j, b, decay, cutoff, force):  # pragma: no cover - compiled
    """Add f_ij to dot i and -f_ij to dot j (nothing beyond the cut-off D_ij)."""
    dx = xy[i, 0] - xy[j, 0]
    dy = xy[i, 1] - xy[j, 1]
    d2 = dx * dx + dy * dy
    L = decay * 0.5 * (a[i] + a[j])
    D = b + cutoff * L
    if d2 >= D * D:
        return
    d = np.sqrt(d2)
    g = 1.0 if d < b else np.exp(-(d - b) / L)
    if d < 1e-12:
        # coincident centres: push apart along x, deterministically by index
        dx = 1.0 if i < j else -1.0
        dy = 0.0
        d = 1.0
    fx = g * dx / d
    fy = g * dy / d
    force[i, 0] += fx
    force[i, 1] += fy
    force[j, 0] -= fx
    force[j, 1] -= fy


@nb.njit(parallel=True, cache=True)
def _md_forces(
    xy, a, b, decay, cutoff, ptr, mid, nbr, skip, cross, ei, ej, force
):  # pragma: no cover - compiled
    """Net force on every dot: blocks in parallel, then cross-block and extra pairs."""
    n = xy.shape[0]
    nblock = (n + BLOCK - 1) // BLOCK
    for blk in nb.prange(nblock):
        lo = blk * BLOCK
        hi = min(lo + BLOCK, n)
        for i in range(lo, hi):
            force[i, 0] = 0.0
            force[i, 1] = 0.0
        for i in range(lo, hi):
            if skip[i]:
                continue
            for k in range(ptr[i], mid[i]):
                j = nbr[k]
                if not skip[j]:
                    _pair_force(xy, a, i, j, b, decay, cutoff, force)
    for q in range(cross.shape[0]):
        i = cross[q]
        if skip[i]:
            continue
        for k in range(mid[i], ptr[i + 1]):
            j = nbr[k]
            if not skip[j]:
                _pair_force(xy, a, i, j, b, decay, cutoff, force)
    for k in range(ei.shape[0]):
        _pair_force(xy, a, ei[k], ej[k], b, decay, cutoff, force)


@nb.njit(parallel=True, cache=True)
def _md_step(xy, force, eta, lo_x, lo_y, hi_x, hi_y):  # pragma: no cover - compiled
    """Euler step (2) then clamp to the panel; returns the largest force magnitude."""
    n = xy.shape[0]
    nblock = (n + BLOCK - 1) // BLOCK
    part = np.zeros(nblock)
    for b in nb.prange(nblock):
        m = 0.0
        for i in range(b * BLOCK, min((b + 1) * BLOCK, n)):
            fx = force[i, 0]
            fy = force[i, 1]
            m = max(m, fx * fx + fy * fy)
            xy[i, 0] = min(max(xy[i, 0] + eta * fx, lo_x), hi_x)
            xy[i, 1] = min(max(xy[i, 1] + eta * fy, lo_y), hi_y)
        part[b] = m
    return np.sqrt(part.max()) if nblock else 0.0


@dataclass(frozen=True)
class MDForce:
    """Parameters of force (1).

    Attributes:
        core: b, the collision distance (dot diameter + gap), mm.
        spacing: ``[n]`` hexagonal spacing a_i at each dot's start density, mm.
        decay: L_ij / ((a_i + a_j) / 2).
        cutoff: (D_ij - b) / L_ij.
    """

    core: float
    spacing: np.ndarray
    decay: float = 0.25
    cutoff: float = 3.0

    def interaction_radius(self) -> np.ndarray:
        """Per-dot radius R_i with ``R_i + R_j = D_ij``, mm, ``[n]``."""
        return 0.5 * self.core + 0.5 * self.cutoff * self.decay * np.asarray(self.spacing)


def md_forces(xy: np.ndarray, law: MDForce, pairs: PairList) -> np.ndarray:
    """Net force (1) on each dot, ``[n, 2]`` (dimensionless), over a prepared pair list.

    Args:
        xy: ``[n, 2]`` positions, mm.
        law: the force's parameters.
        pairs: holds every pair closer than D_ij, once.
    """
    force = np.empty_like(xy)
    _md_forces(
        xy,
        np.ascontiguousarray(law.spacing, dtype=np.float64),
        law.core,
        law.decay,
        law.cutoff,
        pairs.ptr,
        pairs.mid,
        pairs.nbr,
        pairs.skip,
        pairs.cross,
        pairs.ei,
        pairs.ej,
        force,
    )
    return force


def md_relax(
    xy0: np.ndarray,
    law: MDForce,
    box: tuple[float, float, float, float],
    dot_radius: float,
    steps: int = 200,
    step: float = 0.02,
    skin: float = 0.3,
    callback: Callable[[int, float], None] | None = None,
) -> RelaxResult:
    """Run ``steps`` steps of the difference equation (2) from ``xy0``.

    Args:
        xy0: ``[n, 2]`` start positions, mm (not modified).
        law: force (1).
        box: panel ``(xmin, ymin, xmax, ymax)``, mm.
        dot_radius: r0, mm; centres are clamped to the panel shrunk by r0.
        steps: number of steps (the paper: 200, as for OptDot).
        step: dt / c as a fraction of the collision distance ``law.core``.
        skin: relative skin of the Verlet list.
        callback: ``callback(step, max_force)`` after every step.
    """
    xy = np.array(xy0, dtype=np.float64, order="C")
    eta = step * law.core
    verlet = VerletList(law.interaction_radius(), skin)
    lo_x, lo_y = box[0] + dot_radius, box[1] + dot_radius
    hi_x, hi_y = box[2] - dot_radius, box[3] - dot_radius
    history: list[float] = []
    for t in range(1, steps + 1 if len(xy) else 1):
        force = md_forces(xy, law, verlet.update(xy))
        history.append(float(_md_step(xy, force, eta, lo_x, lo_y, hi_x, hi_y)))
        if callback is not None:
            callback(t, history[-1])
    steps = len(history)
    return RelaxResult(
        xy=xy,
        penalty=history[-1] if history else 0.0,
        nit=steps,
        nfev=steps,
        rebuilds=verlet.rebuilds,
        message=f"ran {steps} MD steps",
        history=history,
        extra={"md_step_mm": eta},
    )
