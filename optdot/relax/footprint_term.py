"""What the penalty terms of shaped dots share (:mod:`.multisphere`, :mod:`.exactgap`):
their arguments, the dots that have a footprint, and a Verlet pair list as wide as two
of the largest footprints plus the gap."""

from __future__ import annotations

import numpy as np

from ..geometry.shapes import DotShape
from ..spatial.verlet import VerletList

#: Relative skin of the pair list (:class:`~optdot.spatial.verlet.VerletList`).
SKIN = 0.3


class FootprintTerm:
    """A penalty of shaped dots at fixed angles over a Verlet pair list; a subclass sets
    up its geometry (:meth:`setup`) and evaluates itself (``term(xy, grad) -> value``,
    adding its gradient into ``grad``).

    Args:
        shape: the dots' footprint. angle: ``[n]`` their angles, rad.
        active: ``[n]`` bool, the dots that have a footprint (not phantoms).
        gap: smallest edge gap the term keeps, mm. weight: its weight ``w``.
        skin: relative skin of the list.
        scale: ``[n]`` each dot's footprint scaled by this, or None: all of ``shape``'s
            size.
    """

    def __init__(
        self,
        shape: DotShape,
        angle: np.ndarray,
        active: np.ndarray,
        gap: float,
        weight: float,
        skin: float = SKIN,
        scale: np.ndarray | None = None,
    ) -> None:
        angle = np.asarray(angle, np.float64)
        self.active = np.ascontiguousarray(active, dtype=np.bool_)
        self.gap, self.weight = gap, weight
        self.reach = self.setup(shape, angle, scale, gap)
        self.verlet = VerletList(np.full(len(angle), 0.5 * self.reach), skin)

    def setup(
        self, shape: DotShape, angle: np.ndarray, scale: np.ndarray | None, gap: float
    ) -> float:
        """Prepare the dots' geometry; returns how far two centres interact, mm."""
        raise NotImplementedError

    def __call__(self, xy: np.ndarray, grad: np.ndarray) -> float:
        raise NotImplementedError


def factors(n: int, scale: np.ndarray | None) -> np.ndarray:
    """``[n]`` each dot's scale (ones without ``scale``)."""
    return np.ones(n) if scale is None else np.asarray(scale, np.float64)
