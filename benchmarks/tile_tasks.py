"""Where a tiled run's time goes: every tile task of a panel run in this process (numba on
all cores), timed by kind (initial throw, relax, seams, merge, correction, guarantee pass).

    python benchmarks/tile_tasks.py coupon --max-iter 80 --max-iter 200
    PYTHONPATH=/path/to/old/tree python -P benchmarks/tile_tasks.py coupon   # an A/B side

Prints dots, seconds per kind of task and in all, dots/s and the peak RSS of this process.
"""

from __future__ import annotations

import argparse
import collections
import resource
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
import panels  # noqa: E402

import optdot  # noqa: E402
from optdot import load_job  # noqa: E402
from optdot.orchestration.tiling.plan import plan_tiles  # noqa: E402
from optdot.orchestration.tiling.run import InProcess, run_tiles  # noqa: E402


class Timed(InProcess):
    """Runs each task when submitted, adding its seconds to its kind."""

    def __init__(self) -> None:
        self.seconds: collections.Counter = collections.Counter()

    def submit(self, kind, key, fn, *args):
        t = time.perf_counter()
        out = fn(*args)
        self.seconds[kind] += time.perf_counter() - t
        return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("panel", choices=sorted(panels.PANELS))
    ap.add_argument("--max-iter", type=int, action="append", help="optimize.max_iter")
    args = ap.parse_args()
    print(f"optdot from {Path(optdot.__file__).parent}")
    print(
        "| max_iter | dots | tiles | initial | relax | seams | correct | guarantee | total s "
        "| dots/s |"
    )
    print("|---|---|---|---|---|---|---|---|---|---|")
    for max_iter in args.max_iter or [80]:
        job = load_job(panels.write_panel(args.panel, max_iter=max_iter))
        plan = plan_tiles(job)
        ex = Timed()
        t0 = time.perf_counter()
        run_tiles(job, plan, ex, lambda *a: None)
        secs = time.perf_counter() - t0
        s = ex.seconds
        print(
            f"| {max_iter} | {job.n_dots:,} | {plan.count} | {s['initial']:.1f} | "
            f"{s['relax']:.1f} | {s['seams']:.1f} | {s.get('correct', 0.0):.1f} | "
            f"{s['legal']:.1f} | {secs:.1f} | "
            f"{job.n_dots / secs:,.0f} |",
            flush=True,
        )
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 2**20
    print(f"peak RSS {peak:.2f} GiB")


if __name__ == "__main__":
    main()
