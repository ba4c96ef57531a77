"""Would solid ink caps over the LEDs lift the Lambertian direct-lit stack? (issue 38)

Run: python benchmarks/caps_coverage.py [--caps 0 0.5 0.8] [--rays 4e7]

The issue's direct-lit stack with Lambertian LEDs (``backlight.py direct --profile
lambertian``: 60 x 40 mm, 5 mm pitch, 1.5 mm optical distance) stops at min/max 0.575
with real dots: right over each LED the film needs a fill of about 0.8, more than random
dots that keep QA's gap reach. A cap is a disc of solid ink printed over each LED. This
experiment asks what caps would give before any of them is built into the pattern,
masks or QA: in the coverage mode only, each design cell's coverage is its share under a
cap plus the designed fill over the rest of the cell less a ring of QA's close gap
around each cap, where no dot may print (``optdot.optics.design.Coverage`` is wrapped
here; nothing in optdot changes). For each cap diameter (0: none) the map is designed
(``design()``, default settings), then traced with ``--rays`` rays in 0.5 mm bins;
printed: design seconds, the issue's uniformity (min/max over the panel less 5 mm) with
a bin's noise, 9-point, efficiency, and the luminance of the inner LEDs' pitch cells
folded onto one (10 x 10 bins of 0.5 mm, the LED at the centre) with the fill under it.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
from _common import machine  # noqa: E402
from backlight import DIRECT, INK_AND_DIFFUSER, figures  # noqa: E402

import optdot.optics.design as design_module  # noqa: E402
from optdot.config.schema import load_job  # noqa: E402
from optdot.optics.simulate import simulate  # noqa: E402

#: Sub-samples a side per design cell when measuring a cap's share of it.
SUB = 8


def shares(leds: np.ndarray, radius: float, x0, y0, dx, dy, nx, ny) -> np.ndarray:
    """``[ny, nx]`` share of each cell within ``radius`` of an LED centre."""
    if radius <= 0:
        return np.zeros((ny, nx))
    xs = x0 + (np.arange(nx * SUB) + 0.5) * dx / SUB
    ys = y0 + (np.arange(ny * SUB) + 0.5) * dy / SUB
    gx, gy = np.meshgrid(xs, ys)
    inside = np.zeros(gx.shape, bool)
    for lx, ly in leds:
        inside |= (gx - lx) ** 2 + (gy - ly) ** 2 <= radius * radius
    return inside.reshape(ny, SUB, nx, SUB).mean(axis=(1, 3))


def folded(a: np.ndarray, per: int) -> np.ndarray:
    """``a`` over the inner pitch cells (one pitch in from every edge) averaged onto one
    cell of ``per`` x ``per`` bins."""
    ny, nx = a.shape
    inner = a[per : ny - per, per : nx - per]
    return inner.reshape(inner.shape[0] // per, per, inner.shape[1] // per, per).mean(axis=(0, 2))


def run(cap: float, rays: int, out: Path) -> None:
    out.mkdir(parents=True, exist_ok=True)
    path = out / "job.toml"
    path.write_text(DIRECT.format(profile="lambertian", w=60.0, h=40.0) + INK_AND_DIFFUSER)
    job = load_job(path, need_map=False)
    leds = np.asarray(job.backlight.leds.positions, float)
    gap = job.qa.effective_close_gap
    real = design_module.Coverage

    def with_caps(fill, x0, y0, dx, dy):
        ny, nx = fill.shape
        solid = shares(leds, cap / 2, x0, y0, dx, dy, nx, ny)
        kept = shares(leds, cap / 2 + gap, x0, y0, dx, dy, nx, ny) if cap > 0 else solid
        return real(solid + (1.0 - kept) * fill, x0, y0, dx, dy)

    design_module.Coverage = with_caps
    try:
        t0 = time.perf_counter()
        got = design_module.design(job, seed=1)
        dt = time.perf_counter() - t0
    finally:
        design_module.Coverage = real
    dx, dy = got.cell
    print(f"caps {cap:g} mm: design {dt:.1f} s, fill {got.fill.min():.3f}..{got.fill.max():.3f}")
    sim = simulate(job, rays, seed=7, coverage=with_caps(got.fill, 0.0, 0.0, dx, dy))
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
    ap.add_argument("--out", type=Path, default=HERE / "out" / "caps_coverage")
    args = ap.parse_args()
    print(f"machine: {machine()}")
    for cap in args.caps:
        run(cap, int(args.rays), args.out / f"cap{cap:g}")


if __name__ == "__main__":
    main()
