"""The initial throw (§2.1) of a window: the panel, or a tile."""

from __future__ import annotations

from collections.abc import Sequence

from ..config.job import Job
from ..sampling.initial import Rect, initial_dots_in


def throw(job: Job, n: int, seed: int | Sequence[int], rect: Rect | None, where: str):
    """``[n, 2]`` initial dots of the window ``rect`` (None: the panel), mm, generation
    order: darts in proportion to the fill (to the dot count when sizes vary), only
    those inside the outline kept.

    Raises:
        GeometryError: the map is zero over (most of) the window's part of the panel.
    """
    inside = None if job.domain.rectangle else job.domain.contains
    return initial_dots_in(job.density, n, seed, inside, job.dart_weights, rect, where)
