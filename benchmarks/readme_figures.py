"""The README's walk-through figures, made by running the walk-throughs.

Every figure the README quotes from a walk-through's output (dot counts, efficiencies,
uniformities, the largest JND, the halo's widths) sits between ``<!--fig:NAME-->`` and
``<!--/fig-->`` in README.md. This script runs the walk-throughs as a user pastes them
(the led export, the five-minute map, the lgp guide and the minled film: the installed
``optdot`` command, default seeds and rays), computes each figure, and

- with ``--check`` (what ``tests/test_readme.py`` runs) lists every figure whose text in
  the README differs from the output and exits 1;
- with ``--write`` puts the figures into README.md;
- with neither prints them.

Times are not figures: the README states them with the machine load they hold for.

    python benchmarks/readme_figures.py --check
"""

from __future__ import annotations

import argparse
import json
import re
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / "README.md"
SAMPLES = ROOT / "samples"

#: A marked figure: ``<!--fig:NAME-->text<!--/fig-->``.
MARK = re.compile(r"<!--fig:([\w.]+)-->(.*?)<!--/fig-->", re.S)


def optdot(*args, cwd: Path) -> subprocess.CompletedProcess:
    """Run the installed ``optdot`` command in ``cwd``; its failure stops the script."""
    r = subprocess.run(
        [sys.executable, "-P", "-m", "optdot", *map(str, args)],
        cwd=cwd, capture_output=True, text=True,
    )  # fmt: skip
    if r.returncode not in (0,):
        raise SystemExit(f"optdot {' '.join(map(str, args))}: exit {r.returncode}\n{r.stderr}")
    return r


def _json(path: Path) -> dict:
    return json.loads(path.read_text())


def led(work: Path) -> dict:
    """The README's first command on samples/led, with the QA report kept."""
    optdot("export", SAMPLES / "led" / "job.toml", "--csv", "led.csv",
           "--json", "led.json", "-q", cwd=work)  # fmt: skip
    return {"qa": _json(work / "led.json")}


def five_minutes(work: Path) -> dict:
    """The five-minute map of the README (its density.csv made the README's way)."""
    import numpy as np

    y = np.linspace(0, 1, 40)[:, None]
    np.savetxt(work / "density.csv", np.repeat(0.10 + 0.25 * y**1.5, 60, axis=1),
               delimiter=",", fmt="%.4f")  # fmt: skip
    (work / "job.toml").write_text(
        'name = "my-panel"\n[domain]\nwidth = 60.0\nheight = 40.0\n[density]\n'
        'grid = "density.csv"\n[dots]\ndiameter = 0.046\n'
    )
    out = optdot("check", "job.toml", cwd=work).stdout
    return {"check": out}


def lgp(work: Path) -> dict:
    """The lgp walk-through: design, generate, simulate through the real dots, qa."""
    optdot("design", SAMPLES / "lgp" / "job.toml", "-o", "map.csv", "-q", cwd=work)
    optdot("generate", "map.toml", "-o", "dots.npz", "-q", cwd=work)
    optdot("simulate", "map.toml", "dots.npz", "--json", "lum.json", "-q", cwd=work)
    optdot("qa", "dots.npz", "--job", "map.toml", "--json", "report.json", "-q", cwd=work)
    return {"sim": _json(work / "lum.json"), "qa": _json(work / "report.json")}


def minled(work: Path) -> dict:
    """The minled walk-through: design, generate, simulate (with its halo), qa."""
    optdot("design", SAMPLES / "minled" / "job.toml", "-o", "map.csv", "-q", cwd=work)
    optdot("generate", "map.toml", "-o", "dots.npz", "-q", cwd=work)
    optdot("simulate", "map.toml", "dots.npz", "--json", "lum.json", "-q", cwd=work)
    optdot("qa", "dots.npz", "--job", "map.toml", "--json", "report.json",
           "--simulation", "lum.json", "-q", cwd=work)  # fmt: skip
    import numpy as np

    fill = float(np.loadtxt(work / "map.csv", delimiter=",").max())
    text = (work / "map.toml").read_text()
    sizes = re.search(r"diameter = (\[[^\]]*\])", text)
    return {
        "sim": _json(work / "lum.json"),
        "qa": _json(work / "report.json"),
        "fill": fill,
        "sizes": sizes.group(1) if sizes else "",
    }


def _jnd(r: dict) -> str:
    from optdot.quality.gate import jnd_text

    return jnd_text(r["qa"]["metrics"]["visibility"]["max_jnd"])


def _pct(v: float, digits: int = 1) -> str:
    return f"{100 * v:.{digits}f} %"


#: name -> (walk-through, the figure's text from its outputs).
FIGURES: dict[str, tuple[str, Callable[[dict], str]]] = {
    "led.dots": ("led", lambda r: f"{r['qa']['metrics']['dots']:,}"),
    "led.verdict": ("led", lambda r: f"`{r['qa']['verdict']}`"),
    "led.jnd": ("led", _jnd),
    "five.dots": (
        "five",
        lambda r: "`" + re.search(r"dots: [\d,]+ of [\d.]+ µm", r["check"])[0] + "`",
    ),
    "lgp.efficiency": ("lgp", lambda r: _pct(r["sim"]["efficiency"])),
    "lgp.u9": (
        "lgp",
        lambda r: (
            f"{r['sim']['uniformity_9point']:.3f} ± {r['sim']['uniformity_9point_sigma']:.3f}"
        ),
    ),
    "lgp.rms": ("lgp", lambda r: _pct(r["sim"]["luminance_rms"], 2)),
    "lgp.noise": ("lgp", lambda r: _pct(r["sim"]["luminance_rms_noise"], 2)),
    "lgp.outside": ("lgp", lambda r: f"{r['sim']['outside_max']:.2f}"),
    "lgp.dots": ("lgp", lambda r: f"{r['qa']['metrics']['dots']:,}"),
    "lgp.verdict": ("lgp", lambda r: f"`{r['qa']['verdict']}`"),
    "lgp.jnd": ("lgp", _jnd),
    "lgp.over1": ("lgp", lambda r: str(r["qa"]["metrics"]["visibility"]["blobs_over_1_jnd"])),
    "minled.fill": ("minled", lambda r: f"{r['fill']:.2f}"),
    "minled.sizes": ("minled", lambda r: f"`[dots] diameter = {r['sizes']}`"),
    "minled.dots": ("minled", lambda r: f"{r['sim']['dots']:,}"),
    "minled.efficiency": ("minled", lambda r: _pct(r["sim"]["efficiency"])),
    "minled.range": (
        "minled",
        lambda r: f"{r['sim']['luminance_min']:.3f}–{r['sim']['luminance_max']:.3f}",
    ),
    "minled.rms": ("minled", lambda r: _pct(r["sim"]["luminance_rms"])),
    "minled.noise": ("minled", lambda r: _pct(r["sim"]["luminance_rms_noise"])),
    "minled.halo50": ("minled", lambda r: f"{r['sim']['halo']['width50_mm']:.1f}"),
    "minled.halo10": ("minled", lambda r: f"{r['sim']['halo']['width10_mm']:.1f}"),
    "minled.own": ("minled", lambda r: _pct(r["sim"]["halo"]["share_own_cell"])),
    "minled.verdict": ("minled", lambda r: f"`{r['qa']['verdict']}`"),
    "minled.jnd": ("minled", _jnd),
}

WALKS = {"led": led, "five": five_minutes, "lgp": lgp, "minled": minled}


def figures() -> dict[str, str]:
    """Every figure's text, from fresh runs of the walk-throughs (printed with times)."""
    runs = {}
    with tempfile.TemporaryDirectory(prefix="optdot-readme-") as tmp:
        for name, walk in WALKS.items():
            work = Path(tmp) / name
            work.mkdir()
            t = time.perf_counter()
            runs[name] = walk(work)
            print(f"# {name}: {time.perf_counter() - t:.1f} s", file=sys.stderr)
    return {k: fn(runs[walk]) for k, (walk, fn) in FIGURES.items()}


def differences(text: str, got: dict[str, str]) -> list[str]:
    """Every marked figure whose text differs from ``got``, and every figure of
    :data:`FIGURES` the README does not mark (or marks twice)."""
    out = []
    seen: dict[str, int] = {}
    for m in MARK.finditer(text):
        name, shown = m.group(1), m.group(2)
        seen[name] = seen.get(name, 0) + 1
        if name not in got:
            out.append(f"{name}: marked in the README, not made by this script")
        elif shown != got[name]:
            out.append(f"{name}: the README says {shown!r}, the walk-through gives {got[name]!r}")
    out += [f"{k}: not marked in the README" for k in got if k not in seen]
    return out


def written(text: str, got: dict[str, str]) -> str:
    """``text`` with every marked figure replaced by ``got``'s."""
    return MARK.sub(
        lambda m: f"<!--fig:{m.group(1)}-->{got.get(m.group(1), m.group(2))}<!--/fig-->", text
    )


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--check", action="store_true", help="exit 1 if the README differs")
    ap.add_argument("--write", action="store_true", help="write the figures into README.md")
    args = ap.parse_args()
    got = figures()
    text = README.read_text()
    if args.write:
        README.write_text(written(text, got))
        return 0
    if args.check:
        bad = differences(text, got)
        for line in bad:
            print(line)
        return 1 if bad else 0
    for k, v in got.items():
        print(f"{k}: {v}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
