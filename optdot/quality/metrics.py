"""QA measurements of a pattern: pair distances, order, spectrum, coverage, edge bands.

Distances are measured with shapely/GEOS (``STRtree`` ``dwithin`` queries) and scipy's
``cKDTree``, engines independent of the optimizer's cell grid; tests cross-check them
against a brute-force count. Every function returns its numbers; the pass/fail lines
are made in :mod:`optdot.quality.gate`. All lengths in mm unless a name says otherwise.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
import shapely
from scipy.ndimage import gaussian_filter
from scipy.spatial import cKDTree

from ..geometry.density import DensityMap
from ..geometry.domain import polygon_cell_fractions
from ..spatial.window import bounds


def psi6(xy: np.ndarray, tree: cKDTree | None = None) -> np.ndarray:
    """Six-fold bond order of each dot over its 6 nearest neighbours, ``[n]`` complex."""
    tree = tree or cKDTree(xy)
    k = min(7, len(xy))
    if k < 2:
        return np.zeros(len(xy), complex)
    _, idx = tree.query(xy, k=k)
    return psi6_of(xy, xy, idx)


def psi6_of(pts: np.ndarray, own: np.ndarray, idx: np.ndarray) -> np.ndarray:
    """ψ6 of each dot of ``own`` (``[m, 2]``) over its neighbours ``pts[idx[:, 1:]]``
    (``idx`` ``[m, k]``, column 0 the dot itself), ``[m]`` complex."""
    if idx.shape[1] < 2:
        return np.zeros(len(own), complex)
    v = pts[idx[:, 1:]] - own[:, None, :]
    return np.exp(6j * np.arctan2(v[..., 1], v[..., 0])).mean(axis=1)


def patch_coherence(
    xy: np.ndarray, psi: np.ndarray, patch: float = 2.0, min_dots: int = 50
) -> float:
    """Mean over ``patch``-mm squares of |mean psi6| (high = hexagonal grains)."""
    if len(xy) == 0:
        return 0.0
    x0, y0, x1, y1 = bounds(xy)
    grid = PatchGrid.over(np.array([x0, y0]), np.array([x1, y1]), patch)
    sums = grid.sums(xy, psi)
    return grid.coherence(*sums, total=complex(psi.sum()), n=len(xy), min_dots=min_dots)


@dataclass(frozen=True)
class PatchGrid:
    """Squares of ``patch`` mm on the global lattice ``floor(xy / patch)``, numbered
    ``kx * ny + ky`` from the corner ``(kx0, ky0)`` (the order of the lattice keys)."""

    patch: float
    kx0: int
    ky0: int
    nx: int
    ny: int

    @classmethod
    def over(cls, lo, hi, patch: float) -> PatchGrid:
        """The squares covering the extent ``lo``..``hi`` (``[2]`` mm each)."""
        k0 = np.floor(np.asarray(lo, float) / patch).astype(np.int64)
        k1 = np.floor(np.asarray(hi, float) / patch).astype(np.int64)
        return cls(patch, int(k0[0]), int(k0[1]), int(k1[0] - k0[0] + 1), int(k1[1] - k0[1] + 1))

    def sums(self, xy: np.ndarray, psi: np.ndarray):
        """``(count, sum Re psi, sum Im psi)`` per square, ``[nx * ny]`` each."""
        key = np.floor(xy / self.patch).astype(np.int64)
        idx = np.clip(key[:, 0] - self.kx0, 0, self.nx - 1) * self.ny + np.clip(
            key[:, 1] - self.ky0, 0, self.ny - 1
        )
        size = self.nx * self.ny
        return (
            np.bincount(idx, minlength=size),
            np.bincount(idx, psi.real, minlength=size),
            np.bincount(idx, psi.imag, minlength=size),
        )

    @staticmethod
    def coherence(cnt, re, im, total: complex, n: int, min_dots: int = 50) -> float:
        """Mean |mean psi6| over the squares holding ``min_dots`` or more (none: the
        |mean| of all ``n`` dots' psi6, whose sum is ``total``)."""
        ok = cnt >= min_dots
        if not ok.any():
            return float(abs(total / max(n, 1)))
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


def cell_area_sums(
    xy: np.ndarray, diameter: np.ndarray, uniform: bool, density: DensityMap
) -> np.ndarray:
    """Dot area per map cell of the dots whose centre lies in the map's box, ``[ny * nx]``:
    dot counts (int64) when ``uniform`` (multiply by one dot's area), else areas in mm².
    Sums over parts of a pattern add up to the whole pattern's."""
    inside = in_box(xy, density)
    cells = density.cell_index(xy[inside])
    size = density.grid.size
    if uniform:
        return np.bincount(cells, minlength=size)
    return np.bincount(cells, weights=np.pi * (0.5 * diameter[inside]) ** 2, minlength=size)


def in_box(xy: np.ndarray, density: DensityMap) -> np.ndarray:
    """``[n]`` bool: the centre lies in the map's box (edges included)."""
    return (
        (xy[:, 0] >= density.x0)
        & (xy[:, 0] <= density.x0 + density.width)
        & (xy[:, 1] >= density.y0)
        & (xy[:, 1] <= density.y0 + density.height)
    )


def nn_normalized(
    xy: np.ndarray, radius: np.ndarray, density: DensityMap, nn: np.ndarray
) -> np.ndarray:
    """Nearest-neighbour distances ``nn`` (``[n]`` mm) of dots at ``xy`` (``[n, 2]``) of
    ``radius`` (``[n]`` mm) in units of the local hexagonal spacing 2 r' at each dot's
    fill, ``[n]``: NaN for dots outside the map or where it is 0."""
    inside = in_box(xy, density)
    rho = np.where(inside, density.at(xy), np.nan)
    ok = inside & (rho > 0)
    out = np.full(len(xy), np.nan)
    spacing = 2 * radius[ok] * np.sqrt(math.pi / (2 * math.sqrt(3) * rho[ok]))
    out[ok] = nn[ok] / spacing
    return out


def coverage(
    sums: np.ndarray,
    uniform: float | None,
    n: int,
    nominal: float,
    outline,
    density: DensityMap,
    smoothing: float,
) -> tuple[dict[str, Any], np.ndarray, tuple[float, float, float, float]]:
    """Coverage against the map: per cell, and after Gaussian smoothing of ``smoothing`` mm.

    With an outline each cell counts only its share inside it.

    Args:
        sums: ``[ny * nx]`` of :func:`cell_area_sums` over the whole pattern.
        uniform: the one dot diameter when ``sums`` are counts, mm, else None.
        n: number of dots. nominal: nominal dot diameter, mm.
        outline: the panel outline (a :class:`~optdot.geometry.domain.Domain`) or None.

    Returns:
        ``(metrics, rel, extent)``: the numbers (``dots_expected``, ``dot_count_error``,
        ``coverage_rel_rms_smoothed``, ``coverage_rel_worst_smoothed``,
        ``coverage_worst_at_mm``, ``coverage_per_cell_rel_rms``), the ``[ny, nx]``
        relative error after smoothing and its extent ``(x0, x1, y0, y1)`` mm.
    """
    m: dict[str, Any] = {}
    ny, nx = density.shape
    cw, ch = density.cell_size
    area = sums * disc_area(uniform) if uniform is not None else sums
    got = area.reshape(ny, nx) / (cw * ch)
    if outline is None:
        frac = np.ones_like(density.grid)
    else:
        frac = outline.cell_fractions(density.x0, density.y0, cw, ch, nx, ny)
    target = density.grid * frac
    dot_area = disc_area(nominal)
    m["dots_expected"] = density.dot_count(dot_area, None if outline is None else frac)
    m["dot_count_error"] = (n - m["dots_expected"]) / max(m["dots_expected"], 1)
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


def edge_bands(box, outline, density: DensityMap) -> list[tuple[str, Any, float]]:
    """The 1 mm bands inside each edge: ``left``/``right``/``bottom``/``top`` of the box,
    or each loop of an outline (``outline``, ``hole 1``, ...).

    Returns:
        ``[(name, inside, want)]``: ``inside(xy [n, 2]) -> [n] bool`` selects the dots of
        the band, ``want`` is the dot area the map asks for in it, mm² (cell-exact).
    """
    if outline is not None:
        return _outline_bands(outline, density)
    x0, y0, x1, y1 = box
    bands = {
        "left": (x0, x0 + 1, y0, y1),
        "right": (x1 - 1, x1, y0, y1),
        "bottom": (x0, x1, y0, y0 + 1),
        "top": (x0, x1, y1 - 1, y1),
    }
    out = []
    for name, (bx0, bx1, by0, by1) in bands.items():

        def inside(xy, b=(bx0, bx1, by0, by1)):
            return (xy[:, 0] >= b[0]) & (xy[:, 0] <= b[1]) & (xy[:, 1] >= b[2]) & (xy[:, 1] <= b[3])

        out.append((name, inside, _target_area(density, (bx0, bx1, by0, by1))))
    return out


def disc_area(diameter: float) -> float:
    """Area of a dot of ``diameter`` mm, mm² (as ``pi r r``, the order QA always used)."""
    r = 0.5 * diameter
    return math.pi * r * r


def _outline_bands(dom, density: DensityMap) -> list[tuple[str, Any, float]]:
    """The 1 mm band inside each loop of the outline (outline, hole 1, ...), its target
    counted on the cells' exact shares of the band."""
    ny, nx = density.shape
    cw, ch = density.cell_size
    loops = [(p.exterior, p.interiors) for p in dom.polygons]
    named = []
    n_holes = 0
    for k, (ext, holes) in enumerate(loops):
        named.append((f"outline {k + 1}" if len(loops) > 1 else "outline", ext))
        for h in holes:
            n_holes += 1
            named.append((f"hole {n_holes}", h))
    out = []
    for name, ring in named:
        band = dom.geometry.intersection(shapely.LineString(ring.coords).buffer(1.0))
        shapely.prepare(band)
        frac = polygon_cell_fractions(band, density.x0, density.y0, cw, ch, nx, ny)
        want = float((density.grid * frac).sum() * cw * ch)

        def inside(xy, band=band):
            return shapely.contains_xy(band, xy[:, 0], xy[:, 1])

        out.append((name, inside, want))
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


@dataclass(frozen=True)
class SquareGrid:
    """``size``-mm squares from the box's corner (as many whole ones as fit, at least
    one), for finding the densest region: counts per part add up."""

    x0: float
    y0: float
    s: float
    nx: int
    ny: int

    @classmethod
    def of(cls, box, size: float) -> SquareGrid:
        x0, y0, x1, y1 = box
        s = min(size, x1 - x0, y1 - y0)
        return cls(x0, y0, s, max(1, int((x1 - x0) / s)), max(1, int((y1 - y0) / s)))

    def counts(self, xy: np.ndarray) -> np.ndarray:
        """``[nx, ny]`` dots per square."""
        h, _, _ = np.histogram2d(
            xy[:, 0],
            xy[:, 1],
            bins=(self.nx, self.ny),
            range=((self.x0, self.x0 + self.nx * self.s), (self.y0, self.y0 + self.ny * self.s)),
        )
        return h

    def densest(self, counts: np.ndarray) -> tuple[float, float, float, float]:
        """The square with the most dots, ``(x0, y0, x1, y1)`` mm."""
        i, j = np.unravel_index(np.argmax(counts), counts.shape)
        s = self.s
        return self.x0 + i * s, self.y0 + j * s, self.x0 + (i + 1) * s, self.y0 + (j + 1) * s
