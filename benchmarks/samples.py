"""Run every bundled sample: dots, seconds, iterations, penalty, pairs < 46/60 µm.

Run: python benchmarks/samples.py [--formulation optdot|paper] [--max-iter N] [names...]
(numba kernels are cached after the first run; run once to warm up.)
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import machine, peak_rss_mb  # noqa: E402

from optdot.config.schema import load_job  # noqa: E402
from optdot.orchestration.pipeline import generate  # noqa: E402
from optdot.testing import close_pairs  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("names", nargs="*", default=["uniform", "led", "tsuno", "chokka"])
    ap.add_argument("--formulation", default=None)
    ap.add_argument("--max-iter", type=int, default=None)
    ap.add_argument("--ftol", type=float, default=None)
    a = ap.parse_args()
    print(f"# {machine()}")
    print("sample | dots | seconds | iterations | final penalty mm² | pairs<46um | pairs<60um")
    for name in a.names:
        job = load_job(ROOT / "samples" / name / "job.toml").with_overrides(
            formulation=a.formulation, max_iter=a.max_iter, ftol=a.ftol
        )
        t = time.perf_counter()
        p = generate(job)
        s = time.perf_counter() - t
        print(
            f"{name} | {p.n} | {s:.2f} | {p.meta['iterations']} | {p.meta['penalty']:.4g} | "
            f"{len(close_pairs(p.xy, 0.046))} | {len(close_pairs(p.xy, 0.060))}",
            flush=True,
        )
    print(f"# peak RSS {peak_rss_mb():.0f} MB")


if __name__ == "__main__":
    main()
