"""Where a ray's time goes among real cut dots (issue 60: the time a ray through real 3-D
dots against ink's): the cost of one meeting with the printed face, by what happens there.

Run: python benchmarks/cut_costs.py [--hits 1e6] [--rounds 3]

The face is the lgp sample's guide (30 x 20 mm) with a map graded 0.1 to 0.4 of 46 µm
dots (the speed case of ``benchmarks/neighbours.py``), generated once and printed as
white ink and as 12 µm dimples. ``--hits`` meetings are drawn at random points of the
face (2 mm in from its walls), each with a direction spread evenly over the lower
hemisphere (``grazing``: only those the bare face reflects totally, coming down at 3 to
42° from the normal's complement, the rays a guide carries). Each meeting is handed, one
at a time in a compiled loop, to what the tracer calls there:

- ``ink face``: the print test (``printed``) and the bottom face (``meet_face``);
- ``cut search``: the walk for the first cavity along the ray's path (``_next_cavity``,
  folded for a ray the face reflects totally), alone;
- ``cut face``: ``meet_dots`` over the dimples, whole (the search, and the walk among the
  cavities for those it meets), split into the meetings whose path passes through a
  cavity and those that meet none.

Printed: nanoseconds a meeting (the best of ``--rounds``), and the share that meet a
cavity. The points are drawn at random over the face, so each meeting reads its dots from
memory afresh; a tracer's successive meetings are a few millimetres apart and cost less.
The harness hands the print's arrays to the compiled calls one meeting at a time, and
numba's reference counting of them is most of what it times (58 % of a cut meeting, 80 %
of an ink one under perf, session 49): read the nanoseconds as ratios, not as a trace's.
"""

from __future__ import annotations

import argparse
import math
import sys
import tempfile
import time
from pathlib import Path

import numba as nb
import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
sys.path.insert(0, str(HERE.parent))
from _common import machine, peak_rss_mb  # noqa: E402
from neighbours import speed_jobs  # noqa: E402

from optdot.config.schema import load_job  # noqa: E402
from optdot.optics.faces import meet_dots, meet_face  # noqa: E402
from optdot.optics.faces.cavities import _next_cavity  # noqa: E402
from optdot.optics.faces.dot_profile import _no_lattice, tallest  # noqa: E402
from optdot.optics.marks import BARE, dot_tables, printed  # noqa: E402
from optdot.optics.rays import ray_state, uniform  # noqa: E402
from optdot.optics.scene import scene_of  # noqa: E402
from optdot.optics.tables import F_COS_DOWN, F_PROF_K, F_PROF_V, L_N, face_row  # noqa: E402
from optdot.orchestration.pipeline import generate  # noqa: E402

INK, SEARCH, CUT = 0, 1, 2


def _scenes(root: Path) -> tuple:
    """The ink and dimple scenes over one generated pattern: ``(ink, dimple, box)``."""
    ink_path, _, dimple_path = speed_jobs(root)
    ink = load_job(ink_path)
    pattern = generate(ink)
    print(f"{len(pattern.xy):,} real dots")
    dim = load_job(dimple_path)
    box = np.array(ink.bench.box, np.float64)
    return scene_of(ink.bench, 1000, pattern), scene_of(dim.bench, 1000, pattern), box


def _print_tuple(scene) -> tuple:
    """The scene's print as the tracer hands it on (``trace``'s ``pr_arrays``)."""
    p = scene.print
    return (
        p.explicit, p.phi, p.g, p.phi2, p.g2, p.start, p.x, p.y, p.foot, p.cg,
        p.cap_start, p.cap, p.cap_g, p.cap_ring, p.turn,
    )  # fmt: skip


@nb.njit(cache=True)
def _meeting(i, box, grazing, cos_down):  # pragma: no cover - compiled
    """Meeting ``i``: ``(state, x, y, dx, dy, dz, u)``, a point 2 mm in from the walls, a
    direction down (only those the face reflects totally when ``grazing``) and a draw."""
    state = ray_state(7, i)
    state, a = uniform(state)
    state, b = uniform(state)
    state, c = uniform(state)
    state, d = uniform(state)
    state, u = uniform(state)
    x = box[0] + 2.0 + a * (box[2] - box[0] - 4.0)
    y = box[1] + 2.0 + b * (box[3] - box[1] - 4.0)
    dz = -(0.05 + c * (cos_down - 0.05)) if grazing else -c
    h = math.sqrt(1.0 - dz * dz)
    return state, x, y, h * math.cos(2.0 * math.pi * d), h * math.sin(2.0 * math.pi * d), dz, u


@nb.njit(cache=True)
def _run(sel, what, face, pa, walls, n, box, grazing, met):  # pragma: no cover - compiled
    """The meetings ``sel`` handed to ``what`` (:data:`INK`, :data:`SEARCH`, :data:`CUT`);
    for :data:`SEARCH`, the cavity each meets into ``met``: 1 on its way down, 2 only
    after the face reflected it (its path folded), 0 none. A sum of the results, so that
    none is left out."""
    dots = dot_tables(pa)
    f = face_row(face, 0)
    deep = max(tallest(f, f[F_PROF_V], f[F_PROF_V], f[F_PROF_K]), 1e-9) * (1.0 + 1e-9)
    acc = 0.0
    for m in range(sel.shape[0]):
        state, x, y, dx, dy, dz, u = _meeting(sel[m], box, grazing, f[F_COS_DOWN])
        if what == INK:
            on = printed(x, y, 1, pa, u)
            state, act, dx, dy, dz = meet_face(
                state, f, False, n, 1.0, False, on != BARE, dx, dy, dz
            )
            acc += act + dz
        elif what == SEARCH:  # from where the path comes down into the cavities' layer
            back = deep / -dz
            place = (0.0, 0.0, 1.0, 0.0, dots[1], dots[2], dots[8])
            r = _next_cavity(
                f, True, dots, (0.0, 0.0, 0.0, 0.0), _no_lattice(), place, x - back * dx,
                y - back * dy, deep, dx, dy, dz,
            )  # fmt: skip
            met[m] = 0 if not r[0] else (2 if r[7] else 1)
            acc += r[3] if r[3] < np.inf else 0.0
        else:
            state, act, _, _, _, dx, dy, dz = meet_dots(
                state, f, n, BARE, x, y, dots, walls, 1.0, dx, dy, dz
            )
            acc += act + dz
    return acc


def _time(rounds: int, *args) -> float:
    """The best of ``rounds`` runs of :func:`_run`, nanoseconds a meeting."""
    best = np.inf
    for _ in range(rounds):
        t = time.perf_counter()
        _run(*args)
        best = min(best, time.perf_counter() - t)
    return best / max(len(args[0]), 1) * 1e9


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--hits", type=float, default=1e6, help="meetings with the face")
    ap.add_argument("--rounds", type=int, default=3, help="runs of each; the best is kept")
    a = ap.parse_args()
    print(machine())
    with tempfile.TemporaryDirectory() as tmp:
        ink, dim, box = _scenes(Path(tmp))
    n = float(ink.stack.layer[0, L_N])
    hits = np.arange(int(a.hits))
    for grazing in (True, False):
        met = np.zeros(len(hits), np.int8)
        args = (dim.stack.face, _print_tuple(dim), dim.stack.walls, n, box, grazing)
        _run(hits[:10], SEARCH, *args, met[:10])  # compiled
        _run(hits, SEARCH, *args, met)
        sets = {
            "all": hits,
            "meeting one down": hits[met == 1],
            "meeting one after": hits[met == 2],
            "meeting none": hits[met == 0],
        }
        print(
            f"\n{'grazing (reflected totally)' if grazing else 'every direction down'}: "
            f"{np.mean(met == 1):.1%} meet a cavity on their way down, "
            f"{np.mean(met == 2):.1%} only after the face reflected them"
        )
        ink_args = (ink.stack.face, _print_tuple(ink), ink.stack.walls, n, box, grazing)
        _run(hits[:10], INK, *ink_args, met[:10])
        _run(hits[:10], CUT, *args, met[:10])
        print(f"  ink face                  {_time(a.rounds, hits, INK, *ink_args, met):7.1f} ns")
        for name, sel in sets.items():
            search = _time(a.rounds, sel, SEARCH, *args, met.copy())
            cut = _time(a.rounds, sel, CUT, *args, met.copy())
            print(f"  cut, {name:<18}  search {search:7.1f} ns   face {cut:7.1f} ns")
    print(f"peak {peak_rss_mb():.0f} MB (one process)")


if __name__ == "__main__":
    main()
