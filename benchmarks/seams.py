"""Profiles across tile seams (issue 24): coverage, ψ6, close pairs and nearest-neighbour
distance against the distance from the nearest inner tile border, averaged along every
seam, for a tiled dataset beside the same job in one process measured on the same lines.

Run: python benchmarks/seams.py JOB.toml [--tile-size 10] [--band 0.05] [--reach 1.0]

Each dot goes to the band of its centre's distance from the nearest inner seam line (the
tiled run's own tile edges; the single-process pattern is measured on the same lines, so
its profile is what "no seam" looks like with this map and this noise). Coverage per band
is the number of dots whose centres lie in it over the map's integral over the band (a
raster of 0.01 mm pixels binned the same way), minus 1; at 0.05 mm bands a row of dots
standing on the seam shows as a peak. ψ6 is |ψ6| over the 6 nearest neighbours; close =
share of dots in a pair closer than 60 µm; nn = nearest-neighbour distance over the local
hexagonal spacing. The single process runs two passes of the long-wavelength correction,
tiles one (blended across their borders): compare each column's shape along the rows
(seam against far from it) first, tiled against one second.
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np
from scipy.spatial import cKDTree

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
from _common import machine  # noqa: E402

from optdot.config.schema import load_job  # noqa: E402
from optdot.io.dataset import load_dataset, open_dataset  # noqa: E402
from optdot.io.patterns import load_pattern  # noqa: E402
from optdot.quality.metrics import psi6  # noqa: E402


def seam_distance(xy: np.ndarray, xs: np.ndarray, ys: np.ndarray) -> np.ndarray:
    """``[n]`` distance of each centre from the nearest inner tile edge, mm."""
    d = np.full(len(xy), np.inf)
    if len(xs) > 2:
        d = np.minimum(d, np.abs(xy[:, 0, None] - xs[None, 1:-1]).min(axis=1))
    if len(ys) > 2:
        d = np.minimum(d, np.abs(xy[:, 1, None] - ys[None, 1:-1]).min(axis=1))
    return d


def strip_target(job, xs, ys, edges, px: float = 0.01) -> np.ndarray:
    """``[b]`` the map's integral over each band (pixels of ``px`` by their distance from
    the nearest inner seam line, as the dots are), in dots."""
    dens = job.density
    out = np.zeros(len(edges) - 1)
    cx = dens.x0 + (np.arange(round(dens.width / px)) + 0.5) * px
    for y in dens.y0 + (np.arange(round(dens.height / px)) + 0.5) * px:
        pts = np.column_stack([cx, np.full(len(cx), y)])
        k = np.digitize(seam_distance(pts, xs, ys), edges) - 1
        ok = (k >= 0) & (k < len(out))
        out += np.bincount(k[ok], dens.at(pts[ok]), minlength=len(out)) * px * px
    return out / (np.pi * (0.5 * job.diameter) ** 2)


def profile(xy, job, xs, ys, edges) -> dict[str, np.ndarray]:
    d = seam_distance(xy, xs, ys)
    k = np.digitize(d, edges) - 1
    ok = (k >= 0) & (k < len(edges) - 1)
    nb = len(edges) - 1
    tree = cKDTree(xy)
    close = np.zeros(len(xy), bool)
    pairs = tree.query_pairs(0.060, output_type="ndarray")
    close[pairs.ravel()] = True
    nn, _ = tree.query(xy, 2)
    rho = job.density.at(xy)
    spacing = job.diameter * np.sqrt(np.pi / (2 * np.sqrt(3) * np.maximum(rho, 1e-9)))
    cnt = np.bincount(k[ok], minlength=nb).astype(float)
    return {
        "coverage": cnt / strip_target(job, xs, ys, edges) - 1.0,
        "psi6": np.bincount(k[ok], np.abs(psi6(xy))[ok], minlength=nb) / np.maximum(cnt, 1),
        "close": np.bincount(k[ok], close[ok], minlength=nb) / np.maximum(cnt, 1),
        "nn": np.bincount(k[ok], (nn[:, 1] / spacing)[ok], minlength=nb) / np.maximum(cnt, 1),
        "dots": cnt,
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("job")
    ap.add_argument("--tile-size", type=float, default=10.0)
    ap.add_argument("--band", type=float, default=0.05)
    ap.add_argument("--reach", type=float, default=1.0)
    args = ap.parse_args()
    job = load_job(args.job)
    tmp = Path(tempfile.mkdtemp())
    run = [sys.executable, "-P", "-m", "optdot", "generate", args.job, "-q"]
    subprocess.run([*run, "-o", tmp / "one.npz", "--tiles", "off"], check=True)
    subprocess.run(
        [*run, "-o", tmp / "tiled.parquet", "--tiles", "on", "--tile-size", str(args.tile_size)],
        check=True,
    )
    tiled = load_dataset(tmp / "tiled.parquet")
    xs, ys = (np.asarray(e) for e in open_dataset(tmp / "tiled.parquet").tiling)
    one = load_pattern(tmp / "one.npz")
    edges = np.arange(0.0, args.reach + 0.5 * args.band, args.band)
    print(f"# {machine()}")
    print(f"# {args.job}: tiles {len(xs) - 1} x {len(ys) - 1}, seams at x = "
          f"{np.round(xs[1:-1], 2).tolist()}, y = {np.round(ys[1:-1], 2).tolist()} mm")  # fmt: skip
    got = {
        "tiled": profile(tiled.xy, job, xs, ys, edges),
        "one": profile(one.xy, job, xs, ys, edges),
    }
    head = ["mm from seam", "dots (tiled)", "coverage tiled", "one", "ψ6 tiled", "one"]
    head += ["close tiled", "one", "nn/a tiled", "one"]
    print("| " + " | ".join(head) + " |")
    print("|" + "---|" * len(head))
    for b in range(len(edges) - 1):
        t, o = got["tiled"], got["one"]
        print(
            f"| {edges[b]:.2f}–{edges[b + 1]:.2f} | {int(t['dots'][b])} | "
            f"{100 * t['coverage'][b]:+.1f} % | {100 * o['coverage'][b]:+.1f} % | "
            f"{t['psi6'][b]:.3f} | {o['psi6'][b]:.3f} | "
            f"{t['close'][b]:.4f} | {o['close'][b]:.4f} | "
            f"{t['nn'][b]:.3f} | {o['nn'][b]:.3f} |"
        )


if __name__ == "__main__":
    main()
