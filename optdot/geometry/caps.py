"""Caps: discs of solid ink printed over a direct-lit backlight's LEDs.

A Lambertian LED a short optical distance under the film lights a spot right above it
that random dots cannot hide: the film would need a fill there above what dots that keep
QA's gap reach (about 0.7-0.78). A cap prints that spot solid. The dots keep out of each
cap and a ring of QA's close gap around it, so the pattern around a cap is held to the
same spacing as between two dots; the caps themselves are exact discs on every mask.

Caps are a ``[m, 3]`` array of ``(x, y, diameter)`` rows, mm, in panel coordinates.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import shapely

from .domain import Domain, orient_all, polygon_cell_fractions
from .shapes import polygon_vertices

#: Chord tolerance of a keep-out disc's polygon, mm (the polygon circumscribes the disc).
KEEP_OUT_TOLERANCE = 1e-4
#: GDSII/OASIS: the cell of a cap, a circle on the dots' layer placed by one reference a
#: cap (``CAP_<diameter in nm>`` when the caps differ), also in a flattened file: how a
#: mask read back tells a cap from a dot.
CAP_CELL = "CAP"
#: DXF: the XDATA application that marks a CIRCLE on ``DOTS`` as a cap, not a dot.
CAP_APPID = "OPTDOT_CAP"


def no_caps() -> np.ndarray:
    """The empty ``[0, 3]`` cap array."""
    return np.zeros((0, 3), np.float64)


def cap_array(xy: np.ndarray, diameter: float) -> np.ndarray:
    """``[m, 3]`` caps of one ``diameter`` (mm) centred on ``xy`` ``[m, 2]`` (mm); empty
    when ``diameter`` is 0."""
    xy = np.asarray(xy, np.float64).reshape(-1, 2)
    if diameter <= 0 or len(xy) == 0:
        return no_caps()
    return np.column_stack([xy, np.full(len(xy), float(diameter))])


def discs(caps: np.ndarray, grow: float = 0.0) -> shapely.Geometry:
    """The union of the caps grown by ``grow`` mm, as polygons that contain the true
    discs (circumscribed, within :data:`KEEP_OUT_TOLERANCE` of them)."""
    if len(caps) == 0:
        return shapely.Polygon()
    polys = []
    for x, y, d in caps:
        r = 0.5 * d + grow
        n = polygon_vertices(r, KEEP_OUT_TOLERANCE)
        a = 2 * math.pi * np.arange(n) / n
        rc = r / math.cos(math.pi / n)  # the polygon's edges touch the circle from outside
        polys.append(shapely.Polygon(np.column_stack([x + rc * np.cos(a), y + rc * np.sin(a)])))
    return shapely.union_all(polys)


def cap_shares(
    caps: np.ndarray, x0: float, y0: float, cw: float, ch: float, nx: int, ny: int
) -> np.ndarray:
    """``[ny, nx]`` share of each cell of a grid (lower-left ``x0, y0``, cells ``cw x
    ch`` mm) under a cap."""
    if len(caps) == 0:
        return np.zeros((ny, nx))
    return polygon_cell_fractions(discs(caps), x0, y0, cw, ch, nx, ny)


def with_caps(domain: Domain, caps: np.ndarray, gap: float) -> Domain:
    """``domain`` with the caps and a ring of
    ``gap`` mm around each cut out of where dots may go; the slab (the panel the light
    sees) keeps them. ``domain`` itself when there are no caps."""
    if len(caps) == 0:
        return domain
    geom = orient_all(domain.geometry.difference(discs(caps, gap)))
    slab = domain.slab if domain.slab is not None else domain.geometry
    return replace(domain, geometry=geom, rectangle=False, slab=slab, caps=caps)


def caps_problem(caps: np.ndarray) -> str | None:
    """What is wrong with a cap array read from a file (``[m, 3]`` finite, diameters >
    0), or None."""
    a = np.asarray(caps)
    if a.dtype.kind not in "iuf" or a.ndim != 2 or a.shape[1] != 3 or len(a) == 0:
        return f"caps must be [m, 3] numbers (x, y, diameter mm), got {a.dtype} {a.shape}"
    if not (np.isfinite(a).all() and (a[:, 2] > 0).all()):
        return "caps must be finite with diameters > 0 mm"
    return None
