"""Circles that stand in for dots during relaxation (paper §3.3) and their containers (§3)."""

from __future__ import annotations

import math

import numpy as np


def circle_radius(rho: np.ndarray, dot_radius: float, factor: float = 1.0) -> np.ndarray:
    """Radius of the circle replacing a dot where the fill fraction is ``rho``.

    ``r = factor * r0 * sqrt(pi / (sqrt(3) * rho))``: the paper's rule, i.e. sqrt(2) times
    the radius ``r'`` of touching circles in a hexagonal packing of that density.

    Args:
        rho: ``[n]`` fill fractions, > 0.
        dot_radius: r0, mm.
        factor: multiplier (1 = paper).

    Returns:
        ``[n]`` radii, mm.
    """
    rho = np.asarray(rho, dtype=np.float64)
    return factor * dot_radius * np.sqrt(math.pi / (math.sqrt(3.0) * rho))


def hex_radius(rho: np.ndarray, dot_radius: float) -> np.ndarray:
    """Radius r' of touching circles in a hexagonal packing of fill ``rho`` (eq. 4), mm."""
    rho = np.asarray(rho, dtype=np.float64)
    return dot_radius * np.sqrt(math.pi / (2.0 * math.sqrt(3.0) * rho))


def container_half_sides(radius: np.ndarray, container_factor: float = 4.0) -> np.ndarray:
    """Half side of each circle's square container: side = ``container_factor * r``.

    Args:
        radius: ``[n]`` circle radii, mm.

    Returns:
        ``[n]`` half sides, mm; the container of circle i is the square of that half side
        centred on the circle's initial position.
    """
    return 0.5 * container_factor * np.asarray(radius, dtype=np.float64)
