"""A/B timing of QA (``run_qa`` on one saved pattern) between two source trees, alternated,
because this VM's speed drifts ±25 %.

Run: python benchmarks/qa_ab.py OLD_TREE NEW_TREE PATTERN.npz [--rounds 4]

OLD_TREE and NEW_TREE are checkouts (e.g. ``git worktree add /tmp/old REV``); each run is a
fresh child process importing optdot from that tree and timing ``run_qa`` against a uniform
22 % map over the pattern's box (the map of ``benchmarks/qa_speed.py``, whose pattern can be
saved with ``save_pattern``). A first round warms both trees' numba caches and is not counted.
"""

from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys

CHILD = r"""
import json, sys, time
sys.path.insert(0, sys.argv[1])
import numpy as np
from optdot.config.schema import Job
from optdot.geometry.density import DensityMap
from optdot.io.patterns import load_pattern
from optdot.quality.gate import run_qa
p = load_pattern(sys.argv[2])
x0, y0, x1, y1 = p.box
w, h = x1 - x0, y1 - y0
g = np.full((max(4, int(h / 0.5)), max(4, int(w / 0.5))), 0.22)
job = Job(width=w, height=h, density=DensityMap(g, w, h), diameter=0.046)
t = time.perf_counter()
run_qa(p, job.density, job.qa, job.collision_distance)
print(json.dumps({"s": time.perf_counter() - t}))
"""


def _once(root: str, pattern: str) -> float:
    out = subprocess.run(
        [sys.executable, "-P", "-c", CHILD, root, pattern], capture_output=True, text=True
    )
    if out.returncode:
        sys.exit(out.stderr[-2000:])
    return json.loads(out.stdout.strip().splitlines()[-1])["s"]


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("old")
    ap.add_argument("new")
    ap.add_argument("pattern")
    ap.add_argument("--rounds", type=int, default=4)
    args = ap.parse_args()
    trees = {"old": args.old, "new": args.new}
    for root in trees.values():
        _once(root, args.pattern)  # warm the numba caches
    times: dict[str, list[float]] = {k: [] for k in trees}
    for _ in range(args.rounds):
        for name, root in trees.items():
            s = _once(root, args.pattern)
            times[name].append(s)
            print(f"{name} {s:.2f} s", flush=True)
    for name, v in times.items():
        print(f"{name}: median {statistics.median(v):.2f} s of {[round(x, 2) for x in v]}")


if __name__ == "__main__":
    main()
