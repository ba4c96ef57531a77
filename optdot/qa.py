"""QA metrics of a pattern and the pass/fail gate (``optdot qa``).

Distances are measured with shapely/GEOS (``STRtree`` ``dwithin`` queries), an engine
independent of the optimizer's cell grid; tests cross-check both and a brute-force count.
All lengths in mm unless a name says otherwise.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import shapely
from scipy.ndimage import gaussian_filter
from scipy.spatial import cKDTree

from .density import DensityMap
from .domain import polygon_cell_fractions
from .job import QAParams
from .legalize import protruding_mask
from .pattern import Pattern


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


@dataclass
class Check:
    """One gate line: name, measured value, allowed limit, pass flag and where it fails."""

    name: str
    value: float
    limit: float
    passed: bool
    where: list[list[float]] = field(default_factory=list)
    unit: str = ""


@dataclass
class QAResult:
    """Everything QA measured (``metrics``), the gate lines (``checks``) and arrays for plots."""

    metrics: dict[str, Any]
    checks: list[Check]
    arrays: dict[str, Any]

    @property
    def passed(self) -> bool:
        return all(c.passed for c in self.checks)

    def to_json(self) -> dict[str, Any]:
        return {
            "verdict": "PASS" if self.passed else "FAIL",
            "checks": [c.__dict__ for c in self.checks],
            "metrics": self.metrics,
        }


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


def run_qa(
    pattern: Pattern, density: DensityMap | None, params: QAParams, collision: float
) -> QAResult:
    """Measure ``pattern`` and apply the gate.

    Args:
        pattern: the dots.
        density: the target map (None: density, empty-cell and psi-normalised metrics skipped).
        params: thresholds.
        collision: centre distance below which dots collide, mm.
    """
    xy = pattern.xy
    n = pattern.n
    r0 = pattern.radius
    m: dict[str, Any] = {"dots": n, "diameter_mm": pattern.diameter, "box_mm": list(pattern.box)}
    arrays: dict[str, Any] = {}
    checks: list[Check] = []

    col = close_pairs(xy, collision)
    near = close_pairs(xy, params.close_distance)
    m["collision_distance_mm"] = collision
    m["close_distance_mm"] = params.close_distance
    m["pairs_below_collision"] = int(len(col))
    m["pairs_below_close"] = int(len(near))
    close_dots = np.unique(near.ravel()) if len(near) else np.zeros(0, np.int64)
    m["dots_in_close_pairs_fraction"] = float(len(close_dots) / max(n, 1))
    arrays["collisions"] = col
    arrays["close"] = near
    checks.append(
        Check(
            f"pairs closer than {collision * 1e3:.1f} µm (collisions)",
            len(col),
            params.max_collisions,
            len(col) <= params.max_collisions,
            _where(0.5 * (xy[col[:, 0]] + xy[col[:, 1]])) if len(col) else [],
        )
    )
    checks.append(
        Check(
            f"share of dots in pairs closer than {params.close_distance * 1e3:.1f} µm",
            m["dots_in_close_pairs_fraction"],
            params.max_close_fraction,
            m["dots_in_close_pairs_fraction"] <= params.max_close_fraction,
        )
    )

    tree = cKDTree(xy)
    nn = tree.query(xy, k=2)[0][:, 1] if n > 1 else np.full(n, np.inf)
    arrays["nn"] = nn
    m["nn_min_mm"] = float(nn.min()) if n > 1 else None
    m["nn_percentiles_mm"] = (
        {str(q): float(np.percentile(nn, q)) for q in (1, 5, 50, 95)} if n > 1 else {}
    )

    if pattern.outline is None:
        out = protruding_mask(xy, pattern.box, r0)
        what = "dots protruding from the panel"
    else:
        out = pattern.outline.protruding(xy, r0, margin=False)
        m["outside_outline_or_in_holes"] = int((~pattern.outline.contains(xy)).sum())
        m["edge_margin_mm"] = pattern.outline.edge_margin
        m["edge_margin_violations"] = int(pattern.outline.protruding(xy, r0).sum())
        what = "dots protruding from the outline or in holes / keep-outs"
    m["protruding"] = int(out.sum())
    arrays["protruding"] = np.flatnonzero(out)
    checks.append(
        Check(
            what,
            int(out.sum()),
            params.max_protruding,
            int(out.sum()) <= params.max_protruding,
            _where(xy[out]),
        )
    )

    psi = psi6(xy, tree)
    m["psi6_local_mean"] = float(np.abs(psi).mean()) if n else 0.0
    m["psi6_coherence_2mm"] = patch_coherence(xy, psi, 2.0)
    checks.append(
        Check(
            "psi6 coherence over 2 mm patches (moiré risk)",
            m["psi6_coherence_2mm"],
            params.max_psi6_coherence,
            m["psi6_coherence_2mm"] <= params.max_psi6_coherence,
        )
    )

    if density is not None:
        _density_checks(pattern, density, params, nn, m, arrays, checks)

    tile = _densest_tile(pattern, 2.0)
    freq, power = radial_spectrum(xy, tile, px=pattern.diameter / 4)
    arrays["spectrum"] = (freq, power)
    arrays["tile"] = tile
    if len(power):
        lo = freq > 0.3 / (np.median(nn) if n > 1 else 1)
        m["spectrum_peak_ratio"] = (
            float(power[lo].max() / np.median(power[lo])) if lo.any() else None
        )
    return QAResult(metrics=m, checks=checks, arrays=arrays)


def _density_checks(pattern, density, params, nn, m, arrays, checks) -> None:
    xy = pattern.xy
    r0 = pattern.radius
    dot_area = math.pi * r0 * r0
    inside = (
        (xy[:, 0] >= density.x0)
        & (xy[:, 0] <= density.x0 + density.width)
        & (xy[:, 1] >= density.y0)
        & (xy[:, 1] <= density.y0 + density.height)
    )
    rho = np.where(inside, density.at(xy), np.nan)
    empty = density.empty_mask(xy)
    m["in_empty_cells"] = int(empty.sum())
    arrays["in_empty"] = np.flatnonzero(empty)
    checks.append(
        Check(
            "dots in zero-density cells",
            int(empty.sum()),
            params.max_in_empty,
            int(empty.sum()) <= params.max_in_empty,
            _where(xy[empty]),
        )
    )
    # nearest neighbour in units of the local hexagonal spacing 2 r'
    ok = inside & (rho > 0)
    spacing = 2 * r0 * np.sqrt(math.pi / (2 * math.sqrt(3) * rho[ok]))
    nn_norm = nn[ok] / spacing
    arrays["nn_norm"] = nn_norm
    m["nn_normalized_percentiles"] = (
        {str(q): float(np.percentile(nn_norm, q)) for q in (1, 5, 50, 95)} if len(nn_norm) else {}
    )
    # coverage per cell; with an outline each cell counts only its share inside it
    ny, nx = density.shape
    cw, ch = density.cell_size
    cells = density.cell_index(xy[inside])
    got = np.bincount(cells, minlength=nx * ny).reshape(ny, nx) * dot_area / (cw * ch)
    if pattern.outline is None:
        frac = np.ones_like(density.grid)
    else:
        frac = pattern.outline.cell_fractions(density.x0, density.y0, cw, ch, nx, ny)
    target = density.grid * frac
    m["dots_expected"] = density.dot_count(dot_area, None if pattern.outline is None else frac)
    m["dot_count_error"] = (pattern.n - m["dots_expected"]) / max(m["dots_expected"], 1)
    sig = (params.smoothing / ch, params.smoothing / cw)
    gs = gaussian_filter(got, sig, mode="constant")
    ts = gaussian_filter(target, sig, mode="constant")
    w = gaussian_filter(frac, sig, mode="constant")
    inner = w > 0.25  # smoothing windows mostly inside the domain
    gs, ts = gs / np.where(inner, w, 1), ts / np.where(inner, w, 1)
    valid = (ts > 0.02) & inner & (frac > 0.5)
    rel = np.where(valid, (gs - ts) / np.where(valid, ts, 1), 0.0)
    arrays["coverage_error"] = (
        rel,
        (density.x0, density.x0 + density.width, density.y0, density.y0 + density.height),
    )
    rms = float(np.sqrt(np.mean(rel[valid] ** 2))) if valid.any() else 0.0
    iw = np.unravel_index(np.argmax(np.abs(rel)), rel.shape)
    worst_xy = [density.x0 + (iw[1] + 0.5) * cw, density.y0 + (iw[0] + 0.5) * ch]
    m["coverage_rel_rms_smoothed"] = rms
    m["coverage_rel_worst_smoothed"] = float(rel[iw])
    m["coverage_worst_at_mm"] = worst_xy
    full = (target > 0) & (frac > 0.99)
    m["coverage_per_cell_rel_rms"] = float(
        np.sqrt(np.mean(((got - target)[full] / target[full]) ** 2)) if full.any() else 0.0
    )
    checks.append(
        Check(
            f"coverage error RMS after {params.smoothing:g} mm smoothing",
            rms,
            params.max_coverage_rms,
            rms <= params.max_coverage_rms,
            [worst_xy],
        )
    )
    # coverage in a 1 mm band along each edge vs target
    if pattern.outline is not None:
        m["edge_band_coverage_ratio"] = _outline_bands(pattern, density, dot_area)
        return
    band = {}
    x0, y0, x1, y1 = pattern.box
    bands = {
        "left": (x0, x0 + 1, y0, y1),
        "right": (x1 - 1, x1, y0, y1),
        "bottom": (x0, x1, y0, y0 + 1),
        "top": (x0, x1, y1 - 1, y1),
    }
    for name, (bx0, bx1, by0, by1) in bands.items():
        got = ((xy[:, 0] >= bx0) & (xy[:, 0] <= bx1) & (xy[:, 1] >= by0) & (xy[:, 1] <= by1)).sum()
        want = _target_area(density, (bx0, bx1, by0, by1))
        band[name] = float(got * dot_area / want) if want > 0 else None
    m["edge_band_coverage_ratio"] = band


def _outline_bands(pattern: Pattern, density: DensityMap, dot_area: float) -> dict:
    """Dot area / target in the 1 mm band inside each loop of the outline (outline, hole 1,
    ...), counted on the cells' exact shares of the band."""
    import shapely

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
        got = int(shapely.contains_xy(band, pattern.xy[:, 0], pattern.xy[:, 1]).sum())
        out[name] = float(got * dot_area / want) if want > 0 else None
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


def _densest_tile(pattern: Pattern, size: float) -> tuple[float, float, float, float]:
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


def _where(points: np.ndarray, limit: int = 20) -> list[list[float]]:
    return [[round(float(x), 6), round(float(y), 6)] for x, y in points[:limit]]
