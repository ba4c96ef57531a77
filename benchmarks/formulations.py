"""Formulations compared (issue 8): close pairs vs irregularity vs coverage.

Run: python benchmarks/formulations.py [--map ledcrop|led|tsuno|chokka] [--max-iter 200]
                                       [--only NAME ...]

Every variant starts from the same initial dots (seed 1) and runs ``max_iter`` L-BFGS
iterations with no early stop. Metrics are QA's, on the pattern as shipped (after the
guarantee pass): pairs < 46 µm (always 0 after the pass; the raw count before it is in
its own column), pairs < 60 µm, psi6 local mean (~0.3 random, 1 lattice), psi6
coherence over 2 mm patches (hexagonal grains: moiré), coverage RMS after 1 mm Gaussian
smoothing (visible roughness), and seconds.

``ledcrop`` is the issue's LED-like crop: a 10 x 15 mm edge-lit map, fill 0.08 at the
LED edge rising to 0.55 (hex spacing 59 µm: a perfect lattice is itself under 60 µm
there), two hot spots; ~30k dots.
"""

from __future__ import annotations

import argparse
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
from _common import machine  # noqa: E402

from optdot.density import DensityMap  # noqa: E402
from optdot.formulation import PRESETS, Formulation  # noqa: E402
from optdot.generate import generate  # noqa: E402
from optdot.job import Job, load_job  # noqa: E402
from optdot.neighbors import pairs_within  # noqa: E402
from optdot.qa import run_qa  # noqa: E402

ROOT = HERE.parent
#: the v0.1 default: paper circles + hard core at the dot diameter, hex panel, empty term
BASE = Formulation(w_hard=10.0, hex_panel=True, empty_term=True)
VARIANTS: dict[str, Formulation] = {
    "paper": PRESETS["paper"],
    "optdot (default: x1.05, core 0.93 a in 59..64 um w15, containers 3.5r)": PRESETS["optdot"],
    "paper, radius x0.9": Formulation(radius_factor=0.9),
    "paper + 60 um gap everywhere (w 10)": Formulation(w_hard=10.0, gap=0.060, gap_share=0.0),
    "optdot v0.1 (hard core at 46 um)": BASE,
    "optdot + gap where spacing >= 60/0.85": replace(BASE, gap=0.060, gap_share=0.85),
    "optdot + gap where spacing >= 60/0.95": replace(BASE, gap=0.060, gap_share=0.95),
    "optdot, radius x0.9": replace(BASE, radius_factor=0.9),
    "optdot, dense x0.85 (rho 0.25->0.5)": replace(BASE, dense_factor=0.85),
    "optdot, bidisperse 10%": replace(BASE, polydispersity=0.10),
    "optdot, bidisperse 15%, radius x0.9": replace(BASE, polydispersity=0.15, radius_factor=0.9),
    "optdot, bidisperse 10%, dense x0.85": replace(BASE, polydispersity=0.10, dense_factor=0.85),
    "optdot, staged x1.15 then x0.9": replace(BASE, stages=((0.5, 1.15), (0.5, 0.9))),
    "optdot, staged x0.85 then x1.0": replace(BASE, stages=((0.5, 0.85), (0.5, 1.0))),
    "optdot, containers 6r": replace(BASE, container_factor=6.0),
    "optdot, containers 3r": replace(BASE, container_factor=3.0),
    "optdot + core 0.90 a (w 10)": replace(BASE, core_share=0.90),
    "optdot + core 0.93 a (w 10)": replace(BASE, core_share=0.93),
    "optdot + core 0.93 a (w 100)": replace(BASE, core_share=0.93, w_hard=100.0),
    "optdot + core 0.96 a (w 100)": replace(BASE, core_share=0.96, w_hard=100.0),
    "optdot + core 0.93 a (w 100), bidisperse 5%": replace(
        BASE, core_share=0.93, w_hard=100.0, polydispersity=0.05
    ),
    "optdot + core 0.93 a (w 15)": replace(BASE, core_share=0.93, w_hard=15.0),
    "optdot + core 0.93 a (w 20)": replace(BASE, core_share=0.93, w_hard=20.0),
    "optdot + core 0.94 a (w 10)": replace(BASE, core_share=0.94),
    "optdot + core 0.93 a (w 15), containers 3r": replace(
        BASE, core_share=0.93, w_hard=15.0, container_factor=3.0
    ),
    "optdot + core 0.93 a (w 15), containers 3.5r": replace(
        BASE, core_share=0.93, w_hard=15.0, container_factor=3.5
    ),
    "optdot + core 0.93 a (w 15), containers 3.5r, x1.1": replace(
        BASE, core_share=0.93, w_hard=15.0, container_factor=3.5, radius_factor=1.1
    ),
    "optdot + core 0.93 a (w 15), containers 3.5r, x1.05 (no floor, no cap)": replace(
        BASE, core_share=0.93, w_hard=15.0, container_factor=3.5, radius_factor=1.05
    ),
    "same, core >= 59 um (floor), no cap": replace(PRESETS["optdot"], core_cap=0.0),
    "same, core in 59..68 um": replace(PRESETS["optdot"], core_cap=0.068),
}


def ledcrop() -> Job:
    w, h, cell = 10.0, 15.0, 0.25
    y, x = np.meshgrid((np.arange(60) + 0.5) * cell, (np.arange(40) + 0.5) * cell, indexing="ij")
    light = sum(np.exp(-((x - c) ** 2 + (y + 0.3) ** 2) / (2 * 1.6**2)) for c in (2.5, 7.5))
    g = np.clip(0.08 + 0.52 * (1 - np.exp(-y / 5.0)) - 0.07 * light, 0.03, 0.55)
    return Job(width=w, height=h, density=DensityMap(g, w, h), diameter=0.046, name="ledcrop")


def measure(job: Job, form: Formulation) -> str:
    t = time.perf_counter()
    p = generate(job, keep_stages=True, formulation=form)
    s = time.perf_counter() - t
    m = run_qa(p, job.density, job.qa, job.collision_distance).metrics
    raw = len(pairs_within(p.stats["relaxed_xy"], job.min_distance))
    return (
        f"{raw:,} | {m['pairs_below_collision']} | {m['pairs_below_close']:,} | "
        f"{m['psi6_local_mean']:.2f} | {m['psi6_coherence_2mm']:.3f} | "
        f"{100 * m['coverage_rel_rms_smoothed']:.2f} | {s:.1f}"
    )


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--map", default="ledcrop")
    ap.add_argument("--max-iter", type=int, default=200)
    ap.add_argument("--only", nargs="*", default=None)
    a = ap.parse_args()
    if a.map == "ledcrop":
        job = ledcrop()
    else:
        job = load_job(ROOT / "samples" / a.map / "job.toml")
    job = replace(job, optimize=replace(job.optimize, max_iter=a.max_iter, ftol=0.0))
    print(f"# {machine()}")
    print(f"# python benchmarks/formulations.py --map {a.map}: {job.n_dots:,} dots, seed 1")
    print(
        "variant | raw pairs<46um | pairs<46um | pairs<60um | psi6 mean | "
        "psi6 coherence 2mm | coverage RMS % | seconds"
    )
    print("---|---|---|---|---|---|---|---")
    for name, form in VARIANTS.items():
        if a.only and not any(o in name for o in a.only):
            continue
        print(f"{name} | {measure(job, form)}", flush=True)


if __name__ == "__main__":
    main()
