"""The coverage of cut prisms against their real dots, band by band of distance from the
LEDs (issue 60: what `design` traces against what `generate` makes, near the LEDs).

Run: python benchmarks/coverage_bands.py [--fill 0.10 0.42] [--rays 2e6] [--orientation TEXT]

The guide is the tests' ``graded_guide`` (10 x 8 mm, 0.4 mm thick, two LEDs 1 mm wide on
its bottom edge at x = 2.5 and 7.5 mm; the map graded along y from ``--fill``'s first
value at the LEDs' edge to its second, in 1 mm rows) with cut 45° prisms 120 x 30 µm
(corners 5 µm; 60 µm deep) and ``--orientation`` as the ``[orientation]`` section
(default ``angle = 90``: one angle everywhere, the prisms' length along the light). It is
traced as the coverage (what ``design`` traces) and through its generated dots, with the
same rays and seed. Printed per band of y (mm from the LEDs' edge): the rays extracted
and those leaving within 10° of the normal, coverage against real, with the gap in sigma
(counts' Poisson noise).
"""

from __future__ import annotations

import argparse
import math
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
sys.path.insert(0, str(HERE.parent))
from _common import machine, peak_rss_mb  # noqa: E402

from optdot.config.schema import load_job  # noqa: E402
from optdot.optics.scene import scene_of  # noqa: E402
from optdot.optics.tables import EXTRACTED  # noqa: E402
from optdot.optics.trace import trace  # noqa: E402
from optdot.orchestration.pipeline import generate  # noqa: E402
from tests.conftest import graded_guide  # noqa: E402

DOTS = (
    'shape = "rounded_rectangle"\nlength = 0.120\nwidth = 0.030\ncorner_radius = 0.005\n'
    'profile = "prism"\nfacets = [45, 45]\ncut = true'
)
#: The bands' edges, mm from the LEDs' edge.
EDGES = (0.0, 0.5, 1.0, 2.0, 4.0, 8.0)


def _gap(a: int, b: int) -> float:
    """``a - b`` in sigma of their counts' Poisson noise."""
    return (a - b) / math.sqrt(a + b + 1)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--fill", type=float, nargs=2, default=(0.10, 0.42), help="map's ends")
    ap.add_argument("--rays", type=float, default=2e6, help="rays each trace")
    ap.add_argument("--orientation", default="angle = 90", help="[orientation] keys")
    a = ap.parse_args()
    print(machine())
    rays = int(a.rays)
    with tempfile.TemporaryDirectory() as tmp:
        more = "[orientation]\n" + a.orientation.replace("\\n", "\n")
        job = load_job(graded_guide(Path(tmp), tuple(a.fill), DOTS, more, optimize="gap = 0.005"))
        pattern = generate(job)
    print(
        f"fill {a.fill[0]} to {a.fill[1]}, [orientation] {a.orientation!r}: "
        f"{len(pattern.xy):,} dots"
    )
    counts = {}
    for name, scene in (
        ("coverage", scene_of(job.bench, rays)),
        ("real", scene_of(job.bench, rays, pattern)),
    ):
        t = time.perf_counter()
        fate, _, y, d = trace(3, 0, rays, scene)
        out = fate == EXTRACTED
        on = out & (d[:, 2] > math.cos(math.radians(10.0)))
        counts[name] = (np.histogram(y[out], EDGES)[0], np.histogram(y[on], EDGES)[0])
        sec = time.perf_counter() - t
        print(f"{name:>8}: extracted {out.mean():.4f}, within 10°: {on.sum():,}  ({sec:.1f} s)")
    print("band (mm)   extracted: coverage, real (sigma)   within 10°: coverage, real (sigma)")
    for i in range(len(EDGES) - 1):
        ec, er = counts["coverage"][0][i], counts["real"][0][i]
        oc, orr = counts["coverage"][1][i], counts["real"][1][i]
        print(
            f"{EDGES[i]:>4}-{EDGES[i + 1]:<4}  {ec:10,d} {er:10,d} ({_gap(ec, er):+5.1f})"
            f"      {oc:8,d} {orr:8,d} ({_gap(oc, orr):+5.1f})"
        )
    print(f"peak {peak_rss_mb():.0f} MB (one process)")


if __name__ == "__main__":
    main()
