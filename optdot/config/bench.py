"""What the optics take from a job: the panel and its map, the stack its dots are printed
in, the design's settings and the dots' sizes. ``simulate``, ``design`` and their
figures take this value (a job's :attr:`~optdot.config.job.Job.bench`), never the job."""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from ..geometry.density import DensityMap
    from ..geometry.domain import Domain
    from ..geometry.orientation import Orientation
    from ..geometry.profile import DotProfile
    from ..geometry.shapes import DotShape
    from ..geometry.sizes import DotSizes
    from ..printing.process import Process
    from .backlight import Backlight
    from .light_guide import DesignParams, LightGuide


@dataclass(frozen=True, eq=False)
class Bench:
    """The optical bench a job describes.

    Attributes:
        source: the job file, or None (messages name it).
        name: the job's label.
        domain: the panel (its slab, holes, caps and their rings).
        density: the fill-fraction map.
        viewing_area: ``(x0, y0, x1, y1)`` mm the viewer sees, or None (the panel).
        light_guide: the slab and its LEDs, or None.
        backlight: the stack around the printed face, or None (the bare guide).
        design: how a map is designed (``[design]``).
        process: how the masks print, or None.
        shape: the dot's kind and size.
        profile: the dot's 3-D profile (ink, a bump, a dimple, a prism).
        orientation: where the dots' long axes point (a coverage trace turns its
            profiles so).
        sizes: how diameters vary, or None for one size.
        diameter: the (smallest) dot's diameter, mm.
        close_gap: the edge gap QA counts close pairs under, mm.
    """

    source: Path | None
    name: str
    domain: Domain
    density: DensityMap
    viewing_area: tuple[float, float, float, float] | None
    light_guide: LightGuide | None
    backlight: Backlight | None
    design: DesignParams
    process: Process | None
    shape: DotShape
    profile: DotProfile
    orientation: Orientation
    sizes: DotSizes | None
    diameter: float
    close_gap: float

    @property
    def where(self) -> str:
        """The job file, or ``"job"``, to start a message with."""
        return str(self.source) if self.source else "job"

    @property
    def box(self) -> tuple[float, float, float, float]:
        """The panel's bounding box ``(xmin, ymin, xmax, ymax)``, mm."""
        return self.domain.box

    @cached_property
    def cell_weights(self) -> np.ndarray | None:
        """``[ny, nx]`` share of each map cell inside the panel (None: all of it)."""
        return self.domain.map_weights(self.density)
