"""Each relaxation kernel beside the floor this machine allows (issue 39).

Run: python benchmarks/floors.py [--dots 1.2e6] [--evaluation 40] [--repeat 15]

1. A snapshot: the led sample scaled to ``--dots`` dots (as ``relax_profile.py``) is
   generated in this process, keeping what the penalty kernel sees at its
   ``--evaluation``-th call (positions, terms, pair list).
2. The machine: memory bandwidth (STREAM's triad over three vectors of 128 MiB, bytes
   read and written per second as STREAM counts them, best of 5), and the compute cost
   of each kernel's inner step on data in cache, on one thread: the pair term
   (``pair_grad`` and the gradient scatter, over the first block's own pairs, repeated)
   and the cell scan's candidate test (the scan of the first 4,096 dots, repeated).
3. The kernels on the snapshot, all threads, best of ``--repeat``: the penalty and
   gradient; a Verlet rebuild (cell-grid search and block split); one L-BFGS iteration's
   vector work (the two-loop recursion at memory 6, the step and the (s, y) store).
4. Each kernel's floor is the larger of a compute floor (its inner steps at the in-cache
   cost, spread ideally over the threads) and a bandwidth floor (the bytes it must
   stream, listed below, at the measured bandwidth). Printed: ns per dot for each, and
   the kernel's ratio to its floor.

Bytes read + written per dot (8-byte floats, 4-byte pair indices, K listed pairs per
dot): penalty 85 + 4 K read (positions, radii, containers, CSR pointers, skip flags,
pairs), 48 written (packed rows, gradient); rebuild 40 + 4 K read (positions, radii,
cell ids, the segment copied into the list, split into its blocks on the way), 53 + 8 K
written (cell ids, sorted copies, segment, list, the rows' block ends); L-BFGS at memory
m, two coordinates a dot: 2 x (16 (2 m + 1) + 16 + 32) read, 2 x (8 + 16) written (each
fused update of the two-loop recursion streams a history row and the next dot product's
vector, while the direction it updates, 8 bytes an entry, stays in the last-level cache
between passes; the step reads two vectors and writes one; the store reads four and
writes two).
"""

from __future__ import annotations

import argparse
import sys
import time
from dataclasses import fields
from pathlib import Path

import numba as nb
import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
from _common import machine  # noqa: E402
from relax_profile import scaled_led  # noqa: E402

import optdot.relax.lbfgs as lbfgs  # noqa: E402
import optdot.relax.optdot as relax  # noqa: E402
from optdot.config.schema import load_job  # noqa: E402
from optdot.orchestration import pipeline  # noqa: E402
from optdot.relax.penalty import row_pairs  # noqa: E402
from optdot.spatial.blocks import BLOCK, PairList  # noqa: E402
from optdot.spatial.cellgrid import (  # noqa: E402
    Workspace,
    _scan,
    bin_parts,
    bin_points,
    block_pairs,
    neighbor_grid,
)

#: L-BFGS memory the relaxation runs with (``[optimize] lbfgs_memory`` default).
MEMORY = 6


def snapshot(dots: float, evaluation: int, out: Path):
    """``(xy, terms, pairs, skin)`` the penalty saw at its ``evaluation``-th call."""
    job = load_job(scaled_led(dots, out))
    inner = relax.penalty_fast
    seen: list = []

    def keep(xy, terms, pairs, grad):
        if len(seen) < evaluation:
            seen.append(None)
            if len(seen) == evaluation:
                # a copy: the Verlet list's next rebuild writes over its arrays
                kept = {f.name: getattr(pairs, f.name).copy() for f in fields(pairs)}
                seen[-1] = (xy.copy(), terms, PairList(**kept))
        return inner(xy, terms, pairs, grad)

    relax.penalty_fast = keep
    try:
        pipeline.generate(job)
    finally:
        relax.penalty_fast = inner
    if len(seen) < evaluation or seen[-1] is None:
        raise SystemExit(f"the run made fewer than {evaluation} penalty evaluations")
    return (*seen[-1], job.optimize.skin)


def best(fn, repeat: int) -> float:
    """Best wall time of ``fn()``, s (after one call to warm up)."""
    fn()
    t = np.inf
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        t = min(t, time.perf_counter() - t0)
    return t


@nb.njit(parallel=True, cache=True)
def _triad(a, b, c, s):  # pragma: no cover - compiled
    """STREAM's triad ``a <- b + s c``: 24 bytes read and written an entry."""
    for k in nb.prange(a.shape[0]):
        a[k] = b[k] + s * c[k]


@nb.njit(cache=True)
def _pairs_hot(packed, w, ptr, mid, nbr, skip, hi, reps, grad):  # pragma: no cover - compiled
    """The penalty's in-block loop (:func:`optdot.relax.penalty.row_pairs`) over dots
    ``0..hi`` (in cache), ``reps`` times."""
    f = 0.0
    for _ in range(reps):
        for i in range(hi):
            f, gxi, gyi = row_pairs(
                i, ptr[i], mid[i], packed, nbr, skip, False, w, grad, f, 0.0, 0.0
            )
            grad[i, 0] += gxi
            grad[i, 1] += gyi
    return f


@nb.njit(cache=True)
def _scan_hot(xy, reff, grow, start, order, bx, by, br, x0, y0, cell, nx, ny, hi, reps):
    """The cell scan of dots ``0..hi`` (their cells in cache), ``reps`` times; returns
    the candidates tested."""  # pragma: no cover - compiled
    row = np.empty(256, np.int32)
    keys = np.zeros(0, np.int64)  # the dense grid
    cand = 0
    for _ in range(reps):
        for i in range(hi):
            _scan(i, xy, reff, grow, start, keys, order, bx, by, br, x0, y0, cell, nx, ny, row)
            ri = reff[i]
            reach = 2.0 * ri * grow
            ix0 = max(int((xy[i, 0] - reach - x0) / cell), 0)
            ix1 = min(int((xy[i, 0] + reach - x0) / cell), nx - 1)
            iy0 = max(int((xy[i, 1] - reach - y0) / cell), 0)
            iy1 = min(int((xy[i, 1] + reach - y0) / cell), ny - 1)
            for cy in range(iy0, iy1 + 1):
                cand += start[cy * nx + ix1 + 1] - start[cy * nx + ix0]
    return cand


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--dots", type=float, default=1.2e6)
    ap.add_argument("--evaluation", type=int, default=40)
    ap.add_argument("--repeat", type=int, default=15)
    ap.add_argument("--out", type=Path, default=HERE / "out" / "floors")
    args = ap.parse_args()
    threads = nb.get_num_threads()
    print(f"machine: {machine()}, {threads} threads")
    xy, terms, pairs, skin = snapshot(args.dots, args.evaluation, args.out)
    n = len(xy)
    k_pairs = len(pairs.nbr) / n
    print(f"snapshot: evaluation {args.evaluation}, {n:,} dots, {k_pairs:.2f} listed pairs a dot")

    # the machine
    vec = [np.ones(16 * 2**20) for _ in range(3)]
    bw = 3 * vec[0].nbytes / best(lambda: _triad(*vec, 0.5), 5)
    vec.clear()
    r, cr, w = terms.radius, terms.core_radius, terms.w_hard
    hi = min(BLOCK, n)
    hot_pairs = int(pairs.mid[hi - 1] - pairs.ptr[0]) if hi else 0
    grad = np.zeros_like(xy)
    reps = max(1, 2_000_000 // max(hot_pairs, 1))
    packed = np.column_stack([xy, r, cr])
    args_p = (packed, w, pairs.ptr, pairs.mid, pairs.nbr, pairs.skip, hi)
    t = best(lambda: _pairs_hot(*args_p, reps, grad), 5)
    pair_ns = 1e9 * t / (reps * hot_pairs)
    reff = np.ascontiguousarray(terms.reach)
    grid = neighbor_grid(xy, reff, skin)[2]
    binned = bin_points(xy, reff, grid.x0, grid.y0, grid.cell, grid.nx, grid.ny, bin_parts())
    start, order, bx, by, br, _ = binned
    sargs = (xy, reff, 1.0 + skin, start, order, bx, by, br, grid.x0, grid.y0, grid.cell)
    hi_s = min(4096, n)
    cand = _scan_hot(*sargs, grid.nx, grid.ny, hi_s, 1)
    reps = max(1, 4_000_000 // max(cand, 1))
    t = best(lambda: _scan_hot(*sargs, grid.nx, grid.ny, hi_s, reps), 5)
    cand_ns = 1e9 * t / (reps * cand)
    cand_per_dot = cand / hi_s
    print(
        f"bandwidth {bw / 1e9:.1f} GB/s (STREAM triad); in cache, one "
        f"thread: pair term {pair_ns:.2f} ns a pair, scan {cand_ns:.2f} ns a candidate "
        f"({cand_per_dot:.1f} candidates a dot)"
    )

    # the kernels on the snapshot
    g = np.empty_like(xy)
    t_pen = best(lambda: relax.penalty_fast(xy, terms, pairs, g), args.repeat)

    ws = Workspace()  # as a Verlet list rebuilds: into the last rebuild's memory

    def rebuild():
        block_pairs(xy, reff, skin, grid.cell, 2 + int(k_pairs * 1.25), ws)

    t_reb = best(rebuild, max(3, args.repeat // 3))
    m2 = 2 * n
    rng = np.random.default_rng(0)
    S = rng.standard_normal((MEMORY, m2))
    Y = S + 0.1 * rng.standard_normal((MEMORY, m2))
    rho = 1.0 / np.einsum("ij,ij->i", S, Y)
    gv, d, x2, s2, y2 = (rng.standard_normal(m2) for _ in range(5))
    slots = list(range(MEMORY))

    def lbfgs_iteration():
        lbfgs._two_loop(gv, S, Y, rho, slots, 1.0, d)
        lbfgs._axpy(x2, 0.5, d, s2)
        lbfgs._store(S[0], Y[0], s2, x2, d, gv)

    t_lb = best(lbfgs_iteration, args.repeat)

    rows = [
        ("penalty + gradient", t_pen, k_pairs * pair_ns / threads, (85 + 4 * k_pairs, 48)),
        (
            "Verlet rebuild",
            t_reb,
            cand_per_dot * cand_ns / threads,
            (40 + 4 * k_pairs, 53 + 8 * k_pairs),
        ),
        (
            "L-BFGS vector work (an iteration)",
            t_lb,
            0.0,
            (2 * (16 * (2 * MEMORY + 1) + 48), 2 * 24),
        ),
    ]
    print(
        f"{'kernel':36s} {'ns/dot':>8s} {'compute':>8s} {'bytes':>6s} {'bandw.':>7s} {'ratio':>6s}"
    )
    for label, t, compute_ns, (read, written) in rows:
        ns = 1e9 * t / n
        nbytes = read + written
        band_ns = 1e9 * nbytes / bw
        floor = max(compute_ns, band_ns)
        print(
            f"{label:36s} {ns:8.1f} {compute_ns:8.1f} {nbytes:6.0f} {band_ns:7.1f} "
            f"{ns / floor:6.2f}"
        )


if __name__ == "__main__":
    main()
