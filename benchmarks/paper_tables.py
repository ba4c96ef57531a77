"""The paper's Tables 2–4 and Figure 4 on our samples: initial layout vs MD vs OptDot.

Run: python benchmarks/paper_tables.py [--max-iter 200] [--samples tsuno chokka led]
                                       [--figure docs/figure4.png] [--no-peer]

Both methods start from the same initial dots (same seed) and run ``max_iter`` steps /
iterations with no early stop (``ftol = 0``), as in the paper. Pairs and zero-cell dots
are counted on the *relaxed* layout, before optdot's guarantee pass (which then fixes
whatever is left, for every method); seconds are the relaxation alone and the whole
``generate()`` (initial dots + relaxation + guarantee pass). Pairs are counted by
shapely/GEOS (an independent check of the tool's own grid search).

"OptDot" is the paper's formulation (``formulation = "paper"``); "optdot" is this tool's
default formulation, shown beside it. The peer table puts scipy's PoissonDisk sampler
(a generic blue-noise sampler) next to both methods on the uniform sample.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
from _common import machine, peak_rss_mb  # noqa: E402

from optdot.config.schema import Job, load_job  # noqa: E402
from optdot.orchestration.pipeline import generate  # noqa: E402
from optdot.pattern import Pattern  # noqa: E402
from optdot.quality.gate import run_qa  # noqa: E402
from optdot.testing import close_pairs  # noqa: E402

ROOT = HERE.parent
PAPER = {  # Tables 2–4: minutes MD / OptDot, collisions and close pairs init / MD / OptDot
    "tsuno": ("15", "1.9", "24339 / 1 / 0", "45523 / 66 / 16"),
    "chokka": ("38", "4.7", "36827 / 0 / 0", "73055 / 2 / 0"),
    "led": ("38", "1.8", "57949 / 1315 / 0", "104530 / 37844 / 32644"),
}
VARIANTS = (("MD", {"method": "md"}), ("OptDot", {"formulation": "paper"}), ("optdot", {}))


def run(job: Job, **over) -> tuple[dict, np.ndarray, np.ndarray]:
    job = job.with_overrides(ftol=0.0, **over)
    t = time.perf_counter()
    p = generate(job, keep_stages=True)
    total = time.perf_counter() - t
    relaxed = p.stats["relaxed_xy"]
    row = {"relax_s": p.stats["relax_s"], "total_s": total, **quality(job, relaxed)}
    return row, p.stats["initial_xy"], relaxed


def quality(job: Job, xy: np.ndarray) -> dict:
    """Pairs < 46/60 µm, dots in zero cells, coverage error and psi6 of a layout."""
    pattern = Pattern(xy=xy, diameter=job.diameter, box=(0.0, 0.0, job.width, job.height))
    m = run_qa(pattern, job.density, job.qa, job.collision_distance).metrics
    return {
        "c46": m["pairs_below_collision"],
        "c60": m["pairs_below_close"],
        "zero": m["in_empty_cells"],
        "cov": m["coverage_rel_rms_smoothed"],
        "psi": m["psi6_local_mean"],
        "coh": m["psi6_coherence_2mm"],
    }


def fmt(r: dict) -> str:
    return (
        f"{r['c46']:,} | {r['c60']:,} | {r['zero']:,} | {100 * r['cov']:.2f} | "
        f"{r['psi']:.2f} | {r['coh']:.3f}"
    )


def paper_tables(names: list[str], max_iter: int, figure: Path | None) -> None:
    print("\n## Tables 2–4 (relaxed layouts, before the guarantee pass)\n")
    print(
        "sample | dots | method | relax s | total s | pairs<46um | pairs<60um | "
        "dots in zero cells | coverage RMS % (1 mm) | psi6 mean | psi6 coherence 2 mm"
    )
    print("---|---|---|---|---|---|---|---|---|---|---")
    ratios = []
    for name in names:
        job = load_job(ROOT / "samples" / name / "job.toml").with_overrides(max_iter=max_iter)
        rows, layouts = {}, {}
        for label, over in VARIANTS:
            rows[label], initial, layouts[label] = run(job, **over)
        print(f"{name} | {len(initial):,} | initial | – | – | {fmt(quality(job, initial))}")
        for label, r in rows.items():
            print(
                f"{name} | {len(initial):,} | {label} | {r['relax_s']:.1f} | {r['total_s']:.1f} | "
                f"{fmt(r)}",
                flush=True,
            )
        ratios.append((name, rows["MD"]["relax_s"] / rows["OptDot"]["relax_s"]))
        if figure is not None and name == "tsuno":
            figure_4(job, layouts["MD"], layouts["OptDot"], figure)
    print("\nMD time / OptDot time (relaxation): " + ", ".join(f"{n} {r:.1f}x" for n, r in ratios))
    print(
        "\nPaper (Core 2 Duo, C++): minutes MD / OptDot; "
        "collisions and close pairs init / MD / OptDot"
    )
    for name in names:
        if name in PAPER:
            md, od, col, close = PAPER[name]
            print(f"{name}: {md} / {od} min; <46um {col}; <60um {close}")


def peer_table(max_iter: int) -> None:
    from scipy.spatial import cKDTree
    from scipy.stats import qmc

    job = load_job(ROOT / "samples" / "uniform" / "job.toml").with_overrides(max_iter=max_iter)
    n = job.n_dots
    print(f"\n## Peer: uniform sample ({job.width:g} x {job.height:g} mm, fill 0.2, {n:,} dots)\n")
    print(
        "method | seconds | dots placed | pairs<46um | pairs<60um | NN mean um | NN CV | NN 1% um"
    )
    print("---|---|---|---|---|---|---|---")

    def report(label: str, seconds: float, xy: np.ndarray) -> None:
        nn = cKDTree(xy).query(xy, k=2)[0][:, 1] * 1e3
        print(
            f"{label} | {seconds:.2f} | {len(xy):,} | {len(close_pairs(xy, 0.046)):,} | "
            f"{len(close_pairs(xy, 0.060)):,} | {nn.mean():.1f} | {nn.std() / nn.mean():.3f} | "
            f"{np.quantile(nn, 0.01):.1f}",
            flush=True,
        )

    for label, over in VARIANTS:
        j = job.with_overrides(ftol=0.0, **over)
        t = time.perf_counter()
        p = generate(j)
        report(f"{label} (after guarantee pass)", time.perf_counter() - t, p.xy)
    r0 = 0.5 * job.diameter
    lo, hi = [r0, r0], [job.width - r0, job.height - r0]
    # PoissonDisk.random(n) grows from a seed and stops after n points (a dense patch), so
    # fill the whole panel: at 60 µm (the "close" distance) and at the radius that gives
    # about the map's dot count (found once by bisection: 0.0705 mm here)
    for radius in (0.060, 0.0705):
        t = time.perf_counter()
        eng = qmc.PoissonDisk(2, radius=radius, l_bounds=lo, u_bounds=hi, rng=1)
        xy = eng.fill_space()
        report(f"PoissonDisk fill, radius {radius * 1e3:.1f} um", time.perf_counter() - t, xy)


def figure_4(job: Job, md: np.ndarray, od: np.ndarray, path: Path) -> None:
    """Same zoomed window at the edge of tsuno's empty corner, MD beside OptDot."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.collections import PatchCollection
    from matplotlib.patches import Circle, Rectangle

    x0, y0, w, h = 1.6, 1.9, 2.4, 1.8
    dm = job.density
    cw, ch = dm.cell_size
    fig, axes = plt.subplots(1, 2, figsize=(11, 4.4), dpi=110)
    for ax, xy, title in (
        (axes[0], md, "MD (Idé et al. 2003)"),
        (axes[1], od, "OptDot (paper formulation)"),
    ):
        iy, ix = np.nonzero(dm.grid <= 0)
        cells = [
            Rectangle((dm.x0 + i * cw, dm.y0 + k * ch), cw, ch) for k, i in zip(iy, ix, strict=True)
        ]
        ax.add_collection(PatchCollection(cells, facecolor="#dde6f3", edgecolor="none"))
        sel = (
            (xy[:, 0] > x0 - 0.1)
            & (xy[:, 0] < x0 + w + 0.1)
            & (xy[:, 1] > y0 - 0.1)
            & (xy[:, 1] < y0 + h + 0.1)
        )
        bad = dm.empty_mask(xy[sel])
        dots = [Circle(p, 0.5 * job.diameter) for p in xy[sel]]
        colors = np.where(bad, "#d62728", "#222222")
        ax.add_collection(PatchCollection(dots, facecolor=colors, edgecolor="none"))
        ax.set_xlim(x0, x0 + w)
        ax.set_ylim(y0, y0 + h)
        ax.set_aspect("equal")
        ax.set_title(f"{title}: {int(dm.empty_mask(xy).sum())} dots in the empty region (red)")
        ax.set_xlabel("x (mm)")
    axes[0].set_ylabel("y (mm)")
    fig.suptitle(
        "tsuno, edge of the empty corner (blue cells: rho = 0), "
        "200 steps / iterations, before the guarantee pass"
    )
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, metadata={"Software": None})
    print(f"\nwrote {path}")


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--samples", nargs="*", default=["tsuno", "chokka", "led"])
    ap.add_argument("--max-iter", type=int, default=200)
    ap.add_argument("--figure", type=Path, default=None, help="write the Figure-4 picture here")
    ap.add_argument("--no-peer", action="store_true")
    a = ap.parse_args()
    print(f"# {machine()}")
    print(f"# python benchmarks/paper_tables.py, max_iter = {a.max_iter}, ftol = 0, seed 1")
    paper_tables(a.samples, a.max_iter, a.figure)
    if not a.no_peer:
        peer_table(a.max_iter)
    print(f"\n# peak RSS {peak_rss_mb():.0f} MB")


if __name__ == "__main__":
    main()
