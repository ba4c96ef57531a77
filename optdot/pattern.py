"""The :class:`Pattern`: what the optimizer produces, and :class:`DotSource`: what every
exporter and QA check reads (a pattern in memory, or a dataset on disk part by part).

Reading and writing pattern files (CSV, NPZ) lives in :mod:`optdot.io.patterns`.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass, field
from typing import Any, Protocol

import numpy as np

from .geometry.caps import cap_shares, no_caps, ring_shares
from .geometry.domain import Domain
from .geometry.shapes import CIRCLE, Footprints, Kind

#: ``(label, xy [n, 2] mm, footprints of the n dots)``: one chunk of a dot source (a tile).
Chunk = tuple[tuple[int, int], np.ndarray, Footprints]


class DotSource(Protocol):
    """Dots on a panel, read chunk by chunk: :class:`Pattern` (one chunk, in memory) and
    :class:`optdot.io.dataset.Dataset` (one chunk per tile, from disk) both are one, so a
    writer or a measure that takes a ``DotSource`` holds one chunk at a time whatever
    the size of the panel."""

    @property
    def n(self) -> int:
        """Number of dots."""

    @property
    def box(self) -> tuple[float, float, float, float]:
        """Panel ``(xmin, ymin, xmax, ymax)``, mm."""

    @property
    def kind(self) -> Kind:
        """The footprint kind of every dot (:mod:`optdot.geometry.shapes`)."""

    @property
    def uniform_diameter(self) -> float | None:
        """The one diameter of every dot, mm, or None when sizes vary."""

    @property
    def nominal_diameter(self) -> float:
        """The uniform diameter, or the median of varying ones, mm."""

    def outline_rings(self) -> list[np.ndarray]:
        """The panel's boundary loops, ``[k, 2]`` mm each (exteriors counter-clockwise)."""

    def chunks(self) -> Iterator[Chunk]:
        """The dots, one chunk at a time, in a fixed order."""

    @property
    def outline(self) -> Domain | None:
        """The panel outline, or None for the box."""

    @property
    def part_counts(self) -> list[int]:
        """Dots per chunk, in chunk order."""

    def read_part(self, k: int) -> tuple[np.ndarray, Footprints]:
        """Chunk ``k`` alone: ``(xy [n, 2] mm, footprints)`` (QA reads a chunk's
        neighbours for its halo)."""

    @property
    def tiling(self) -> tuple[np.ndarray, np.ndarray] | None:
        """``(xs, ys)`` tile edges, mm, when the dots were made in tiles (seam
        measures), else None."""

    @property
    def label(self) -> str:
        """Where the dots come from, for messages (a file, or empty)."""

    @property
    def meta(self) -> dict[str, Any]:
        """How the dots were made (job, seed, method, ...), as far as known."""

    def verify(self) -> None:
        """Check the dots' stored form (checksums) before they are measured."""


@dataclass(frozen=True, eq=False)
class Pattern:
    """Dot centres and sizes on a panel.

    Attributes:
        xy: ``[n, 2]`` float64 dot centres, mm, rounded to 1 nm.
        diameter: ``[n]`` float64 dot diameters, mm (a number given here is broadcast to
            every dot; :attr:`uniform_diameter` is the scalar view when all are equal).
        box: panel ``(xmin, ymin, xmax, ymax)``, mm.
        meta: provenance (job name, seed, method, iterations, ...). Deterministic values
            only; timings live in :attr:`stats`.
        stats: run statistics that may vary between runs (seconds, memory).
        outline: the panel outline with holes and keep-outs, when it is not the box.
        dots: the footprints of shaped dots (their kind, sizes and angles), or None for
            discs of :attr:`diameter`; with them, :attr:`diameter` is each footprint's
            bounding disc's.
    """

    xy: np.ndarray
    diameter: np.ndarray
    box: tuple[float, float, float, float]
    meta: dict[str, Any] = field(default_factory=dict)
    stats: dict[str, Any] = field(default_factory=dict)
    outline: Domain | None = None
    dots: Footprints | None = None

    def __post_init__(self) -> None:
        xy = np.ascontiguousarray(self.xy, dtype=np.float64)
        if xy.ndim != 2 or xy.shape[1] != 2:
            raise ValueError(f"xy must have shape [n, 2], got {xy.shape}")
        xy.setflags(write=False)
        if self.dots is not None:
            if self.dots.n != len(xy):
                raise ValueError(f"dots must hold {len(xy)} footprints, got {self.dots.n}")
            object.__setattr__(self, "diameter", self.dots.diameter)
        d = np.asarray(self.diameter, dtype=np.float64)
        if d.ndim > 1 or (d.ndim == 1 and len(d) != len(xy)):
            raise ValueError(f"diameter must be a number or shape [{len(xy)}], got {d.shape}")
        d = np.ascontiguousarray(np.broadcast_to(d, (len(xy),)))
        d.setflags(write=False)
        object.__setattr__(self, "xy", xy)
        object.__setattr__(self, "diameter", d)
        object.__setattr__(self, "box", tuple(float(v) for v in self.box))

    def outline_rings(self) -> list[np.ndarray]:
        """The panel's boundary loops as ``[k, 2]`` vertex arrays, mm: the outline and its
        holes (exteriors counter-clockwise, holes clockwise), or the box."""
        if self.outline is not None:
            return self.outline.rings()
        x0, y0, x1, y1 = self.box
        return [np.array([(x0, y0), (x1, y0), (x1, y1), (x0, y1)], dtype=np.float64)]

    def chunks(self) -> Iterator[Chunk]:
        """``(label, xy [n, 2], footprints)`` parts of the dots: one, all of them (a
        :class:`~optdot.io.dataset.Dataset` yields one per tile; exporters stream either)."""
        yield (0, 0), self.xy, self.shape

    @property
    def kind(self) -> Kind:
        """The footprint kind of every dot."""
        return CIRCLE if self.dots is None else self.dots.kind

    @property
    def shape(self) -> Footprints:
        """The dots' footprints (:attr:`dots`, or discs of :attr:`diameter`)."""
        return Footprints.circles(self.diameter) if self.dots is None else self.dots

    @property
    def n(self) -> int:
        """Number of dots."""
        return int(self.xy.shape[0])

    @property
    def part_counts(self) -> list[int]:
        """One chunk: all the dots."""
        return [self.n]

    def read_part(self, k: int) -> tuple[np.ndarray, Footprints]:
        """The one chunk (``k`` = 0): ``(xy, footprints)``."""
        if k != 0:
            raise IndexError(f"a pattern has one part, not part {k}")
        return self.xy, self.shape

    @property
    def tiling(self) -> tuple[np.ndarray, np.ndarray] | None:
        """``(xs, ys)`` tile edges of a pattern gathered from tiles, mm, else None."""
        t = self.meta.get("tiling")
        if isinstance(t, dict) and "xs" in t and "ys" in t:
            return np.asarray(t["xs"], float), np.asarray(t["ys"], float)
        return None

    @property
    def label(self) -> str:
        """The file the pattern was read from, or empty."""
        return str(self.meta.get("source", ""))

    def verify(self) -> None:
        """Nothing to check: the dots are in memory, validated when made or read."""

    @property
    def uniform_diameter(self) -> float | None:
        """The one diameter of every disc, mm, or None when sizes vary (or no dots, or
        the dots are shaped)."""
        d = self.diameter
        if len(d) == 0 or d.min() != d.max() or self.dots is not None:
            return None
        return float(d[0])

    @property
    def nominal_diameter(self) -> float:
        """The uniform diameter, or the median of varying ones, mm."""
        u = self.uniform_diameter
        return u if u is not None else float(np.median(self.diameter)) if self.n else 0.0

    @property
    def radius(self) -> np.ndarray:
        """``[n]`` dot radii, mm."""
        return 0.5 * self.diameter

    @property
    def areas(self) -> np.ndarray:
        """``[n]`` dot areas, mm²."""
        return self.shape.area()


def coverage_image(
    pattern: Pattern, max_px: int = 400
) -> tuple[np.ndarray, tuple[float, float, float, float]]:
    """Covered area share per pixel, ``[ny, nx]``, and its extent ``(x0, x1, y0, y1)`` mm.

    Pixels are at least 6 nominal dot diameters, so each holds several dots and the map
    reads as coverage rather than as dot positions; at most ``max_px`` a side. Caps over
    LEDs (:func:`caps_of`) count with their share of each pixel (graded caps: their rings').
    """
    x0, y0, x1, y1 = pattern.box
    nx, ny = coverage_pixels(pattern.box, pattern.nominal_diameter, max_px)
    rng = ((y0, y1), (x0, x1))
    cell = (x1 - x0) / nx * (y1 - y0) / ny
    u = pattern.uniform_diameter
    if u is not None:
        h, _, _ = np.histogram2d(pattern.xy[:, 1], pattern.xy[:, 0], bins=(ny, nx), range=rng)
        img = h * (np.pi * (0.5 * u) ** 2) / cell
    else:
        h, _, _ = np.histogram2d(
            pattern.xy[:, 1], pattern.xy[:, 0], bins=(ny, nx), range=rng, weights=pattern.areas
        )
        img = h / cell
    caps = caps_of(pattern)
    rings = pattern.outline.cap_rings if pattern.outline is not None else None
    cw, ch = (x1 - x0) / nx, (y1 - y0) / ny
    if len(caps) and rings is None:  # solid ink: their share of each pixel
        img = img + cap_shares(caps, x0, y0, cw, ch, nx, ny)
    elif len(caps):  # graded: their rings' share
        img = img + ring_shares(caps, rings, x0, y0, cw, ch, nx, ny)
    return img, (x0, x1, y0, y1)


def coverage_pixels(box, nominal: float, max_px: int) -> tuple[int, int]:
    """``(nx, ny)`` pixels of a coverage image of the panel ``box`` (mm): pixels of at
    least 6 ``nominal`` dot diameters (mm), at most ``max_px`` a side."""
    x0, y0, x1, y1 = box
    px = max(max((x1 - x0), (y1 - y0)) / max_px, 6.0 * nominal)
    return max(1, int(round((x1 - x0) / px))), max(1, int(round((y1 - y0) / px)))


def caps_of(src: DotSource) -> np.ndarray:
    """The caps ``[m, 3]`` ``(x, y, diameter)``, mm, printed with ``src``'s dots (its
    outline's: :mod:`optdot.geometry.caps`), or ``[0, 3]``."""
    outline = src.outline
    return no_caps() if outline is None or outline.caps is None else outline.caps
