"""A map designed through a 3-D profile's own extraction, checked through the real dots
(issue 60: "design with any profile"): the prisms sample redesigned for cut prisms facing
their LEDs, against its ink map traced as the same prisms; or the lgp sample designed for
bumps or dimples.

Run: python benchmarks/designed_profile.py [--profile cut-prisms|bumps|dimples] [--rays 4e6]
[--out DIR]

``cut-prisms`` (the default): the guide is ``samples/prisms`` (24 x 12 mm, 0.4 mm PMMA,
eight LEDs on the bottom edge, 120 x 30 µm footprints, 5 µm corners, gap 5 µm) with
``[dots] profile = "prism"``, ``facets = [45, 45]``, ``cut = true`` and ``[orientation]
toward = "leds"``, ``relative = "parallel"`` (the facets face the LED), designed on 0.5 mm
cells with fill 0 to 0.5 (``[design]``). ``bumps`` and ``dimples``: ``samples/lgp`` (30 x
20 mm, three LEDs, 46 µm dots, designed on its own 0.5 mm cells, fill 0 to 0.4) with bumps
10 µm high or dimples 10 µm deep. The steps are the user's, each a command: ``optdot
design``, ``optdot generate`` of the map it wrote, ``optdot simulate`` of that map's
coverage and of its real dots with ``--rays`` rays; then, for cut prisms, the sample's own
map (designed for ink) generated and traced as the same prisms. Printed per trace: the
efficiency, the 9-point uniformity (with its noise), the luminance's min and max over the
panel less 5 mm (bins of 0.6 mm), the on-axis luminance, and the nine spots' rays; then
the seconds of each step.
"""

from __future__ import annotations

import argparse
import json
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
from _common import machine  # noqa: E402

SAMPLE = HERE.parent / "samples" / "prisms"
PROFILE = 'profile = "prism"\nfacets = [45, 45]\ncut = true\n'
DESIGN = "\n[design]\ncell = 0.5\nfill_range = [0.0, 0.5]\n"
#: The lgp sample's dots as ``--profile`` makes them.
CAPS = {
    "bumps": 'profile = "bump"\nheight = 0.010\n',
    "dimples": 'profile = "dimple"\ndepth = 0.010\n',
}


def write_job(out: Path, profile: str = "cut-prisms") -> Path:
    """The prisms sample as cut prisms facing their LEDs, its map beside it; or the lgp
    sample with ``profile``'s caps (:data:`CAPS`)."""
    path = out / "job.toml"
    if profile in CAPS:
        text = (HERE.parent / "samples" / "lgp" / "job.toml").read_text()
        dots = "diameter = 0.046   # mm\n"
        assert dots in text, "samples/lgp changed"
        path.write_text(text.replace(dots, dots + CAPS[profile]))
        return path
    shutil.copy(SAMPLE / "density.csv", out / "density.csv")
    text = (SAMPLE / "job.toml").read_text()
    corner = "corner_radius = 0.005   # mm; width / 2 makes a capsule, 0 a sharp rectangle\n"
    assert corner in text and 'relative = "perpendicular"' in text, "samples/prisms changed"
    text = text.replace(corner, corner + PROFILE)
    text = text.replace('relative = "perpendicular"', 'relative = "parallel"') + DESIGN
    path.write_text(text)
    return path


def optdot(*args: str | Path) -> float:
    """Run ``optdot ARGS`` in this Python; its seconds. Fails loudly on a nonzero exit."""
    t = time.perf_counter()
    subprocess.run([sys.executable, "-m", "optdot", *map(str, args)], check=True)
    return time.perf_counter() - t


def row(label: str, path: Path) -> str:
    """One line of figures of ``optdot simulate --json``'s ``path``."""
    s = json.loads(path.read_text())
    spots = " ".join(f"{p[2]:,}" for p in s["spots"])
    return (
        f"{label:<40} efficiency {s['efficiency']:.4f}  9-point {s['uniformity_9point']:.3f} "
        f"± {s['uniformity_9point_sigma']:.3f}  min {s['luminance_min']:.3f} max "
        f"{s['luminance_max']:.3f}  on-axis {s['angles']['on_axis']:.3f}\n"
        f"{'':<40} spots (rays): {spots}"
    )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--rays", type=float, default=4e6, help="rays each check trace")
    ap.add_argument("--out", type=Path, default=None, help="folder to keep the files in")
    ap.add_argument("--profile", choices=("cut-prisms", *CAPS), default="cut-prisms")
    a = ap.parse_args()
    print(machine())
    rays = str(int(a.rays))
    with tempfile.TemporaryDirectory() as tmp:
        out = a.out or Path(tmp)
        out.mkdir(parents=True, exist_ok=True)
        job = write_job(out, a.profile)
        what = a.profile.replace("-", " ")
        sec = {"design": optdot("design", job, "-o", out / "map.csv", "-q")}
        sec["generate"] = optdot("generate", out / "map.toml", "-o", out / "dots.npz", "-q")
        q = ("--rays", rays, "-q", "--json")
        sec["coverage"] = optdot("simulate", out / "map.toml", *q, out / "cover.json")
        sec["real"] = optdot("simulate", out / "map.toml", out / "dots.npz", *q, out / "real.json")
        if a.profile not in CAPS:
            optdot("generate", job, "-o", out / "ink_map_dots.npz", "-q")
            sec["ink map"] = optdot("simulate", job, out / "ink_map_dots.npz", *q, out / "ink.json")
        print(row(f"designed for {what}, coverage", out / "cover.json"))
        print(row(f"designed for {what}, real dots", out / "real.json"))
        if a.profile not in CAPS:
            print(row("the sample's ink map, real cut prisms", out / "ink.json"))
    print("seconds: " + ", ".join(f"{k} {v:.1f}" for k, v in sec.items()))


if __name__ == "__main__":
    main()
