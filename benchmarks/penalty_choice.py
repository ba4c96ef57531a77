"""Which footprint penalty relaxes shaped dots better: the paper's multi-sphere scheme
(what optdot ships, :mod:`optdot.relax.multisphere`) or the exact edge gap of convex
footprints (issue 37 asks to measure both)?

The exact term (:mod:`optdot.relax.exactgap`) penalises every pair whose exact edge gap
is under the gap, ``w (gap - g)²``, on the same Verlet list and at the same weight; each
term is put in for the case's kind for one run (the kind's ``relaxation``);
everything else (the spacing circles, containers, walls, the correction, the exact
guarantee pass) is the job's.

Prints per case and term: seconds of ``generate`` (one process), L-BFGS evaluations, the
pairs the guarantee pass had to fix, and QA's close-pair share and ψ6 coherence:

    python benchmarks/penalty_choice.py --dots 1e5
"""

from __future__ import annotations

import argparse
import time

from shapes import job as write_job  # benchmarks/shapes.py: the same edge-lit jobs

from optdot.config.schema import load_job
from optdot.geometry.kinds import KINDS
from optdot.orchestration.pipeline import generate, qa
from optdot.relax import optdot as relax_optdot
from optdot.relax.exactgap import ExactGapTerm
from optdot.relax.multisphere import MultiSphereTerm


def run(path, kind: str, term) -> dict:
    """Generate the job at ``path`` with ``term`` relaxing dots of ``kind``; QA it."""
    cls = type(KINDS[kind])  # on the kind's class (a polygon is made per job) for this run
    name = next(n for n, t in relax_optdot.FOOTPRINT_TERMS.items() if t is term)
    own = cls.__dict__.get("relaxation")
    cls.relaxation = name
    try:
        job = load_job(path)
        t0 = time.perf_counter()
        p = generate(job)
        secs = time.perf_counter() - t0
    finally:  # the kind's own again
        if own is None:
            del cls.relaxation
        else:
            cls.relaxation = own
    r = qa(p, job)
    m = r.metrics
    return {
        "dots": p.n,
        "s": secs,
        "iterations": p.meta.get("iterations"),
        "guarantee pair fixes": p.meta.get("legalize_pair_fixes"),
        "collisions": m["pairs_below_collision"],
        "in close pairs": round(m["dots_in_close_pairs_fraction"], 4),
        "psi6": round(m["psi6_coherence_2mm"], 4),
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--dots", type=float, default=1e5)
    ap.add_argument("--case", action="append", choices=["ellipse", "prism", "hexagon", "triangle"])
    a = ap.parse_args()
    for case in a.case or ["ellipse", "prism"]:
        path = write_job(case, a.dots)
        kind = {"ellipse": "ellipse", "prism": "rounded_rectangle"}.get(case, "polygon")
        run(path, kind, MultiSphereTerm)  # compile both once
        run(path, kind, ExactGapTerm)
        for name, term in (("multi-sphere", MultiSphereTerm), ("exact gap", ExactGapTerm)):
            got = run(path, kind, term)
            print(f"{case:8s} {name:13s} " + ", ".join(f"{k} {v}" for k, v in got.items()))


if __name__ == "__main__":
    main()
