"""Texture of patterns beside their peers (issue 24): grain, structure factor, order, close
pairs and walls, all measured by the same code (:mod:`optdot.quality.texture`).

Run: python benchmarks/texture.py [--map uniform|led|tsuno|chokka|walls] [--only NAME ...]

``uniform``: fill 0.20 on 30 x 30 mm (~108k dots of 46 µm), the issue's grain map.
``walls``: 10 x 10 mm at fill 0.3 with a round hole and a zero-fill block.
Columns: coverage RMS seen through a 0.5 mm Gaussian (uniform map only: elsewhere the map
itself varies), S(k) averaged over k·a in 0.3–1 and 1–3 and over the issue's
wavelengths of 3–10 spacings (k·a 2π/10–2π/3) (Hann-tapered window, a the hexagonal
spacing), mean |ψ6| and its 2 mm coherence, the 1st percentile of the
nearest-neighbour distance over a, pairs closer than 60 µm and than 46 µm, the worst
0.1 mm band within 2 mm of any wall (coverage / map - 1), seconds. Statistics use the
central 80 % of the box (walls: the whole panel).

``--time-rounds N`` times the default against ``optdot 0.3`` instead (the issue's time
target), alternated in one warm process.

Rows: ``optdot`` (the default), ``optdot 0.3`` (the default before issue 24: no phantoms,
no long-wavelength correction), ``paper``, ``md`` (the §2.2 baseline), and on the uniform
map the peers: ``sobol`` (the initial throw, unrelaxed), ``poisson``, ``scipy
PoissonDisk`` (radius = the hexagonal spacing x 0.85; fills fewer dots), ``lloyd`` (20
Lloyd iterations from the Sobol throw, by 50 samples per point), and any ``--points``:
points a peer made elsewhere, e.g. Gaussian blue noise from ``blue-sampler`` (it needs jax
and Python >= 3.12; its 2.1.7 release imports on 3.11): in a separate venv, ``pip install
jax finufft gridpoints squarenet matplotlib`` then ``pip install --no-deps
--ignore-requires-python blue-sampler==2.1.7``, ``x = blue_sampler.sample_points(N=108310,
D=2, method="rgbn")``, ``numpy.save("blue.npy", x)``, then ``--points "blue-sampler
rgbn=blue.npy:SECONDS"`` here.
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from scipy.spatial import cKDTree

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
sys.path.insert(0, str(HERE))
from _common import machine  # noqa: E402

from optdot.config.schema import load_job  # noqa: E402
from optdot.orchestration.pipeline import generate  # noqa: E402
from optdot.quality.metrics import patch_coherence, psi6  # noqa: E402
from optdot.quality.texture import (  # noqa: E402
    band_mean,
    blurred_coverage_rms,
    structure_factor,
)
from optdot.quality.wall_profile import wall_profile  # noqa: E402
from optdot.relax.formulation import PRESETS  # noqa: E402


def uniform_job(tmp: Path, size: float = 30.0, fill: float = 0.2) -> Path:
    n = int(size)
    np.savetxt(tmp / "density.csv", np.full((n, n), fill), delimiter=",", fmt="%.4f")
    (tmp / "job.toml").write_text(
        f'name = "uniform"\n[domain]\nwidth = {size}\nheight = {size}\n'
        '[density]\ngrid = "density.csv"\n[dots]\ndiameter = 0.046\n'
        '[optimize]\nmethod = "optdot"\nmax_iter = 200\nseed = 1\n'
    )
    return tmp / "job.toml"


def walls_job(tmp: Path) -> Path:
    import shapely

    panel = shapely.box(0, 0, 10, 10).difference(shapely.Point(6.5, 6.5).buffer(1.2, quad_segs=24))
    (tmp / "panel.wkt").write_text(panel.wkt)
    grid = np.full((10, 10), 0.3)
    grid[0:3, 0:3] = 0.0
    np.savetxt(tmp / "density.csv", grid, delimiter=",", fmt="%.4f")
    (tmp / "job.toml").write_text(
        'name = "walls"\n[domain]\noutline = "panel.wkt"\n[density]\ngrid = "density.csv"\n'
        "[dots]\ndiameter = 0.046\n[optimize]\nmax_iter = 200\nseed = 2\n"
    )
    return tmp / "job.toml"


def lloyd(xy: np.ndarray, box, iters: int = 20, per: int = 50, seed: int = 0) -> np.ndarray:
    """Lloyd relaxation by sampling: each iteration moves every point to the mean of the
    uniform samples nearest to it."""
    rng = np.random.default_rng(seed)
    x0, y0, x1, y1 = box
    xy = xy.copy()
    for _ in range(iters):
        s = rng.uniform([x0, y0], [x1, y1], (per * len(xy), 2))
        _, k = cKDTree(xy).query(s)
        cnt = np.bincount(k, minlength=len(xy))
        for a in range(2):
            m = np.bincount(k, s[:, a], minlength=len(xy))
            xy[:, a] = np.where(cnt > 0, m / np.maximum(cnt, 1), xy[:, a])
    return xy


def measure(xy, diameter, job, uniform: bool, whole: bool) -> dict:
    x0, y0 = job.density.x0, job.density.y0
    w, h = job.density.width, job.density.height
    inset = 0.0 if whole else 0.1
    win = (x0 + inset * w, y0 + inset * h, x0 + (1 - inset) * w, y0 + (1 - inset) * h)
    ka, s, a = structure_factor(xy, win)
    inw = (xy[:, 0] >= win[0]) & (xy[:, 0] < win[2]) & (xy[:, 1] >= win[1]) & (xy[:, 1] < win[3])
    p = psi6(xy)
    tree = cKDTree(xy)
    dd, _ = tree.query(xy, 2)
    wp = wall_profile(xy, diameter, job.density, job.domain, band=0.1, reach=2.0)
    rel = wp.relative
    worst = rel[np.nanargmax(np.abs(rel))]
    return {
        "rms": blurred_coverage_rms(xy, diameter, win) if uniform else float("nan"),
        "S_0.3-1": band_mean(ka, s, 0.3, 1.0),
        "S_1-3": band_mean(ka, s, 1.0, 3.0),
        "S_3-10a": band_mean(ka, s, 2 * math.pi / 10, 2 * math.pi / 3),
        "psi6": float(np.abs(p[inw]).mean()),
        "coh2": patch_coherence(xy[inw], p[inw]),
        "nn1/a": float(np.percentile(dd[:, 1], 1) / a),
        "<60": len(tree.query_pairs(0.060)),
        "<46": len(tree.query_pairs(0.046 - 1e-9)),
        "wall": float(worst),
    }


def time_against(job, old, rounds: int, name: str) -> None:
    """The issue's time target: ``generate()`` for the default and for ``old``, each
    warmed once, then alternated ``rounds`` times; medians and their ratio."""
    generate(job)
    generate(job, formulation=old)
    then, now = [], []
    for _ in range(rounds):
        t = time.perf_counter()
        generate(job, formulation=old)
        then.append(time.perf_counter() - t)
        t = time.perf_counter()
        generate(job)
        now.append(time.perf_counter() - t)
    a, b = float(np.median(then)), float(np.median(now))
    print(f"# {machine()}")
    print(f"{name}: optdot 0.3 {a:.3f} s, optdot {b:.3f} s, ratio {b / a:.2f} ({rounds} rounds)")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    maps = ["uniform", "led", "tsuno", "chokka", "walls"]
    ap.add_argument("--map", default="uniform", choices=maps)
    ap.add_argument("--only", nargs="*")
    ap.add_argument(
        "--points", action="append", default=[], metavar="NAME=FILE[:SECONDS]",
        help="a peer's points from another environment: FILE.npy of [n, 2] in the unit "
        "square (scaled to the map's box), measured as row NAME (uniform map only)",
    )  # fmt: skip
    ap.add_argument(
        "--time-rounds", type=int, default=0, metavar="N",
        help="instead: time generate() for the default and for 'optdot 0.3', alternated N "
        "times in one warm process, and print the medians and their ratio",
    )  # fmt: skip
    args = ap.parse_args()
    tmp = Path(tempfile.mkdtemp())
    path = {
        "uniform": lambda: uniform_job(tmp),
        "walls": lambda: walls_job(tmp),
    }.get(args.map, lambda: ROOT / "samples" / args.map / "job.toml")()
    job = load_job(path)
    uniform = args.map == "uniform"
    old = dataclasses.replace(PRESETS["optdot"], phantoms=False, lowpass=0, lowpass_core_iter=0)
    if args.time_rounds:
        time_against(job, old, args.time_rounds, args.map)
        return
    print(f"# {machine()}")
    print(f"# map {args.map}: {path}")
    head = ["pattern", "dots", "coverage RMS 0.5 mm", "S 0.3–1", "S 1–3", "S 3–10 a"]
    head += ["ψ6", "coherence 2 mm"]
    head += ["nn 1% / a", "< 60 µm", "< 46 µm", "worst wall band", "s"]
    print("| " + " | ".join(head) + " |")
    print("|" + "---|" * len(head))

    def row(name, xy, diameter, seconds):
        m = measure(xy, diameter, job, uniform, whole=args.map == "walls")
        rms = "–" if math.isnan(m["rms"]) else f"{100 * m['rms']:.3f} %"
        cells = [name, len(xy), rms, f"{m['S_0.3-1']:.5f}", f"{m['S_1-3']:.4f}"]
        cells += [f"{m['S_3-10a']:.4f}"]
        cells += [f"{m['psi6']:.3f}", f"{m['coh2']:.3f}", f"{m['nn1/a']:.2f}", m["<60"]]
        secs = "–" if math.isnan(seconds) else f"{seconds:.1f}"
        cells += [m["<46"], f"{100 * m['wall']:+.1f} %", secs]
        print("| " + " | ".join(str(c) for c in cells) + " |", flush=True)

    def run(name, form=None, method=None):
        if args.only and name not in args.only:
            return
        j = job
        if method is not None:
            j = dataclasses.replace(job, optimize=dataclasses.replace(job.optimize, method=method))
        t = time.perf_counter()
        p = generate(j, formulation=form)
        row(name, p.xy, p.diameter, time.perf_counter() - t)

    run("optdot")
    run("optdot 0.3", old)
    run("paper", PRESETS["paper"])
    run("md", method="md")
    if not uniform:
        return
    from optdot.orchestration.job_settings import stage_settings
    from optdot.stages import throw

    n = job.density.dot_count(math.pi * 0.023**2)
    box = (0.0, 0.0, job.density.width, job.density.height)
    peers = {
        "sobol": lambda: throw(stage_settings(job), n, 1, None, "uniform"),
        "poisson": lambda: np.random.default_rng(1).uniform(box[:2], box[2:], (n, 2)),
        "scipy PoissonDisk": lambda: poisson_disk(job, n),
        "lloyd": lambda: lloyd(throw(job, n, 1, None, "uniform"), box),
    }
    for name, make in peers.items():
        if args.only and name not in args.only:
            continue
        t = time.perf_counter()
        xy = make()
        row(name, xy, 0.046, time.perf_counter() - t)
    for spec in args.points:
        name, _, rest = spec.partition("=")
        file, _, secs = rest.partition(":")
        u = np.load(file)
        row(name, np.mod(u, 1.0) * np.array([box[2], box[3]]), 0.046, float(secs or "nan"))


def poisson_disk(job, n: int) -> np.ndarray:
    from scipy.stats import qmc

    w, h = job.density.width, job.density.height
    a = math.sqrt(2 * w * h / (math.sqrt(3) * n))
    eng = qmc.PoissonDisk(d=2, radius=0.85 * a / w, seed=1)
    u = eng.random(n)
    return u * np.array([w, h])


if __name__ == "__main__":
    main()
