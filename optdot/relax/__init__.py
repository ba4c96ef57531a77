"""Stage 2, relaxation: circles and containers (§3.3, §3), penalty terms (3), L-BFGS,
formulations, the MD baseline (§2.2) and the guarantee pass."""

from .optdot import VerletPenalty, relax
from .result import RelaxResult

__all__ = ["RelaxResult", "VerletPenalty", "relax"]
