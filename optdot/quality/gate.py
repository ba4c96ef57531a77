"""The QA gate: measure a pattern (:mod:`optdot.quality.measure`) and judge it against
the job's thresholds, one :class:`Check` per line of the verdict."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from ..config.job import QAParams
from ..geometry.density import DensityMap
from ..pattern import Pattern
from .measure import Source, dataset_source, measure, pattern_source
from .metrics import close_pairs

__all__ = ["Check", "QAResult", "close_pairs", "judge", "run_qa", "run_qa_dataset"]


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
    pattern: Pattern,
    density: DensityMap | None,
    params: QAParams,
    collision: float,
    collision_gap: float = 0.0,
) -> QAResult:
    """Measure an in-memory ``pattern`` and apply the gate.

    Args:
        pattern: the dots.
        density: the target map (None: density, empty-cell and psi-normalised metrics skipped).
        params: thresholds.
        collision: centre distance below which dots of one size collide, mm.
        collision_gap: edge gap below which dots of varying size collide, mm.
    """
    return judge(pattern_source(pattern), density, params, collision, collision_gap)


def run_qa_dataset(
    ds,
    density: DensityMap | None,
    params: QAParams,
    collision: float,
    box=None,
    outline=True,
    collision_gap: float = 0.0,
) -> QAResult:
    """Measure a partitioned dataset tile by tile (bounded memory) and apply the gate.

    Args:
        ds: an opened :class:`~optdot.io.dataset.Dataset` (checksums verified here).
        box, outline: the panel (default: the dataset's own).
        Others as :func:`run_qa`.
    """
    ds.verify()
    return judge(dataset_source(ds, box, outline), density, params, collision, collision_gap)


def judge(
    src: Source,
    density: DensityMap | None,
    params: QAParams,
    collision: float,
    collision_gap: float = 0.0,
) -> QAResult:
    """Measure ``src`` (:func:`optdot.quality.measure.measure`) and make the gate lines.

    Dots of one size are judged by centre distances (``collision``, and
    ``params.close_distance``, or the diameter + ``params.close_gap`` when that is set);
    dots of varying size by edge gaps (``collision_gap``, ``params.close_gap`` or
    :data:`~optdot.config.job.DEFAULT_CLOSE_GAP`).
    """
    close = params.close_distance
    u = src.uniform_diameter
    if u is not None and params.close_gap is not None:
        close = u + params.close_gap
    gaps = None
    if u is None:
        gaps = (params.effective_close_gap, collision_gap)
    got = measure(src, density, params.smoothing, close, collision, gaps, params.viewing)
    m, w = got.metrics, got.where
    if gaps is None:
        collide_text = f"pairs closer than {collision * 1e3:.1f} µm (collisions)"
        close_text = f"share of dots in pairs closer than {close * 1e3:.1f} µm"
    else:
        collide_text = f"pairs with an edge gap under {gaps[1] * 1e3:.1f} µm (collisions)"
        close_text = f"share of dots in pairs with an edge gap under {gaps[0] * 1e3:.1f} µm"
    checks = [
        Check(
            collide_text,
            m["pairs_below_collision"],
            params.max_collisions,
            m["pairs_below_collision"] <= params.max_collisions,
            w["collisions"],
        ),
        Check(
            close_text,
            m["dots_in_close_pairs_fraction"],
            params.max_close_fraction,
            m["dots_in_close_pairs_fraction"] <= params.max_close_fraction,
        ),
        Check(
            "dots protruding from the panel"
            if src.outline is None
            else "dots protruding from the outline or in holes / keep-outs",
            m["protruding"],
            params.max_protruding,
            m["protruding"] <= params.max_protruding,
            w["protruding"],
        ),
        Check(
            "psi6 coherence over 2 mm patches (moiré risk)",
            m["psi6_coherence_2mm"],
            params.max_psi6_coherence,
            m["psi6_coherence_2mm"] <= params.max_psi6_coherence,
        ),
    ]
    if density is not None:
        checks.append(
            Check(
                "dots in zero-density cells",
                m["in_empty_cells"],
                params.max_in_empty,
                m["in_empty_cells"] <= params.max_in_empty,
                w["in_empty"],
            )
        )
        rms = m["coverage_rel_rms_smoothed"]
        checks.append(
            Check(
                f"coverage error RMS after {params.smoothing:g} mm smoothing",
                rms,
                params.max_coverage_rms,
                rms <= params.max_coverage_rms,
                w["coverage"],
            )
        )
    if params.max_jnd is not None and "visibility" in m:
        vis = m["visibility"]
        checks.append(
            Check(
                f"largest |JND| at {params.viewing.describe()}",
                vis["max_jnd"],
                params.max_jnd,
                vis["max_jnd"] <= params.max_jnd,
                w["visibility"],
            )
        )
    return QAResult(metrics=m, checks=checks, arrays=got.arrays)


def _num(v) -> str:
    return f"{v:.4g}" if isinstance(v, float) else str(v)
