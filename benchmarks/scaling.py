"""Scaling: synthetic direct-lit maps of 10⁵ … 10⁷ dots, end to end in one process each.

Run: python benchmarks/scaling.py [--sizes 1e5 3e5 1e6 1e7] [--max-iter 200]
Each size runs in a fresh subprocess so peak RSS is per size. Prints dots, seconds
(generate only, numba cache warm), seconds per iteration, peak RSS, pairs < 46/60 µm.
"""

from __future__ import annotations

import argparse
import subprocess
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
CHILD = r"""
import sys, time, math, numpy as np
sys.path.insert(0, {here!r})
from _common import peak_rss_mb
from optdot.density import DensityMap
from optdot.job import Job, OptimizeParams
from optdot.generate import generate
from optdot.neighbors import pairs_within
n_target, max_iter, ftol = {n}, {it}, {ftol}
mean_fill, d = 0.22, 0.046
area = n_target * math.pi * (d / 2) ** 2 / mean_fill
w = math.sqrt(area * 16 / 9); h = area / w
ny, nx = max(4, int(h / 0.5)), max(4, int(w / 0.5))
Y, X = np.meshgrid((np.arange(ny) + .5) * h / ny, (np.arange(nx) + .5) * w / nx, indexing="ij")
g = 0.28 - 0.18 * np.exp(-(((X % 13) - 6.5) ** 2 + ((Y % 13) - 6.5) ** 2) / 18.0)
g *= mean_fill / g.mean()
job = Job(width=w, height=h, density=DensityMap(g, w, h), diameter=d,
          optimize=OptimizeParams(max_iter=max_iter, ftol=ftol))
t = time.perf_counter(); p = generate(job); s = time.perf_counter() - t
it = max(p.meta["iterations"], 1)
print(f"{{p.n}} | {{s:.1f}} | {{p.meta['iterations']}} | {{s / it:.3f}} | {{peak_rss_mb():.0f}} | "
      f"{{len(pairs_within(p.xy, 0.046))}} | {{len(pairs_within(p.xy, 0.060))}}", flush=True)
"""


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--sizes", nargs="*", type=float, default=[1e5, 3e5, 1e6])
    ap.add_argument("--max-iter", type=int, default=200)
    ap.add_argument("--ftol", type=float, default=1e-3)
    a = ap.parse_args()
    sys.path.insert(0, str(HERE))
    from _common import machine

    print(f"# {machine()}")
    print("dots | seconds | iterations | s/iteration | peak RSS MB | pairs<46um | pairs<60um")
    for n in a.sizes:
        code = CHILD.format(here=str(HERE), n=int(n), it=a.max_iter, ftol=a.ftol)
        subprocess.run([sys.executable, "-c", code], check=True)


if __name__ == "__main__":
    main()
