"""What ``simulate`` and ``design`` write: the figures as JSON, the luminance map as PNG,
the designed map (CSV, 16-bit PNG) and the job that uses it. Every file goes through
:func:`optdot.io.atomic.atomic_path` inside one transaction: all of a command's outputs
appear together or none does, and a failed run leaves the old files as they were."""

from __future__ import annotations

import io
import json
import math
import tomllib
from pathlib import Path

import numpy as np

from ..config.bench import Bench
from ..config.writer import job_toml, rebased
from ..errors import JobError
from ..io.atomic import atomic_path
from .angles import STEP_DEG
from .design import Designed
from .simulate import Simulation


def simulation_json(sim: Simulation, bench: Bench, pattern: Path | None, dots: int | None) -> str:
    """The figures of ``sim`` with the luminance map (JSON text)."""
    doc = {
        "job": str(bench.source) if bench.source else bench.name,
        "pattern": str(pattern) if pattern else None,
        "dots": dots,
        **sim.summary(),
        "box_mm": list(sim.box),
        "luminance": np.round(sim.luminance, 5).tolist(),
        "luminance_rows": "row 0 = bottom (y = ymin)",
        **(
            {
                "angular_luminance": sim.angles.rows(),
                "angular_luminance_rows": (
                    f"row k: polar angle {STEP_DEG:g} k to {STEP_DEG:g} (k + 1) deg from the "
                    f"normal; column m: azimuth {STEP_DEG:g} m to {STEP_DEG:g} (m + 1) deg "
                    "from +x towards +y; 1 = a Lambertian top of the same flux"
                ),
            }
            if sim.angles is not None
            else {}
        ),
    }
    return json.dumps(_finite(doc), indent=1, allow_nan=False) + "\n"


def _finite(v):
    """``v`` with every NaN or infinity (a figure of no light: every bin dark) as null:
    JSON has no NaN, and readers refuse it."""
    if isinstance(v, float):
        return v if math.isfinite(v) else None
    if isinstance(v, dict):
        return {k: _finite(x) for k, x in v.items()}
    if isinstance(v, list | tuple):
        return [_finite(x) for x in v]
    return v


def read_simulation(path: Path) -> dict:
    """A JSON file ``simulate --json`` wrote, checked: figures, box and luminance map.

    Raises:
        JobError: one line naming the file and what is wrong with it.
    """
    from ..files import input_problem

    problem = input_problem(path, 1 << 28)
    if problem is not None:
        raise JobError(f"{path}: simulation file {problem}")
    try:
        doc = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, ValueError) as e:
        raise JobError(f"{path}: not a simulation JSON file ({type(e).__name__})") from None
    need = ("luminance", "box_mm", "efficiency", "uniformity_9point", "rays", "mode")
    missing = [k for k in need if not isinstance(doc, dict) or k not in doc]
    if missing:
        raise JobError(f"{path}: not a simulation JSON file (no {', '.join(missing)})")
    try:
        lum = np.array(doc["luminance"], dtype=np.float64)
        box = [float(v) for v in doc["box_mm"]]
    except (TypeError, ValueError):
        lum, box = np.zeros(0), []
    if lum.ndim != 2 or lum.size == 0 or not np.all(np.isfinite(lum)) or len(box) != 4:
        raise JobError(f"{path}: the luminance map or box_mm is malformed")
    doc["luminance"] = lum
    if "angular_luminance" in doc or "angles" in doc:
        problem = _angles_problem(doc.get("angular_luminance"), doc.get("angles"))
        if problem is not None:
            raise JobError(f"{path}: {problem}")
    return doc


def _angles_problem(table, figures) -> str | None:
    """What is wrong with a simulation file's ``angular_luminance`` table (rings of
    azimuth bins, numbers >= 0 or null, every ring as long) and its ``angles`` figures,
    or None."""
    ok_row = isinstance(table, list) and len(table) > 0
    rows = table if ok_row else []
    if not ok_row or not all(isinstance(r, list) and len(r) == len(rows[0]) > 0 for r in rows):
        return "angular_luminance must be a table of rings of azimuth bins, all as long"
    if not all(v is None or (_number(v) and v >= 0) for r in rows for v in r):
        return "angular_luminance holds a value that is not a number >= 0 (or null)"
    if not isinstance(figures, dict) or not _number(figures.get("rays")):
        return "angles must hold the figures of the angular_luminance table (rays, on_axis, ...)"
    for key in ("on_axis", "on_axis_sigma"):
        if figures.get(key) is not None and not _number(figures[key]):
            return f"angles.{key} must be a number or null"
    half = figures.get("half_luminance_deg", {})
    profiles = figures.get("profiles", {})
    if not isinstance(half, dict) or not all(v is None or _number(v) for v in half.values()):
        return "angles.half_luminance_deg must map planes to angles in degrees or null"
    if not isinstance(profiles, dict) or not all(
        isinstance(v, list) and len(v) == len(rows) and all(x is None or _number(x) for x in v)
        for v in profiles.values()
    ):
        return "angles.profiles must map planes to one number (or null) a ring"
    return None


def _number(v) -> bool:
    """``v`` is a finite JSON number (not a bool)."""
    return isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)


def write_text(path: Path, text: str) -> None:
    with atomic_path(path) as tmp:
        tmp.write_text(text, encoding="utf-8")


def luminance_png(path: Path, sim: Simulation, title: str) -> None:
    """The relative luminance over the panel with the 9 spots, beside its smoothed view
    (the Monte Carlo noise said on each, and the rays that would bring it to 1 %), for a
    direct-lit stack the halo of one LED lit alone (its map and radial profile), and the
    luminance's angles (a polar map and the two planes' profiles), as a PNG."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.patches import Circle

    from ..figures import angles_pair, halo_pair, luminance_pair, noise_text

    x0, y0, x1, y1 = sim.box
    figures = sim.summary()
    halo = figures.get("halo")
    angles = figures.get("angles") if sim.angles is not None and sim.angles.total else None
    heights = [5.2 * min((y1 - y0) / (x1 - x0), 1.5) + 1.2]
    heights += [5.6] * (bool(halo) + bool(angles))
    rows = len(heights)
    fig, axes = plt.subplots(
        rows, 2, figsize=(13, sum(heights)), dpi=110, squeeze=False, layout="constrained",
        gridspec_kw={"height_ratios": heights},
    )  # fmt: skip
    raw, _ = luminance_pair(
        axes[0], sim.luminance, (x0, x1, y0, y1), figures["luminance_rms_noise"]
    )
    m = sim.measured
    for ax in axes[0]:
        for sx, sy, _ in sim.spots:
            ax.add_patch(Circle((sx, sy), sim.spot / 2, fill=False, color="k", lw=0.8))
        if m.any() and not m.all() and min(m.shape) > 1:  # the bins the figures are taken over
            ny, nx = m.shape
            ax.contour(
                np.linspace(x0 + 0.5 * sim.bin[0], x1 - 0.5 * sim.bin[0], nx),
                np.linspace(y0 + 0.5 * sim.bin[1], y1 - 0.5 * sim.bin[1], ny),
                m.astype(float), levels=[0.5], colors="k", linewidths=0.9, linestyles="--",
            )  # fmt: skip
    lo, hi = raw.get_clim()
    lum = sim.luminance
    over = float(lum.max()) > hi or float(lum.min()) < lo  # hot spots: arrows
    fig.colorbar(
        raw, ax=list(axes[0]), label="luminance / mean", shrink=0.8,
        extend="both" if over else "neither",
    )  # fmt: skip
    if halo:
        halo_pair(axes[1], halo)
    if angles:
        angles_pair(axes[rows - 1], sim.angles.rows(), angles)
    u9, _ = sim.uniformity9()
    fig.suptitle(
        f"{title}: efficiency {sim.efficiency:.1%}, 9-point {u9:.3f}; {noise_text(figures)}",
        fontsize=10,
    )
    buf = io.BytesIO()
    fig.savefig(buf, format="png", bbox_inches="tight")
    plt.close(fig)
    with atomic_path(path) as tmp:
        tmp.write_bytes(buf.getvalue())


def map_csv(fill: np.ndarray) -> str:
    """The map as CSV, row 0 = bottom, six decimals."""
    out = io.StringIO()
    np.savetxt(out, fill, delimiter=",", fmt="%.6f")
    return out.getvalue()


def map_png(path: Path, fill: np.ndarray) -> None:
    """The map as a 16-bit greyscale PNG, top row = top of the panel, pixel = fill x
    65535 (read back with ``image = ...`` and ``fill_range = [0, 1]``)."""
    from PIL import Image

    px = np.round(np.clip(fill[::-1], 0, 1) * 65535).astype(np.uint16)
    img = Image.fromarray(px)
    with atomic_path(path) as tmp:
        img.save(tmp, format="PNG")


def designed_job(
    bench: Bench,
    map_path: Path,
    job_path: Path,
    sizes: tuple[float, float] | None = None,
    cap_ink: np.ndarray | None = None,
) -> str:
    """TOML of the job of ``bench`` reading its map from ``map_path``, to be written at
    ``job_path``;
    with ``sizes``, its dots' diameters ``[low, high]`` mm (the claim rule sizes them);
    with ``cap_ink``, its graded caps' band inks (``[backlight.leds] cap_ink``, 4
    decimals)."""
    if bench.source is None:
        raise JobError("the designed job needs the job file it comes from")
    raw = tomllib.loads(Path(bench.source).read_text(encoding="utf-8-sig"))
    raw = rebased(raw, Path(bench.source).parent, job_path.parent)
    import os

    rel = os.path.relpath(os.path.abspath(map_path), os.path.abspath(job_path.parent))
    raw["density"] = {"grid": rel, "interpolation": "linear"}
    if sizes is not None:
        raw["dots"] = {**raw.get("dots", {}), "diameter": [sizes[0], sizes[1]]}
    if cap_ink is not None:
        ink = [round(float(f), 4) for f in cap_ink]
        raw["backlight"]["leds"] = {**raw["backlight"]["leds"], "cap_ink": ink}
    return job_toml(_ordered(raw))


def _ordered(raw: dict) -> dict:
    """Top-level keys first, then the sections in the README's order."""
    order = ["domain", "density", "dots", "optimize", "qa", "light_guide", "backlight", "design"]
    top = {k: v for k, v in raw.items() if not isinstance(v, dict)}
    secs = {k: raw[k] for k in order if k in raw}
    secs.update({k: v for k, v in raw.items() if isinstance(v, dict) and k not in secs})
    return {**top, **secs}


def write_design(
    designed: Designed, bench: Bench, out_csv: Path, out_png: Path | None, out_job: Path | None
) -> None:
    """Write the designed map (CSV, optional PNG) and the job that uses it."""
    text = map_csv(designed.fill)
    job_text = None
    if out_job is not None:
        job_text = designed_job(bench, out_csv, out_job, designed.sizes, designed.cap_ink)
    write_text(out_csv, text)
    if out_png is not None:
        map_png(out_png, designed.fill)
    if out_job is not None:
        write_text(out_job, job_text)
