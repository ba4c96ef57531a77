"""The QA gate: measure a pattern (:mod:`optdot.quality.metrics`) and judge it against
the job's thresholds, one :class:`Check` per line of the verdict."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy.spatial import cKDTree

from ..config.job import QAParams
from ..geometry.density import DensityMap
from ..geometry.domain import box_protruding
from ..pattern import Pattern
from .metrics import (
    close_pairs,
    coverage,
    densest_tile,
    edge_bands,
    nn_normalized,
    patch_coherence,
    psi6,
    radial_spectrum,
)
from .seams import seam_metrics


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
        """Every check passed."""
        return all(c.passed for c in self.checks)

    def failures(self) -> str:
        """The failed checks as one line: ``name: value > limit; ...``."""
        return "; ".join(
            f"{c.name}: {_num(c.value)} > {_num(c.limit)}" for c in self.checks if not c.passed
        )

    def to_json(self) -> dict[str, Any]:
        """The verdict, the checks and the metrics as JSON-ready data."""
        return {
            "verdict": "PASS" if self.passed else "FAIL",
            "checks": [c.__dict__ for c in self.checks],
            "metrics": self.metrics,
        }


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
    u = pattern.uniform_diameter
    m: dict[str, Any] = {
        "dots": n,
        "diameter_mm": u if u is not None else _spread(pattern.diameter),
        "box_mm": list(pattern.box),
    }
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
        out = box_protruding(xy, pattern.box, r0)
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
        nn_norm = nn_normalized(pattern, density, nn)
        arrays["nn_norm"] = nn_norm
        m["nn_normalized_percentiles"] = (
            {str(q): float(np.percentile(nn_norm, q)) for q in (1, 5, 50, 95)}
            if len(nn_norm)
            else {}
        )
        cov, rel, extent = coverage(pattern, density, params.smoothing)
        m.update(cov)
        arrays["coverage_error"] = (rel, extent)
        rms = cov["coverage_rel_rms_smoothed"]
        checks.append(
            Check(
                f"coverage error RMS after {params.smoothing:g} mm smoothing",
                rms,
                params.max_coverage_rms,
                rms <= params.max_coverage_rms,
                [cov["coverage_worst_at_mm"]],
            )
        )
        m["edge_band_coverage_ratio"] = edge_bands(pattern, density)

    tiling = pattern.meta.get("tiling")
    if isinstance(tiling, dict) and "xs" in tiling and "ys" in tiling:
        flag = np.zeros(n, bool)
        flag[near.ravel()] = True
        nn_n = arrays.get("nn_norm")
        m["seams"] = seam_metrics(
            xy,
            pattern.areas,
            np.asarray(tiling["xs"], float),
            np.asarray(tiling["ys"], float),
            flag,
            np.abs(psi),
            nn_n if nn_n is not None and len(nn_n) == n else None,
            density,
        )

    tile = densest_tile(pattern, 2.0)
    freq, power = radial_spectrum(xy, tile, px=pattern.nominal_diameter / 4)
    arrays["spectrum"] = (freq, power)
    arrays["tile"] = tile
    if len(power):
        lo = freq > 0.3 / (np.median(nn) if n > 1 else 1)
        m["spectrum_peak_ratio"] = (
            float(power[lo].max() / np.median(power[lo])) if lo.any() else None
        )
    return QAResult(metrics=m, checks=checks, arrays=arrays)


def _spread(d: np.ndarray) -> dict[str, float]:
    return {"min": float(d.min()), "median": float(np.median(d)), "max": float(d.max())}


def _where(points: np.ndarray, limit: int = 20) -> list[list[float]]:
    return [[round(float(x), 6), round(float(y), 6)] for x, y in points[:limit]]


def _num(v) -> str:
    return f"{v:.4g}" if isinstance(v, float) else str(v)
