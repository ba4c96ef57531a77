"""A designed map's LED fronts: does the pattern follow them, and does the light agree?

Run: python benchmarks/led_front.py [JOB] [--rays 2e7] [--steps 1 6] [--out DIR]

JOB is a job with a designed map (``optdot design``'s ``map.toml``); without one, the
lgp sample is designed first (the README's walk-through). For each count of wide-pass
steps in ``--steps`` (1: the pass as it was, one linear step with the first passes' cap;
the default formulation's count with its own cap otherwise) the pattern is generated in
this process and judged three ways:

- **QA's eye model**: largest |JND| and regions over 1 JND (``optdot qa``'s numbers).
- **Coverage against the map** through a 1 mm Gaussian (the stack's default blur) on a
  0.025 mm raster, independent of the QA grid: RMS and worst relative error within 6 mm
  of the LED edge, and the profile across the middle LED.
- **The tracer** (``simulate``, the independent judge): the real dots against the map's
  coverage at 0.25 mm bins, both blurred by 1 mm; the worst relative difference within
  6 mm of the LED edge (the panel's first 0.5 mm left out: the LEDs' own hot spots) and
  the Monte Carlo noise of that difference.

Prints dots, seconds and the figures per variant.
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from scipy.ndimage import gaussian_filter

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
from _common import machine, peak_rss_mb  # noqa: E402

import optdot.relax.formulation as formulation  # noqa: E402
from optdot.config.schema import load_job  # noqa: E402
from optdot.optics.design import design  # noqa: E402
from optdot.optics.simulate import simulate  # noqa: E402
from optdot.optics.writing import write_design  # noqa: E402
from optdot.orchestration.pipeline import generate, qa  # noqa: E402

RASTER = 0.025  # mm
BLUR = 1.0  # mm
NEAR = 6.0  # mm from the LED edge
BIN = 0.25  # mm, tracer bins


def designed_lgp(out: Path) -> Path:
    """The lgp sample designed as the README does (``optdot design``, default settings)."""
    job = load_job(HERE.parent / "samples" / "lgp" / "job.toml", need_map=False)
    t = time.perf_counter()
    got = design(job.bench)
    write_design(got, job.bench, out / "map.csv", None, out / "map.toml")
    print(f"designed lgp in {time.perf_counter() - t:.1f} s")
    return out / "map.toml"


def coverage_error(job, xy: np.ndarray, area: float) -> np.ndarray:
    """``[ny, nx]`` coverage / map - 1 through a ``BLUR`` Gaussian on the raster."""
    x0, y0, x1, y1 = job.box
    nx, ny = round((x1 - x0) / RASTER), round((y1 - y0) / RASTER)
    h, _, _ = np.histogram2d(xy[:, 1], xy[:, 0], bins=[ny, nx], range=[[y0, y1], [x0, x1]])
    cov = gaussian_filter(h * area / RASTER**2, BLUR / RASTER, mode="mirror")
    want = gaussian_filter(job.density.resampled(x0, y0, RASTER, RASTER, nx, ny), BLUR / RASTER,
                           mode="mirror")  # fmt: skip
    return cov / np.maximum(want, 1e-12) - 1.0


def traced(job, pattern, rays: int) -> np.ndarray:
    """Extracted rays per ``BIN`` bin over the panel (``[nby, nbx]``)."""
    return simulate(job.bench, rays, seed=11, dots=pattern, bin_mm=BIN).counts.astype(np.float64)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("job", nargs="?", type=Path)
    ap.add_argument("--rays", type=float, default=2e7)
    ap.add_argument("--steps", type=int, nargs="+", default=[1, 6])
    ap.add_argument("--out", type=Path, default=None)
    args = ap.parse_args()
    print(machine())
    out = args.out or Path(tempfile.mkdtemp(prefix="led_front_"))
    out.mkdir(parents=True, exist_ok=True)
    path = args.job or designed_lgp(out)
    job = load_job(path)
    guide = job.light_guide
    rays = int(args.rays)
    base = formulation.PRESETS["optdot"]
    edge_rows = None
    t = time.perf_counter()
    coverage = traced(job.bench, None, rays) if rays else None
    if rays:
        print(f"coverage mode: {rays:,} rays in {time.perf_counter() - t:.1f} s")
    for steps in args.steps:
        cap = 0.0 if steps == 1 else base.lowpass_last_cap
        form = dataclasses.replace(base, lowpass_last_steps=steps, lowpass_last_cap=cap)
        formulation.PRESETS["optdot"] = form
        t = time.perf_counter()
        pattern = generate(job)
        seconds = time.perf_counter() - t
        formulation.PRESETS["optdot"] = base
        vis = qa(pattern, job).metrics["visibility"]
        err = coverage_error(job, pattern.xy, float(np.pi * job.diameter**2 / 4))
        near = np.arange(err.shape[0]) * RASTER < NEAR
        front = err[near]
        print(
            f"steps {steps}: {len(pattern.xy):,} dots in {seconds:.1f} s; QA largest |JND| "
            f"{vis['max_jnd']:.2f} at {vis['max_jnd_at_mm']}, {vis['blobs_over_1_jnd']} over 1; "
            f"coverage/map - 1 (1 mm blur) within {NEAR:g} mm of the LED edge: RMS "
            f"{100 * np.sqrt(np.mean(front**2)):.3f} %, worst {100 * np.abs(front).max():.2f} %"
        )
        leds = [p for row in guide.leds for p in row.positions] if guide else []
        if leds:
            mid = leds[len(leds) // 2]
            col = int(mid / RASTER)
            ys = np.arange(0.25, 6, 0.5)
            prof = " ".join(f"{100 * err[int(y / RASTER), col + 15]:+.2f}" for y in ys)
            print(f"  across the LED at x = {mid + 15 * RASTER:g} mm, y = 0.25..5.75: {prof} %")
        if rays:
            t = time.perf_counter()
            dots = traced(job.bench, pattern, rays)
            s = BLUR / BIN
            a = gaussian_filter(dots, s, mode="mirror")
            b = gaussian_filter(coverage, s, mode="mirror")
            diff = a / np.maximum(b, 1e-12) - 1
            # noise of a blurred count ratio: both counts Poisson
            w2 = 1.0 / (4 * np.pi * s**2)  # sum of a normalised 2-D Gaussian's squared weights
            noise = np.sqrt(w2 * (1 / np.maximum(a, 1) + 1 / np.maximum(b, 1)))
            y = (np.arange(dots.shape[0]) + 0.5) * BIN
            rows = (y > 0.5) & (y < NEAR)
            if edge_rows is None:
                edge_rows = rows
            k = np.unravel_index(np.argmax(np.abs(diff[rows])), diff[rows].shape)
            print(
                f"  traced through the real dots ({rays:,} rays, {time.perf_counter() - t:.1f} s): "
                f"dots / coverage - 1 (1 mm blur) within 0.5..{NEAR:g} mm of the LED edge: RMS "
                f"{100 * np.sqrt(np.mean(diff[rows] ** 2)):.3f} %, worst "
                f"{100 * diff[rows][k]:+.2f} % at x = {(k[1] + 0.5) * BIN:.2f} mm "
                f"(noise {100 * float(np.median(noise[rows])):.2f} % RMS)"
            )
    print(f"peak memory {peak_rss_mb():.0f} MB")


if __name__ == "__main__":
    main()
