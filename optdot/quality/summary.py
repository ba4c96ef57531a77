"""The QA numbers and plot data of a measured pattern: the two passes' sums
(:mod:`optdot.quality.sums`) turned into JSON-ready metrics, the places of failures and
the bounded arrays the report draws."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from ..geometry.density import DensityMap
from ..geometry.orientation import Orientation
from ..geometry.shapes import Footprints
from .metrics import coverage, disc_area, radial_spectrum
from .seams import seam_finish
from .source import Source
from .sums import FirstSums, SecondSums, cat
from .texture import band_mean, structure_factor
from .wall_profile import WallProfile


@dataclass
class Measured:
    """Numbers for the gate and the report.

    Attributes:
        metrics: JSON-ready numbers (see :func:`measure`).
        where: ``{check: [[x, y], ...]}`` places of failures, mm (first 20).
        arrays: plot data: ``overview`` (image, extent), ``close_mid`` / ``collision_mid``
            / ``defects`` (``[m, 2]`` mm, at most :data:`MAX_MARKS`), ``zoom`` (xy, d,
            segments ``[s, 2, 2]``), ``nn_hist`` (counts, µm edges), ``coverage_error``
            (rel ``[ny, nx]``, extent), ``spectrum`` (freq, power), ``tile``, ``rings`` (the
            outline's loops; none for a box).
    """

    metrics: dict[str, Any]
    where: dict[str, list[list[float]]]
    arrays: dict[str, Any]


def summarize(
    src: Source,
    density: DensityMap | None,
    smoothing: float,
    close: float,
    collision: float,
    f: FirstSums,
    s: SecondSums,
    gaps: tuple[float, float] | None = None,
    field: Orientation | None = None,
) -> Measured:
    n = src.n
    u = src.uniform_diameter
    m: dict[str, Any] = {"dots": n, "box_mm": list(src.box)}
    if u is not None:
        m["diameter_mm"] = u
    else:
        d = np.concatenate(f.diameters)
        m["diameter_mm"] = {
            "min": float(d.min()),
            "median": float(np.median(d)),
            "max": float(d.max()),
        }
    where: dict[str, list[list[float]]] = {}
    arrays: dict[str, Any] = {"rings": [] if src.outline is None else src.outline.rings()}
    if gaps is None:
        m["collision_distance_mm"] = collision
        m["close_distance_mm"] = close
    else:
        m["collision_gap_mm"] = gaps[1]
        m["close_gap_mm"] = gaps[0]
    if not src.kind.round:
        m["shape"] = {
            "kind": src.kind.name,
            "gaps": "exact edge-to-edge distances of the footprints",
            "shapely_checked_pairs": s.shapely_pairs,
            "shapely_disagreements": s.shapely_disagree,
        }
    if f.angle_hist is not None:
        m["orientation"] = {"histogram_5deg_from_-90": f.angle_hist.tolist()}
        if field is not None and field.follows_position:
            m["orientation"]["field_error_max_deg"] = f.field_error_max
            m["orientation"]["field_error_mean_deg"] = f.field_error_sum / max(n, 1)
    m["pairs_below_collision"] = s.pairs_collision
    m["pairs_below_close"] = s.pairs_close
    m["dots_in_close_pairs_fraction"] = float(s.close_dots / max(n, 1))
    arrays["collision_mid"] = cat(s.collision_mid, (2,))
    arrays["close_mid"] = cat(s.close_mid, (2,))
    where["collisions"] = _where(arrays["collision_mid"])
    nn = s.nn
    ok = n > 1
    m["nn_min_mm"] = float(nn.min()) if ok else None
    m["nn_percentiles_mm"] = _percentiles(nn) if ok else {}
    arrays["nn_hist"] = _histogram(nn * 1e3) if ok and np.isfinite(nn).all() else None
    if src.outline is not None:
        m["outside_outline_or_in_holes"] = f.outside
        m["edge_margin_mm"] = src.outline.edge_margin
        m["edge_margin_violations"] = f.margin_violations
    m["protruding"] = f.protruding
    where["protruding"] = _where(cat(f.where_protruding, (2,)))
    arrays["defects"] = cat(f.defects, (2,))
    m["psi6_local_mean"] = float(s.psi_abs_sum / n) if n else 0.0
    grid, cnt, re, im = s.patches
    m["psi6_coherence_2mm"] = grid.coherence(cnt, re, im, total=s.psi_sum, n=n)
    nn_norm = None
    if density is not None:
        m["in_empty_cells"] = f.empty
        where["in_empty"] = _where(cat(f.where_empty, (2,)))
        nn_norm = np.concatenate(s.nn_norm) if s.nn_norm else np.zeros(0)
        m["nn_normalized_percentiles"] = _percentiles(nn_norm) if len(nn_norm) else {}
        cov, rel, extent = coverage(
            f.cells, u, n, src.nominal_diameter, src.outline, density, smoothing
        )
        m.update(cov)
        arrays["coverage_error"] = (rel, extent)
        where["coverage"] = [cov["coverage_worst_at_mm"]]
        one = disc_area(u) if u is not None else 1.0
        m["edge_band_coverage_ratio"] = {
            name: float(got * one / want) if want > 0 else None
            for (name, _, want), got in zip(f.bands, f.band_sums, strict=True)
        }
        if f.walls is not None:
            arrays["walls"] = f.walls.result()
            m["walls"] = _walls(arrays["walls"], src.nominal_diameter)
    if src.tiling is not None and s.seams is not None:
        m["seams"] = seam_finish(s.seams, *src.tiling, density)
    if len(src.counts) > 1:
        m["qa_requeried_dots"] = s.requeried  # k-NN re-queried with a wider halo
    grain = _grain(cat(s.grain_xy, (2,)), s.grain_window, density)
    if grain is not None:
        m["grain"] = grain
    tile = f.squares.densest(f.square_counts)
    freq, power = radial_spectrum(cat(s.window_xy, (2,)), tile, px=src.nominal_diameter / 4)
    arrays["spectrum"] = (freq, power)
    arrays["tile"] = tile
    arrays["overview"] = (f.overview, f.overview_extent)
    zoom = Footprints.concat(s.zoom_d, src.kind)
    arrays["zoom"] = (cat(s.zoom_xy, (2,)), zoom, cat(s.segments, (2, 2)))
    if len(power):
        lo = freq > 0.3 / (np.median(nn) if n > 1 else 1)
        m["spectrum_peak_ratio"] = (
            float(power[lo].max() / np.median(power[lo])) if lo.any() else None
        )
    return Measured(metrics=m, where=where, arrays=arrays)


#: Advisory level of the worst wall band (coverage / map - 1), unless the bands hold so few
#: dots that their own noise is larger.
WALL_BAND_LIMIT = 0.03


def _walls(prof: WallProfile, nominal: float) -> dict[str, Any]:
    """The wall profile's numbers: each band's coverage / map - 1, the worst band and the
    advisory limit ``max(WALL_BAND_LIMIT, 1 / sqrt(dots in the emptiest band))``."""
    rel = prof.relative
    worst, at = prof.worst()
    dots = prof.target * prof.area / disc_area(nominal)
    fewest = float(np.min(dots[prof.area > 0])) if (prof.area > 0).any() else 0.0
    return {
        "band_mm": float(prof.edges[-1] - prof.edges[-2]),
        "first_band_mm": float(prof.edges[1]),
        "reach_mm": float(prof.edges[-1]),
        "relative": [None if not np.isfinite(v) else float(v) for v in rel],
        "worst_relative": worst,
        "worst_band_from_mm": at,
        "band_dots_min": fewest,
        "limit": float(max(WALL_BAND_LIMIT, 1.0 / np.sqrt(max(fewest, 1.0)))),
    }


def _histogram(values: np.ndarray, bins: int = 100) -> tuple[np.ndarray, np.ndarray]:
    """``np.histogram`` of ``values`` over bins that always exist: numpy refuses 100 bins
    over a range too narrow for its floats (two dots 3 m apart, nearest-neighbour
    distances equal to 1 part in 10¹⁵), so the range is widened to at least a part in
    10⁹ of its magnitude."""
    lo, hi = float(values.min()), float(values.max())
    width = max(hi - lo, 1e-9 * max(abs(lo), abs(hi), 1.0))
    edges = np.linspace(lo, lo + width, bins + 1)
    counts, _ = np.histogram(np.clip(values, lo, edges[-1]), bins=edges)
    return counts, edges


def _percentiles(v: np.ndarray) -> dict[str, float]:
    """The 1st, 5th, 50th and 95th percentiles of ``v``, keyed by their number."""
    qs = (1, 5, 50, 95)
    return {str(q): float(x) for q, x in zip(qs, np.percentile(v, qs), strict=True)}


def _where(points: np.ndarray, limit: int = 20) -> list[list[float]]:
    return [[round(float(x), 6), round(float(y), 6)] for x, y in points[:limit]]


def _grain(xy: np.ndarray, window, density: DensityMap | None) -> dict | None:
    """The long-wavelength structure factor on the densest region (a square of
    ``measure.GRAIN_MM``): S averaged over k·a 0.3-1 (wavelengths of 6-20 spacings, the
    grain a viewer sees through a diffuser) and 1-3; Poisson points give 1, the single
    process on a uniform map ~1e-5 (BENCHMARKS.md). None when the window holds
    too few dots or spacings to resolve k·a 0.3."""
    if window is None or len(xy) < 2000:
        return None
    ka, sf, a = structure_factor(xy, window)
    if min(window[2] - window[0], window[3] - window[1]) < 40 * a:
        return None
    out = {
        "window_mm": [float(v) for v in window],
        "dots": int(len(xy)),
        "spacing_mm": float(a),
        "s_ka_0.3_1": band_mean(ka, sf, 0.3, 1.0),
        "s_ka_1_3": band_mean(ka, sf, 1.0, 3.0),
    }
    if density is not None:
        cw, ch = density.cell_size
        ix0 = int(np.clip((window[0] - density.x0) // cw, 0, density.shape[1] - 1))
        ix1 = int(np.clip((window[2] - density.x0) // cw, 0, density.shape[1] - 1))
        iy0 = int(np.clip((window[1] - density.y0) // ch, 0, density.shape[0] - 1))
        iy1 = int(np.clip((window[3] - density.y0) // ch, 0, density.shape[0] - 1))
        g = density.grid[iy0 : iy1 + 1, ix0 : ix1 + 1]
        out["fill_range"] = [float(g.min()), float(g.max())]
    return out
