"""A/B timing of ``optdot design`` of two commits, interleaved (this VM drifts ±25 %).

Run: python benchmarks/design_ab.py JOB.toml [--old REV] [--rounds 3] [--new-tree PATH]

Checks ``--old`` (default ``HEAD~1``) out into a temporary git worktree and runs ``design``
of ``JOB.toml`` with it (``PYTHONPATH=<tree> python -P -m optdot``) and with the
installed optdot (or ``--new-tree``), alternately, ``--rounds`` times after one warm-up
run each (the numba cache). Prints each run's wall seconds and iterations, then the
medians, the machine and the command.
"""

from __future__ import annotations

import argparse
import os
import re
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
sys.path.insert(0, str(HERE))
from _common import machine  # noqa: E402


def run(tree: Path | None, job: Path, out: Path) -> tuple[float, int]:
    """One ``design`` of ``job`` into ``out``: ``(wall seconds, iterations)``."""
    env = dict(os.environ)
    if tree is not None:
        env["PYTHONPATH"] = str(tree)
    t = time.perf_counter()
    r = subprocess.run(
        [sys.executable, "-P", "-m", "optdot", "design", str(job), "-o", str(out)],
        env=env, capture_output=True, text=True,
    )  # fmt: skip
    wall = time.perf_counter() - t
    if r.returncode != 0:
        raise SystemExit(r.stderr)
    return wall, len(re.findall(r"^iteration +\d+:", r.stderr, flags=re.M))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("job", type=Path)
    ap.add_argument("--old", default="HEAD~1")
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--new-tree", type=Path, default=None)
    args = ap.parse_args()
    job = args.job.resolve()
    with tempfile.TemporaryDirectory(prefix="optdot-design-ab-") as tmp:
        old = Path(tmp) / "old"
        subprocess.run(
            ["git", "-C", str(ROOT), "worktree", "add", "--detach", str(old), args.old],
            check=True, capture_output=True,
        )  # fmt: skip
        try:
            trees = {"old": old, "new": args.new_tree}
            got: dict[str, list[tuple[float, int]]] = {"old": [], "new": []}
            for name, tree in trees.items():  # warm-up: each tree's numba cache
                run(tree, job, Path(tmp) / f"warm-{name}.csv")
            for k in range(args.rounds):
                for name, tree in trees.items():
                    wall, its = run(tree, job, Path(tmp) / f"{name}{k}.csv")
                    got[name].append((wall, its))
                    print(f"round {k + 1} {name}: {wall:.2f} s, {its} iterations", flush=True)
        finally:
            subprocess.run(
                ["git", "-C", str(ROOT), "worktree", "remove", "--force", str(old)],
                capture_output=True,
            )  # fmt: skip
    for name, runs in got.items():
        walls = [w for w, _ in runs]
        print(f"{name}: median {statistics.median(walls):.2f} s over {len(walls)} runs, "
              f"iterations {sorted({i for _, i in runs})}")  # fmt: skip
    print(machine())
    print(f"python benchmarks/design_ab.py {args.job} --old {args.old} --rounds {args.rounds}")


if __name__ == "__main__":
    main()
