"""Shaped dots against circles of the same count (issue 37's targets).

Each case writes a job on an edge-lit map (fill 0.05-0.30, LEDs along the bottom edge)
under ``benchmarks/out/shapes/``, runs ``optdot generate`` as a subprocess, and prints
dots, seconds, dots/s and the peak RSS of the process; then ``optdot qa`` on the result
(collisions by the exact gap, shapely's cross-check, psi6, coverage, the field error).
The circle case has the footprint's area-equivalent diameter, so the same count.

    python benchmarks/shapes.py --dots 1e6                   # ellipses, prisms, circles
    python benchmarks/shapes.py --dots 1e5 --case ellipse    # one case
    python benchmarks/shapes.py --grain                      # uniform map, 2:1 ellipses

``--grain`` runs a uniform 0.2 map of 2:1 ellipses with random angles and prints QA's
coverage grain through a 0.5 mm Gaussian and the psi6 coherence.

``--shapely-all`` checks every pair whose bounding discs come within the gap with
shapely (polygons within 10 nm of the footprints), not only QA's first 20,000 near pairs,
and prints how many pairs it checked and how many shapely finds under the gap.

``--tiled`` runs tiled (``--tiles on``) into a ``.parquet`` dataset on each ``--workers``
count given (default 2), peak RSS of the command and all its workers, and says whether
the datasets of different worker counts are byte-identical:

    python benchmarks/shapes.py --dots 1e7 --case ellipse --case circle --tiled
    python benchmarks/shapes.py --dots 1e6 --case ellipse --tiled --workers 1 --workers 2
"""

from __future__ import annotations

import argparse
import json
import math
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import psutil

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "benchmarks" / "out" / "shapes"
#: case: (the [dots] lines, the [orientation] lines, LEDs along the bottom edge)
CASES = {
    "ellipse": ('shape = "ellipse"\nlength = 0.080\nwidth = 0.040', "random = true", 4),
    "prism": (
        'shape = "rounded_rectangle"\nlength = 0.120\nwidth = 0.030\ncorner_radius = 0.005',
        'toward = "leds"\nrelative = "perpendicular"',
        8,
    ),
    "circle": ("diameter = 0.056569", "", 4),  # the 80 x 40 µm ellipse's area
    "hexagon": (  # 60 µm corner to corner
        'shape = "polygon"\nvertices = [[0.03, 0.0], [0.015, 0.025981], [-0.015, 0.025981], '
        "[-0.03, 0.0], [-0.015, -0.025981], [0.015, -0.025981]]",
        "random = true",
        4,
    ),
    "triangle": (  # a prism's base, 60 µm long, its point toward the nearest LED
        'shape = "polygon"\nvertices = [[-0.02, -0.03], [0.04, 0.0], [-0.02, 0.03]]',
        'toward = "leds"\nrelative = "parallel"',
        8,
    ),
}
AREA = {"ellipse": math.pi * 0.04 * 0.02, "prism": 0.12 * 0.03 - (4 - math.pi) * 0.005**2}
AREA["circle"] = math.pi * (0.056569 / 2) ** 2
AREA["hexagon"] = 1.5 * math.sqrt(3) * 0.03**2
AREA["triangle"] = 0.5 * 0.06 * 0.06


def edge_lit(width: float, height: float, cell: float = 0.5) -> np.ndarray:
    """``[ny, nx]`` fill 0.05 at the LED edge (y = 0) rising to 0.30 at the far edge."""
    ny, nx = round(height / cell), round(width / cell)
    t = (np.arange(ny) + 0.5) / ny
    return np.repeat((0.05 + 0.25 * t**1.3)[:, None], nx, axis=1)


def run(cmd: list[str]) -> tuple[float, float, str]:
    """``(seconds, peak RSS MB of the process tree, stderr)`` of a command."""
    t0 = time.perf_counter()
    p = subprocess.Popen(cmd, stderr=subprocess.PIPE, text=True)
    peak = [0.0]

    def watch() -> None:
        proc = psutil.Process(p.pid)
        while p.poll() is None:
            try:
                rss = sum(c.memory_info().rss for c in [proc, *proc.children(recursive=True)])
            except psutil.Error:
                break
            peak[0] = max(peak[0], rss / 2**20)
            time.sleep(0.2)

    th = threading.Thread(target=watch, daemon=True)
    th.start()
    _, err = p.communicate()
    th.join()
    if p.returncode != 0:
        sys.exit(f"{' '.join(cmd)} failed ({p.returncode}): {err.strip()}")
    return time.perf_counter() - t0, peak[0], err


def job(case: str, dots: float, grid: str = "map.csv") -> Path:
    """Write the case's job for about ``dots`` dots; its path."""
    shape, turn, leds = CASES[case]
    mean = 0.20 if grid == "uniform.csv" else 0.05 + 0.25 / 2.3
    area = dots * AREA[case] / mean
    width = round(math.sqrt(area * 1.5), 1)
    height = round(area / width, 1)
    if grid == "uniform.csv":  # texture.py's grain map: 30 x 30 mm at 0.2
        width = height = 30.0
    folder = OUT / f"{case}_{int(dots)}{'_uniform' if grid == 'uniform.csv' else ''}"
    folder.mkdir(parents=True, exist_ok=True)
    fill = edge_lit(width, height) if grid == "map.csv" else np.full((8, 8), 0.20)
    np.savetxt(folder / grid, fill, delimiter=",", fmt="%.5f")
    xs = [(k + 0.5) * width / leds for k in range(leds)]
    text = (
        f'name = "{case}"\n[domain]\nwidth = {width}\nheight = {height}\n'
        f'[density]\ngrid = "{grid}"\n[dots]\n{shape}\n'
        + (f"[orientation]\n{turn}\n" if turn else "")
        + "[optimize]\nseed = 1\ngap = 0.005\n"
        + '[light_guide]\nthickness = 0.4\n[[light_guide.leds]]\nedge = "bottom"\n'
        + f"positions = {[round(x, 3) for x in xs]}\nwidth = 1.0\n"
    )
    (folder / "job.toml").write_text(text)
    return folder / "job.toml"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--dots", type=float, default=1e5)
    ap.add_argument("--case", action="append", choices=list(CASES))
    ap.add_argument("--grain", action="store_true")
    ap.add_argument("--tiled", action="store_true", help="tiles on, into a .parquet dataset")
    ap.add_argument("--shapely-all", action="store_true", help="shapely on every near pair")
    ap.add_argument("--workers", type=int, action="append", help="with --tiled (repeatable)")
    a = ap.parse_args()
    cases = a.case or list(CASES)
    exe = [sys.executable, "-m", "optdot"]
    runs = [("ellipse", "uniform.csv")] if a.grain else [(c, "map.csv") for c in cases]
    for case, grid in runs:
        path = job(case, a.dots, grid)
        if a.tiled:
            tiled(exe, case, path, a.workers or [2])
            continue
        out = path.parent / "pattern.npz"
        secs, mb, _ = run([*exe, "generate", str(path), "-o", str(out), "-q", "--tiles", "off"])
        n = int(np.load(out)["xy"].shape[0])
        print(f"{case:8s} {n:>10,} dots {secs:8.1f} s {n / secs:>10,.0f} dots/s {mb:8.0f} MB")
        if a.shapely_all and case != "circle":
            shapely_all(out, 0.005)
        qa_json = path.parent / "qa.json"
        qsecs, qmb, _ = run([*exe, "qa", str(out), "--job", str(path), "--json", str(qa_json)])
        m = json.loads(qa_json.read_text())["metrics"]
        shape = m.get("shape") or {}
        turn = m.get("orientation") or {}
        print(
            f"         qa {qsecs:.1f} s {qmb:.0f} MB: collisions {m['pairs_below_collision']}, "
            f"shapely {shape.get('shapely_checked_pairs', '-')} checked / "
            f"{shape.get('shapely_disagreements', '-')} disagree, psi6 "
            f"{m['psi6_coherence_2mm']:.4f}, coverage rms {m['coverage_rel_rms_smoothed']:.4f}"
            f", field error {turn.get('field_error_max_deg', '-')}"
        )
        if grid == "uniform.csv":
            from optdot.quality.texture import blurred_coverage_rms

            xy = np.load(out)["xy"]
            w = 30.0
            win = (0.1 * w, 0.1 * w, 0.9 * w, 0.9 * w)  # texture.py's central 80 %
            rms = blurred_coverage_rms(xy, 2 * math.sqrt(AREA[case] / math.pi), win)
            print(f"         grain through a 0.5 mm Gaussian: {100 * rms:.3f} %")


def shapely_all(pattern: Path, gap: float, tolerance: float = 1e-5) -> None:
    """Every pair of the pattern whose bounding discs come within ``gap`` (mm), measured
    by shapely between polygons inscribed within ``tolerance`` of the footprints: prints
    the pairs checked and those under the gap (a polygon pair is never nearer than its
    footprints: one under the gap is a violation, whatever optdot's distance says)."""
    import shapely
    from scipy.spatial import cKDTree

    from optdot.io.patterns import load_pattern

    p = load_pattern(pattern)
    t0 = time.perf_counter()
    reach = float(2.0 * p.dots.extent().max()) + gap
    pairs = cKDTree(p.xy).query_pairs(reach, output_type="ndarray")
    polys = np.array(
        [shapely.Polygon(p.dots.outline(k, tolerance) + p.xy[k]) for k in range(p.n)],
        dtype=object,
    )
    under = 0
    for s in range(0, len(pairs), 500_000):
        pr = pairs[s : s + 500_000]
        dist = shapely.distance(polys[pr[:, 0]], polys[pr[:, 1]])
        under += int(np.sum(dist < gap - 1e-9))
    secs = time.perf_counter() - t0
    print(
        f"         shapely on every pair within {reach * 1e3:.1f} µm of centres: "
        f"{len(pairs):,} pairs, {under} under the gap ({secs:.0f} s)"
    )


def tiled(exe: list[str], case: str, path: Path, workers: list[int]) -> None:
    """The case tiled into a dataset on each worker count; QA of the first dataset."""
    outs = []
    for k in workers:
        out = path.parent / f"tiled_{k}.parquet"
        cmd = [*exe, "generate", str(path), "-o", str(out), "-q", "--tiles", "on"]
        secs, mb, _ = run([*cmd, "--workers", str(k)])
        n = json.loads((out / "_manifest.json").read_text())["n"]
        print(
            f"{case:8s} {n:>10,} dots {secs:8.1f} s {n / secs:>10,.0f} dots/s {mb:8.0f} MB "
            f"(tiled, {k} workers, all processes)"
        )
        outs.append(out)
    for other in outs[1:]:
        names = sorted(p.name for p in outs[0].iterdir())
        same = names == sorted(p.name for p in other.iterdir()) and all(
            (outs[0] / f).read_bytes() == (other / f).read_bytes() for f in names
        )
        print(f"         {outs[0].name} and {other.name}: {'byte-identical' if same else 'DIFFER'}")
    qa_json = path.parent / "qa_tiled.json"
    qsecs, qmb, _ = run([*exe, "qa", str(outs[0]), "--job", str(path), "--json", str(qa_json)])
    m = json.loads(qa_json.read_text())["metrics"]
    shape = m.get("shape") or {}
    print(
        f"         qa {qsecs:.1f} s {qmb:.0f} MB: collisions {m['pairs_below_collision']}, "
        f"shapely {shape.get('shapely_checked_pairs', '-')} checked / "
        f"{shape.get('shapely_disagreements', '-')} disagree, psi6 "
        f"{m['psi6_coherence_2mm']:.4f}, seams {m.get('seams', {}).get('passed', '-')}"
    )


if __name__ == "__main__":
    main()
