"""``optdot simulate`` and ``optdot design``: the light guide's luminance, and the map that
makes it uniform (see :mod:`optdot.optics`)."""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from pathlib import Path

import click

from ..figures import angles_judged
from ..runtime.kernels import warm
from .app import main, user_errors
from .records import Count, Finite, record

RAYS = Count(1000, 10**10)
#: ``--seed`` of ``simulate`` and ``design``.
SEED = click.option(
    "--seed",
    type=click.IntRange(0, 2**63 - 1),
    default=0,
    show_default=True,
    help="Monte Carlo seed: the same job, rays and seed give the same figures.",
)


@dataclass(frozen=True)
class Trace:
    """What ``simulate`` traces: ``--rays``, ``--seed``, ``--halo`` (a direct-lit stack's
    one LED alone too)."""

    rays: int = 2_000_000
    seed: int = 0
    halo: bool = True


@dataclass(frozen=True)
class Bins:
    """How ``simulate`` bins the luminance, mm: ``--bin``, ``--spot`` (the 9-point
    spots' diameter), ``--border`` (left out of RMS and min/max); None: its defaults."""

    bin_mm: float | None = None
    spot_mm: float | None = None
    border_mm: float | None = None


@dataclass(frozen=True)
class Figures:
    """The files ``simulate`` writes: ``--json`` (figures and map), ``--png`` (the map)."""

    json_path: Path | None = None
    png_path: Path | None = None


@main.command()
@click.argument("job_file", type=click.Path(path_type=Path))
@click.argument("pattern", type=click.Path(path_type=Path), required=False)
@record(Trace, "trace")
@record(Bins, "bins")
@record(Figures, "files")
@click.option("--rays", type=RAYS, default=2_000_000, show_default=True, help="Rays to trace.")
@SEED
@click.option(
    "--bin",
    "bin_mm",
    type=Finite(0.01, 1000),
    help="Luminance bin, mm (default: 1/20 of the shorter side, at most 5).",
)
@click.option(
    "--spot",
    "spot_mm",
    type=Finite(0.01, 1000),
    help="9-point spot diameter, mm (default: 1/6 of the shorter side, at most 10).",
)
@click.option(
    "--border",
    "border_mm",
    type=Finite(0, 1000),
    default=None,
    help="Left out of the RMS and min/max, mm inside the outline (default 5), or inside "
    "the job's viewing area ([domain] active_area or bezel; default 0).",
)
@click.option(
    "--json",
    "json_path",
    type=click.Path(path_type=Path),
    help="Figures and luminance map (JSON) to write.",
)
@click.option(
    "--png", "png_path", type=click.Path(path_type=Path), help="Luminance map (PNG) to write."
)
@click.option(
    "--halo/--no-halo",
    default=True,
    show_default=True,
    help="Direct-lit: also light the LED nearest the centre alone (a quarter of the rays) "
    "and measure its halo (widths at 50 % and 10 %, share in its own cell).",
)
@click.option("--quiet", "-q", is_flag=True, help="Print the figures only.")
@user_errors
def simulate(job_file, pattern, trace, bins, files, quiet):
    """Trace JOB_FILE's backlight (its light guide, or the direct-lit stack of
    [backlight]) and report its luminance: with PATTERN (a pattern file, dataset or mask)
    through the real dots, without it through the map's coverage. Prints efficiency, where
    the rest of the light went, 9-point uniformity, the luminance RMS and min/max, each
    with its Monte Carlo noise, and for a direct-lit stack the halo of one LED."""
    from ..config.schema import load_job
    from ..io.atomic import transaction
    from ..io.outputs import check_outputs
    from ..optics.scene import is_direct
    from ..optics.simulate import simulate as run
    from ..optics.writing import luminance_png, simulation_json, write_text

    rays, seed = trace.rays, trace.seed
    bin_mm, spot_mm, border_mm = bins.bin_mm, bins.spot_mm, bins.border_mm
    json_path, png_path = files.json_path, files.png_path
    job = load_job(job_file, need_map=pattern is None)  # real dots need no map
    outs = {k: v for k, v in (("json", json_path), ("png", png_path)) if v is not None}
    inputs = (*job.inputs, *((pattern,) if pattern else ()))
    check_outputs(outs, inputs)
    dots = None
    if pattern is not None:
        from .tooling import _read_with_job, traced_as_made

        dots = _read_with_job(pattern, job)
        traced_as_made(pattern, dots, job)
    warm("simulate")  # a first run: the tracer's kernels on all cores
    t0 = time.perf_counter()
    bench = job.bench
    sim = run(bench, rays, seed, dots=dots, bin_mm=bin_mm, spot_mm=spot_mm, border_mm=border_mm)
    if trace.halo and is_direct(bench):
        from ..optics.halo import halo as one_led

        sim.extra["halo"] = one_led(bench, max(rays // 4, 1000), seed, dots=dots)
    if dots is not None and job.process is not None and job.process.gain_tolerance > 0:
        from ..optics.band import tolerance_band

        sim.extra["tolerance_band"] = tolerance_band(
            bench, dots, sim, rays, seed, bin_mm=bin_mm, spot_mm=spot_mm, border_mm=border_mm
        )
    seconds = time.perf_counter() - t0  # printed, not written: same seed, same bytes
    _print_simulation(sim, seconds)
    band = sim.extra.get("tolerance_band")
    for k, g in enumerate(band["gain_mm"] if band else []):
        click.echo(
            f"at a gain of {g * 1e3:.4g} µm: efficiency {band['efficiency'][k]:.2%}, 9-point "
            f"uniformity {band['uniformity_9point'][k]:.3f}, luminance RMS "
            f"{band['luminance_rms'][k]:.2%}, min {band['luminance_min'][k]:.3f}, max "
            f"{band['luminance_max'][k]:.3f} of the mean"
        )
    for warning in sim.summary().get("warnings", []):
        click.echo(f"optdot: warning: {warning}", err=True)
    with transaction():
        if json_path is not None:
            write_text(json_path, simulation_json(sim, bench, pattern, dots.n if dots else None))
        if png_path is not None:
            luminance_png(png_path, sim, job.name)


def _print_simulation(sim, seconds: float, echo=click.echo) -> None:
    from ..figures import structure_text

    s = sim.summary()
    from ..optics.simulate import traced_what

    mode = traced_what(sim)
    echo(
        f"traced {s['rays']:,} rays through the {mode} in {seconds:.1f} s "
        f"({s['rays'] / max(seconds, 1e-9):,.0f} rays/s), seed {s['seed']}"
    )
    into = "the stack" if s.get("stack") == "direct" else "the edge"
    echo(
        f"efficiency: {s['efficiency']:.2%} ± {s['efficiency_sigma']:.2%} of the injected "
        f"light leaves the top (coupled into {into}: {s['coupling']:.1%})"
    )
    sh = s["shares"]
    echo(
        "the rest: "
        + ", ".join(f"{k.replace('_', ' ')} {v:.2%}" for k, v in sh.items() if k != "extracted")
    )
    echo(
        f"9-point uniformity: {s['uniformity_9point']:.3f} ± "
        f"{s['uniformity_9point_sigma']:.3f} (spots of {s['spot_diameter_mm']:.3g} mm)"
    )
    region = "the viewing area" if "viewing_area_mm" in s else "the panel"
    less = f" less {s['border_mm']:g} mm" if s["border_mm"] else ""
    bins = f"bins of {s['bin_mm'][0]:.3g} x {s['bin_mm'][1]:.3g} mm"
    if math.isfinite(s["luminance_rms"]):
        echo(
            f"luminance over {region}{less}, {bins}: RMS {s['luminance_rms']:.2%} "
            f"(noise alone {s['luminance_rms_noise']:.2%}), min {s['luminance_min']:.3f}, "
            f"max {s['luminance_max']:.3f} of the mean"
        )
        echo(f"  {structure_text(s)}")
    else:
        echo(f"luminance over {region}{less}, {bins}: no light reached them")
    if "outside_max" in s:
        x, y = s["outside_max_at_mm"]
        echo(
            f"outside {region}{less}: brightest bin {s['outside_max']:.3f} of the mean at "
            f"({x:.2f}, {y:.2f}) mm" + (" (hidden by the bezel)" if "viewing_area_mm" in s else "")
        )
    a = s.get("angles")
    if a is not None and not a.get("rays"):
        if s["counts"].get("extracted"):
            echo("angles: none measured: the rays ended at the dots (an idealised extractor)")
    elif a is not None and not angles_judged(a):
        echo(
            f"angles: {a.get('on_axis_rays', 0)} rays left within 5 deg of the normal, too few "
            f"to judge the on-axis luminance and its half angles (trace more rays)"
        )
    elif a is not None:
        half = ", ".join(
            f"{k} {'over 87.5' if v is None else f'{v:.1f}'} deg"
            for k, v in a["half_luminance_deg"].items()
        )
        echo(
            f"angles: on-axis luminance {a['on_axis']:.3f} ± {a['on_axis_sigma']:.3f} of a "
            f"Lambertian's of the same flux; half luminance at {half}"
        )
    if "halo" in s:
        _print_halo(s["halo"], echo)


def _print_halo(h: dict, echo) -> None:
    x, y = h["led_mm"]
    if h["extracted"] == 0:
        echo(f"halo of the LED at ({x:.2f}, {y:.2f}) mm lit alone: no light left the top")
        return
    w50, w10 = (
        f"{w:.3g} mm" if w is not None else "beyond the panel"
        for w in (h["width50_mm"], h["width10_mm"])
    )
    cells = (
        f"; {h['share_own_cell']:.1%} of its light in its own pitch cell, "
        f"{h['share_3x3']:.1%} in the 3 x 3 cells around it"
        if h["share_own_cell"] is not None
        else ""
    )
    echo(
        f"halo of the LED at ({x:.2f}, {y:.2f}) mm lit alone: width at 50 % {w50}, "
        f"at 10 % {w10}{cells}"
    )


@main.command()
@click.argument("job_file", type=click.Path(path_type=Path))
@click.option(
    "-o",
    "--output",
    type=click.Path(path_type=Path),
    required=True,
    help="Designed fill map to write (CSV, row 0 = bottom).",
)
@click.option(
    "--png",
    "png_path",
    type=click.Path(path_type=Path),
    help="16-bit PNG of the map (default: OUTPUT with .png).",
)
@click.option(
    "--job-out",
    type=click.Path(path_type=Path),
    help="Job that uses the map (default: OUTPUT with .toml).",
)
@click.option(
    "--rays", type=RAYS, help="Rays of the last iteration (default: [design] rays or 400 per cell)."
)
@click.option("--iterations", type=click.IntRange(1, 200), help="Override design.iterations.")
@SEED
@click.option("--quiet", "-q", is_flag=True, help="No line per iteration.")
@user_errors
def design(job_file, output, png_path, job_out, rays, iterations, seed, quiet):
    """Design the fill map that makes JOB_FILE's backlight uniform (or follow [design]
    target): the guide's map, or the film's of a [backlight] (more ink, less light).
    Iterate ray traces of the map's coverage, print the uniformity of each, and write the
    map (CSV and 16-bit PNG) and a job ready for 'optdot generate' (with the dot sizes a
    dense film map needs)."""
    from ..config.schema import load_job
    from ..io.atomic import transaction
    from ..io.outputs import check_outputs
    from ..optics.design import check_iterations, design_grid
    from ..optics.design import design as run
    from ..optics.writing import write_design

    if output.suffix.lower() != ".csv":
        raise click.BadParameter("must end in .csv", param_hint="'-o' / '--output'")
    png_path = png_path or output.with_suffix(".png")
    if job_out is None and output.with_suffix(".toml").resolve() == job_file.resolve():
        raise click.BadParameter(
            f"the written job defaults to the map's name with .toml, {job_file}, the job "
            "read: give --job-out another name (or the map another name)",
            param_hint="'--job-out'",
        )
    job_out = job_out or output.with_suffix(".toml")
    job = load_job(job_file, need_map=False)
    check_outputs({"output": output, "png": png_path, "job-out": job_out}, job.inputs)
    if job.light_guide is None and job.backlight is None:
        from ..errors import JobError

        raise JobError(f"{job_file}: no [light_guide] or [backlight] section to design for")
    if not job.shape.kind.round:  # the map must be one the dots can be dealt at
        from ..config.shaping import check_shaped_fill

        check_shaped_fill(job, job.design.fill_range[1], f"{job_file}: design.fill_range")
    check_iterations(job.bench, iterations or job.design.iterations)
    nx, ny, dx, dy = design_grid(job.bench)
    p = job.design
    if not quiet:
        click.echo(
            f"designing {nx} x {ny} cells of {dx:.3g} x {dy:.3g} mm, fill "
            f"{p.fill_range[0]:g}..{p.fill_range[1]:g}",
            err=True,
        )
    warm("simulate", announce=None if quiet else lambda s: click.echo(s, err=True))
    t0 = time.perf_counter()

    def report(f: dict) -> None:
        if not quiet:
            click.echo(
                f"iteration {f['iteration']:2d}: {f['rays']:>11,} rays, 9-point "
                f"{f['uniformity_9point']:.3f}, RMS "
                + (
                    f"against the target {f['luminance_rms_target']:.2%}"
                    if "luminance_rms_target" in f
                    else f"{f['luminance_rms']:.2%}"
                )
                + " (noise "
                f"{f['luminance_rms_noise']:.2%}), efficiency {f['efficiency']:.1%}"
                + (
                    f", updates agree {f['update_agreement']:+.2f}"
                    if math.isfinite(f.get("update_agreement", math.nan))
                    else ""
                )
                + f", {time.perf_counter() - t0:.0f} s",
                err=True,
            )

    got = run(job.bench, seed=seed, rays=rays, iterations=iterations, report=report)
    if not quiet:
        click.echo(f"design {got.stopped}", err=True)
    with transaction():
        write_design(got, job.bench, output, png_path, job_out)
    last = got.history[-1]
    if got.sizes is not None:
        lo_d, hi_d = got.sizes
        click.echo(
            f"the map's largest fill {float(got.fill.max()):.3g} needs larger dots than "
            f"{job.diameter * 1e3:.4g} µm to keep the {job.qa.effective_close_gap * 1e3:.3g} µm "
            f"close gap: {job_out} sizes them, [dots] diameter = [{lo_d:g}, {hi_d:g}] mm"
        )
    click.echo(
        f"{output}: designed map, 9-point uniformity {last['uniformity_9point']:.3f}, "
        f"efficiency {last['efficiency']:.1%} (map coverage; check it with "
        f"'optdot simulate {job_out} PATTERN' after 'optdot generate {job_out}')"
    )
