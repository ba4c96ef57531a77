"""The stages of generation as functions of a run's settings and a set of dots: one path
for every dot. A job becomes those settings once, in the orchestration
(:func:`optdot.orchestration.job_settings.stage_settings`, values: the panel, the map, the
dots, the formulation); no stage takes the job.

:func:`optdot.orchestration.pipeline.generate` runs them once over the whole panel; the tiles of
:mod:`optdot.orchestration.tiling.tasks` run the same functions over a tile, with the neighbouring
tiles' dots held still around it. Nothing here knows whether it sees a panel or a tile:

* :func:`throw` (:mod:`.throw`): the initial dots of a window (the panel, or a tile),
  §2.1; for tiles, their long-wavelength grain removed across the panel before they
  relax (:func:`coarse_shift` along the field :func:`coarse_solve` makes from every
  tile's :func:`coarse_part`).
* :func:`relax` (:mod:`.relaxation`): circles and containers on the initial dots, phantom
  dots beyond the walls (:mod:`.beyond_walls`), then OptDot (L-BFGS through the formulation's
  stages, then the long-wavelength correction and the hard core, :mod:`.correction`) or
  the MD baseline of §2.2. A tile relaxes without the correction; it gets
  :func:`correction_region` over windows that span its seams, the wide last pass over
  the panel from every tile's :func:`wide_part` (:func:`wide_solve`), and
  :func:`hard_core` in its guarantee task.
* :func:`finish` (:mod:`.finishing`): dot sizes fitted to the coverage where the dots
  stand (when sizes vary, :mod:`optdot.relax.resize`), then the guarantee pass and its
  check.

What each stage takes (its problem, formulation, settings, sizes, halo, spacing) is
:class:`.settings.StageSettings`.
"""

from .beyond_walls import job_phantoms, phantom_reach, phantoms_near
from .correction import (
    TILE_GRID,
    correction_pad,
    correction_region,
    hard_core,
    wide_part,
    wide_rounds,
    wide_sigma,
    wide_solve,
)
from .finishing import Finished, finish
from .held import Held
from .relaxation import relax
from .settings import FIT_SHARE, StageSettings
from .throw import coarse_part, coarse_shift, coarse_solve, throw

__all__ = [
    "FIT_SHARE",
    "TILE_GRID",
    "Finished",
    "Held",
    "StageSettings",
    "coarse_part",
    "coarse_shift",
    "coarse_solve",
    "correction_pad",
    "correction_region",
    "finish",
    "hard_core",
    "job_phantoms",
    "phantom_reach",
    "phantoms_near",
    "relax",
    "throw",
    "wide_part",
    "wide_rounds",
    "wide_sigma",
    "wide_solve",
]
