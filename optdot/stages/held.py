"""The dots a stage holds still around the dots it moves (a tile's neighbours)."""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from ..spatial.window import in_rect


class Held(NamedTuple):
    """Dots held still: they count in the spacing (and the coverage of a size fit), and
    another task fixes them.

    Attributes:
        xy: ``[h, 2]`` positions, mm.
        diameter: their diameters, mm (one, or ``[h]``).
        angle: ``[h]`` shaped dots' angles, rad (what their footprints are turned by:
            final ones as written, else the job's field where they stand), or None for
            discs.
    """

    xy: np.ndarray
    diameter: np.ndarray | float
    angle: np.ndarray | None = None

    @classmethod
    def near(cls, parts: list[Held], box: tuple[float, float, float, float]) -> Held | None:
        """The dots of ``parts`` inside ``box`` (mm), in one; None without parts."""
        if not parts:
            return None
        xs, ds, angles = [], [], []
        for p in parts:
            sel = in_rect(p.xy, box)
            xs.append(p.xy[sel])
            ds.append(np.broadcast_to(p.diameter, (len(p.xy),))[sel])
            if p.angle is not None:
                angles.append(p.angle[sel])
        angle = np.concatenate(angles) if len(angles) == len(parts) else None
        return cls(np.concatenate(xs), np.concatenate(ds), angle)
