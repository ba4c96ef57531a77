"""Light from one raised 3-D dot into its neighbours (issue 60): the coverage's twins (what
``design`` traces) against the real dots ``generate`` makes, where bumps and prisms stand
tall and close; and the time a ray through real bumps and dimples against ink's on the
same dots.

Run: python benchmarks/neighbours.py [--rays 2e6] [--speed-rays 2e6] [--speed-only]

Each case is a 10 x 8 mm guide 0.6 mm thick (PMMA, a white reflector 0.95 under it), two
LEDs 1 mm wide on its bottom edge, and a map graded along y: traced as the coverage and
through its generated dots with the same rays and seed. Printed per case: the dots, then
per trace the efficiency (share of the injected light out of the top), the shares lost
under the guide and at the edges, the on-axis luminance (over a Lambertian's of the same
flux) with its 1-sigma noise, seconds and rays/s. Then the speed: the lgp sample's guide
(30 x 20 mm) with a map graded 0.1 to 0.4 of 46 µm dots, traced through the same real
dots as white ink, as 12 µm bumps and as 12 µm dimples (ten runs of each in turn, after
a first that compiles; the CPU seconds summed), rays per CPU second and each 3-D dot's
time a ray over ink's, and how many events (a face or a wall met) a ray takes with each
(the share of 100k rays still unfinished when given up after 1, 2, 4, ... 4096 events,
summed). At the end the peak memory.
"""

from __future__ import annotations

import argparse
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
from optdot.optics.scene import probe, scene_of  # noqa: E402
from optdot.optics.simulate import simulate  # noqa: E402
from optdot.optics.tables import UNFINISHED  # noqa: E402
from optdot.optics.trace import trace  # noqa: E402
from optdot.orchestration.pipeline import generate  # noqa: E402
from tests.conftest import graded_guide  # noqa: E402

PRISM = 'shape = "rounded_rectangle"\nlength = 0.24\nwidth = 0.08\ncorner_radius = 0.01\n'
BUMP = 'diameter = 0.2\nprofile = "bump"\nheight = '
#: name, fill range, [dots], [orientation]
CASES = [
    ("bumps 0.2 mm, 0.08 mm high", (0.1, 0.6), BUMP + "0.08", ""),
    ("hemispheres 0.2 mm", (0.3, 0.75), BUMP + "0.1", ""),
    (
        "raised prisms 45/45, random angles", (0.1, 0.5),
        PRISM + 'profile = "prism"\nfacets = [45, 45]', "[orientation]\nrandom = true",
    ),
    (
        "raised prisms 40/40, toward the LEDs", (0.1, 0.5),
        PRISM + 'profile = "prism"\nfacets = [40, 40]',
        '[orientation]\ntoward = "leds"\nrelative = "parallel"',
    ),
]  # fmt: skip


def _case(root: Path, name: str, fill: tuple, dots: str, orientation: str, rays: int) -> None:
    d = root / name.replace(" ", "_").replace("/", "-")
    d.mkdir()
    job = load_job(graded_guide(d, fill, dots, orientation, thickness=0.6))
    pattern = generate(job)
    print(f"{name}, fill {fill[0]}-{fill[1]}: {len(pattern.xy):,} dots")
    for how, kw in (("coverage", {}), ("real dots", {"dots": pattern})):
        t = time.perf_counter()
        s = simulate(job.bench, rays, 3, **kw).summary()
        sec = time.perf_counter() - t
        sh, a = s["shares"], s["angles"]
        print(
            f"  {how:<10} efficiency {s['efficiency']:.4f}  under {sh['lost_bottom']:.4f}  "
            f"edges {sh['lost_edges']:.4f}  on-axis {a['on_axis']:.3f} ± "
            f"{a['on_axis_sigma']:.3f}  {sec:.1f} s  {rays / sec / 1e6:.2f} M rays/s"
        )


def speed_jobs(root: Path) -> tuple[Path, Path, Path]:
    """The speed case's jobs, written into ``root``: the lgp sample's guide with a map
    graded 0.1 to 0.4 of 46 µm dots as white ink, 12 µm bumps and 12 µm dimples
    (``ink.toml``, ``bump.toml``, ``dimple.toml``; the map ``fill.csv`` beside them)."""
    job_text = (HERE.parent / "samples/lgp/job.toml").read_text().split("[design]")[0]
    job_text = job_text.replace("[dots]\n", '[density]\ngrid = "fill.csv"\n\n[dots]\n')
    grid = np.repeat(np.linspace(0.1, 0.4, 20)[:, None], 30, axis=1)
    np.savetxt(root / "fill.csv", grid, delimiter=",")
    (root / "ink.toml").write_text(job_text)
    bump = 'diameter = 0.046   # mm\nprofile = "bump"\nheight = 0.012\n'
    (root / "bump.toml").write_text(job_text.replace("diameter = 0.046   # mm\n", bump))
    dimple = 'diameter = 0.046   # mm\nprofile = "dimple"\ndepth = 0.012\n'
    (root / "dimple.toml").write_text(job_text.replace("diameter = 0.046   # mm\n", dimple))
    return root / "ink.toml", root / "bump.toml", root / "dimple.toml"


def _speed(root: Path, rays: int) -> None:
    ink_path, bump_path, dimple_path = speed_jobs(root)
    ink, bumps = load_job(ink_path), load_job(bump_path)
    pattern = generate(ink)
    rounds = 10
    print(
        f"speed: the lgp guide, {len(pattern.xy):,} real 46 µm dots, {rays:,} rays each, "
        f"in {rounds} alternating runs (CPU seconds summed: a noisy machine's load falls "
        "on both)"
    )
    scenes = {"ink": scene_of(ink.bench, rays, pattern)}
    scenes["bumps 12 µm"] = scene_of(bumps.bench, rays, pattern)
    scenes["dimples 12 µm"] = scene_of(load_job(dimple_path).bench, rays, pattern)
    for scene in scenes.values():
        trace(0, 0, 1000, scene)  # compiled
    cpu = dict.fromkeys(scenes, 0.0)
    for r in range(rounds):
        for name, scene in scenes.items():
            t = time.process_time()
            trace(1, r * (rays // rounds), rays // rounds, scene)
            cpu[name] += time.process_time() - t
    for name, sec in cpu.items():
        print(f"  {name:<12} {sec:.2f} CPU s  {rays / sec / 1e6:.2f} M rays per CPU s")
    for name in ("bumps 12 µm", "dimples 12 µm"):
        print(f"  {name.split()[0]} / ink, time a ray: {cpu[name] / cpu['ink']:.2f}")
    for name, scene in scenes.items():
        print(f"  {name:<12} {_events(scene):.1f} events a ray")


#: The event limits :func:`_events` gives rays up after.
LIMITS = (1, 2, 4, 8, 12, 16, 24, 32, 48, 64, 96, 128, 192, 256, 384, 512, 768, 1024, 2048, 4096)


def _events(scene, rays: int = 100_000) -> float:
    """The mean number of events (a face or a wall met) a coupled or uncoupled ray of
    ``scene`` takes: the sum over ``k`` of the share of rays not finished after ``k``
    events, from traces given up after each of :data:`LIMITS` (trapezoids between them)."""
    alive = [float(np.mean(trace(1, 0, rays, probe(scene, k))[0] == UNFINISHED)) for k in LIMITS]
    steps = zip(LIMITS, LIMITS[1:], alive, alive[1:], strict=False)
    return LIMITS[0] + sum((k2 - k1) * (a1 + a2) / 2 for k1, k2, a1, a2 in steps)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--rays", type=float, default=2e6, help="rays a trace of each case")
    ap.add_argument("--speed-rays", type=float, default=2e6, help="rays a timed trace")
    ap.add_argument("--speed-only", action="store_true", help="only the time a ray")
    a = ap.parse_args()
    print(machine())
    with tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp)
        for name, fill, dots, orientation in () if a.speed_only else CASES:
            _case(root, name, fill, dots, orientation, int(a.rays))
        _speed(root, int(a.speed_rays))
    print(f"peak {peak_rss_mb():.0f} MB (one process)")


if __name__ == "__main__":
    main()
