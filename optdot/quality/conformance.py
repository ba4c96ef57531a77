"""Whether a file's dots are the job's: the footprints QA holds a pattern or mask to.

A mask whose dots are not the ones the job asks for must not pass the gate, however well
spaced they are: circles under an ellipse job, a 60 µm dot among 46 µm ones, prisms with
15 µm corners where the job asks for 5 µm. :class:`DotRule` is the job's dot as a value
(its kind, its size, and the size rule when sizes vary); :meth:`DotRule.stray` tells, dot by
dot, which footprints the job could not have drawn:

- another kind than the job's: every dot, unless both draw the same disc (a capsule as
  long as it is wide, which a mask reader recognises as a circle);
- one size: any size parameter off the job's by more than :data:`TOLERANCE`;
- sizes that vary (``[dots] diameter = [lo, hi]``): a dot's area-equivalent diameter
  must be one of the rule's (in the range, on its step: :meth:`DotSizes.quantise`) and
  one the rule gives the place it stands (:class:`SizeBand`: its neighbourhood's cell
  diameters, widened by the size fit's freedom), and a shaped dot's every parameter the
  job's footprint scaled to that diameter (so a corner radius or an aspect of its own is
  caught too).

Angles are held to the job's orientation field by the gate's own line (where the field is
a function of position; random angles have nothing to hold them to).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..geometry.shapes import DotShape, Footprints, Kind
from ..geometry.sizes import DotSizes

#: How far a footprint's size parameter may be off the job's, mm (0.1 µm): masks read
#: back recover sizes to 1–2 nm (vertices on a 1 nm grid), and the size rule's steps are
#: 0.5 µm by default, so a size off its step is caught.
TOLERANCE = 1e-4


@dataclass(frozen=True, eq=False)
class SizeBand:
    """The area-equivalent diameters a job of varying sizes gives a dot where it stands:
    the size rule's diameters of the cells around it, widened by the freedom of the size
    fit (:mod:`optdot.relax.resize`), per map cell.

    Attributes:
        low, high: ``[ny, nx]`` the band's ends in each cell, mm.
        box: ``(x0, y0, x1, y1)`` the cells cover, mm.
    """

    low: np.ndarray
    high: np.ndarray
    box: tuple[float, float, float, float]

    def at(self, xy: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``([n], [n])`` the band's ends at the points ``xy`` (``[n, 2]`` mm; outside the
        box, the nearest cell's), mm."""
        ny, nx = self.low.shape
        x0, y0, x1, y1 = self.box
        ix = np.clip(np.floor((xy[:, 0] - x0) / (x1 - x0) * nx).astype(np.int64), 0, nx - 1)
        iy = np.clip(np.floor((xy[:, 1] - y0) / (y1 - y0) * ny).astype(np.int64), 0, ny - 1)
        return self.low[iy, ix], self.high[iy, ix]


@dataclass(frozen=True)
class DotRule:
    """The footprints a job draws.

    Attributes:
        shape: the job's dot at its nominal size (a circle job: a circle of its diameter;
            with ``sizes``, the shaped dot whose area-equivalent diameter is scaled).
        sizes: how diameters vary, or None for one size.
        band: with ``sizes``, the diameters the rule gives each place (a dot of the
            range's smallest size where the rule asks for its largest is not the job's),
            or None (any diameter of the range anywhere).
        tolerance: how far a size parameter may be off the job's, mm (:data:`TOLERANCE`;
            more for a mask on a process's address grid, whose vertices the grid moved).
    """

    shape: DotShape
    sizes: DotSizes | None = None
    band: SizeBand | None = None
    tolerance: float = TOLERANCE

    def angle_slack_deg(self) -> float:
        """How far, degrees, a footprint's angle read off a mask on a process's grid may
        be off: its size's slack over the footprint's length less its width (the
        difference of axes the angle is read from); 0 on the files' own 1 nm grid, and
        for round footprints."""
        extra = self.tolerance - TOLERANCE
        lever = self.shape.kind.angle_lever(np.asarray(self.shape.size, np.float64))
        if extra <= 0 or self.shape.kind.round or lever <= 0:
            return 0.0
        return math.degrees(math.atan(extra / lever))

    def describe(self) -> str:
        """The job's dot in words, sizes in µm: ``circle 46 µm``, ``ellipse 80 × 40 µm``,
        ``rounded_rectangle 120 × 30 µm, corner_radius 5 µm``, or with sizes
        ``circle 30–120 µm on 0.5 µm steps``."""
        if self.sizes is not None and self.shape.kind.round:
            s = self.sizes
            return f"{self.shape.kind.name} {_um(s.low)}–{_um(s.high)} µm on {_um(s.step)} µm steps"
        text = footprint_text(self.shape.kind, self.shape.size)
        if self.sizes is not None:
            s = self.sizes
            text += f", scaled to diameters {_um(s.low)}–{_um(s.high)} µm on {_um(s.step)} µm steps"
        return text

    def expected(self, dots: Footprints) -> np.ndarray:
        """``[n, k]`` the size parameters (mm, the job's kind's) the job gives each of
        ``dots``: its one size, or the job's footprint at the rule's diameter nearest each
        dot's own (area-equivalent, whatever the dot's kind)."""
        kind, size = self.shape.kind, np.asarray(self.shape.size, np.float64)
        if self.sizes is None:
            return np.broadcast_to(size, (dots.n, len(size)))
        d = self.sizes.quantise(dots.equivalent_diameter())
        if kind.round:
            return d[:, None]
        return kind.drawable(np.round(np.outer(self.shape.scale_of(d), size), 6))

    def stray(self, dots: Footprints, xy: np.ndarray | None = None) -> np.ndarray:
        """``[n]`` bool: the dots whose footprint the job does not draw (see the module),
        centred at ``xy`` (``[n, 2]`` mm; with a :attr:`band`, a size must also be one the
        rule gives that place). A dot of another kind is the job's only where both are the
        same disc (a capsule as long as it is wide, read back from a mask as a circle)."""
        if not dots.n:
            return np.zeros(0, bool)
        want = self.expected(dots)
        if dots.kind == self.shape.kind:  # a kind made per job: by its vertices
            bad = ~np.all(np.abs(dots.size - want) <= self.tolerance, axis=1)
        else:
            off = np.abs(dots.kind.disc(dots.size) - self.shape.kind.disc(want))
            bad = ~(off <= self.tolerance)
        if self.band is not None and xy is not None and self.sizes is not None:
            lo, hi = self.band.at(xy)
            d = dots.equivalent_diameter()
            slack = self.sizes.step + self.tolerance  # the fit's quantisation, the rounding
            bad |= (d < lo - slack) | (d > hi + slack)
        return bad


def footprint_text(kind: Kind, size) -> str:
    """One footprint of ``kind`` and ``size`` (``[k]`` mm) in words, µm: ``circle 56.6
    µm``, ``ellipse 80 × 40 µm``, ``rounded_rectangle 120 × 30 µm, corner_radius 15 µm``."""
    size = [float(v) for v in size]
    if kind.round:
        return f"{kind.name} {_um(size[0])} µm"
    text = f"{kind.name} {_um(size[0])} × {_um(size[1])} µm"
    for p, v in zip(kind.params[2:], size[2:], strict=True):
        text += f", {p} {_um(v)} µm"
    return text


def _um(mm: float) -> str:
    """A length in mm as µm, 4 significant digits."""
    return f"{mm * 1e3:.4g}"


__all__ = ["TOLERANCE", "DotRule", "SizeBand", "footprint_text"]
