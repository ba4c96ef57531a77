"""What QA measures: any :class:`~optdot.pattern.DotSource` (a pattern in memory, a
dataset on disk) as parts read through a small cache, each part checked as it is read, and
the dots of the other parts around one part (its halo)."""

from __future__ import annotations

from collections import OrderedDict
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from ..geometry.domain import Domain
from ..geometry.limits import validate_dots
from ..geometry.shapes import CIRCLE, Footprints, Kind
from ..pattern import DotSource
from ..spatial.window import grown, in_rect


@dataclass
class Source:
    """Dots in parts on a panel: what QA measures.

    Attributes:
        box: panel ``(xmin, ymin, xmax, ymax)``, mm.
        outline: the panel outline, or None for the box.
        uniform_diameter: the one dot diameter, mm, or None when sizes vary.
        nominal_diameter: the uniform or median diameter, mm.
        counts: dots per part.
        read: ``read(k) -> (xy [n_k, 2] mm, footprints of the n_k dots)``.
        tiling: ``(xs, ys)`` tile edges of a tiled pattern (seam metrics), or None.
        label: the file, for messages.
        cache_parts: parts kept in memory while their neighbours are measured.
        kind: the footprint kind of every dot.
    """

    box: tuple[float, float, float, float]
    outline: Domain | None
    uniform_diameter: float | None
    nominal_diameter: float
    counts: list[int]
    read: Callable[[int], tuple[np.ndarray, Footprints]]
    tiling: tuple[np.ndarray, np.ndarray] | None = None
    label: str = ""
    cache_parts: int = 8
    kind: Kind = CIRCLE
    _cache: OrderedDict = field(default_factory=OrderedDict, repr=False)

    @property
    def n(self) -> int:
        return int(sum(self.counts))

    def part(self, k: int) -> tuple[np.ndarray, Footprints]:
        """Part ``k``, through the cache."""
        if k in self._cache:
            self._cache.move_to_end(k)
            return self._cache[k]
        got = self.read(k)
        self._cache[k] = got
        while len(self._cache) > self.cache_parts:
            self._cache.popitem(last=False)
        return got


def source_of(dots: DotSource, box=None, outline: Domain | None | bool = True) -> Source:
    """``dots`` as QA reads them: part by part, each part validated as it is read
    (finite, diameters and extent in range).

    Args:
        box: the panel box (default: the dots' own).
        outline: the panel outline; True (default) for the dots' own.
    """
    the_box = tuple(box) if box is not None else tuple(dots.box)
    label = dots.label

    def read(k: int):
        xy, footprints = dots.read_part(k)
        validate_dots(label or "the pattern", xy, footprints.diameter, the_box)
        return xy, footprints

    tiling = dots.tiling
    nx = 1 if tiling is None else len(tiling[0]) - 1
    return Source(
        box=the_box,
        outline=dots.outline if outline is True else outline,
        uniform_diameter=dots.uniform_diameter,
        nominal_diameter=dots.nominal_diameter,
        counts=list(dots.part_counts),
        read=read,
        tiling=tiling,
        label=label,
        cache_parts=3 * nx + 3,
        kind=dots.kind,
    )


def gather(
    src: Source, boxes: np.ndarray, k: int, halo: float
) -> tuple[np.ndarray, np.ndarray, Footprints]:
    """Dots of the other parts within the box of part ``k`` grown by ``halo``:
    ``(xy [h, 2] mm, part index [h], their footprints)``."""
    g = grown(tuple(boxes[k]), halo)
    ok = ~np.isnan(boxes[:, 0])
    ok &= (
        (boxes[:, 0] <= g[2])
        & (boxes[:, 2] >= g[0])
        & (boxes[:, 1] <= g[3])
        & (boxes[:, 3] >= g[1])
    )
    ok[k] = False
    xys, parts, fps = [], [], []
    for j in np.flatnonzero(ok):
        xy, footprints = src.part(int(j))
        sel = in_rect(xy, g)
        xys.append(xy[sel])
        parts.append(np.full(int(sel.sum()), j, np.int64))
        fps.append(footprints.take(sel))
    if not xys:
        return np.zeros((0, 2)), np.zeros(0, np.int64), Footprints.concat([])
    return np.vstack(xys), np.concatenate(parts), Footprints.concat(fps)
