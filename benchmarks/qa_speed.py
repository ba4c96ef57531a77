"""QA time on a generated pattern: python benchmarks/qa_speed.py [--dots 1e6]

Generates a synthetic direct-lit pattern (as benchmarks/scaling.py), then times
``run_qa`` (all metrics, pair counts by cKDTree) and the HTML + JSON report.
"""

from __future__ import annotations

import argparse
import math
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import machine, peak_rss_mb  # noqa: E402

from optdot.config.schema import Job  # noqa: E402
from optdot.geometry.density import DensityMap  # noqa: E402
from optdot.orchestration.pipeline import generate  # noqa: E402
from optdot.quality.gate import run_qa  # noqa: E402
from optdot.quality.report import write_html, write_json  # noqa: E402


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--dots", type=float, default=1e6)
    n = int(ap.parse_args().dots)
    d, fill = 0.046, 0.22
    area = n * math.pi * (d / 2) ** 2 / fill
    w = math.sqrt(area * 16 / 9)
    h = area / w
    g = np.full((max(4, int(h / 0.5)), max(4, int(w / 0.5))), fill)
    job = Job(width=w, height=h, density=DensityMap(g, w, h), diameter=d)
    p = generate(job)
    print(f"# {machine()}")
    t = time.perf_counter()
    r = run_qa(p, job.density, job.qa, job.collision_distance)
    t_qa = time.perf_counter() - t
    with tempfile.TemporaryDirectory() as tmp:
        t = time.perf_counter()
        write_json(r, Path(tmp) / "r.json")
        write_html(r, Path(tmp) / "r.html")
        t_rep = time.perf_counter() - t
    print("dots | qa seconds | report seconds | verdict | peak RSS MB")
    verdict = r.verdict
    print(f"{p.n} | {t_qa:.1f} | {t_rep:.1f} | {verdict} | {peak_rss_mb():.0f}")


if __name__ == "__main__":
    main()
