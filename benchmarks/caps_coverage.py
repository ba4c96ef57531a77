"""Caps over the LEDs of the Lambertian direct-lit stack, in the coverage mode (issue 38).

Run: python benchmarks/caps_coverage.py [--caps 0 0.8 1.0] [--graded] [--fill-max 0.7]
         [--cell 0.5] [--smoothing 1] [--rays 4e7]

The issue's direct-lit stack with Lambertian LEDs (``backlight.py direct --profile
lambertian``: 60 x 40 mm, 5 mm pitch, 1.5 mm optical distance) stops at min/max 0.575
with real dots: right over each LED the film needs a fill of about 0.8, more than random
dots that keep QA's gap reach. A cap (``[backlight.leds] cap``, :mod:`optdot.geometry.caps`)
prints that spot as a disc of solid ink; the dots keep out of it and a ring of QA's close
gap. For each cap diameter (0: none) the map is designed (``design()``, default settings
but ``--fill-max``), then traced in the coverage mode (the caps as exact discs, the dots'
coverage around them) with ``--rays`` rays in 0.5 mm bins; printed: design seconds, the
issue's uniformity (min/max over the panel less 5 mm) with a bin's noise, 9-point,
efficiency, and the luminance of the inner LEDs' pitch cells folded onto one (10 x 10
bins of 0.5 mm, the LED at the centre) with the fill under it. ``--graded`` prints the
caps as rings the design sizes (``cap_ink = "design"``) and prints the bands' ink. The
real dots of one setting: ``backlight.py direct --cap D [--graded]``.
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
from backlight import DIRECT, INK_AND_DIFFUSER, figures  # noqa: E402

from optdot.config.schema import load_job  # noqa: E402
from optdot.geometry.caps import ring_table  # noqa: E402
from optdot.optics.design import design  # noqa: E402
from optdot.optics.scene import Coverage  # noqa: E402
from optdot.optics.simulate import simulate  # noqa: E402


def folded(a: np.ndarray, per: int) -> np.ndarray:
    """``a`` over the inner pitch cells (one pitch in from every edge) averaged onto one
    cell of ``per`` x ``per`` bins."""
    ny, nx = a.shape
    inner = a[per : ny - per, per : nx - per]
    return inner.reshape(inner.shape[0] // per, per, inner.shape[1] // per, per).mean(axis=(0, 2))


def run(
    cap: float,
    rays: int,
    out: Path,
    fill_max: float | None = None,
    cell: float | None = None,
    graded: bool = False,
    smoothing: float | None = None,
) -> None:
    out.mkdir(parents=True, exist_ok=True)
    path = out / "job.toml"
    text = DIRECT.format(profile="lambertian", w=60.0, h=40.0)
    if cap > 0:
        ink = 'cap_ink = "design"\n' if graded else ""
        text = text.replace(
            'profile = "lambertian"\n', f'profile = "lambertian"\ncap = {cap}\n{ink}'
        )
    design_sec = "[design]\n"
    if fill_max is not None:
        design_sec += f"fill_range = [0.0, {fill_max}]\n"
    if cell is not None:
        design_sec += f"cell = {cell}\n"
    if smoothing is not None:
        design_sec += f"smoothing = {smoothing}\n"
    path.write_text(text + INK_AND_DIFFUSER + design_sec)
    job = load_job(path, need_map=False)
    t0 = time.perf_counter()
    got = design(job.bench, seed=1)
    dt = time.perf_counter() - t0
    dx, dy = got.cell
    print(f"caps {cap:g} mm: design {dt:.1f} s, fill {got.fill.min():.3f}..{got.fill.max():.3f}")
    if got.cap_ink is not None:
        print("bands' ink from the centre out:", np.array2string(got.cap_ink, precision=2))
        rings = ring_table(cap, got.cap_ink)
        job = replace(job, domain=replace(job.domain, cap_rings=rings))
    inside = job.domain.cell_fractions(0.0, 0.0, dx, dy, *got.fill.shape[::-1])
    sim = simulate(job.bench, rays, seed=7, coverage=Coverage(got.fill * inside, 0.0, 0.0, dx, dy))
    figures(f"caps {cap:g} mm, coverage ({rays:.2g} rays)", sim)
    per = int(round(5.0 / (60.0 / sim.luminance.shape[1])))
    np.set_printoptions(precision=2, linewidth=120)
    print("luminance folded onto one pitch cell (LED at the centre):")
    print(folded(sim.luminance, per))
    print("fill folded (design cells):")
    print(folded(got.fill, int(round(5.0 / dx))))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--caps", type=float, nargs="+", default=[0.0, 0.5, 0.8])
    ap.add_argument("--rays", type=float, default=4e7)
    ap.add_argument("--fill-max", type=float, help="design.fill_range's top (default 0.7)")
    ap.add_argument("--cell", type=float, help="design.cell, mm (default: pitch / 10)")
    ap.add_argument("--smoothing", type=float, help="design.smoothing, cells (default 1)")
    ap.add_argument(
        "--graded", action="store_true", help='graded caps (cap_ink = "design"), not solid'
    )
    ap.add_argument("--out", type=Path, default=HERE / "out" / "caps_coverage")
    args = ap.parse_args()
    print(f"machine: {machine()}")
    for cap in args.caps:
        run(
            cap,
            int(args.rays),
            args.out / f"cap{cap:g}",
            args.fill_max,
            args.cell,
            args.graded,
            args.smoothing,
        )


if __name__ == "__main__":
    main()
