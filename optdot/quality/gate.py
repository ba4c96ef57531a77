"""The QA gate: measure a pattern (:mod:`optdot.quality.measure`) and judge it against
the job's thresholds, one :class:`Check` per line of the verdict.

The verdict has three values. **FAIL**: a gating check failed (collisions, protrusion,
dots in empty cells, coverage, moiré, and the JND limit when ``qa.max_jnd`` is set);
the command exits 1 and ``export`` writes nothing. **PASS WITH WARNINGS**: every gating
check passed, but an advisory one did not (what a viewer will see over ``qa.warn_jnd``,
tile seams that differ from the tile interiors) or checks were skipped (no job: no map
to judge coverage, empty cells or visibility against); exit 0, the warnings printed and
in the report. **PASS**: everything checked, nothing to warn about.
"""

from __future__ import annotations

import numbers
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..config.job import QAParams
from ..geometry.density import DensityMap
from ..geometry.domain import Domain
from ..geometry.orientation import Orientation
from ..pattern import DotSource
from .conformance import DotRule
from .measure import measure
from .source import Source, source_of

__all__ = ["Check", "QAResult", "caps_check", "jnd_text", "judge", "run_qa"]


@dataclass
class Check:
    """One gate line: name, measured value, allowed limit, pass flag and where it fails."""

    name: str
    value: float
    limit: float
    passed: bool
    where: list[list[float]] = field(default_factory=list)
    unit: str = ""
    advisory: bool = False


@dataclass
class QAResult:
    """Everything QA measured (``metrics``), the gate lines (``checks``) and arrays for plots."""

    metrics: dict[str, Any]
    checks: list[Check]
    arrays: dict[str, Any]

    skipped: list[str] = field(default_factory=list)
    provenance: dict[str, Any] = field(default_factory=dict)

    @property
    def passed(self) -> bool:
        """Every gating check passed (advisory ones may not have)."""
        return all(c.passed for c in self.checks if not c.advisory)

    @property
    def warnings(self) -> list[Check]:
        """The advisory checks that did not pass."""
        return [c for c in self.checks if c.advisory and not c.passed]

    @property
    def verdict(self) -> str:
        """``"FAIL"``, ``"PASS WITH WARNINGS"`` (advisory checks over their level, or
        checks skipped) or ``"PASS"``."""
        if not self.passed:
            return "FAIL"
        return "PASS WITH WARNINGS" if self.warnings or self.skipped else "PASS"

    def __repr__(self) -> str:
        n = self.metrics.get("dots", "?")
        bad = [c.name for c in self.checks if not c.passed]
        return f"<QAResult {self.verdict}: {n} dots, {len(self.checks)} checks, not passed: {bad}>"

    def failures(self) -> str:
        """The failed checks as one line: ``name: value > limit; ...``."""
        return "; ".join(
            f"{c.name}: {number_text(c.value)} > {number_text(c.limit)}"
            for c in self.checks
            if not c.passed and not c.advisory
        )

    def to_json(self) -> dict[str, Any]:
        """The verdict, the checks and the metrics as JSON-ready data."""
        return {
            "verdict": self.verdict,
            "provenance": self.provenance,
            "warnings": [c.name for c in self.warnings],
            "skipped": self.skipped,
            "checks": [c.__dict__ for c in self.checks],
            "metrics": self.metrics,
        }


#: Randomly turned dots: the most ``-log10`` of the chance (chi-square, 35 degrees of
#: freedom) that uniform angles spread as far from uniform as theirs (6: one in a
#: million), and the fewest dots it is judged on (five to a 5° bin). A job's seeded angles
#: are uniform: a mask whose angles follow anything else (another job's field) fails.
RANDOM_MAX_RARITY = 6.0
RANDOM_MIN_DOTS = 180

#: Largest angle a shaped dot may be off its orientation field, degrees.
MAX_FIELD_ERROR_DEG = 0.5


def run_qa(
    dots: DotSource,
    density: DensityMap | None,
    params: QAParams,
    collision: float,
    collision_gap: float = 0.0,
    box=None,
    outline: Domain | None | bool = True,
    area: tuple[float, float, float, float] | None = None,
    orientation: Orientation | None = None,
    ink: float | None = None,
    rule: DotRule | None = None,
) -> QAResult:
    """Measure ``dots`` (a pattern in memory, or a dataset tile by tile in bounded
    memory, its checksums verified first) and apply the gate.

    Args:
        dots: any :class:`~optdot.pattern.DotSource`.
        density: the target map (None: density, empty-cell and psi-normalised metrics skipped).
        params: thresholds.
        collision: centre distance below which dots of one size collide, mm.
        collision_gap: edge gap below which dots of varying size collide, mm.
        box, outline: the panel (default: the dots' own; True keeps their outline).
        area: ``(x0, y0, x1, y1)`` mm, the part of the panel a viewer sees (the job's
            ``viewing_area``): visibility is judged there; None: the whole panel.
        orientation: the field shaped dots should follow (the job's), or None.
        ink: the printed film's ink contrast (the job's :attr:`~optdot.config.job.Job.ink`:
            its luminance goes as ``1 - ink * coverage``), or None for a guide's dots.
        rule: the footprints the job draws (kind, sizes): a dot that is not one of them
            fails the gate; None (no job) leaves them unchecked.
    """
    dots.verify()
    src = source_of(dots, box, outline)
    return judge(src, density, params, collision, collision_gap, area, orientation, ink, rule)


def judge(
    src: Source,
    density: DensityMap | None,
    params: QAParams,
    collision: float,
    collision_gap: float = 0.0,
    area: tuple[float, float, float, float] | None = None,
    orientation: Orientation | None = None,
    ink: float | None = None,
    rule: DotRule | None = None,
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
    got = measure(
        src,
        density,
        params.smoothing,
        close,
        collision,
        gaps,
        params.viewing,
        area,
        orientation,
        ink,
        rule,
    )
    m, w = got.metrics, got.where
    skipped: list[str] = []
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
    own = m.get("footprints")
    if own is not None:
        first = own["first_not_the_jobs"]
        checks.append(
            Check(
                f"dots whose footprint is not the job's {own['job']}"
                + (f" (the first: {first})" if first else ""),
                own["not_the_jobs"],
                0,
                own["not_the_jobs"] == 0,
                w["footprints"],
            )
        )
    shape = m.get("shape")
    if shape:
        checks.append(
            Check(
                f"near pairs where shapely's distance disagrees with the exact gap "
                f"(of {shape['shapely_checked_pairs']} checked)",
                shape["shapely_disagreements"],
                0,
                shape["shapely_disagreements"] == 0,
            )
        )
    turned = m.get("orientation") or {}
    field_limit = MAX_FIELD_ERROR_DEG + (rule.angle_slack_deg() if rule is not None else 0.0)
    if "field_error_max_deg" in turned:
        turned_back = turned["field_error_max_deg"] > 179.0  # directions: a half turn off
        checks.append(
            Check(
                "largest angle of a dot off the orientation field where it stands, degrees"
                + (
                    " (a prism whose facets differ, turned half a turn, faces away from its "
                    "LED; a DXF holds outlines, not which way prisms point: check the "
                    "GDSII, OASIS or pattern file)"
                    if turned_back
                    else ""
                ),
                turned["field_error_max_deg"],
                field_limit,
                turned["field_error_max_deg"] <= field_limit,
            )
        )
    hist = turned.get("histogram_5deg_from_-90")
    random_field = orientation is not None and not orientation.follows_position
    if random_field and hist is not None and sum(hist) >= RANDOM_MIN_DOTS:
        rare = -np.log10(max(_uniform_p(np.asarray(hist, np.float64)), 1e-300))
        checks.append(
            Check(
                "random angles: how unlikely their spread is from uniform ones, -log10 of "
                "the chance (chi-square of their 5° histogram)",
                float(rare),
                RANDOM_MAX_RARITY,
                bool(rare <= RANDOM_MAX_RARITY),
            )
        )
    elif random_field and hist is not None:
        skipped.append(f"random angles' spread (under {RANDOM_MIN_DOTS} shaped dots)")
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
    if "visibility" in m:
        vis = m["visibility"]
        gated = params.max_jnd is not None
        limit = params.max_jnd if gated else params.warn_jnd
        checks.append(
            Check(
                f"largest |JND|{' in the viewing area' if area else ''} at "
                f"{params.viewing.describe()}" + ("" if gated else " (advisory: a viewer sees it)"),
                vis["max_jnd"],
                limit,
                vis["max_jnd"] <= limit,
                w["visibility"],
                advisory=not gated,
            )
        )
    walls = m.get("walls")
    if walls and walls["band_dots_min"] > 0:
        checks.append(
            Check(
                f"coverage / map - 1 in the worst {walls['band_mm']:g} mm band within "
                f"{walls['reach_mm']:g} mm of a wall (advisory: layering at edges)",
                walls["worst_relative"],
                walls["limit"],
                bool(abs(walls["worst_relative"]) <= walls["limit"]),
                advisory=True,
            )
        )
    seams = m.get("seams") or {}
    if seams:
        differ = [k for k, v in seams["measures"].items() if not v["passed"]]
        checks.append(
            Check(
                "tile-seam measures that differ from the tile interiors (advisory)",
                len(differ),
                0,
                not differ,
                advisory=True,
            )
        )
    if density is None:
        skipped += [
            "coverage error (no target map: give --job)",
            "dots in zero-density cells (no target map: give --job)",
            "visibility (no target map: give --job)",
        ]
    return QAResult(metrics=m, checks=checks, arrays=got.arrays, skipped=skipped)


#: How far a printed cap may sit from the job's, or differ in diameter, mm (1 µm).
CAP_TOLERANCE = 1e-3


def caps_check(
    printed: np.ndarray,
    wanted: np.ndarray,
    printed_rings: np.ndarray | None = None,
    wanted_rings: np.ndarray | None = None,
) -> Check:
    """The gate line of caps over LEDs (:mod:`optdot.geometry.caps`): how many of the job's
    caps ``wanted`` ``[m, 3]`` (x, y, diameter mm) the dots' file does not print as a cap
    of that diameter within :data:`CAP_TOLERANCE`, plus caps it prints that the job does
    not ask for. An LED without its cap is a bright spot; one too many a dark one. Graded
    caps (``*_rings`` ``[k, 2]`` ``(r_in, r_out)`` mm; None: solid) must print the job's
    rings within the tolerance, else every cap counts."""
    from scipy.spatial import cKDTree

    from ..geometry.caps import ring_table

    def table(caps: np.ndarray, rings: np.ndarray | None) -> np.ndarray:
        d = float(caps[:, 2].max()) if len(caps) else 0.0
        return ring_table(d, None) if rings is None else np.asarray(rings).reshape(-1, 2)

    def unmatched(a: np.ndarray, b: np.ndarray) -> np.ndarray:
        if len(b) == 0:
            return np.ones(len(a), bool)
        d, k = cKDTree(b[:, :2]).query(a[:, :2])
        return (d > CAP_TOLERANCE) | (np.abs(a[:, 2] - b[k, 2]) > CAP_TOLERANCE)

    missing = unmatched(wanted, printed)
    extra = unmatched(printed, wanted)
    a, b = table(printed, printed_rings), table(wanted, wanted_rings)
    graded = printed_rings is not None or wanted_rings is not None
    if (
        graded
        and len(printed)
        and len(wanted)
        and not (a.shape == b.shape and np.all(np.abs(a - b) <= CAP_TOLERANCE))
    ):
        missing[:] = True  # every cap prints other rings than the job's
    where = [list(map(float, r[:2])) for r in (*wanted[missing], *printed[extra])][:10]
    bad = int(missing.sum() + extra.sum())
    return Check(
        f"caps over LEDs missing, extra, of another size or other rings (of {len(wanted)} "
        "the job prints)",
        bad,
        0,
        bad == 0,
        where,
    )


def number_text(v) -> str:
    """A measured number for a message: 4 significant digits for floats (numpy's too,
    never their repr such as ``np.float64(0.875)``), integers as they are."""
    if isinstance(v, bool):
        return str(v)
    if isinstance(v, numbers.Integral):
        return str(int(v))
    if isinstance(v, numbers.Real):
        return f"{float(v):.4g}"
    return str(v)


def jnd_text(v: float, limit: float = 1.0) -> str:
    """A JND for a reader: 2 decimals, more where 2 would put it on the other side of
    ``limit`` or onto it (0.9973 is "0.997", not "1.00" beside "0 regions over 1")."""
    v = float(v)
    text = ""
    for digits in range(2, 7):
        text = f"{v:.{digits}f}"
        shown = float(text)
        if (shown < limit) == (v < limit) and (shown > limit) == (v > limit):
            return text
    return text


def _uniform_p(hist: np.ndarray) -> float:
    """The chance that uniform angles spread over ``hist``'s bins at least as unevenly
    (Pearson's chi-square against equal bins)."""
    from scipy.stats import chi2

    e = hist.sum() / len(hist)
    return float(chi2.sf(((hist - e) ** 2 / e).sum(), len(hist) - 1))
