"""The print against the design, measured on the masks: each sample job under a process,
its GDSII mask read back three ways.

Per job: the printed coverage over the map's, two ways (every mask polygon, unscaled,
grown by the gain with shapely's ``buffer``; and what ``qa`` reads back, Steiner's sum
over the footprints it fits); the printed gaps after the grid (the mask's polygons,
unscaled and grown by the gain, by shapely on every pair closer than 0.1 mm: the count
under ``min_space``); and KLayout's areas of the mask's footprints against the
compensated design footprint's.

Run: python benchmarks/printed.py [--grid MM] [--jobs led ellipses prisms]
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import shapely

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import machine, peak_rss_mb  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent
#: The gain each sample is printed with (the issue's figures): circles 10 µm, 80 × 40 µm
#: ellipses 8 µm, 120 × 30 µm prisms with 5 µm corners 5 µm.
GAINS = {"led": 0.010, "ellipses": 0.008, "prisms": 0.005}


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--grid", type=float, default=0.001)
    ap.add_argument("--min-space", type=float, default=0.004)
    ap.add_argument("--jobs", nargs="*", default=list(GAINS))
    a = ap.parse_args()
    print(f"# {machine()}")
    print(
        "job | dots | gain µm | grid µm | printed/map (the mask grown by shapely) | "
        "printed/map (qa's read-back, Steiner) | "
        "pairs checked | printed gaps under min_space | smallest printed gap µm | "
        "KLayout area / compensated | seconds"
    )
    for name in a.jobs:
        with tempfile.TemporaryDirectory() as d:
            print(_one(name, GAINS[name], a.grid, a.min_space, Path(d)), flush=True)
    print(f"peak memory {peak_rss_mb():.0f} MB")


def _one(name: str, gain: float, grid: float, min_space: float, tmp: Path) -> str:
    import gdstk

    from optdot.config.schema import load_job
    from optdot.exporters import ExportOptions, write
    from optdot.exporters.readback import read_any
    from optdot.orchestration.pipeline import generate

    t0 = time.perf_counter()
    src = ROOT / "samples" / name
    for f in src.iterdir():
        (tmp / f.name).write_bytes(f.read_bytes())
    job_path = tmp / "job.toml"
    job_path.write_text(
        job_path.read_text()
        + f"\n[process]\ndot_gain = {gain}\nmin_space = {min_space}\ngrid = {grid}\n"
        'shrink = 0.004\nmirror = "x"\n'
    )
    job = load_job(job_path)
    p = generate(job)
    opts = ExportOptions(process=job.process)
    write(p, "gds", tmp / "m.gds", opts)
    q = read_any(tmp / "m.gds", opts)
    proc = job.process
    feet = q.shape
    area = proc.steiner_area(feet.kind, feet.size, 0.0)
    d = job.density
    cw, ch = d.cell_size
    frac = (
        np.ones_like(d.grid)
        if job.domain.rectangle
        else job.domain.cell_fractions(d.x0, d.y0, cw, ch, d.shape[1], d.shape[0])
    )
    ratio = float(area.sum()) / (float((d.grid * frac).sum()) * cw * ch)
    polys = _mask_polygons(gdstk.read_gds(str(tmp / "m.gds")), proc)
    k = 1.0 / float(proc.scale[0])
    shapes = np.array([shapely.Polygon(pts * k) for pts in polys], dtype=object)
    printed = float(shapely.area(shapely.buffer(shapes, gain, quad_segs=32)).sum())
    wanted = float((d.grid * frac).sum()) * cw * ch
    tree = shapely.STRtree(shapes)
    i, j = tree.query(shapes, predicate="dwithin", distance=0.1)
    keep = i < j
    gaps = shapely.distance(shapes[i[keep]], shapes[j[keep]]) - 2.0 * gain
    under = int((gaps < min_space - 1e-9).sum())
    kind, size = _design(job)
    want = float(proc.steiner_area(kind, size[None], -gain)[0]) * float(proc.scale[0]) ** 2
    got = np.array(_klayout_areas(tmp / "m.gds"))
    return (
        f"{name} | {p.n:,} | {gain * 1e3:g} | {grid * 1e3:g} | {printed / wanted:.5f} | "
        f"{ratio:.5f} | {int(keep.sum()):,} | {under} | {gaps.min() * 1e3:.3f} | "
        f"{got.mean() / want:.5f} (worst {np.max(np.abs(got / want - 1)):.2%}) | "
        f"{time.perf_counter() - t0:.1f}"
    )


def _design(job):
    """``(kind, size [k] mm)`` of the job's one printed footprint."""
    from optdot.geometry.shapes import CIRCLE

    if job.shape is None:
        return CIRCLE, np.array([job.diameter])
    return job.shape.kind, np.asarray(job.shape.size, float)


def _mask_polygons(lib, proc) -> list[np.ndarray]:
    """Every dot's polygon of a mask in world mm (references resolved)."""
    top = lib.top_level()[0]
    flat = top.copy("FLAT", deep_copy=True)
    flat.flatten()
    return [p.points * 1e-3 for p in flat.polygons if (p.layer, p.datatype) == (1, 0)]


def _klayout_areas(path: Path) -> list[float]:
    import klayout.db as kdb

    ly = kdb.Layout()
    ly.read(str(path))
    it = ly.top_cell().begin_shapes_rec(ly.layer(1, 0))
    out = []
    while not it.at_end():
        out.append(it.shape().polygon.area() * ly.dbu**2 * 1e-6)
        it.next()
    return out


if __name__ == "__main__":
    main()
