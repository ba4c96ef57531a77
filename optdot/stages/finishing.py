"""The last stage: dot sizes fitted to the coverage (when they vary by a rule), then the
guarantee pass and its check."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..geometry.shapes import Footprints
from ..relax.legalize import LegalizeResult, make_legal
from ..relax.resize import fit_sizes
from ..relax.shaped import make_legal_shapes
from ..sampling.initial import Rect
from .held import Held
from .settings import StageSettings


@dataclass
class Finished:
    """What :func:`finish` made of a set of dots.

    Attributes:
        xy: ``[n, 2]`` final positions, mm, rounded to 1 nm.
        diameter: the one diameter, mm, or ``[n]`` per dot.
        legalize: the guarantee pass's facts (sweeps, fixes).
        dots: shaped dots' footprints, turned by the job's orientation field where each
            dot ended (angles rounded to 1e-6°, what files hold), or None for discs.
    """

    xy: np.ndarray
    diameter: float | np.ndarray
    legalize: LegalizeResult
    dots: Footprints | None = None


def finish(
    s: StageSettings,
    xy: np.ndarray,
    xy0: np.ndarray,
    where: str,
    held: Held | None = None,
    window: Rect | None = None,
) -> Finished:
    """Sizes fitted (when they vary by a rule), then the guarantee pass and its check.

    Args:
        xy: ``[n, 2]`` relaxed positions, mm.
        xy0: ``[n, 2]`` where they were thrown (their start cells: size and the cell a
            dot returns to if it drifted into a zero cell).
        where: the job or tile, for the error message.
        held: dots held still around these (a tile's neighbours within
            :func:`~optdot.orchestration.job_settings.halo_width`): they count in the coverage
            and the spacing, and someone
            else fixes them; shaped dots' with their angles.
        window: the part of the panel the size fit covers (a tile grown by the fit's
            reach; None: the panel).

    Raises:
        GuaranteeError: a violation is left after the pass.
    """
    n = len(xy)
    d = s.rule_diameters(xy0)
    home = s.density.cell_index(xy0)
    frozen = None
    if held is not None and len(held[0]):
        xy = np.concatenate([xy, held[0]])
        home = np.concatenate([home, np.zeros(len(held[0]), np.int64)])
        frozen = np.zeros(len(xy), bool)
        frozen[n:] = True
        if d is not None:
            d = np.concatenate([d, np.broadcast_to(held[1], (len(held[0]),))])
    if d is None:
        radius, dmin = s.dot_radius, s.min_distance
    else:
        if s.fitted:
            fit = None if frozen is None else ~frozen
            d = fit_sizes(xy, d, s.sizes, s.density, s.domain, s.fit_sigma, fit, window)
        radius, dmin = 0.5 * d, d + s.optimize.gap
    diameter = s.diameter if d is None else d[:n]
    if s.shape.kind.round:
        leg = make_legal(xy, s.density, home, s.domain, radius, dmin, where, frozen)
        return Finished(np.ascontiguousarray(leg.xy[:n]), diameter, leg)
    thrown, fixed = xy0, None
    if frozen is not None:  # held shaped dots keep their angles
        thrown = np.concatenate([xy0, held.xy])
        if held.angle is None:
            raise ValueError(f"{where}: held shaped dots come without their angles")
        fixed = held.angle
    scale = None if d is None else s.shape.scale_of(d)  # footprints scaled by their sizes
    leg, dots = make_legal_shapes(
        xy, thrown, s.density, home, s.domain, s.shape, s.orientation,
        s.optimize.gap, where, frozen, fixed, scale,
    )  # fmt: skip
    return Finished(np.ascontiguousarray(leg.xy[:n]), diameter, leg, dots.take(slice(0, n)))
