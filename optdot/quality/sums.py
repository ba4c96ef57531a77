"""What the two passes of :mod:`optdot.quality.measure` add up part by part: sums over
dots (exact across parts), bounded lists of markers, and the per-dot arrays kept."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..geometry.shapes import Footprints
from .metrics import SquareGrid
from .visibility import LuminanceGrid
from .wall_profile import WallProfiler


@dataclass
class FirstSums:
    boxes: np.ndarray  # [P, 4] bounding boxes of the parts (NaN for empty parts)
    cells: np.ndarray | None
    squares: SquareGrid
    square_counts: np.ndarray
    overview: np.ndarray
    overview_extent: tuple[float, float, float, float]
    protruding: int = 0
    outside: int = 0
    margin_violations: int = 0
    empty: int = 0
    defects: list[np.ndarray] = field(default_factory=list)
    where_protruding: list[np.ndarray] = field(default_factory=list)
    where_empty: list[np.ndarray] = field(default_factory=list)
    bands: list[tuple[str, Any, float]] = field(default_factory=list)
    band_sums: list[float] = field(default_factory=list)
    diameters: list[np.ndarray] = field(default_factory=list)
    luminance: LuminanceGrid | None = None
    walls: WallProfiler | None = None
    angle_hist: np.ndarray | None = None  # [36] shaped dots per 5° of their axis
    field_error_max: float = 0.0  # largest |angle - field| of shaped dots, degrees
    field_error_sum: float = 0.0
    stray: int = 0  # dots whose footprint is not the job's (:mod:`.conformance`)
    where_stray: list[np.ndarray] = field(default_factory=list)
    stray_example: str | None = None  # the first such footprint, in words
    size_lo: np.ndarray | None = None  # [k] shaped dots' smallest size parameters, mm
    size_hi: np.ndarray | None = None  # [k] and largest


@dataclass
class SecondSums:
    pairs_collision: int = 0
    pairs_close: int = 0
    close_dots: int = 0
    collision_mid: list[np.ndarray] = field(default_factory=list)
    close_mid: list[np.ndarray] = field(default_factory=list)
    nn: np.ndarray | None = None
    nn_norm: list[np.ndarray] = field(default_factory=list)
    psi_abs_sum: float = 0.0
    psi_sum: complex = 0j
    patches: tuple | None = None
    seams: dict | None = None
    window_xy: list[np.ndarray] = field(default_factory=list)
    grain_xy: list[np.ndarray] = field(default_factory=list)
    grain_window: tuple[float, float, float, float] | None = None
    zoom_xy: list[np.ndarray] = field(default_factory=list)
    zoom_d: list[Footprints] = field(default_factory=list)  # the zoom's dots' footprints
    segments: list[np.ndarray] = field(default_factory=list)
    requeried: int = 0
    shapely_pairs: int = 0  # near pairs of shaped dots checked again with shapely
    shapely_disagree: int = 0  # of them, where shapely and the exact gap disagree


def add_nested(a: dict, b: dict) -> dict:
    """Sum of two nested dicts of arrays with the same keys."""
    return {k: add_nested(v, b[k]) if isinstance(v, dict) else v + b[k] for k, v in a.items()}


def keep(bucket: list[np.ndarray], rows: np.ndarray, limit: int) -> None:
    """Append ``rows`` to ``bucket`` up to ``limit`` rows in all."""
    have = sum(len(r) for r in bucket)
    if have < limit and len(rows):
        bucket.append(rows[: limit - have])


def cat(bucket: list[np.ndarray], shape: tuple[int, ...]) -> np.ndarray:
    return np.concatenate(bucket) if bucket else np.zeros((0, *shape))
