"""Panel-scale benchmark: edge-lit light guides of a notebook, a monitor and a TV.

Writes each panel's job and map (fill 0.08-0.42, LEDs along the bottom long edge; 1 mm
cells) under ``benchmarks/out/panels/`` (not committed), runs ``optdot generate`` as a
subprocess and prints dots, seconds, dots/s and the peak RSS of the whole process tree
(the command, the Dask scheduler, nannies and workers), sampled every 0.2 s; then the QA
summary and the seam table (bands along tile borders against tile interiors). Beside the
peak: what each process held at that moment (the command, then its children largest first:
the Dask workers).

    python benchmarks/panels.py notebook --single        # single process and tiled
    python benchmarks/panels.py notebook monitor tv      # tiled only
    python benchmarks/panels.py notebook --tile-size 20 --tile-size 30   # sweep tile size
    python benchmarks/panels.py tv --reuse --qa --masks   # QA and GDSII/OASIS of a run
    python benchmarks/panels.py notebook --sizes --workers 2 --workers 1 --check
                                  # 30-120 µm dots, tiled on 2 and 1 workers, bytes compared
    python benchmarks/panels.py monitor --max-iter 200   # at the default iterations

``--qa`` times ``optdot qa`` (JSON + HTML report; a dataset is measured tile by tile),
``--masks`` times ``optdot export`` to GDSII and to OASIS (each gated by QA), both as
subprocesses with the peak RSS of their process tree.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import psutil

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "benchmarks" / "out" / "panels"
#: name: (width, height) mm
PANELS = {
    "notebook": (345.0, 194.0),  # 15.6-inch, ~1e7 dots
    "monitor": (598.0, 336.0),  # 27-inch, ~3e7
    "tv": (1218.0, 685.0),  # 55-inch, ~1.2e8
    "coupon": (120.0, 70.0),  # ~1.2e6, for quick checks
}


def edge_lit_map(width: float, height: float, cell: float = 1.0) -> np.ndarray:
    """``[ny, nx]`` fill 0.08-0.42: low at the LED edge (y = 0), rising away from it, with
    darker spots in front of LEDs every 20 mm and brighter gaps between them."""
    nx, ny = round(width / cell), round(height / cell)
    x = (np.arange(nx) + 0.5) * cell
    y = (np.arange(ny) + 0.5) * cell
    X, Y = np.meshgrid(x, y)
    t = Y / height
    base = 0.08 + 0.30 * t**1.2
    pitch = 20.0
    led = np.cos(np.pi * X / pitch) ** 2  # 1 in front of an LED
    near = np.exp(-Y / 8.0)
    f = base + 0.04 * near * (1.0 - 2.0 * led) + 0.04 * t**3
    return np.clip(f, 0.08, 0.42)


#: Dot diameters of ``--sizes``: the range of the issue's size-modulated notebook, mm.
SIZES = "[0.030, 0.120]"


def write_panel(name: str, sizes: bool = False, max_iter: int = 80) -> Path:
    """The panel's job and map under ``OUT/<name>[-sizes][-i<max_iter>]``."""
    w, h = PANELS[name]
    d = OUT / (name + ("-sizes" if sizes else "") + ("" if max_iter == 80 else f"-i{max_iter}"))
    d.mkdir(parents=True, exist_ok=True)
    np.save(d / "density.npy", edge_lit_map(w, h))
    (d / "job.toml").write_text(
        f'name = "{d.name}"\n[domain]\nwidth = {w}\nheight = {h}\n'
        f'[density]\ngrid = "density.npy"\n[dots]\ndiameter = {SIZES if sizes else 0.046}\n'
        f'[optimize]\nmethod = "optdot"\nmax_iter = {max_iter}\nseed = 1\n'
    )
    return d / "job.toml"


def same_parts(a: Path, b: Path) -> bool:
    """Whether two datasets hold the same files with the same bytes."""
    names = sorted(p.name for p in a.iterdir())
    if names != sorted(p.name for p in b.iterdir()):
        return False
    return all((a / n).read_bytes() == (b / n).read_bytes() for n in names)


def mixed_pairs_too_close(dataset: Path, gap: float) -> tuple[int, int]:
    """``(pairs checked, pairs closer than their mean diameter + gap)`` over the whole
    dataset, by cKDTree (independent of optdot's cell grid)."""
    from scipy.spatial import cKDTree

    from optdot.io.dataset import load_dataset

    p = load_dataset(dataset)
    tree = cKDTree(p.xy)
    pairs = tree.query_pairs(float(p.diameter.max()) + gap, output_type="ndarray")
    dist = np.hypot(*(p.xy[pairs[:, 0]] - p.xy[pairs[:, 1]]).T)
    limit = 0.5 * (p.diameter[pairs[:, 0]] + p.diameter[pairs[:, 1]]) + gap
    return len(pairs), int((dist < limit - 1e-9).sum())


#: Each process's RSS (GiB) at the last :func:`run`'s peak: the command first, then its
#: children (the Dask workers, and a resource tracker) largest first.
PEAK_SPLIT: list[float] = []


def run(cmd: list[str]) -> tuple[float, float, int, str]:
    """``(seconds, peak RSS of the tree in GiB, exit code, stderr)`` of a command; what
    each process held at that peak is left in :data:`PEAK_SPLIT`."""
    t0 = time.perf_counter()
    proc = subprocess.Popen(cmd, stderr=subprocess.PIPE, text=True)
    peak = [0]
    split: list[float] = []
    done = threading.Event()

    def watch() -> None:
        root = psutil.Process(proc.pid)
        while not done.is_set():
            try:
                procs = [root, *root.children(recursive=True)]
                each = []
                for p in procs:
                    try:
                        each.append(p.memory_info().rss)
                    except psutil.Error:
                        each.append(0)
                if sum(each) > peak[0]:
                    peak[0] = sum(each)
                    split[:] = [
                        each[0] / 2**30,
                        *sorted((b / 2**30 for b in each[1:]), reverse=True),
                    ]
            except psutil.Error:
                pass
            time.sleep(0.2)

    th = threading.Thread(target=watch, daemon=True)
    th.start()
    err = proc.communicate()[1]
    done.set()
    th.join()
    PEAK_SPLIT[:] = split
    return time.perf_counter() - t0, peak[0] / 2**30, proc.returncode, err


def optdot(*args) -> list[str]:
    return [sys.executable, "-P", "-m", "optdot", *map(str, args)]


def blob_places(blobs: list[dict], box, xs, ys, seam_mm: float = 1.5, edge_mm: float = 2.0):
    """Where the strongest blobs sit (issue 24's measure): ``(on edges, edge band's share
    of the panel, on seams, seam bands' share, blobs)``. A blob is on an edge within
    ``edge_mm`` of the panel's border, else on a seam within ``seam_mm`` of an inner tile
    border (``xs``, ``ys``: the tiling's borders, both ends included)."""
    x0, y0, x1, y1 = box

    def where(x, y):
        edge = np.minimum(np.minimum(x - x0, x1 - x), np.minimum(y - y0, y1 - y)) < edge_mm
        dx = np.min(np.abs(np.subtract.outer(x, np.asarray(xs[1:-1]))), axis=-1, initial=np.inf)
        dy = np.min(np.abs(np.subtract.outer(y, np.asarray(ys[1:-1]))), axis=-1, initial=np.inf)
        return edge, ~edge & (np.minimum(dx, dy) < seam_mm)

    gx, gy = np.meshgrid(np.arange(x0 + 0.25, x1, 0.5), np.arange(y0 + 0.25, y1, 0.5))
    e_area, s_area = where(gx.ravel(), gy.ravel())
    bx = np.array([b["x_mm"] for b in blobs])
    by = np.array([b["y_mm"] for b in blobs])
    on_e, on_s = where(bx, by) if len(blobs) else (np.zeros(0, bool), np.zeros(0, bool))
    return int(on_e.sum()), float(e_area.mean()), int(on_s.sum()), float(s_area.mean()), len(blobs)


def report(label: str, dots: int, secs: float, gib: float) -> None:
    each = " + ".join(f"{g:.2f}" for g in PEAK_SPLIT)
    print(
        f"| {label} | {dots:,} | {secs:.0f} | {dots / secs:,.0f} | {gib:.2f} ({each}) |",
        flush=True,
    )


def qa_summary(pattern: Path, job: Path) -> dict:
    js = pattern.with_suffix(".qa.json")
    page = pattern.with_suffix(".qa.html")
    secs, gib, rc, err = run(
        optdot("qa", pattern, "--job", job, "--json", js, "--html", page, "-q")
    )
    if rc not in (0, 1):
        raise SystemExit(f"qa failed: {err}")
    m = json.loads(js.read_text())["metrics"]
    m["_qa_s"], m["_qa_gib"] = secs, gib
    return m


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("panels", nargs="+", choices=sorted(PANELS))
    ap.add_argument("--single", action="store_true", help="also run the single process")
    ap.add_argument("--tile-size", type=float, action="append", help="tile side, mm")
    ap.add_argument("--qa", action="store_true", help="QA every pattern (JSON + HTML)")
    ap.add_argument("--masks", action="store_true", help="export GDSII and OASIS, timed")
    ap.add_argument("--reuse", action="store_true", help="keep patterns already generated")
    ap.add_argument("--sizes", action="store_true", help=f"dots.diameter = {SIZES}")
    ap.add_argument("--max-iter", type=int, default=80, help="optimize.max_iter (default 80)")
    ap.add_argument("--workers", type=int, action="append", help="local workers (repeatable)")
    ap.add_argument(
        "--check", action="store_true", help="count mixed-pair violations; compare worker runs"
    )
    args = ap.parse_args()
    print(
        "| run | dots | s | dots/s | peak GiB, all processes (the command + each child) |"
        "\n|---|---|---|---|---|"
    )
    sys.stdout.flush()
    for name in args.panels:
        job = write_panel(name, args.sizes, args.max_iter)
        outs = []
        if args.single:
            out = job.parent / "single.npz"
            if not (args.reuse and out.exists()):
                secs, gib, rc, err = run(optdot("generate", job, "-o", out, "--tiles", "off", "-q"))
                if rc:
                    print(err, file=sys.stderr)
                    continue
                n = int(np.load(out)["xy"].shape[0])
                report(f"{name} single process", n, secs, gib)
            outs.append(("single", out))
        for side in args.tile_size or [None]:
            by_workers = []
            for k in args.workers or [None]:
                tag = ("" if side is None else f"-{side:g}") + ("" if k is None else f"-w{k}")
                out = job.parent / f"tiled{tag}.parquet"
                cmd = ["generate", job, "-o", out, "--tiles", "on"]
                if side is not None:
                    cmd += ["--tile-size", side]
                if k is not None:
                    cmd += ["--workers", k]
                if not (args.reuse and out.exists()):
                    secs, gib, rc, err = run(optdot(*cmd))
                    if rc:
                        print(err, file=sys.stderr)
                        continue
                    n = json.loads((out / "_manifest.json").read_text())["n"]
                    tiles = [ln for ln in err.splitlines() if "tiles (" in ln]
                    what = tiles[0].split("; ")[-1] if tiles else ""
                    label = f"{job.parent.name} tiled {what}" + ("" if k is None else f", {k} w")
                    report(label, n, secs, gib)
                outs.append((f"tiled {side or 'auto'}{'' if k is None else f' {k}w'}", out))
                by_workers.append(out)
            if args.check and by_workers:
                from optdot import load_job

                gap = load_job(job).optimize.gap
                checked, bad = mixed_pairs_too_close(by_workers[0], gap)
                print(f"\n{by_workers[0].name}: {bad} of {checked:,} near pairs too close")
                for other in by_workers[1:]:
                    same = same_parts(by_workers[0], other)
                    print(f"{other.name}: {'same bytes' if same else 'DIFFERENT bytes'}")
        if args.masks:
            print("\n| pattern | mask | s | peak GiB | file GB |\n|---|---|---|---|---|")
            for label, out in outs:
                if out.suffix != ".parquet":
                    continue
                for fmt in ("gds", "oas"):
                    mask = out.with_suffix(f".{fmt}")
                    secs, gib, rc, err = run(
                        optdot("export", out, "--job", job, f"--{fmt}", mask, "-q")
                    )
                    if rc:
                        print(err, file=sys.stderr)
                        continue
                    size = mask.stat().st_size / 1e9
                    print(f"| {name} {label} | {fmt} | {secs:.0f} | {gib:.2f} | {size:.2f} |")
        if args.qa:
            print(
                "\n| pattern | pairs < 60 µm | ψ6 mean | coverage RMS | JND p50 / p99 | largest"
                " JND | blobs > 1 JND | of the strongest: on edges (area) | on seams (area) "
                "| QA s | QA GiB |"
            )
            print("|---|---|---|---|---|---|---|---|---|---|---|")
            seams = []
            tiling = None
            for _, out in outs:
                if out.suffix == ".parquet":
                    tiling = json.loads((out / "_manifest.json").read_text())["tiles"]
            for label, out in outs:
                m = qa_summary(out, job)
                v = m.get("visibility", {})
                pct = v.get("jnd_percentiles", {})
                places = "– | –"
                if tiling is not None and v.get("blobs"):
                    w, h = PANELS[name]
                    ne, ae, ns, as_, nb = blob_places(
                        v["blobs"], (0, 0, w, h), tiling["xs"], tiling["ys"]
                    )
                    places = f"{ne} of {nb} ({100 * ae:.0f} %) | {ns} of {nb} ({100 * as_:.0f} %)"
                print(
                    f"| {name} {label} | {m['pairs_below_close']:,} | "
                    f"{m['psi6_local_mean']:.4f} | {100 * m['coverage_rel_rms_smoothed']:.3f} % "
                    f"| {pct.get('50', float('nan')):.2f} / {pct.get('99', float('nan')):.2f} "
                    f"| {v.get('max_jnd_signed', float('nan')):+.2f} "
                    f"| {v.get('blobs_over_1_jnd', 0)} "
                    f"| {places} | {m['_qa_s']:.0f} | {m['_qa_gib']:.2f} |"
                )
                if m.get("seams"):
                    seams.append((label, m["seams"]))
            for label, s in seams:
                print(f"\nseams of {name} {label} (band {s['band_mm']} mm, tiles {s['tiles']}):")
                print("| measure | band | interior | band sd | interior sd | passed |")
                print("|---|---|---|---|---|---|")
                for k, v in s["measures"].items():
                    print(
                        f"| {k} | {v['band']:.5f} | {v['interior']:.5f} | {v['band_sd']:.5f} "
                        f"| {v['interior_sd']:.5f} | {v['passed']} |"
                    )


if __name__ == "__main__":
    main()
