"""Scaling: synthetic direct-lit maps of 10⁵ … 10⁷ dots, `optdot generate` end to end.

Run: python benchmarks/scaling.py [--sizes 1e5 1.2e5 3e5 1e6 1.2e6 1e7] [--max-iter 200]
                                  [--ftol 0] [--keep DIR]

For each size a job (density CSV + job.toml) is written to a temporary directory and
`optdot generate job.toml -o pattern.npz -q` runs as a child process: seconds are wall
time from process start to the file renamed into place (imports and numba cache loading
included; the cache is warm after the first run of the suite). Peak RSS is the child's
(``wait4``). `ftol = 0` by default so every size does all `max_iter` iterations, as the
speed targets state. Pairs < 46/60 µm are counted on the written file with the same
grid search the tool uses (cross-checked by shapely in the QA benchmark).
"""

from __future__ import annotations

import argparse
import math
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
from _common import machine  # noqa: E402

from optdot.io.patterns import load_pattern  # noqa: E402
from optdot.spatial.cellgrid import pairs_within  # noqa: E402

DIAMETER = 0.046
MEAN_FILL = 0.22


def write_job(folder: Path, n_target: int, max_iter: int, ftol: float) -> None:
    """A 16:9 panel whose map (0.5 mm cells) holds about ``n_target`` 46 µm dots.

    The map is a direct-lit array: fill 0.28 between LEDs dipping to ~0.10 over each LED
    on a 13 mm pitch, scaled to a mean of 0.22.
    """
    area = n_target * math.pi * (DIAMETER / 2) ** 2 / MEAN_FILL
    w = math.sqrt(area * 16 / 9)
    h = area / w
    ny, nx = max(4, round(h / 0.5)), max(4, round(w / 0.5))
    yy, xx = np.meshgrid(
        (np.arange(ny) + 0.5) * h / ny, (np.arange(nx) + 0.5) * w / nx, indexing="ij"
    )
    g = 0.28 - 0.18 * np.exp(-(((xx % 13) - 6.5) ** 2 + ((yy % 13) - 6.5) ** 2) / 18.0)
    g *= MEAN_FILL / g.mean()
    np.savetxt(folder / "density.csv", g, fmt="%.5f", delimiter=",")
    (folder / "job.toml").write_text(
        f'name = "scaling-{n_target}"\n[domain]\nwidth = {w!r}\nheight = {h!r}\n'
        f'[density]\ngrid = "density.csv"\n[dots]\ndiameter = {DIAMETER}\n'
        f"[optimize]\nmax_iter = {max_iter}\nftol = {ftol}\nseed = 1\n"
    )


def run_one(n_target: int, max_iter: int, ftol: float, keep: Path | None) -> str:
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp) if keep is None else keep / f"n{n_target}"
        folder.mkdir(parents=True, exist_ok=True)
        write_job(folder, n_target, max_iter, ftol)
        out = folder / "pattern.npz"
        cmd = [sys.executable, "-P", "-m", "optdot.cli", "generate", str(folder / "job.toml")]
        t = time.perf_counter()
        proc = subprocess.Popen([*cmd, "-o", str(out), "-q"])
        _, status, usage = os.wait4(proc.pid, 0)
        seconds = time.perf_counter() - t
        if os.waitstatus_to_exitcode(status) != 0:
            return f"{n_target:,} | failed with exit code {os.waitstatus_to_exitcode(status)}"
        p = load_pattern(out)
        it = max(int(p.meta["iterations"]), 1)
        c46 = len(pairs_within(p.xy, DIAMETER))
        c60 = len(pairs_within(p.xy, 0.060))
        rss = usage.ru_maxrss / 1024
        return (
            f"{p.n:,} | {seconds:.1f} | {p.meta['iterations']} | {seconds / it:.3f} | "
            f"{p.n / seconds:,.0f} | {rss:,.0f} | {c46} | {c60:,}"
        )


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--sizes", nargs="*", type=float, default=[1e5, 1.2e5, 3e5, 1e6, 1.2e6])
    ap.add_argument("--max-iter", type=int, default=200)
    ap.add_argument("--ftol", type=float, default=0.0)
    ap.add_argument("--keep", type=Path, default=None, help="keep jobs and patterns here")
    a = ap.parse_args()
    print(f"# {machine()}")
    print(f"# optdot generate, max_iter = {a.max_iter}, ftol = {a.ftol}, seed 1")
    print(
        "dots | seconds | iterations | s/iteration | dots/s | peak RSS MB | pairs<46um | pairs<60um"
    )
    for n in a.sizes:
        print(run_one(int(n), a.max_iter, a.ftol, a.keep), flush=True)


if __name__ == "__main__":
    main()
