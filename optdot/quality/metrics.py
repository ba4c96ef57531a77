"""QA measurements of a pattern: pair distances, order, spectrum, coverage, edge bands.

Distances are measured with shapely/GEOS (``STRtree`` ``dwithin`` queries) and scipy's
``cKDTree``, engines independent of the optimizer's cell grid; tests cross-check them
against a brute-force count. Every function returns its numbers; the pass/fail lines
are made in :mod:`optdot.quality.gate`. All lengths in mm unless a name says otherwise.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import shapely
from scipy.ndimage import gaussian_filter
from scipy.spatial import cKDTree

from ..geometry.density import DensityMap
from ..geometry.domain import polygon_cell_fractions
from ..pattern import Pattern


def close_pairs(xy: np.ndarray, distance: float) -> np.ndarray:
    """Pairs of centres strictly closer than ``distance``, via shapely STRtree.

    Returns:
        ``[K, 2]`` int64, i < j, sorted.
    """
    pts = shapely.points(xy)
    tree = shapely.STRtree(pts)
    i, j = tree.query(pts, predicate="dwithin", distance=distance)
    keep = i < j
    i, j = i[keep], j[keep]
    d = np.hypot(*(xy[i] - xy[j]).T)
    keep = d < distance
    p = np.stack([i[keep], j[keep]], axis=1).astype(np.int64)
    return p[np.lexsort((p[:, 1], p[:, 0]))] if len(p) else p


def psi6(xy: np.ndarray, tree: cKDTree | None = None) -> np.ndarray:
    """Six-fold bond order of each dot over its 6 nearest neighbours, ``[n]`` complex."""
    tree = tree or cKDTree(xy)
    k = min(7, len(xy))
    _, idx = tree.query(xy, k=k)
    if k < 2:
        return np.zeros(len(xy), complex)
    v = xy[idx[:, 1:]] - xy[:, None, :]
    return np.exp(6j * np.arctan2(v[..., 1], v[..., 0])).mean(axis=1)


def patch_coherence(
    xy: np.ndarray, psi: np.ndarray, patch: float = 2.0, min_dots: int = 50
) -> float:
    """Mean over ``patch``-mm squares of |mean psi6| (high = hexagonal grains)."""
    key = np.floor(xy / patch).astype(np.int64)
    _, inv = np.unique(key[:, 0] * 1_000_003 + key[:, 1], return_inverse=True)
    cnt = np.bincount(inv)
    re = np.bincount(inv, psi.real)
    im = np.bincount(inv, psi.imag)
    ok = cnt >= min_dots
    if not ok.any():
        return float(np.abs(psi.mean()))
    return float(np.mean(np.hypot(re[ok], im[ok]) / cnt[ok]))


def radial_spectrum(xy: np.ndarray, window: tuple[float, float, float, float], px: float):
    """Radially averaged power spectrum of the dot centres in ``window`` (mm).

    Returns:
        ``(freq [k] in 1/mm, power [k])``, power normalised so a Poisson pattern is ~1.
    """
    x0, y0, x1, y1 = window
    nx = max(8, int((x1 - x0) / px))
    ny = max(8, int((y1 - y0) / px))
    h, _, _ = np.histogram2d(xy[:, 0], xy[:, 1], bins=(nx, ny), range=((x0, x1), (y0, y1)))
    n = h.sum()
    if n < 10:
        return np.zeros(0), np.zeros(0)
    f = np.fft.fftshift(np.abs(np.fft.fft2(h - h.mean())) ** 2) / n
    ky = np.fft.fftshift(np.fft.fftfreq(ny, d=px))
    kx = np.fft.fftshift(np.fft.fftfreq(nx, d=px))
    kr = np.hypot(*np.meshgrid(kx, ky, indexing="ij"))
    dk = max(kx[1] - kx[0], ky[1] - ky[0])
    b = (kr / dk).astype(int).ravel()
    p = np.bincount(b, f.ravel()) / np.maximum(np.bincount(b), 1)
    freq = np.arange(len(p)) * dk
    m = freq <= 0.5 / px
    return freq[m][1:], p[m][1:]


def area_per_cell(pattern: Pattern, sel: np.ndarray, cells: np.ndarray, size: int) -> np.ndarray:
    """Dot area (mm²) of the selected dots summed per flat cell index, ``[size]``.

    Args:
        sel: ``[n]`` bool, the dots to count.
        cells: the selected dots' flat cell indices.
    """
    u = pattern.uniform_diameter
    if u is not None:
        return np.bincount(cells, minlength=size) * _disc_area(u)
    return np.bincount(cells, weights=pattern.areas[sel], minlength=size)


def in_box(xy: np.ndarray, density: DensityMap) -> np.ndarray:
    """``[n]`` bool: the centre lies in the map's box (edges included)."""
    return (
        (xy[:, 0] >= density.x0)
        & (xy[:, 0] <= density.x0 + density.width)
        & (xy[:, 1] >= density.y0)
        & (xy[:, 1] <= density.y0 + density.height)
    )


def nn_normalized(pattern: Pattern, density: DensityMap, nn: np.ndarray) -> np.ndarray:
    """Nearest-neighbour distances ``nn`` (``[n]`` mm) in units of the local hexagonal
    spacing 2 r' at each dot's fill, for the dots inside the map where it is > 0."""
    xy = pattern.xy
    inside = in_box(xy, density)
    rho = np.where(inside, density.at(xy), np.nan)
    ok = inside & (rho > 0)
    r0 = pattern.radius[ok]
    spacing = 2 * r0 * np.sqrt(math.pi / (2 * math.sqrt(3) * rho[ok]))
    return nn[ok] / spacing


def coverage(
    pattern: Pattern, density: DensityMap, smoothing: float
) -> tuple[dict[str, Any], np.ndarray, tuple[float, float, float, float]]:
    """Coverage against the map: per cell, and after Gaussian smoothing of ``smoothing`` mm.

    With an outline each cell counts only its share inside it.

    Returns:
        ``(metrics, rel, extent)``: the numbers (``dots_expected``, ``dot_count_error``,
        ``coverage_rel_rms_smoothed``, ``coverage_rel_worst_smoothed``,
        ``coverage_worst_at_mm``, ``coverage_per_cell_rel_rms``), the ``[ny, nx]``
        relative error after smoothing and its extent ``(x0, x1, y0, y1)`` mm.
    """
    xy = pattern.xy
    m: dict[str, Any] = {}
    inside = in_box(xy, density)
    ny, nx = density.shape
    cw, ch = density.cell_size
    cells = density.cell_index(xy[inside])
    got = area_per_cell(pattern, inside, cells, nx * ny).reshape(ny, nx) / (cw * ch)
    if pattern.outline is None:
        frac = np.ones_like(density.grid)
    else:
        frac = pattern.outline.cell_fractions(density.x0, density.y0, cw, ch, nx, ny)
    target = density.grid * frac
    dot_area = _disc_area(pattern.nominal_diameter)
    m["dots_expected"] = density.dot_count(dot_area, None if pattern.outline is None else frac)
    m["dot_count_error"] = (pattern.n - m["dots_expected"]) / max(m["dots_expected"], 1)
    sig = (smoothing / ch, smoothing / cw)
    gs = gaussian_filter(got, sig, mode="constant")
    ts = gaussian_filter(target, sig, mode="constant")
    w = gaussian_filter(frac, sig, mode="constant")
    inner = w > 0.25  # smoothing windows mostly inside the domain
    gs, ts = gs / np.where(inner, w, 1), ts / np.where(inner, w, 1)
    valid = (ts > 0.02) & inner & (frac > 0.5)
    rel = np.where(valid, (gs - ts) / np.where(valid, ts, 1), 0.0)
    extent = (density.x0, density.x0 + density.width, density.y0, density.y0 + density.height)
    rms = float(np.sqrt(np.mean(rel[valid] ** 2))) if valid.any() else 0.0
    iw = np.unravel_index(np.argmax(np.abs(rel)), rel.shape)
    m["coverage_rel_rms_smoothed"] = rms
    m["coverage_rel_worst_smoothed"] = float(rel[iw])
    m["coverage_worst_at_mm"] = [density.x0 + (iw[1] + 0.5) * cw, density.y0 + (iw[0] + 0.5) * ch]
    full = (target > 0) & (frac > 0.99)
    m["coverage_per_cell_rel_rms"] = float(
        np.sqrt(np.mean(((got - target)[full] / target[full]) ** 2)) if full.any() else 0.0
    )
    return m, rel, extent


def edge_bands(pattern: Pattern, density: DensityMap) -> dict[str, float | None]:
    """Dot area / target in the 1 mm band inside each edge: ``left``/``right``/``bottom``/
    ``top`` of the box, or each loop of an outline (``outline``, ``hole 1``, ...)."""
    if pattern.outline is not None:
        return _outline_bands(pattern, density)
    xy = pattern.xy
    band = {}
    x0, y0, x1, y1 = pattern.box
    bands = {
        "left": (x0, x0 + 1, y0, y1),
        "right": (x1 - 1, x1, y0, y1),
        "bottom": (x0, x1, y0, y0 + 1),
        "top": (x0, x1, y1 - 1, y1),
    }
    for name, (bx0, bx1, by0, by1) in bands.items():
        sel = (xy[:, 0] >= bx0) & (xy[:, 0] <= bx1) & (xy[:, 1] >= by0) & (xy[:, 1] <= by1)
        want = _target_area(density, (bx0, bx1, by0, by1))
        band[name] = float(_area_of(pattern, sel) / want) if want > 0 else None
    return band


def _disc_area(diameter: float) -> float:
    """Area of a dot of ``diameter`` mm, mm² (as ``pi r r``, the order QA always used)."""
    r = 0.5 * diameter
    return math.pi * r * r


def _area_of(pattern: Pattern, sel: np.ndarray) -> float:
    """Total dot area of the selected dots, mm² (count x area when sizes are uniform)."""
    u = pattern.uniform_diameter
    if u is not None:
        return sel.sum() * _disc_area(u)
    return float(pattern.areas[sel].sum())


def _outline_bands(pattern: Pattern, density: DensityMap) -> dict:
    """Dot area / target in the 1 mm band inside each loop of the outline (outline, hole 1,
    ...), counted on the cells' exact shares of the band."""
    dom = pattern.outline
    ny, nx = density.shape
    cw, ch = density.cell_size
    out = {}
    loops = [(p.exterior, p.interiors) for p in dom.polygons]
    named = []
    n_holes = 0
    for k, (ext, holes) in enumerate(loops):
        named.append((f"outline {k + 1}" if len(loops) > 1 else "outline", ext))
        for h in holes:
            n_holes += 1
            named.append((f"hole {n_holes}", h))
    for name, ring in named:
        band = dom.geometry.intersection(shapely.LineString(ring.coords).buffer(1.0))
        frac = polygon_cell_fractions(band, density.x0, density.y0, cw, ch, nx, ny)
        want = float((density.grid * frac).sum() * cw * ch)
        sel = shapely.contains_xy(band, pattern.xy[:, 0], pattern.xy[:, 1])
        out[name] = float(_area_of(pattern, sel) / want) if want > 0 else None
    return out


def _target_area(density: DensityMap, b) -> float:
    """Dot area the map asks for inside box ``b = (x0, x1, y0, y1)``, mm² (cell-exact)."""
    ny, nx = density.shape
    cw, ch = density.cell_size
    xs = density.x0 + np.arange(nx + 1) * cw
    ys = density.y0 + np.arange(ny + 1) * ch
    ox = np.clip(np.minimum(xs[1:], b[1]) - np.maximum(xs[:-1], b[0]), 0, None)
    oy = np.clip(np.minimum(ys[1:], b[3]) - np.maximum(ys[:-1], b[2]), 0, None)
    return float((density.grid * np.outer(oy, ox)).sum())


def densest_tile(pattern: Pattern, size: float) -> tuple[float, float, float, float]:
    x0, y0, x1, y1 = pattern.box
    s = min(size, x1 - x0, y1 - y0)
    nxb = max(1, int((x1 - x0) / s))
    nyb = max(1, int((y1 - y0) / s))
    h, _, _ = np.histogram2d(
        pattern.xy[:, 0],
        pattern.xy[:, 1],
        bins=(nxb, nyb),
        range=((x0, x0 + nxb * s), (y0, y0 + nyb * s)),
    )
    i, j = np.unravel_index(np.argmax(h), h.shape)
    return x0 + i * s, y0 + j * s, x0 + (i + 1) * s, y0 + (j + 1) * s
