"""Write time and file size per format at 10⁵ and 10⁶ dots (random centres, 46 µm dots).

Run: python benchmarks/export_speed.py [--sizes 1e5 1e6]
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import machine  # noqa: E402

from optdot import exporters  # noqa: E402
from optdot.pattern import Pattern  # noqa: E402


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--sizes", nargs="*", type=float, default=[1e5, 1e6])
    a = ap.parse_args()
    print(f"# {machine()}")
    print("dots | format | seconds | MB")
    with tempfile.TemporaryDirectory() as d:
        for n in map(int, a.sizes):
            w = np.sqrt(n / 70.0 * 16 / 9)
            h = w * 9 / 16
            xy = np.round(np.random.default_rng(0).random((n, 2)) * [w, h], 6)
            p = Pattern(xy=xy, diameter=0.046, box=(0.0, 0.0, float(w), float(h)))
            for fmt in ("gds", "oas", "dxf", "csv"):
                path = os.path.join(d, f"p.{fmt}")
                t = time.perf_counter()
                exporters.write(p, fmt, path)
                s = time.perf_counter() - t
                print(f"{n} | {fmt} | {s:.2f} | {os.path.getsize(path) / 1e6:.1f}", flush=True)


if __name__ == "__main__":
    main()
