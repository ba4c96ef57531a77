"""A/B timing of two commits, interleaved, because this VM's speed drifts ±25 %.

Run: python benchmarks/ab.py JOB.toml [--old REV] [--new REV] [--rounds 4]

Checks out ``--old`` (default ``HEAD~1``) and ``--new`` (default: the working tree) into
temporary git worktrees, warms each one's numba cache, then alternates old/new runs of
``generate()`` in fresh child processes, ``--rounds`` times. Each run prints the
in-process timings (initial dots, relaxation, guarantee pass, total; imports excluded),
then the medians. Comparing runs made minutes apart on this machine is meaningless; runs
made in alternation are not. The children call ``generate()``, not the command: what the
command sets up before numpy loads (``NUMPY_MADVISE_HUGEPAGE=0``, ``optdot.console``) is
not in these figures; time the command itself (``/usr/bin/time optdot generate ...``,
the old tree by ``PYTHONPATH=<tree> python -P -m optdot``) to see it.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
sys.path.insert(0, str(HERE))
from _common import machine  # noqa: E402

CHILD = """
import json, sys, time
import optdot
if hasattr(optdot, "__all__"):  # the public API (0.2 on)
    from optdot import generate, load_job
else:  # a commit from before it
    from optdot.generate import generate
    from optdot.job import load_job
job = load_job(sys.argv[1])
t = time.perf_counter()
p = generate(job)
s = {k: v for k, v in p.stats.items() if k.endswith("_s")}
print(json.dumps({"wall_s": time.perf_counter() - t, "src": optdot.__file__, **s}))
"""


def checkout(rev: str | None, where: Path) -> Path:
    """The source tree of ``rev`` (a worktree under ``where``), or the working tree."""
    if rev is None:
        return ROOT
    path = where / rev.replace("/", "_").replace("~", "_")
    subprocess.run(
        ["git", "-C", str(ROOT), "worktree", "add", "--detach", "-f", str(path), rev],
        check=True,
        capture_output=True,
    )
    return path


def run(tree: Path, job: Path) -> dict:
    out = subprocess.run(
        [sys.executable, "-P", "-c", CHILD, str(job)],
        env={**os.environ, "PYTHONPATH": str(tree)},
        cwd=tree,  # `python -c` puts the working directory first on sys.path
        check=True,
        capture_output=True,
        text=True,
    ).stdout
    res = json.loads(out.strip().splitlines()[-1])
    if not Path(res.pop("src")).resolve().is_relative_to(tree.resolve()):
        raise SystemExit(f"the child imported optdot from outside {tree}")
    return res


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("job", type=Path)
    ap.add_argument("--old", default="HEAD~1")
    ap.add_argument("--new", default=None, help="default: the working tree")
    ap.add_argument("--rounds", type=int, default=4)
    a = ap.parse_args()
    job = a.job.resolve()
    print(f"# {machine()}")
    with tempfile.TemporaryDirectory() as tmp:
        trees = {"old": checkout(a.old, Path(tmp)), "new": checkout(a.new, Path(tmp))}
        try:
            for tree in trees.values():
                run(tree, job)  # compile / warm the numba cache
            seen: dict[str, list[dict]] = {"old": [], "new": []}
            print("run | wall s | initial s | relax s | legalize s")
            for k in range(a.rounds):
                for name, tree in trees.items():
                    r = run(tree, job)
                    seen[name].append(r)
                    print(
                        f"{name} {k + 1} | {r['wall_s']:.2f} | {r['initial_s']:.2f} | "
                        f"{r['relax_s']:.2f} | {r['legalize_s']:.2f}",
                        flush=True,
                    )
            for name, rs in seen.items():
                med = {key: statistics.median(r[key] for r in rs) for key in rs[0]}
                print(f"median {name}: wall {med['wall_s']:.2f} s, relax {med['relax_s']:.2f} s")
        finally:
            for tree in trees.values():
                if tree != ROOT:
                    subprocess.run(
                        ["git", "-C", str(ROOT), "worktree", "remove", "--force", str(tree)],
                        capture_output=True,
                    )


if __name__ == "__main__":
    main()
