"""Dot-size modulation on a dense LED-like map: one size against a diameter range.

Run: python benchmarks/sizes.py [--map ledcrop|ledcrop-issue] [--spacing MM]
     [--range LO HI] [--rule spacing|claim] [--seed N]

The map is ``ledcrop`` of ``benchmarks/formulations.py`` (10 x 15 mm, fill 0.45-0.55 over
most of it: where 46 µm dots cannot avoid pairs under 60 µm without ordering). Both runs
use the default formulation and the same QA: close pairs are edge gaps under 14 µm
(= centre distances under 60 µm for the 46 µm run). Prints one row per run: dots,
seconds, peak memory, collisions, close pairs (and their share of the fixed run's),
mean |psi6|, 2 mm coherence, coverage RMS after 1 mm smoothing, the fill integral's
error (sum of dot areas against the map's integral) and the number of distinct sizes.
Each run is a child process (peak memory = its own maximum RSS, with numba's kernels
loaded from their cache).
"""

from __future__ import annotations

import argparse
import multiprocessing
import resource
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).parent))
from formulations import ledcrop, ledcrop_issue  # noqa: E402

from optdot import generate, qa  # noqa: E402
from optdot.geometry.sizes import DotSizes  # noqa: E402


def run(job, label: str, base_close: int | None = None) -> tuple[str, int]:
    """One row, measured in a child process so its peak memory is its own (spawned:
    numba's thread pool does not survive a fork)."""
    with multiprocessing.get_context("spawn").Pool(1) as pool:
        return pool.apply(_run, (job, label, base_close))


def _run(job, label: str, base_close: int | None) -> tuple[str, int]:
    t0 = time.perf_counter()
    p = generate(job)
    secs = time.perf_counter() - t0
    r = qa(p, job)
    m = r.metrics
    d = job.density
    want = float(d.grid.sum()) * d.cell_size[0] * d.cell_size[1]
    fill_err = p.areas.sum() / want - 1.0
    close = m["pairs_below_close"]
    share = f"{close / base_close:.1%}" if base_close else "100 %"
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 2**20
    row = (
        f"| {label} | {p.n:,} | {secs:.1f} | {peak:.2f} | {m['pairs_below_collision']} | "
        f"{close:,} ({share}) | {m['psi6_local_mean']:.3f} | {m['psi6_coherence_2mm']:.3f} | "
        f"{m['coverage_rel_rms_smoothed'] * 100:.3f} % | {fill_err * 100:+.3f} % | "
        f"{len(np.unique(p.diameter))} |"
    )
    return row, close


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--map", default="ledcrop", choices=("ledcrop", "ledcrop-issue"))
    ap.add_argument("--range", nargs=2, type=float, default=(0.030, 0.120))
    ap.add_argument("--spacing", type=float, default=0.150)
    ap.add_argument("--rule", default="spacing", choices=("spacing", "claim"))
    ap.add_argument("--seed", type=int, default=1)
    a = ap.parse_args()
    fixed = ledcrop() if a.map == "ledcrop" else ledcrop_issue()
    fixed = fixed.with_overrides(seed=a.seed)
    lo, hi = a.range
    spacing = a.spacing if a.rule == "spacing" else None
    sized = replace(fixed, diameter=lo, sizes=DotSizes(lo, hi, spacing=spacing))
    print(
        f"**python benchmarks/sizes.py --map {a.map} --range {lo} {hi} --rule {a.rule}"
        + (f" --spacing {spacing}" if spacing else "")
        + f" --seed {a.seed}**\n"
    )
    print(
        "| run | dots | s | peak GiB | collisions | close pairs (vs 46 µm) | psi6 | "
        "coherence 2 mm | coverage RMS | fill integral | sizes |"
    )
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    row, base = run(fixed, "46 µm fixed")
    print(row, flush=True)
    what = f"spacing {spacing * 1e3:g} µm" if spacing else "claim rule"
    row, _ = run(sized, f"{lo * 1e3:g}–{hi * 1e3:g} µm, {what}", base)
    print(row)


if __name__ == "__main__":
    main()
