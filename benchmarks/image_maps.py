"""Loading an image density map: a 27-inch panel (598 x 336 mm) at 0.1 mm per pixel, a
5980 x 3360 16-bit PNG, with a CAD-like outline (rounded corners, two holes), in a fresh
process: load the job (decode, map to fills, validate) and integrate the map over the
outline (the dot count). Prints seconds and the peak RSS of the process.

    python benchmarks/image_maps.py            # writes benchmarks/out/image_maps/
"""

from __future__ import annotations

import subprocess
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "benchmarks" / "out" / "image_maps"
W, H, PX = 598.0, 336.0, 0.1

CHILD = """
import sys, time, resource
t0 = time.perf_counter()
from optdot.config.schema import load_job
job = load_job(sys.argv[1])
t1 = time.perf_counter()
n = job.n_dots
t2 = time.perf_counter()
print(f"{job.density.shape[1]} x {job.density.shape[0]} px | {t1 - t0:.2f} | {t2 - t1:.2f} "
      f"| {n:,} | {resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 2**20:.2f}")
"""


def write_inputs() -> Path:
    from PIL import Image

    OUT.mkdir(parents=True, exist_ok=True)
    nx, ny = round(W / PX), round(H / PX)
    x = (np.arange(nx) + 0.5) / nx
    y = (np.arange(ny) + 0.5) / ny
    fill = 0.08 + 0.3 * y[::-1, None] ** 1.2 + 0.02 * np.cos(2 * np.pi * 15 * x)[None, :]
    img = np.round(fill / 0.45 * 65535).astype(np.uint16)  # top-down: row 0 = top
    Image.fromarray(img).save(OUT / "map.png")
    r = 8.0
    import shapely

    body = shapely.box(r, r, W - r, H - r).buffer(r, quad_segs=16)
    holes = [shapely.Point(40, 40).buffer(3), shapely.Point(W - 40, 40).buffer(3)]
    keep = ", ".join(f'"{h.wkt}"' for h in holes)
    (OUT / "job.toml").write_text(
        f'[domain]\noutline = "outline.wkt"\nkeep_out = [{keep}]\n'
        '[density]\nimage = "map.png"\nfill_range = [0.0, 0.45]\n'
        "[dots]\ndiameter = 0.046\n"
    )
    (OUT / "outline.wkt").write_text(body.wkt)
    return OUT / "job.toml"


def main() -> None:
    job = write_inputs()
    print("| image | load job s | dot count s | dots | peak GiB |\n|---|---|---|---|---|")
    for _ in range(2):
        t0 = time.perf_counter()
        r = subprocess.run(
            [sys.executable, "-P", "-c", CHILD, str(job)], capture_output=True, text=True
        )
        if r.returncode:
            raise SystemExit(r.stderr)
        print(f"| {r.stdout.strip()} |  (process {time.perf_counter() - t0:.1f} s)")


if __name__ == "__main__":
    main()
