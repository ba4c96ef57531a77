"""3-D dots on the prisms sample (issue 60): micro-prisms turned toward their LEDs against
random angles, raised and cut, on the same map; the time per ray through real 3-D dots
against ink's; and bumps on the ellipses sample's 80 x 40 µm footprints, turned and not.

Run: python benchmarks/profiles.py [--rays 4e6] [--facets 45 45] [--out DIR]

The guide is ``samples/prisms`` (24 x 12 mm, 0.4 mm PMMA, 8 LEDs on the bottom edge,
120 x 30 µm footprints with 5 µm corners) with ``[dots] profile = "prism"``. Each
orientation (``toward = "leds"`` along the light, ``parallel``: the facets face the LED;
across it, ``perpendicular``; ``random``) is traced in the coverage mode (what ``design``
traces) with ``--rays`` rays and the same seed, raised and cut. Printed per row: the
extraction (efficiency) and the on-axis luminance (over a Lambertian's of the same flux),
each with its 1-sigma noise, the 9-point uniformity, seconds and rays/s. Then the
``parallel`` cut prisms and ink are generated and traced through their real dots: the
real dots against the coverage, and rays/s of prisms against ink's (the issue asks <= 2x
the time a ray).
"""

from __future__ import annotations

import argparse
import math
import shutil
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
from _common import machine, peak_rss_mb  # noqa: E402

from optdot.config.schema import load_job  # noqa: E402
from optdot.optics.simulate import simulate  # noqa: E402
from optdot.orchestration.pipeline import generate  # noqa: E402

SAMPLES = HERE.parent / "samples"
ORIENTATIONS = {
    "parallel": 'toward = "leds"\nrelative = "parallel"',
    "perpendicular": 'toward = "leds"\nrelative = "perpendicular"',
    "random": "random = true",
}


def write_job(out: Path, sample: str, orientation: str, profile: str) -> Path:
    """``samples/<sample>`` with ``profile`` (TOML lines for ``[dots]``) and
    ``orientation``, its map copied beside it."""
    shutil.copy(SAMPLES / sample / "density.csv", out / "density.csv")
    text = (SAMPLES / sample / "job.toml").read_text()
    head, rest = text.split("[orientation]", 1)
    rest = rest.split("[optimize]", 1)[1]
    text = head.rstrip() + f"\n{profile}\n\n[orientation]\n{ORIENTATIONS[orientation]}\n\n"
    text += f"[optimize]{rest}"
    path = out / f"{sample}_{orientation}_{len(profile)}.toml"
    path.write_text(text)
    return path


def row(label: str, s: dict, seconds: float, rays: int) -> str:
    """One line of figures of a simulation's summary ``s``."""
    a = s["angles"]
    return (
        f"{label:<34} efficiency {s['efficiency']:.4f} ± {s['efficiency_sigma']:.4f}  on-axis "
        f"{a['on_axis']:.3f} ± {a['on_axis_sigma']:.3f}  9-point {s['uniformity_9point']:.3f}  "
        f"{seconds:.1f} s  {rays / seconds / 1e6:.2f} M rays/s"
    )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rays", type=float, default=4e6)
    ap.add_argument("--facets", type=float, nargs=2, default=(45.0, 45.0))
    ap.add_argument("--out", type=Path, default=HERE / "out" / "profiles")
    args = ap.parse_args()
    rays = int(args.rays)
    out = args.out
    out.mkdir(parents=True, exist_ok=True)
    print(machine())
    f1, f2 = args.facets
    sims = {}
    for cut in (False, True):
        profile = f'profile = "prism"\nfacets = [{f1:g}, {f2:g}]\ncut = {str(cut).lower()}'
        for o in ORIENTATIONS:
            job = load_job(write_job(out, "prisms", o, profile))
            t = time.perf_counter()
            sim = simulate(job.bench, rays, seed=1).summary()
            dt = time.perf_counter() - t
            sims[cut, o] = sim
            print(row(f"{'cut' if cut else 'raised'} prisms, {o} (coverage)", sim, dt, rays))
        for o in ("perpendicular", "random"):
            p, q = sims[cut, "parallel"], sims[cut, o]
            a, b = p["angles"], q["angles"]
            de = p["efficiency"] - q["efficiency"]
            se = math.hypot(p["efficiency_sigma"], q["efficiency_sigma"])
            da = a["on_axis"] - b["on_axis"]
            sa = math.hypot(a["on_axis_sigma"], b["on_axis_sigma"])
            print(
                f"  parallel - {o}: efficiency {de:+.4f} ± {se:.4f} ({de / se:+.1f} sigma), "
                f"on-axis {da:+.3f} ± {sa:.3f} ({da / sa:+.1f} sigma)"
            )
    cut = f'profile = "prism"\nfacets = [{f1:g}, {f2:g}]\ncut = true'
    for label, profile in (("cut prisms, parallel", cut), ("ink", "")):
        job = load_job(write_job(out, "prisms", "parallel", profile))
        t = time.perf_counter()
        dots = generate(job)
        gen = time.perf_counter() - t
        simulate(job.bench, 20_000, seed=1, dots=dots)  # the kernels compiled
        t = time.perf_counter()
        sim = simulate(job.bench, rays, seed=1, dots=dots).summary()
        dt = time.perf_counter() - t
        label = f"{label} ({len(dots.xy):,} real dots)"
        print(row(label, sim, dt, rays) + f"  (generate {gen:.1f} s)")
    bump = 'profile = "bump"\nheight = 0.015'
    for o in ORIENTATIONS:
        job = load_job(write_job(out, "ellipses", o, bump))
        t = time.perf_counter()
        sim = simulate(job.bench, rays, seed=1).summary()
        print(row(f"ellipse bumps 15 µm, {o} (coverage)", sim, time.perf_counter() - t, rays))
    print(f"peak {peak_rss_mb():.0f} MB")


if __name__ == "__main__":
    main()
