"""Where a one-process ``generate`` spends its time, kernel by kernel (issue 39).

Run: python benchmarks/relax_profile.py [--dots 1.2e6] [--job JOB.toml] [--warm]

Builds the led sample scaled to about ``--dots`` dots of 46 µm (or reads ``--job``),
wraps the relaxation's compiled kernels in timers (the penalty and gradient, the L-BFGS
vector work, the Verlet list's rebuilds and mover patches; nothing in optdot is
changed), runs :func:`optdot.orchestration.pipeline.generate` in this process (``--warm``: once
before,
so no compilation is timed) and prints: dots, seconds, the stages' seconds, each
kernel's calls and seconds, the penalty's nanoseconds per dot-evaluation (on the dots the
kernels see, phantoms included) and its listed pairs per dot, and peak memory.
"""

from __future__ import annotations

import argparse
import math
import re
import sys
import time
from collections import defaultdict
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
from _common import machine, peak_rss_mb  # noqa: E402

import optdot.relax.lbfgs as lbfgs  # noqa: E402
import optdot.relax.optdot as relax  # noqa: E402
import optdot.spatial.verlet as verlet  # noqa: E402
from optdot.config.schema import load_job  # noqa: E402
from optdot.orchestration import pipeline  # noqa: E402

ROOT = HERE.parent
#: Dots of the led sample as bundled (36 x 15 mm).
LED_DOTS = 111_215

SECONDS: dict[str, float] = defaultdict(float)
CALLS: dict[str, int] = defaultdict(int)
EVALS: list[tuple[int, int]] = []  # (dots the kernel saw, listed pairs) per penalty call


def timed(owner, name: str, label: str) -> None:
    """Replace ``owner.name`` by the same function timed under ``label``."""
    inner = getattr(owner, name)

    def wrapper(*args, **kwargs):
        t0 = time.perf_counter()
        try:
            return inner(*args, **kwargs)
        finally:
            SECONDS[label] += time.perf_counter() - t0
            CALLS[label] += 1

    setattr(owner, name, wrapper)


def instrument() -> None:
    """Timers around the kernels (module attributes the relaxation calls through)."""
    penalty = relax.penalty_fast

    def counted(xy, terms, pairs, grad):
        EVALS.append((len(xy), len(pairs.nbr)))
        return penalty(xy, terms, pairs, grad)

    relax.penalty_fast = counted
    timed(relax, "penalty_fast", "penalty + gradient")
    timed(relax, "minimize_lbfgs", "L-BFGS (all of it)")
    for name in ("_two_loop", "_store", "_axpy"):
        timed(lbfgs, name, "L-BFGS vector work")
    timed(verlet.VerletList, "_rebuild", "Verlet rebuilds")
    timed(verlet, "neighbor_grid", "  of which the cell-grid search")
    timed(verlet, "mover_pairs", "Verlet mover patches")


def scaled_led(dots: float, out: Path) -> Path:
    """The led sample's job with its panel scaled to about ``dots`` dots."""
    src = ROOT / "samples" / "led"
    s = math.sqrt(dots / LED_DOTS)
    text = (src / "job.toml").read_text()
    text = re.sub(
        r"^(width|height) = ([0-9.]+)",
        lambda m: f"{m[1]} = {float(m[2]) * s:.4f}",
        text,
        count=2,
        flags=re.M,
    )
    text = text.replace('grid = "density.csv"', f'grid = "{src / "density.csv"}"')
    out.mkdir(parents=True, exist_ok=True)
    path = out / "job.toml"
    path.write_text(text)
    return path


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--dots", type=float, default=1.2e6)
    ap.add_argument("--job", type=Path)
    ap.add_argument("--out", type=Path, default=HERE / "out" / "relax_profile")
    ap.add_argument("--warm", action="store_true", help="run once before the timed run")
    args = ap.parse_args()
    job = load_job(args.job or scaled_led(args.dots, args.out))
    print(f"machine: {machine()}")
    if args.warm:
        pipeline.generate(job)
    instrument()
    t0 = time.perf_counter()
    pattern = pipeline.generate(job)
    total = time.perf_counter() - t0
    n = pattern.n
    rate = n / total
    print(f"dots: {n:,}; generate {total:.2f} s ({rate:,.0f} dots/s), peak {peak_rss_mb():.0f} MB")
    stages = {k: v for k, v in pattern.stats.items() if k.endswith("_s")}
    print("stages: " + ", ".join(f"{k} {v:.2f}" for k, v in stages.items()))
    for label in sorted(SECONDS, key=lambda k: -SECONDS[k]):
        print(f"  {label:34s} {CALLS[label]:5d} calls {SECONDS[label]:8.3f} s")
    if EVALS:
        seen = sum(d for d, _ in EVALS)
        pairs = max(p / d for d, p in EVALS)
        ns = 1e9 * SECONDS["penalty + gradient"] / seen
        print(
            f"penalty + gradient: {len(EVALS)} evaluations, {ns:.1f} ns per dot-evaluation "
            f"(dots the kernel sees, phantoms included: {EVALS[0][0]:,}); at most {pairs:.2f} "
            "listed pairs per dot (the main relaxation's; the hard-core pass lists fewer)"
        )


if __name__ == "__main__":
    main()
