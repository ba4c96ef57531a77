"""Every sample's outputs, for byte-for-byte comparison of two versions of optdot.

Run: python benchmarks/sample_outputs.py OUT [--compare REF]

Writes into OUT (emptied first), with the installed ``optdot``: each sample's NPZ, CSV,
GDSII, OASIS, DXF, SVG and Speos mapping (from ``optdot generate`` then ``optdot
export``); the lgp sample's designed map, its pattern, GDSII, DXF and a simulation
(JSON, 2·10⁵ rays through the real dots); the led_sizes sample tiled on 2 workers as a
Parquet dataset, with the masks streamed from it; and two QA reports (JSON). With
``--compare REF`` (a folder made the same way by another version) it then lists every
file that differs (QA reports compared without their ``date_utc`` and their inputs'
paths, which name the checkout), and exits 1 if any
does. Takes about 1.5 minutes on the reference machine.
"""

from __future__ import annotations

import argparse
import filecmp
import json
import shutil
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
SAMPLES = (
    "chokka", "ellipses", "hexagons", "led", "led_sizes", "outline", "prisms", "tiny", "tsuno",
    "uniform",
)  # fmt: skip

#: A direct-lit film with graded caps of given ink over four LEDs (the rings a kind of
#: their own in the masks).
CAPS_JOB = """name = "caps"
[domain]
width = 10.0
height = 10.0
[density]
grid = "caps_map.csv"
[dots]
diameter = 0.046
[backlight]
kind = "direct"
[backlight.leds]
pitch = [5.0, 5.0]
size = 0.2
cap = 0.8
cap_ink = [1.0, 0.9, 0.7, 0.5, 0.35, 0.2]
[backlight.cavity]
gap = 1.5
[backlight.film]
thickness = 0.2
"""


#: A process for the ellipses sample (screen printing on a moulded guide's stamper).
PROCESS = """
[process]
dot_gain = 0.006
gain_tolerance = 0.001
min_space = 0.004
grid = 0.00005
shrink = 0.004
mirror = "x"
"""


def run(*args, cwd: Path) -> None:
    """``optdot *args`` in ``cwd``; a failed gate (exit 1) still writes with --force."""
    subprocess.run([sys.executable, "-P", "-m", "optdot", *map(str, args)], cwd=cwd, check=True)


def make(out: Path) -> None:
    shutil.rmtree(out, ignore_errors=True)
    out.mkdir(parents=True)
    for s in SAMPLES:
        job = ROOT / "samples" / s / "job.toml"
        run("generate", job, "-o", f"{s}.npz", "-q", cwd=out)
        run(
            "export", f"{s}.npz", "--job", job, "--gds", f"{s}.gds", "--oas", f"{s}.oas",
            "--dxf", f"{s}.dxf", "--csv", f"{s}.csv", "--svg", f"{s}.svg",
            "--speos", f"{s}.OPT3DMapping", "--force", "-q", cwd=out,
        )  # fmt: skip
    run("design", ROOT / "samples" / "lgp" / "job.toml", "-o", "lgp_map.csv", "-q", cwd=out)
    run("generate", "lgp_map.toml", "-o", "lgp.npz", "-q", cwd=out)
    run("export", "lgp.npz", "--job", "lgp_map.toml", "--gds", "lgp.gds", "--dxf", "lgp.dxf",
        "--force", "-q", cwd=out)  # fmt: skip
    run("simulate", "lgp_map.toml", "lgp.npz", "--rays", "200000", "--json", "lgp_sim.json",
        "-q", cwd=out)  # fmt: skip
    caps = out / "caps.toml"
    caps.write_text(CAPS_JOB)
    (out / "caps_map.csv").write_text("0.3,0.25\n0.2,0.35\n")
    run("generate", caps, "-o", "caps.npz", "-q", cwd=out)
    run("export", "caps.npz", "--job", caps, "--gds", "caps.gds", "--dxf", "caps.dxf",
        "--oas", "caps.oas", "--force", "-q", cwd=out)  # fmt: skip
    # the ellipses printed: masks compensated for a gain, a shrink, a mirror and a grid
    shutil.copy(ROOT / "samples" / "ellipses" / "density.csv", out / "density.csv")
    printed = out / "printed.toml"
    printed.write_text((ROOT / "samples" / "ellipses" / "job.toml").read_text() + PROCESS)
    run("export", printed, "--gds", "printed.gds", "--oas", "printed.oas",
        "--dxf", "printed.dxf", "--csv", "printed.csv", "--json", "printed_qa.json",
        "-q", cwd=out)  # fmt: skip
    for mask in ("printed.gds", "printed.dxf"):
        run("qa", mask, "--job", printed, "--json", f"{mask}.qa.json", "-q", cwd=out)
    sizes = ROOT / "samples" / "led_sizes" / "job.toml"
    run("generate", sizes, "-o", "ls.parquet", "--tiles", "on", "--workers", 2, "-q", cwd=out)
    run("export", "ls.parquet", "--job", sizes, "--gds", "ls_ds.gds", "--oas", "ls_ds.oas",
        "--dxf", "ls_ds.dxf", "--force", "-q", cwd=out)  # fmt: skip
    for name, src, job in (("led", "led.npz", "led"), ("ls", "ls.parquet", "led_sizes")):
        subprocess.run(
            [sys.executable, "-P", "-m", "optdot", "qa", src, "--job",
             str(ROOT / "samples" / job / "job.toml"), "--json", f"{name}_qa.json", "-q"],
            cwd=out, check=False,
        )  # fmt: skip


def _undated(path: Path):
    def strip(o):
        if isinstance(o, dict):
            return {k: strip(v) for k, v in o.items() if k not in ("date_utc", "path")}
        return [strip(v) for v in o] if isinstance(o, list) else o

    return strip(json.loads(path.read_text()))


def differing(out: Path, ref: Path) -> list[str]:
    """Names of the files (a dataset's parts included) of ``ref`` that ``out`` lacks or
    holds with other bytes."""
    bad = []
    for r in sorted(ref.rglob("*")):
        if r.is_dir():
            continue
        name = r.relative_to(ref)
        o = out / name
        if not o.exists():
            bad.append(f"{name} (missing)")
        elif name.name.endswith("qa.json"):  # _qa.json, .gds.qa.json
            if _undated(o) != _undated(r):
                bad.append(str(name))
        elif not filecmp.cmp(o, r, shallow=False):
            bad.append(str(name))
    return bad


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("out", type=Path)
    ap.add_argument("--compare", type=Path, help="a folder made the same way to compare with")
    a = ap.parse_args()
    make(a.out.resolve())
    files = sum(1 for p in a.out.rglob("*") if p.is_file())
    print(f"{a.out}: {files} files")
    if a.compare is not None:
        bad = differing(a.out, a.compare)
        print("\n".join(bad) if bad else f"byte-identical to {a.compare}")
        sys.exit(1 if bad else 0)


if __name__ == "__main__":
    main()
