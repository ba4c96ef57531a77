"""The initial throw (§2.1) of a window (the panel, or a tile), and, for tiles, the
throw's long-wavelength grain removed across the whole panel before any tile relaxes.

Why the tiles need the second. The relaxation keeps the long-wavelength grain of its
throw (:mod:`optdot.relax.lowpass`): one process removes it after relaxing, by one field
over the panel. A tile's correction (:func:`optdot.orchestration.tiling.tasks.correct_tile`) solves
over windows a tile wide, each with its own mean and walls, so it misses wavelengths of
a tile and longer, and neighbouring windows disagree about them by 25-45 %
(BENCHMARKS.md): on a crop of the notebook panel tiled at 15 mm the strongest
blob read 3.85 JND against 1.16 from one process. The grain is the throw's, so it is
known before anything relaxes: every tile deposits its initial dots on one coarse
lattice (:func:`coarse_part`), one task solves the panel's field from all of them
(:func:`coarse_solve`), and each tile's throw is moved along it (:func:`coarse_shift`)
before it relaxes: strongest blob 1.18 JND, p99 0.65 (1.30 without the field). The same field
applied at the correction instead (subtracted from the windows' error) read 1.28 JND,
and on the led sample brought the wall bands' p99 from 1.49 to 1.70 JND: the throw's
error by a wall is not the relaxed pattern's, which the phantoms reshape there; moved
before relaxing, the relaxation settles the wall as always.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from ..relax.lowpass import CoarseField, Lattice, LatticePart, coarse_field, deposit_part
from ..sampling.initial import Rect, initial_dots_in
from .correction import corrected
from .settings import StageSettings


def throw(s: StageSettings, n: int, seed: int | Sequence[int], rect: Rect | None, where: str):
    """``[n, 2]`` initial dots of the window ``rect`` (None: the panel), mm, generation
    order: darts in proportion to the fill (to the dot count when sizes vary), only
    those inside the outline kept.

    Raises:
        GeometryError: the map is zero over (most of) the window's part of the panel.
    """
    inside = None if s.domain.rectangle else s.domain.contains
    return initial_dots_in(s.density, n, seed, inside, s.dart_weights, rect, where)


#: Blur of the panel-wide field, in spacings. Notebook crop (spacing 0.14 mm), 4 x 2
#: tiles of 15 mm, applied at the correction (BENCHMARKS.md): 3.6 spacings left the
#: strongest blob at 1.30 JND, 7.1 at 1.25, 14 at 1.93.
COARSE_SIGMA = 7.0
#: Lattice step of the panel-wide field, in spacings (a third of its blur).
COARSE_STEP = COARSE_SIGMA / 3.0
#: Largest displacement of the panel-wide field, in spacings. Its error is the throw's
#: grain, not a map step: the notebook crop's largest was 0.15 spacing (a corner, where
#: the blur sees a quarter of its dots), and the correction's cap of 0.1 left a 3.2 JND
#: blob there (1.28 JND uncapped).
COARSE_SHIFT = 0.5
#: Cells of the panel-wide lattice at most (32 MB a float32 array). A 55-inch panel at
#: 0.1 mm spacings would need 15M: its step grows to 0.31 mm, still 2 cells a sigma.
COARSE_CELLS = 1 << 23


def coarse_lattice(s: StageSettings) -> Lattice:
    """The lattice of the panel-wide field over the panel's box."""
    return Lattice.over(s.box, COARSE_STEP * s.spacing, COARSE_CELLS)


def coarse_part(s: StageSettings, xy0: np.ndarray) -> LatticePart:
    """A tile's initial dots ``xy0`` (``[n, 2]`` mm) deposited by their areas on
    :func:`coarse_lattice`, for :func:`coarse_solve`."""
    return deposit_part(xy0, s.thrown_areas(xy0), coarse_lattice(s))


def coarse_solve(s: StageSettings, parts: list[LatticePart]) -> CoarseField | None:
    """The panel-wide field (:class:`optdot.relax.lowpass.CoarseField`) from every tile's
    :func:`coarse_part`, added in the order given (the plan's tile order, so the bytes do
    not depend on who computed what); None when the job has no long-wavelength
    correction."""
    if not corrected(s):
        return None
    spacing = s.spacing
    return coarse_field(
        parts, coarse_lattice(s), s.density, COARSE_SIGMA * spacing, COARSE_SHIFT * spacing,
        s.domain,
    )  # fmt: skip


def coarse_shift(s: StageSettings, coarse: CoarseField | None, xy: np.ndarray) -> np.ndarray:
    """Initial dots ``xy`` (``[n, 2]`` mm) moved along the panel-wide field: ``[n, 2]``,
    a new array. A dot the move would take out of the panel, or into a cell of fill 0,
    stays where it was thrown (the throw's promise: every dot starts in a lit cell)."""
    if coarse is None or not len(xy):
        return xy
    new = xy + coarse.displacement(xy)
    x0, y0, x1, y1 = s.box
    ok = (new[:, 0] >= x0) & (new[:, 0] <= x1) & (new[:, 1] >= y0) & (new[:, 1] <= y1)
    ok &= s.density.at(new) > 0
    if not s.domain.rectangle:
        ok &= s.domain.contains(new)
    return np.ascontiguousarray(np.where(ok[:, None], new, xy))
