"""Designed light guides (issue 27): design -> generate -> simulate with the real dots.

Run: python benchmarks/light_guide.py notebook|notebook2|phone [--out DIR] [--rays 1e7]
     [--design-rays N] [--skip-generate]

- ``notebook``: 345 x 194 mm, 0.5 mm PMMA, 40 LEDs along one long edge (y = 0).
- ``notebook2``: the same lit from both long edges (40 + 40 LEDs).
- ``phone``: 65 x 140 mm, 0.4 mm, lit at one corner (an LED on the bottom and one on the
  left edge, both 2.5 mm from the corner), an empty region (a 12 x 8 mm keep-out, the
  camera) near the top.

Each is designed on 1 mm cells (``optdot design``, in this process: time, iterations,
the coverage-mode figures), generated with ``optdot generate`` (a child process, tiled by
itself when large) and traced through its real dots with ``--rays`` rays. Printed: dots,
seconds, rays/s and peak memory of each step, and the figures the issue's targets name
(9-point uniformity, luminance RMS over the panel less 5 mm in 5 mm bins, efficiency).
"""

from __future__ import annotations

import argparse
import resource
import subprocess
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
from _common import machine, peak_rss_mb  # noqa: E402

from optdot.config.schema import load_job  # noqa: E402
from optdot.exporters.readback import read_any  # noqa: E402
from optdot.optics.design import design  # noqa: E402
from optdot.optics.simulate import simulate  # noqa: E402
from optdot.optics.writing import write_design  # noqa: E402

GUIDE = """[light_guide]
thickness = {t}
refractive_index = 1.49
absorption = 0.0002
dot_albedo = 0.9
reflector = 0.95
edge_reflectance = 0.9
"""


def _leds(edge: str, positions: list[float], width: float = 3.0) -> str:
    return (
        f'\n[[light_guide.leds]]\nedge = "{edge}"\n'
        f"positions = {[round(p, 3) for p in positions]}\nwidth = {width}\n"
    )


def write_job(kind: str, out: Path) -> Path:
    """The benchmark guide's job (no map yet)."""
    if kind in ("notebook", "notebook2"):
        w, h = 345.0, 194.0
        pos = [w / 40 * (i + 0.5) for i in range(40)]
        text = f'name = "{kind}"\n[domain]\nwidth = {w}\nheight = {h}\n'
        text += "[dots]\ndiameter = 0.046\n[design]\ncell = 1.0\n" + GUIDE.format(t=0.5)
        text += _leds("bottom", pos)
        if kind == "notebook2":
            text += _leds("top", pos)
    elif kind == "phone":
        (out / "phone.wkt").write_text("POLYGON ((0 0, 65 0, 65 140, 0 140, 0 0))\n")
        text = (
            'name = "phone"\n[domain]\noutline = "phone.wkt"\n'
            'keep_out = ["POLYGON ((26.5 128, 38.5 128, 38.5 136, 26.5 136, 26.5 128))"]\n'
            "[dots]\ndiameter = 0.046\n[design]\ncell = 1.0\n" + GUIDE.format(t=0.4)
        )
        text += _leds("bottom", [2.5], 3.0) + _leds("left", [2.5], 3.0)
    else:
        raise SystemExit(f"unknown guide {kind!r}")
    path = out / "job.toml"
    path.write_text(text)
    return path


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("guide", choices=["notebook", "notebook2", "phone"])
    ap.add_argument("--out", type=Path, default=None)
    ap.add_argument("--rays", type=float, default=1e7)
    ap.add_argument("--design-rays", type=int, default=None)
    ap.add_argument("--skip-generate", action="store_true")
    ap.add_argument(
        "--simulate-only",
        action="store_true",
        help="trace the map and pattern an earlier run left in --out, nothing else",
    )
    ap.add_argument(
        "--fill",
        type=float,
        default=None,
        help="no design: a uniform map of this fill (the scale run: 0.255 gives ~1e7 dots "
        "on the notebook guide)",
    )
    args = ap.parse_args()
    out = args.out or Path(f"/tmp/optdot-lgp-{args.guide}")
    out.mkdir(parents=True, exist_ok=True)
    print(machine())
    if args.simulate_only:
        args.skip_generate = True
        run_generate_and_simulate(args, out)
        return
    job = load_job(write_job(args.guide, out), need_map=False)
    if args.fill is not None:
        (out / "uniform.csv").write_text(f"{args.fill}\n")
        text = (out / "job.toml").read_text()
        (out / "map.toml").write_text(text + '\n[density]\ngrid = "uniform.csv"\n')
        run_generate_and_simulate(args, out)
        return
    t0 = time.perf_counter()
    got = design(
        job.bench,
        rays=args.design_rays,
        report=lambda f: print(
            f"  iteration {f['iteration']:2d}: {f['rays']:>11,} rays, 9-point "
            f"{f['uniformity_9point']:.3f}, efficiency {f['efficiency']:.1%}, "
            f"{time.perf_counter() - t0:.0f} s",
            flush=True,
        ),
    )
    t_design = time.perf_counter() - t0
    write_design(got, job.bench, out / "map.csv", out / "map.png", out / "map.toml")
    last = got.history[-1]
    print(
        f"design: {len(got.history)} iterations, {t_design:.0f} s, peak {peak_rss_mb():.0f} MB; "
        f"coverage mode 9-point {last['uniformity_9point']:.3f}, efficiency "
        f"{last['efficiency']:.1%}"
    )
    run_generate_and_simulate(args, out)


def run_generate_and_simulate(args, out: Path) -> None:
    """Generate the map's pattern (a child process) and trace it both ways."""
    dots = out / "dots.parquet"
    if not args.skip_generate or not dots.exists():
        t0 = time.perf_counter()
        subprocess.run(
            [
                sys.executable,
                "-m",
                "optdot",
                "generate",
                str(out / "map.toml"),
                "-o",
                str(dots),
                "-q",
            ],
            check=True,
        )
        child = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024
        print(f"generate: {time.perf_counter() - t0:.0f} s (largest process {child:.0f} MB)")
    job = load_job(out / "map.toml")
    pattern = read_any(dots, None, box=job.box)
    rays = int(args.rays)
    for mode, src in (("coverage", None), ("dots", pattern)):
        t0 = time.perf_counter()
        sim = simulate(job.bench, rays, seed=1, dots=src, bin_mm=5.0)
        dt = time.perf_counter() - t0
        s = sim.summary()
        print(
            f"simulate {mode}: {pattern.n:,} dots, {rays:,} rays, {dt:.0f} s, "
            f"{rays / dt:,.0f} rays/s, peak {peak_rss_mb():.0f} MB; 9-point "
            f"{s['uniformity_9point']:.3f} ± {s['uniformity_9point_sigma']:.3f}, RMS "
            f"{s['luminance_rms']:.2%} (noise {s['luminance_rms_noise']:.2%}), min/max "
            f"{s['luminance_min']:.3f}/{s['luminance_max']:.3f}, efficiency "
            f"{s['efficiency']:.1%} ± {s['efficiency_sigma']:.2%}",
            flush=True,
        )


if __name__ == "__main__":
    main()
