"""Direct-lit and film stacks (issue 38): design -> generate -> simulate with the real dots.

Run: python benchmarks/backlight.py direct [--profile lambertian|batwing] [--out DIR]
         [--rays 4e8] [--halo-rays 4e6] [--size 60x40] [--cap 0.8 [--graded]] [--fill-max 0.75]
         [--smoothing 1]
     python benchmarks/backlight.py guide-film [--out DIR] [--rays 6.4e7]

``direct``: the issue's stack. A 60 x 40 mm mini-LED backlight: LEDs of 0.2 mm on a 5 mm
grid (the first half a pitch from the corner) on a reflector of 0.95, an optical distance
of 1.5 mm to a 0.2 mm PC film (n 1.59) printed with white ink (diffuse R 0.85, T 0.10) on
its face to the LEDs, a Lambertian top face (haze), one diffuser (T 0.65, the rest back),
a white frame (0.9). The film's map is designed (``optdot design``, in this process:
time, iterations), its dots generated at the sizes the design asks for (``optdot
generate``, a child process), then traced with ``--rays`` rays through the real dots and,
for comparison, through the bare film (no dots) and the map's coverage. Printed: the
uniformity the issue names (min/max over 0.5 mm bins of the panel less 5 mm) with the
noise of a bin, the 9-point uniformity, efficiency and where the rest went, the halo of
the middle LED lit alone, and seconds and peak memory of each step.

``guide-film``: the lgp sample's guide designed on its own, then a dotted film (0.1 mm,
50 µm above it, Lambertian top face) and a diffuser over it, the film's map designed with
the guide's dots held: the 9-point uniformity of the guide alone and with its film, each
with its noise, with the viewing area 3 mm inside the panel (the bezel over the LEDs).
"""

from __future__ import annotations

import argparse
import math
import resource
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
from _common import machine, peak_rss_mb  # noqa: E402

from optdot.config.schema import load_job  # noqa: E402
from optdot.exporters.readback import read_any  # noqa: E402
from optdot.optics.design import design  # noqa: E402
from optdot.optics.halo import halo  # noqa: E402
from optdot.optics.scene import Coverage  # noqa: E402
from optdot.optics.simulate import simulate  # noqa: E402
from optdot.optics.writing import write_design  # noqa: E402

#: The white ink and the diffuser of both stacks (the end of each job's text).
INK_AND_DIFFUSER = """dot_reflectance = 0.85
dot_transmittance = 0.10
haze = "lambertian"
[[backlight.sheets]]
kind = "diffuser"
transmittance = 0.65
"""

DIRECT = """name = "minled-{profile}"
[domain]
width = {w}
height = {h}
[dots]
diameter = 0.046
[backlight]
kind = "direct"
frame = 0.9
[backlight.leds]
pitch = [5.0, 5.0]
offset = [2.5, 2.5]
size = 0.2
profile = "{profile}"
[backlight.cavity]
gap = 1.5
reflector = 0.95
[backlight.film]
thickness = 0.2
refractive_index = 1.59
"""

GUIDE = """name = "lgp-film"
[domain]
width = 30.0
height = 20.0
bezel = 3.0
[dots]
diameter = 0.046
[light_guide]
thickness = 0.4
refractive_index = 1.49
absorption = 0.0002
dot_albedo = 0.9
reflector = 0.95
edge_reflectance = 0.9
[[light_guide.leds]]
edge = "bottom"
positions = [5.0, 15.0, 25.0]
width = 2.0
[design]
cell = 0.5
fill_range = [0.0, 0.4]
"""

FILM = """[backlight]
kind = "edge"
print = "film"
other_map = "guide_map.csv"
[backlight.film]
thickness = 0.1
gap = 0.05
"""


def children_peak_mb() -> float:
    return resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024.0


def figures(label: str, sim) -> dict:
    """Print and return the figures of one simulation."""
    s = sim.summary()
    rms, noise, lo, hi = sim.rms()
    u9, u9s = sim.uniformity9()
    out = {
        "min_over_max": lo / hi,
        "min": lo,
        "max": hi,
        "rms": rms,
        "noise": noise,
        "u9": u9,
        "u9_sigma": u9s,
        "efficiency": sim.efficiency,
    }
    shares = ", ".join(f"{k} {v:.2%}" for k, v in s["shares"].items() if k != "extracted" and v > 0)
    print(
        f"{label}: min/max {lo / hi:.3f} (min {lo:.3f}, max {hi:.3f} of the mean; a bin's "
        f"noise {noise:.2%}), RMS {rms:.2%}, 9-point {u9:.3f} ± {u9s:.3f}, efficiency "
        f"{sim.efficiency:.2%} ({shares})",
        flush=True,
    )
    return out


def direct(args) -> None:
    w, h = (float(v) for v in args.size.split("x"))
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    job_path = out / "job.toml"
    text = DIRECT.format(profile=args.profile, w=w, h=h)
    if args.cap > 0:
        ink = 'cap_ink = "design"\n' if args.graded else ""
        text = text.replace(
            f'profile = "{args.profile}"\n',
            f'profile = "{args.profile}"\ncap = {args.cap}\n{ink}',
        )
    extra = []
    if args.fill_max is not None:
        extra.append(f"fill_range = [0.0, {args.fill_max}]")
    if args.smoothing is not None:
        extra.append(f"smoothing = {args.smoothing}")
    design_sec = "[design]\n" + "\n".join(extra) + "\n" if extra else ""
    job_path.write_text(text + INK_AND_DIFFUSER + design_sec)
    job = load_job(job_path, need_map=False)
    rays = int(float(args.rays))
    print(f"machine: {machine()}")
    caps = f", {'graded' if args.graded else 'solid'} caps of {args.cap:g} mm" if args.cap else ""
    print(f"stack: {args.profile} LEDs, {len(job.backlight.leds.positions)} on a 5 mm grid{caps}")

    t0 = time.perf_counter()
    got = design(job.bench, seed=1)
    t_design = time.perf_counter() - t0
    write_design(got, job.bench, out / "map.csv", out / "map.png", out / "map.toml")
    last = got.history[-1]
    print(
        f"design: {got.fill.shape[1]} x {got.fill.shape[0]} cells, {len(got.history)} "
        f"iterations, {t_design:.1f} s, peak {peak_rss_mb():.0f} MB; fill "
        f"{got.fill.min():.3f}..{got.fill.max():.3f}, sizes asked {got.sizes}; last "
        f"iteration RMS {last['luminance_rms']:.2%} (noise {last['luminance_rms_noise']:.2%})",
        flush=True,
    )
    t0 = time.perf_counter()
    subprocess.run(
        [sys.executable, "-m", "optdot", "generate", str(out / "map.toml"), "-o",
         str(out / "dots.npz"), "-q"],
        check=True,
    )  # fmt: skip
    t_gen = time.perf_counter() - t0
    designed = load_job(out / "map.toml")
    pattern = read_any(out / "dots.npz")
    print(
        f"generate: {pattern.n:,} dots, {t_gen:.1f} s, peak {children_peak_mb():.0f} MB",
        flush=True,
    )
    bare = Coverage(np.zeros((1, 1)), 0.0, 0.0, w, h)
    # the bare stack: the film without dots and without caps
    (out / "bare.toml").write_text(DIRECT.format(profile=args.profile, w=w, h=h) + INK_AND_DIFFUSER)
    bare_job = load_job(out / "bare.toml", need_map=False)
    result = {}
    for label, on, kw in (
        ("bare film", bare_job, {"coverage": bare}),
        ("designed map, coverage", designed, {}),
        ("designed map, real dots", designed, {"dots": pattern}),
    ):
        t0 = time.perf_counter()
        sim = simulate(on.bench, rays, seed=7, **kw)
        dt = time.perf_counter() - t0
        result[label] = figures(f"{label} ({rays:.2g} rays, {dt:.0f} s)", sim)
    ratio = result["designed map, real dots"]["efficiency"] / result["bare film"]["efficiency"]
    print(f"efficiency of the designed stack / the bare stack's: {ratio:.3f}")
    t0 = time.perf_counter()
    hal = halo(designed.bench, int(float(args.halo_rays)), seed=3, dots=pattern)
    print(
        f"halo of the LED at {hal['led_mm']} lit alone ({args.halo_rays} rays, "
        f"{time.perf_counter() - t0:.0f} s): width at 50 % {hal['width50_mm']:.2f} mm, at 10 % "
        f"{hal['width10_mm']:.2f} mm; {hal['share_own_cell']:.1%} in its own pitch cell, "
        f"{hal['share_3x3']:.1%} in the 3 x 3 around it"
    )
    print(f"peak memory: this process {peak_rss_mb():.0f} MB, children {children_peak_mb():.0f} MB")


def guide_film(args) -> None:
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    rays = int(float(args.rays))
    print(f"machine: {machine()}")
    np.savetxt(out / "guide_map.csv", np.full((2, 2), 0.2), delimiter=",")
    (out / "guide.toml").write_text(GUIDE + '[density]\ngrid = "guide_map.csv"\n')
    t0 = time.perf_counter()
    g = design(load_job(out / "guide.toml"), seed=1)
    print(f"guide designed in {time.perf_counter() - t0:.1f} s")
    np.savetxt(out / "guide_map.csv", g.fill, delimiter=",", fmt="%.6f")
    guide = load_job(out / "guide.toml")
    (out / "film.toml").write_text(GUIDE + FILM + INK_AND_DIFFUSER)
    film = load_job(out / "film.toml", need_map=False)
    t0 = time.perf_counter()
    f = design(film.bench, seed=2)
    print(f"film designed in {time.perf_counter() - t0:.1f} s, fill {f.fill.min():.3f}.."
          f"{f.fill.max():.3f}")  # fmt: skip
    nx, ny = f.fill.shape[1], f.fill.shape[0]
    a = figures(f"guide alone ({rays:.2g} rays)", simulate(guide.bench, rays, seed=9))
    cov = Coverage(f.fill, 0.0, 0.0, 30.0 / nx, 20.0 / ny)
    b = figures(f"guide + film ({rays:.2g} rays)", simulate(film.bench, rays, seed=9, coverage=cov))
    lift = b["u9"] - a["u9"]
    sigma = math.hypot(a["u9_sigma"], b["u9_sigma"])
    print(f"9-point lift {lift:+.3f} ± {sigma:.3f} ({lift / sigma:.1f} sigma)")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("case", choices=["direct", "guide-film"])
    ap.add_argument("--profile", default="lambertian", choices=["lambertian", "batwing"])
    ap.add_argument("--out", default="benchmarks/out/backlight")
    ap.add_argument("--rays", default=None)
    ap.add_argument("--halo-rays", default="4e6")
    ap.add_argument("--size", default="60x40")
    ap.add_argument("--cap", type=float, default=0.0, help="direct: LED cap diameter, mm")
    ap.add_argument("--graded", action="store_true", help='direct: cap_ink = "design"')
    ap.add_argument("--fill-max", type=float, help="direct: design.fill_range's top")
    ap.add_argument("--smoothing", type=float, help="direct: design.smoothing, cells")
    args = ap.parse_args()
    if args.case == "direct":
        args.rays = args.rays or "4e8"
        direct(args)
    else:
        args.rays = args.rays or "6.4e7"
        guide_film(args)


if __name__ == "__main__":
    main()
