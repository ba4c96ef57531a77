"""Laser dotting paths: write time, path length against the pattern's order, and the
points read back, per dialect (G-code, HPGL/2, CSV) at 10⁶ dots (46 µm dots at about 70
per mm², random centres in a random order, as a generated pattern's order is).

Run: python benchmarks/laser_path.py [--dots 1e6]
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from scipy.spatial import cKDTree

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import machine, peak_rss_mb  # noqa: E402

from optdot import exporters  # noqa: E402
from optdot.exporters.options import ExportOptions  # noqa: E402
from optdot.pattern import Pattern  # noqa: E402
from optdot.printing.laser import Laser, path_length  # noqa: E402

#: How far a point may lie from its dot in each dialect, mm: G-code's 4 decimals, HPGL's
#: integer micrometres, the CSV's 6 decimals (each a half step per axis, diagonally).
RESOLUTION_MM = {"nc": 7.1e-5, "plt": 7.1e-4, "csv": 7.1e-7}


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--dots", type=float, default=1e6)
    n = int(ap.parse_args().dots)
    print(f"# {machine()}")
    w = np.sqrt(n / 70.0 * 16 / 9)
    h = w * 9 / 16
    xy = np.round(np.random.default_rng(0).random((n, 2)) * [w, h], 6)
    p = Pattern(xy=xy, diameter=0.046, box=(0.0, 0.0, float(w), float(h)))
    opts = ExportOptions(laser=Laser(speed=300.0, acceleration=3000.0, dwell=0.002))
    own = path_length(xy)
    print("dots | dialect | seconds | dots/s | path mm | pattern's order / path | read back")
    with tempfile.TemporaryDirectory() as d:
        for name in ("p.nc", "p.plt", "p.csv"):
            path = Path(d) / name
            t = time.perf_counter()
            exporters.named("exporters.laser_path:write_laser")(p, path, opts)
            s = time.perf_counter() - t
            back = _read(path)
            ours = path_length(back)
            near, _ = cKDTree(xy).query(back)
            tol = RESOLUTION_MM[name[2:]]
            same = len(back) == n and near.max() <= tol  # random centres: some pairs < 1 µm
            print(
                f"{n} | {name[2:]} | {s:.2f} | {n / s:,.0f} | {ours:,.0f} | {own / ours:.0f}x"
                f" | {f'every point, within {tol * 1e3:g} µm' if same else 'DIFFERS'}",
                flush=True,
            )
    print(f"peak memory {peak_rss_mb():.0f} MB")


def _read(path: Path) -> np.ndarray:
    """The points of a laser file in its order, mm (a plain parse: the tests read them
    with gcodeparser and ezdxf)."""
    text = path.read_text()
    if path.suffix == ".csv":
        return np.loadtxt(path, delimiter=",", skiprows=1, usecols=(1, 2))
    if path.suffix == ".nc":
        rows = [ln.split() for ln in text.splitlines() if ln.startswith("G0 ")]
        return np.array([(float(a[1:]), float(b[1:])) for _, a, b in rows])
    pts = [c[2:].split(",") for c in text.split(";") if c.startswith("PD")]
    return np.array(pts, dtype=float) * 1e-3


if __name__ == "__main__":
    main()
