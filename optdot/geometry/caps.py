"""Caps: discs of solid ink printed over a direct-lit backlight's LEDs.

A Lambertian LED a short optical distance under the film lights a spot right above it
that random dots cannot hide: the film would need a fill there above what dots that keep
QA's gap reach (about 0.7-0.78). A cap prints that spot solid. The dots keep out of each
cap and a ring of QA's close gap around it, so the pattern around a cap is held to the
same spacing as between two dots; the caps themselves are exact discs on every mask.

Caps are a ``[m, 3]`` array of ``(x, y, diameter)`` rows, mm, in panel coordinates.

**Graded caps.** A solid cap hides the LED's own peak, but the ring around it still needs
more ink than dots reach (the Lambertian stack of ``benchmarks/caps_coverage.py``). A graded
cap prints its disc as concentric rings instead: the disc is cut into bands of equal width
from the centre, and each band carries a ring whose area is the band's ink share
(``[backlight.leds] cap_ink``, which ``optdot design`` sizes). Each ring starts at its
band's inner edge; its width is at least :data:`RING_LINE` and leaves at least that much
clear before the next band, or the band is empty or full (1-D error diffusion from the
centre out keeps the running ink). Touching rings merge. The printed rings are one
``[k, 2]`` table ``(r_in, r_out)``, mm, shared by every cap of the pattern
(:func:`ring_table`); a solid cap is the table ``[[0, d / 2]]``.
"""

from __future__ import annotations

import functools
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
#: The band width the design grades a cap with, mm.
RING_PITCH = 0.05
#: The narrowest printed ring, and the narrowest clear space between two, mm.
RING_LINE = 0.01
#: Radii of printed rings are rounded to this, mm (1 nm: the masks' grid).
RING_GRID = 1e-6


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
    caps = np.ascontiguousarray(caps, np.float64)
    key = (caps.tobytes(), caps.shape, float(x0), float(y0), float(cw), float(ch), nx, ny)
    return _cap_shares(key).copy()


@functools.lru_cache(maxsize=8)
def _cap_shares(key: tuple) -> np.ndarray:
    """:func:`cap_shares` by its arguments' bytes: a design traces the same caps on the
    same grid every iteration (shapely's cell intersections take ~1 s a call on a
    160 x 110 grid with 176 caps)."""
    raw, shape, x0, y0, cw, ch, nx, ny = key
    caps = np.frombuffer(raw, np.float64).reshape(shape)
    out = polygon_cell_fractions(discs(caps), x0, y0, cw, ch, nx, ny)
    out.flags.writeable = False
    return out


def with_caps(
    domain: Domain, caps: np.ndarray, gap: float, rings: np.ndarray | None = None
) -> Domain:
    """``domain`` with the caps and a ring of
    ``gap`` mm around each cut out of where dots may go; the slab (the panel the light
    sees) keeps them. ``rings``: the graded caps' printed rings (:func:`ring_table`), or
    None for solid caps. ``domain`` itself when there are no caps."""
    if len(caps) == 0:
        return domain
    geom = orient_all(domain.geometry.difference(discs(caps, gap)))
    slab = domain.slab if domain.slab is not None else domain.geometry
    return replace(domain, geometry=geom, rectangle=False, slab=slab, caps=caps, cap_rings=rings)


def rings_of(domain: Domain | None) -> np.ndarray:
    """The rings ``[k, 2]`` (mm) each of ``domain``'s caps prints: its graded rings, else
    the solid disc of its caps' largest diameter (``[0, 2]`` without caps)."""
    if domain is None or domain.caps is None or len(domain.caps) == 0:
        return np.zeros((0, 2))
    if domain.cap_rings is not None:
        return domain.cap_rings
    return ring_table(float(domain.caps[:, 2].max()), None)


def caps_problem(caps: np.ndarray) -> str | None:
    """What is wrong with a cap array read from a file (``[m, 3]`` finite, diameters >
    0), or None."""
    a = np.asarray(caps)
    if a.dtype.kind not in "iuf" or a.ndim != 2 or a.shape[1] != 3 or len(a) == 0:
        return f"caps must be [m, 3] numbers (x, y, diameter mm), got {a.dtype} {a.shape}"
    if not (np.isfinite(a).all() and (a[:, 2] > 0).all()):
        return "caps must be finite with diameters > 0 mm"
    return None


def ring_table(diameter: float, ink: np.ndarray | None) -> np.ndarray:
    """The printed rings ``[k, 2]`` ``(r_in, r_out)``, mm, of a cap of ``diameter`` mm
    graded by ``ink`` ``[n]`` (the ink share of each of ``n`` bands of equal width from
    the centre; see the module doc), or the solid disc ``[[0, d / 2]]`` when ``ink`` is
    None. Empty when no band prints."""
    big_r = 0.5 * float(diameter)
    if ink is None:
        return np.array([[0.0, big_r]])
    f = np.clip(np.asarray(ink, np.float64).ravel(), 0.0, 1.0)
    n = len(f)
    p = big_r / n
    line = min(RING_LINE, 0.5 * p)
    rows: list[list[float]] = []
    carry = 0.0  # ink area asked for but not printed yet, mm^2
    for i in range(n):
        a = i * p
        band = math.pi * ((a + p) ** 2 - a * a)
        want = f[i] * band + carry
        b = math.sqrt(a * a + max(0.0, min(want, band)) / math.pi)
        w = b - a
        if w < 0.5 * line:
            w = 0.0
        elif w < line:
            w = line
        elif w > p - 0.5 * line:
            w = p
        elif w > p - line:
            w = p - line
        b = min(round((a + w) / RING_GRID) * RING_GRID, big_r)
        a = round(a / RING_GRID) * RING_GRID
        carry = want - math.pi * (b * b - a * a) if b > a else want
        if b <= a:
            continue
        if rows and abs(rows[-1][1] - a) < 0.5 * RING_GRID:
            rows[-1][1] = b  # touching rings merge
        else:
            rows.append([a, b])
    return np.array(rows, np.float64).reshape(-1, 2)


def design_bands(diameter: float) -> int:
    """How many bands the design grades a cap of ``diameter`` mm with (each about
    :data:`RING_PITCH` wide)."""
    return max(1, int(round(0.5 * diameter / RING_PITCH)))


def _quadrant_area(x: np.ndarray, y: np.ndarray, r: np.ndarray) -> np.ndarray:
    """Area of the disc of radius ``r`` about the origin where ``X <= x`` and ``Y <= y``
    (elementwise, broadcast)."""
    r = np.maximum(r, 0.0)
    rs = np.where(r > 0, r, 1.0)

    def prim(t):  # integral of sqrt(r^2 - X^2) from 0 to t, |t| <= r
        t = np.clip(t, -r, r)
        return 0.5 * (t * np.sqrt(np.maximum(r * r - t * t, 0.0)) + r * r * np.arcsin(t / rs))

    xc = np.clip(x, -r, r)
    yc = np.clip(y, -r, r)
    c = np.sqrt(np.maximum(r * r - yc * yc, 0.0))  # the chord at Y = y reaches |X| = c
    u = np.minimum(xc, c)
    mid = np.where(u > -c, yc * (u + c) + prim(u) + prim(c), 0.0)
    upper = yc >= 0  # above the chord the disc's own height counts, beyond |X| = c
    left = np.where(upper, 2 * (prim(np.minimum(xc, -c)) + prim(r)), 0.0)
    right = np.where(upper & (xc > c), 2 * (prim(xc) - prim(c)), 0.0)
    return np.where(r > 0, mid + left + right, 0.0)


def disc_rect_area(cx, cy, r, x0, y0, x1, y1) -> np.ndarray:
    """Exact area, mm^2, of the disc of radius ``r`` about ``(cx, cy)`` inside the
    rectangle ``[x0, x1] x [y0, y1]`` (all mm, elementwise, broadcast)."""
    a, b, c, d = x0 - cx, y0 - cy, x1 - cx, y1 - cy
    q = _quadrant_area
    return q(c, d, r) - q(a, d, r) - q(c, b, r) + q(a, b, r)


def ring_shares(
    caps: np.ndarray,
    rings: np.ndarray,
    x0: float,
    y0: float,
    cw: float,
    ch: float,
    nx: int,
    ny: int,
) -> np.ndarray:
    """``[ny, nx]`` share of each cell of a grid (lower-left ``x0, y0``, cells ``cw x
    ch`` mm) printed by the caps' rings (``rings`` ``[k, 2]`` ``(r_in, r_out)`` mm about
    each cap's centre), exactly."""
    out = np.zeros((ny, nx))
    if len(caps) == 0 or len(rings) == 0:
        return out
    reach = float(rings[:, 1].max())
    x, y = caps[:, 0], caps[:, 1]
    i0 = np.floor((x - reach - x0) / cw).astype(np.int64)
    j0 = np.floor((y - reach - y0) / ch).astype(np.int64)
    i1 = np.ceil((x + reach - x0) / cw).astype(np.int64)
    j1 = np.ceil((y + reach - y0) / ch).astype(np.int64)
    w, h = int((i1 - i0).max()), int((j1 - j0).max())
    # every cap's window of w x h cells at once; each cap adds the cells its rings reach
    # (its own window, clipped to the grid)
    ex = x0 + cw * (i0[:, None] + np.arange(w + 1))  # [m, w + 1] cell edges
    ey = y0 + ch * (j0[:, None] + np.arange(h + 1))
    cx, cy = x[:, None, None], y[:, None, None]
    gx0, gx1 = ex[:, None, :-1], ex[:, None, 1:]
    gy0, gy1 = ey[:, :-1, None], ey[:, 1:, None]
    area = np.zeros((len(caps), h, w))
    for a, b in rings:
        area += disc_rect_area(cx, cy, b, gx0, gy0, gx1, gy1)
        if a > 0:
            area -= disc_rect_area(cx, cy, a, gx0, gy0, gx1, gy1)
    area /= cw * ch
    for k in range(len(caps)):  # in the caps' order: the same sums to the last bit
        a0, b0 = int(i0[k]), int(j0[k])
        i_lo, j_lo = max(0, a0), max(0, b0)
        i_hi, j_hi = min(nx, int(i1[k])), min(ny, int(j1[k]))
        if i_lo < i_hi and j_lo < j_hi:
            out[j_lo:j_hi, i_lo:i_hi] += area[k, j_lo - b0 : j_hi - b0, i_lo - a0 : i_hi - a0]
    return np.clip(out, 0.0, 1.0)


def rings_problem(rings: np.ndarray, caps: np.ndarray) -> str | None:
    """What is wrong with a ring table read from a file (``[k, 2]`` finite, ``0 <= r_in
    < r_out``, sorted, apart, within the caps, whose diameters must then be one), or
    None."""
    a = np.asarray(rings)
    if a.dtype.kind not in "iuf" or a.ndim != 2 or a.shape[1] != 2:
        return f"cap_rings must be [k, 2] numbers (r_in, r_out mm), got {a.dtype} {a.shape}"
    if not np.isfinite(a).all() or (a[:, 0] < 0).any() or (a[:, 1] <= a[:, 0]).any():
        return "cap_rings must be finite with 0 <= r_in < r_out"
    if (a[1:, 0] < a[:-1, 1]).any():
        return "cap_rings must be sorted outward and must not overlap"
    d = np.asarray(caps)[:, 2]
    if len(d) and (np.ptp(d) > 1e-9 or (len(a) and a[-1, 1] > 0.5 * d[0] + 1e-9)):
        return "cap_rings need caps of one diameter that holds every ring"
    return None
