"""Visibility QA on the samples: JND maps, time and memory.

Run: python benchmarks/visibility.py [led tsuno chokka] [--view notebook] [--psf MM]
     [--png-dir docs]

Each sample is generated (``samples/S/job.toml``) in this process; then the luminance grid
is filled and the JND map computed (:mod:`optdot.quality.visibility`), timed alone. Prints
one row per sample: dots, grid cells, seconds of the visibility step, peak RSS of the
process, the largest |JND| and where, the 99th percentile, blobs over 1 JND; writes the
JND map as ``<png-dir>/jnd_<sample>.png``.
"""

from __future__ import annotations

import argparse
import resource
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from optdot.config.schema import load_job  # noqa: E402
from optdot.config.viewing import VIEW_PRESETS, viewing  # noqa: E402
from optdot.orchestration.pipeline import generate  # noqa: E402
from optdot.quality.visibility import LuminanceGrid, visibility  # noqa: E402


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("samples", nargs="*", default=["led", "tsuno", "chokka"])
    ap.add_argument("--view", default="notebook", choices=list(VIEW_PRESETS))
    ap.add_argument("--psf", type=float, default=None)
    ap.add_argument("--png-dir", type=Path, default=None)
    args = ap.parse_args()
    view = viewing(args.view, psf=args.psf)
    print(f"**python benchmarks/visibility.py {' '.join(args.samples)} --view {args.view}**")
    print(f"view: {view.describe()}\n")
    print(
        "| sample | dots | grid cells | visibility s | peak GiB | max JND | at (mm) | p99 "
        "| blobs > 1 |"
    )
    print("|---|---|---|---|---|---|---|---|---|")
    for name in args.samples:
        job = load_job(ROOT / "samples" / name / "job.toml")
        pattern = generate(job)
        t = time.perf_counter()
        g = LuminanceGrid.over(job.density, view)
        area = np.pi * (0.5 * pattern.diameter) ** 2 * np.ones(len(pattern.xy))
        g.add(pattern.xy, area)
        outline = None if job.domain.rectangle else job.domain
        m, arrays = visibility(g, job.density, outline, view)
        secs = time.perf_counter() - t
        gib = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 2**20
        x, y = m["max_jnd_at_mm"]
        print(
            f"| {name} | {len(pattern.xy):,} | {g.nx * g.ny:,} | {secs:.2f} | {gib:.2f} | "
            f"{m['max_jnd']:.2f} | ({x:.1f}, {y:.1f}) | {m['jnd_percentiles']['99']:.2f} | "
            f"{m['blobs_over_1_jnd']} |"
        )
        if args.png_dir:
            _png(arrays["jnd"], args.png_dir / f"jnd_{name}.png", f"{name}: {view.describe()}")


def _png(jnd, path: Path, title: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    img, ext = jnd
    fig, ax = plt.subplots(figsize=(7, 3.5))
    im = ax.imshow(img, origin="lower", extent=ext, cmap="RdBu_r", vmin=-3, vmax=3)
    fig.colorbar(im, ax=ax, label="JND")
    ax.set(xlabel="x (mm)", ylabel="y (mm)", title=title)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=70, metadata={"Software": None})
    plt.close(fig)


if __name__ == "__main__":
    main()
