"""A luminance simulation (``optdot simulate --json``) joined to a QA result, so the report
shows what the light guide does with these dots beside what a viewer would see of them."""

from __future__ import annotations

from typing import Any

import numpy as np

from .gate import QAResult

#: The figures carried into the QA metrics (the map goes to the plot arrays).
FIGURES = (
    "mode",
    "rays",
    "seed",
    "dots",
    "pattern",
    "efficiency",
    "efficiency_sigma",
    "shares",
    "uniformity_9point",
    "uniformity_9point_sigma",
    "spot_diameter_mm",
    "luminance_rms",
    "luminance_rms_noise",
    "luminance_structure",
    "rays_for_1pct_noise",
    "luminance_min",
    "luminance_max",
    "bin_mm",
    "border_mm",
    "viewing_area_mm",
    "outside_max",
    "outside_max_at_mm",
    "tolerance_band",
)


def attach_simulation(result: QAResult, doc: dict[str, Any], label: str) -> None:
    """Put the simulation ``doc`` (its ``luminance`` already an ``[ny, nx]`` array) into
    ``result``: figures in ``metrics["simulation"]``, the map in ``arrays["luminance"]``
    (a direct-lit stack's halo of one LED in ``arrays["halo"]``, the luminance's angles in
    ``arrays["angles"]``).
    A simulation of another pattern (another dot count) is marked, not refused."""
    figures = {k: doc.get(k) for k in FIGURES}
    figures["file"] = label
    dots = doc.get("dots")
    figures["same_pattern"] = dots is None or dots == result.metrics.get("dots")
    result.metrics["simulation"] = figures
    x0, y0, x1, y1 = (float(v) for v in doc["box_mm"])
    spots = np.array(doc.get("spots") or np.zeros((0, 3)), dtype=np.float64).reshape(-1, 3)
    result.arrays["luminance"] = (np.asarray(doc["luminance"]), (x0, x1, y0, y1), spots)
    if doc.get("angular_luminance") and (doc.get("angles") or {}).get("rays"):
        result.arrays["angles"] = doc["angular_luminance"]
        figures["angles"] = doc["angles"]
    if doc.get("halo"):  # one LED lit alone: drawn beside the luminance
        result.arrays["halo"] = doc["halo"]
        figures["halo"] = {k: v for k, v in doc["halo"].items() if k not in ("map", "profile")}
