"""One result for every relaxation: OptDot's L-BFGS stages and the MD baseline alike."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .lbfgs import MAX_ITER


@dataclass
class RelaxResult:
    """Outcome of a relaxation (:func:`optdot.relax.optdot.relax`,
    :func:`~optdot.relax.optdot.relax_staged`, :func:`optdot.relax.md.md_relax`), in
    scipy's spirit: the solution, the final value, counts, a status code and why.

    Attributes:
        xy: ``[n, 2]`` relaxed positions, mm.
        penalty: final penalty, mm² (OptDot); the largest force of the last step (MD).
        nit, nfev: iterations (MD: steps) and evaluations.
        rebuilds: neighbour-list builds.
        message: why it stopped.
        history: penalty (OptDot) or largest force (MD) after each iteration.
        status: :data:`optdot.relax.lbfgs.CONVERGED`, ``MAX_ITER``, ... (MD: ``MAX_ITER``).
        extra: method-specific facts for the run's metadata (MD: ``md_step_mm``).
    """

    xy: np.ndarray
    penalty: float
    nit: int
    nfev: int
    rebuilds: int
    message: str
    history: list[float]
    status: int = MAX_ITER
    extra: dict[str, Any] = field(default_factory=dict)

    def run_info(self) -> dict[str, Any]:
        """What a pattern's metadata records of the run (iterations, evaluations,
        neighbour builds, the final penalty or the MD step, the message)."""
        info: dict[str, Any] = {
            "iterations": self.nit,
            "evaluations": self.nfev,
            "neighbor_builds": self.rebuilds,
        }
        info.update(self.extra or {"penalty": float(self.penalty)})
        info["message"] = self.message
        return info
