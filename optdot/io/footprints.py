"""Shaped dots as a file holds them (CSV, NPZ, a dataset's parts), checked before use."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..errors import PatternFileError
from ..geometry.shapes import Footprints, Kind

#: Largest angle a file may give, degrees (optdot writes (-90, 90]; a full turn either way
#: is read, beyond it is not an angle a mask or a CSV can hold).
MAX_ANGLE_DEG = 360.0


def file_footprints(path: Path, kind: Kind, size: np.ndarray, angle_deg: np.ndarray) -> Footprints:
    """The footprints a file holds (``size [n, k]`` mm, ``angle_deg [n]``), refused in one
    line when they cannot be drawn: NaN or infinite, a width not > 0, a length under the
    width, a corner radius over half the width, an angle beyond ±360°.

    Raises:
        PatternFileError: naming the file and the first bad dot (1-based).
    """
    size = np.ascontiguousarray(size, dtype=np.float64)
    angle_deg = np.asarray(angle_deg, dtype=np.float64)
    if not (np.all(np.isfinite(size)) and np.all(np.isfinite(angle_deg))):
        raise PatternFileError(f"{path}: NaN or infinite {kind.name} size or angle_deg")
    turned = np.abs(angle_deg) > MAX_ANGLE_DEG
    if turned.any():
        i = int(np.argmax(turned))
        raise PatternFileError(
            f"{path}: dot {i + 1}: angle_deg = {angle_deg[i]:g} is not an angle "
            f"(-{MAX_ANGLE_DEG:g}..{MAX_ANGLE_DEG:g})"
        )
    bad = kind.undrawable(size)
    if bad.any():
        i = int(np.argmax(bad))
        raise PatternFileError(
            f"{path}: dot {i + 1}: {kind.name} of {tuple(size[i].tolist())} mm cannot be "
            "drawn (width > 0, length >= width, corner radius <= width / 2)"
        )
    return Footprints(kind, size, np.radians(angle_deg))
