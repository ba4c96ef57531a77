"""``optdot export`` and ``optdot qa``: the QA gate, then the masks and reports."""

from __future__ import annotations

import sys
from dataclasses import dataclass, replace
from pathlib import Path

import click
import numpy as np

from ..config.viewing import VIEW_PRESETS
from ..io.outputs import check_outputs
from .app import main, user_errors
from .records import (
    POSITIVE,
    Finite,
    JobChoice,
    Reports,
    job_options,
    layer_options,
    load_job_with,
    record,
    run_job,
)


def format_options(fn):
    """One ``--<format> PATH`` option per format ``export`` writes
    (:data:`optdot.formats.EXPORTED`), passed to the command by the format's name."""
    from ..formats import EXPORTED, FORMATS

    for name in reversed(EXPORTED):
        fn = click.option(
            f"--{name}", name, type=click.Path(path_type=Path), help=FORMATS[name].help
        )(fn)
    return fn


def _inputs(source: Path, job_path) -> tuple:
    """(job or None, every input file): the job is ``source`` when it is a .toml file."""
    from ..config.schema import load_job

    if job_path is None and source.suffix.lower() == ".toml":
        job_path = source
    job = load_job(job_path) if job_path else None
    return job, (source, *(job.inputs if job else ()))


def _read_with_job(path: Path, job, opts=None):
    """The pattern read from ``path``, on the job's panel when there is a job (a mask
    read as the print it makes under the job's ``[process]``, unless ``opts`` say how)."""
    from ..exporters.options import ExportOptions
    from ..exporters.readback import read_any
    from ..orchestration.pipeline import with_job_panel

    if job is not None:  # a mask read as the job's dots, printed by its process
        made = job.shape.kind if job.shape.kind.derived else None
        if opts is None and (job.process is not None or made is not None):
            opts = ExportOptions(process=job.process, kind=made)
        elif opts is not None and made is not None and opts.kind is None:
            opts = replace(opts, kind=made)

    stored = path.suffix.lower() in (".npz", ".parquet")  # these keep their panel's box
    pattern = read_any(path, opts, box=job.box if job and not stored else None)
    made_for(path, pattern.box, job)
    _on_the_panel(path, pattern, job)
    return with_job_panel(pattern, job)


#: How far outside the job's panel a dot's centre may lie before the pattern is taken for
#: another job's, mm (a dot a few micrometres out is a protrusion, for QA to report).
FAR_OUT_MM = 1.0


def _on_the_panel(path: Path, pattern, job) -> None:
    """Refuse a pattern with dots far outside the job's panel (a CSV or mask of another
    job: QA read them as protruding by the hundred thousand, the tracer lost them)."""
    if job is None or not hasattr(pattern, "xy") or not len(pattern.xy):
        return
    from ..errors import JobError

    x0, y0, x1, y1 = job.box
    xy = pattern.xy
    far = (
        (xy[:, 0] < x0 - FAR_OUT_MM)
        | (xy[:, 0] > x1 + FAR_OUT_MM)
        | (xy[:, 1] < y0 - FAR_OUT_MM)
        | (xy[:, 1] > y1 + FAR_OUT_MM)
    )
    n = int(far.sum())
    if n:
        lo, hi = xy.min(axis=0), xy.max(axis=0)
        raise JobError(
            f"{path}: {n:,} of its {len(xy):,} dots lie more than {FAR_OUT_MM:g} mm outside "
            f"this job's panel [{x0:g}, {y0:g}, {x1:g}, {y1:g}] mm (the dots span "
            f"[{lo[0]:.4g}, {lo[1]:.4g}, {hi[0]:.4g}, {hi[1]:.4g}]): give the job it was made with"
        )


def traced_as_made(path: Path, pattern, job) -> None:
    """Refuse to trace a pattern that is not ``job``'s: footprints of another kind or size
    than the job's dots (an ellipse pattern under a prism job), or dots that leave a band
    of the panel empty where the map asks for dots (a CSV of a smaller panel: a CSV keeps
    no panel box for :func:`made_for` to compare), or prisms whose facets differ read from a
    DXF (its outlines say nothing of which end is which: half of them would be traced turned
    half a turn). QA reports the first two as failed checks; a trace would report the
    luminance of a guide nobody asked for.

    Raises:
        JobError: one line naming the file and what differs.
    """
    from ..errors import JobError
    from ..orchestration.pipeline import dot_rule
    from ..quality.conformance import footprint_text

    prof = job.profile
    if path.suffix.lower() == ".dxf" and prof.facets[0] != prof.facets[1]:  # (0, 0) off prisms
        raise JobError(
            f"{path}: a DXF holds each prism's outline, not which way it points, and this "
            f"job's facets differ (dots.facets = [{prof.facets[0]:g}, {prof.facets[1]:g}]): "
            "trace its pattern file (NPZ, CSV or dataset) or its GDSII / OASIS mask"
        )
    rule = dot_rule(job)
    feet = pattern.shape
    stray = rule.stray(feet, pattern.xy)
    if stray.any():
        i = int(np.flatnonzero(stray)[0])
        where = ""
        if rule.band is not None:  # a size of the range, but not the one the rule gives there
            lo, hi = (float(v[0]) * 1e3 for v in rule.band.at(pattern.xy[i : i + 1]))
            x, y = pattern.xy[i]
            span = f"{lo:.4g}" if abs(hi - lo) < 1e-9 else f"{lo:.4g}–{hi:.4g}"
            where = f" at ({x:.3f}, {y:.3f}) mm, where the job's size rule gives {span} µm"
        raise JobError(
            f"{path}: {int(stray.sum()):,} of its {pattern.n:,} dots are not this job's "
            f"{rule.describe()} (the first: {footprint_text(feet.kind, feet.size[i])}{where}): "
            "trace a pattern with the job it was made for"
        )
    band = _empty_band(pattern, job)
    if band is not None:
        raise JobError(f"{path}: {band}: give the job it was made with")


def _empty_band(pattern, job) -> str | None:
    """Where the dots leave a band along one side of the map's non-zero cells wider than
    a run's dots ever do, in words, or None: wider than 2 mm, 2 map cells and 10 dot
    spacings at the map's lowest non-zero fill."""
    d = job.density
    grid = np.asarray(d.grid)
    on = grid > 0
    if not on.any() or not pattern.n:
        return None
    cw, ch = d.cell_size
    cols, rows = np.flatnonzero(on.any(axis=0)), np.flatnonzero(on.any(axis=1))
    x0, y0, x1, y1 = job.box
    want = (
        max(d.x0 + cols[0] * cw, x0),
        max(d.y0 + rows[0] * ch, y0),
        min(d.x0 + (cols[-1] + 1) * cw, x1),
        min(d.y0 + (rows[-1] + 1) * ch, y1),
    )
    lo, hi = pattern.xy.min(axis=0), pattern.xy.max(axis=0)
    spacing = float(np.sqrt(float(np.median(pattern.shape.area())) / float(grid[on].min())))
    gaps = {
        "left": (lo[0] - want[0], cw),
        "bottom": (lo[1] - want[1], ch),
        "right": (want[2] - hi[0], cw),
        "top": (want[3] - hi[1], ch),
    }
    for side, (gap, cell) in gaps.items():
        if gap > max(EMPTY_BAND_MM, 2.0 * cell, 10.0 * spacing):
            return (
                f"its dots span [{lo[0]:.4g}, {lo[1]:.4g}, {hi[0]:.4g}, {hi[1]:.4g}] mm, "
                f"leaving {gap:.3g} mm empty along the {side} of this job's map "
                f"[{want[0]:.4g}, {want[1]:.4g}, {want[2]:.4g}, {want[3]:.4g}] mm"
            )
    return None


#: Narrowest empty band along a side of the map that :func:`traced_as_made` refuses, mm.
EMPTY_BAND_MM = 2.0


def made_for(path: Path, box, job) -> None:
    """Refuse a pattern or dataset that stores its panel (``.npz``, ``.parquet``) when that
    panel is not the job's: judged against another panel, its dots read as protruding or
    missing by the hundred thousand (one line naming both panels instead).

    Raises:
        JobError: the panels differ by more than a micrometre.
    """
    if job is None or path.suffix.lower() not in (".npz", ".parquet"):
        return
    if all(abs(float(a) - float(b)) <= 1e-3 for a, b in zip(box, job.box, strict=True)):
        return
    from ..errors import JobError

    def panel(b) -> str:
        return f"{b[2] - b[0]:g} x {b[3] - b[1]:g} mm at ({b[0]:g}, {b[1]:g})"

    raise JobError(
        f"{path}: this pattern was made for a panel of {panel(box)}, not this job's "
        f"{panel(job.box)} ({job.source or job.name}): give the job it was made with"
    )


@dataclass(frozen=True)
class MaskStyle:
    """How ``export`` draws its masks: ``--speos-reference-diameter`` (mm), ``--tolerance``
    (µm), ``--flatten``, ``--top-cell``, ``--dxf-version``."""

    speos_reference_diameter: float | None = None
    tolerance: float = 0.01
    flatten: bool = False
    top_cell: str = "TOP"
    dxf_version: str = "R2010"


@dataclass(frozen=True)
class Keep:
    """What ``export`` may replace: ``--force`` (write though the gate fails),
    ``--overwrite`` (replace a mask that differs)."""

    force: bool = False
    overwrite: bool = False


@main.command()
@click.argument("source", type=click.Path(path_type=Path))
@format_options
@record(MaskStyle, "style")
@record(JobChoice, "choice")
@record(Keep, "keep")
@record(Reports, "reports")
@click.option(
    "--speos-reference-diameter",
    type=POSITIVE,
    help="Diameter of the Speos texture element, mm (scale 1; default: the nominal diameter).",
)
@click.option(
    "--job",
    "job_path",
    type=click.Path(path_type=Path),
    help="Job file for the QA gate when SOURCE is a pattern.",
)
@click.option(
    "--tolerance",
    type=POSITIVE,
    default=0.01,
    show_default=True,
    help="Circle polygon tolerance, µm (GDS/OAS).",
)
@click.option("--flatten", is_flag=True, help="Plain polygons instead of a dot cell + references.")
@layer_options
@click.option("--top-cell", default="TOP", show_default=True, help="Name of the top cell.")
@click.option(
    "--dxf-version", default="R2010", show_default=True, help="DXF release: R2010, R2000, R12, ..."
)
@click.option("--force", is_flag=True, help="Write masks even if the QA gate fails.")
@click.option(
    "--no-job",
    is_flag=True,
    help="Write without a job, knowingly: the gate then judges the spacing alone; without "
    "--job (or a job file as SOURCE) nothing is written and the exit code is 5 unless "
    "this is given.",
)
@click.option(
    "--overwrite",
    is_flag=True,
    help="Replace an existing mask (GDS/OAS/DXF) that differs from the new one.",
)
@click.option(
    "--html", "html_path", type=click.Path(path_type=Path), help="QA report (HTML) to write."
)
@click.option(
    "--json", "json_path", type=click.Path(path_type=Path), help="QA report (JSON) to write."
)
@job_options
@user_errors
def export(source, style, choice, keep, layers, reports, run, **paths):
    """Write masks and previews of SOURCE (a job file, or a pattern .csv/.npz/.parquet).

    An existing mask (GDS/OAS/DXF) is kept unless the new one has the same bytes (a
    repeated run) or --overwrite is given; other outputs are replaced. Either way the
    outputs are replaced together and atomically: a failed run leaves them as they were.
    Masks are written only if the QA gate passes, unless --force; the verdict is printed,
    and --html/--json keep the gate's report (written also when the gate fails).
    """
    from ..exporters.options import ExportOptions
    from ..orchestration.pipeline import export as export_pattern

    outputs = {k: v for k, v in paths.items() if v is not None}
    if not outputs:
        raise click.UsageError("give at least one of " + " ".join(f"--{k}" for k in paths))
    opts = ExportOptions(
        tolerance_um=style.tolerance,
        flatten=style.flatten,
        layer=layers.layer,
        datatype=layers.datatype,
        outline_layer=layers.outline_layer,
        top_cell=style.top_cell,
        dxf_version=style.dxf_version,
        speos_reference_mm=style.speos_reference_diameter,
    )
    quiet = run.quiet
    if source.suffix.lower() == ".toml":
        job = load_job_with(source, run)
        inputs = (source, *job.inputs)
    else:
        job, inputs = _inputs(source, choice.job_path)
    reports = reports.paths()
    check_outputs({**outputs, **reports}, inputs)
    stream = pattern = None
    if source.suffix.lower() == ".toml":
        pattern = run_job(job, quiet)
    elif source.suffix.lower() == ".parquet":
        from ..io.dataset import open_dataset

        stream = open_dataset(source)  # gate and masks tile by tile
        made_for(source, stream.box, job)
    else:
        pattern = _read_with_job(source, job)
    if job is None and not choice.no_job:  # --force overrides a failed gate, not a missing job
        _incomplete_export(pattern if pattern is not None else stream, reports, quiet)
    lines: list[str] = []
    from .progress import ProgressBar

    bar = ProgressBar(1, label="optdot", enabled=False if quiet else None)
    try:
        result = export_pattern(
            pattern,
            outputs,
            job,
            opts,
            force=keep.force,
            overwrite=keep.overwrite,
            stream=stream,
            reports=reports,
            written=lambda fmt, path, what: lines.append(f"{path}: {what}"),
            stage=bar.stage,
        )
    finally:
        bar.close()
    if not result.passed:
        click.echo(
            f"optdot: warning: QA gate failed ({result.failures()}); writing anyway (--force)",
            err=True,
        )
    if not quiet:
        _print_checks(result, lambda line: click.echo(line, err=True))
        for line in lines:
            click.echo(line, err=True)


@dataclass(frozen=True)
class Limits:
    """The thresholds ``qa`` may be given: ``--collision``, ``--close`` (centre distances,
    mm), ``--close-gap`` (edge gap, mm), ``--max-jnd`` (None: the job's or the
    defaults)."""

    collision: float | None = None
    close: float | None = None
    close_gap: float | None = None
    max_jnd: float | None = None


@dataclass(frozen=True)
class Looks:
    """How ``qa``'s viewer looks: ``--view`` (a preset), ``--distance`` (mm),
    ``--luminance`` (cd/m²), ``--psf`` (mm; None: the job's or the preset's)."""

    view: str | None = None
    distance: float | None = None
    luminance: float | None = None
    psf: float | None = None


@main.command()
@click.argument("pattern_file", type=click.Path(path_type=Path))
@record(JobChoice, "choice")
@record(Reports, "reports")
@record(Limits, "limits")
@record(Looks, "looks")
@click.option(
    "--job",
    "job_path",
    type=click.Path(path_type=Path),
    help="Job file: target map and thresholds.",
)
@click.option("--html", "html_path", type=click.Path(path_type=Path), help="HTML report to write.")
@click.option("--json", "json_path", type=click.Path(path_type=Path), help="JSON report to write.")
@click.option(
    "--simulation",
    "simulation_path",
    type=click.Path(path_type=Path),
    help="A luminance simulation ('optdot simulate --json') to show beside the JND map.",
)
@click.option(
    "--collision", type=POSITIVE, help="Collision distance, mm (default: dot diameter + gap)."
)
@click.option("--close", type=POSITIVE, help="Too-close distance, mm (default 0.060).")
@click.option(
    "--close-gap",
    type=Finite(0.0, None),
    help="Too-close edge gap, mm (dots of varying size; default qa.close_gap or 0.014).",
)
@click.option(
    "--view",
    type=click.Choice(list(VIEW_PRESETS)),
    help="Viewing preset of the visibility check (default qa.view or notebook).",
)
@click.option("--distance", type=POSITIVE, help="Viewing distance, mm (overrides the preset).")
@click.option("--luminance", type=POSITIVE, help="Screen luminance, cd/m² (overrides the preset).")
@click.option("--psf", type=POSITIVE, help="Gaussian sigma of the stack's blur, mm (default 1.0).")
@click.option(
    "--no-job",
    is_flag=True,
    help="Judge the spacing alone, knowingly: without a job, coverage, empty cells and "
    "visibility are not checked and the exit code is 5 unless this is given.",
)
@click.option("--max-jnd", type=POSITIVE, help="Gate: largest allowed |JND| (default: not gated).")
@layer_options
@click.option("--quiet", "-q", is_flag=True, help="Only the exit code.")
@user_errors
def qa(pattern_file, choice, reports, simulation_path, limits, looks, layers, quiet):
    """Check PATTERN_FILE (csv, npz, a .parquet dataset, gds, oas, dxf) before tooling:
    exit 0 pass, 1 fail, 5 passed but incomplete (no --job: the map was not checked)."""
    from ..io.atomic import transaction
    from ..orchestration.pipeline import qa as run_gate
    from ..quality.report import write_reports

    close_gap = limits.close_gap
    if close_gap is not None and not 0 <= close_gap < 10:
        raise click.BadParameter("must be an edge gap in mm, 0 <= x < 10", param_hint="--close-gap")
    from ..exporters.options import ExportOptions

    outs = reports.paths()
    view = {
        k: v
        for k, v in (
            ("view", looks.view),
            ("view_distance", looks.distance),
            ("view_luminance", looks.luminance),
            ("psf", looks.psf),
            ("max_jnd", limits.max_jnd),
        )
        if v is not None
    }
    job, inputs = _inputs(pattern_file, choice.job_path)
    process = job.process if job is not None else None  # a mask is read as what it prints
    opts = ExportOptions(
        layer=layers.layer,
        datatype=layers.datatype,
        outline_layer=layers.outline_layer,
        process=process,
    )
    check_outputs(outs, (*inputs, *((simulation_path,) if simulation_path else ())))
    simulation = None
    if simulation_path is not None:
        from ..optics.writing import read_simulation

        simulation = read_simulation(simulation_path)
    if pattern_file.suffix.lower() == ".parquet":
        from ..io.dataset import open_dataset

        # a dataset is measured tile by tile with halos, in bounded memory
        dataset = open_dataset(pattern_file)
        made_for(pattern_file, dataset.box, job)
        result = run_gate(
            None, job, limits.collision, limits.close, dataset=dataset, close_gap=close_gap,
            view=view,
        )  # fmt: skip
    else:
        pattern = _read_with_job(pattern_file, job, opts)
        result = run_gate(
            pattern, job, limits.collision, limits.close, close_gap=close_gap, view=view
        )
    if simulation is not None:
        from ..quality.simulated import attach_simulation

        attach_simulation(result, simulation, str(simulation_path))
    with transaction():  # both reports replaced together, or neither
        write_reports(result, outs, title=f"optdot QA: {pattern_file.name}")
    if not quiet:
        _print_checks(result)
    if not result.passed:
        sys.exit(1)
    if job is None and not choice.no_job:
        click.echo(INCOMPLETE_TEXT.format(""), err=True)
        sys.exit(INCOMPLETE)
    sys.exit(0)


#: Exit code of ``qa`` and ``export`` when the gate passed but the map's checks were
#: skipped (no job, no ``--no-job``); ``export`` then writes nothing.
INCOMPLETE = 5

#: What ``qa`` and ``export`` say when they exit :data:`INCOMPLETE`.
INCOMPLETE_TEXT = (
    "optdot: incomplete: without --job the pattern's coverage, empty cells and visibility "
    "were not checked (exit 5){}; give the job, or --no-job to judge the spacing alone"
)


def _incomplete_export(dots, reports: dict, quiet: bool) -> None:
    """``export`` without a job: the gate judged, its report written, nothing else, and
    the exit code ``qa`` gives the same pattern (1 failed, else :data:`INCOMPLETE`)."""
    from ..io.atomic import transaction
    from ..orchestration.pipeline import qa as run_gate
    from ..quality.report import write_reports

    result = run_gate(dots, None)
    with transaction():
        write_reports(result, reports, title="optdot QA: pattern")
    if not quiet:
        _print_checks(result, lambda line: click.echo(line, err=True))
    if not result.passed:
        click.echo(f"optdot: QA gate failed ({result.failures()}); nothing written", err=True)
        sys.exit(1)
    click.echo(INCOMPLETE_TEXT.format("; nothing written"), err=True)
    sys.exit(INCOMPLETE)


def _print_checks(result, echo=click.echo) -> None:
    """The gate as a user reads it: one line per check (PASS, FAIL, or WARN for an
    advisory one over its level), the checks skipped, the visibility summary, and the
    verdict (PASS, PASS WITH WARNINGS or FAIL) last."""
    from ..quality.gate import jnd_text
    from ..quality.gate import number_text as _num

    for c in result.checks:
        mark = "PASS" if c.passed else ("WARN" if c.advisory else "FAIL")
        where = f"  at {_places(c.where[:3])}" if (c.where and not c.passed) else ""
        echo(f"{mark}  {c.name}: {_num(c.value)} (limit {_num(c.limit)}){where}")
    for s in result.skipped:
        echo(f"SKIP  {s}")
    vis = result.metrics.get("visibility")
    if vis:
        x, y = vis["max_jnd_at_mm"]
        echo(
            f"visibility ({vis['view']}, {vis['distance_mm']:g} mm, "
            f"{vis['luminance_cd_m2']:g} cd/m², PSF sigma {vis['psf_sigma_mm']:g} mm): "
            f"largest |JND| {jnd_text(vis['max_jnd'])} at ({x:.2f}, {y:.2f}) mm, "
            f"{vis['blobs_over_1_jnd']} blobs over 1 JND" + _panel_jnd(vis)
        )
    echo(f"verdict: {result.verdict}")


def _places(where: list) -> str:
    """Places as ``(x, y) mm, ...`` (mm, 3 decimals), whatever numbers they hold."""
    out = []
    for p in where:
        try:
            out.append("(" + ", ".join(f"{float(v):.3f}" for v in p) + ")")
        except (TypeError, ValueError):
            out.append(str(p))
    return ", ".join(out) + " mm"


def _panel_jnd(vis: dict) -> str:
    """`` in the viewing area; the whole panel's largest ... at ...`` when the job names a
    viewing area, else nothing."""
    from ..quality.gate import jnd_text

    if "panel_max_jnd" not in vis:
        return ""
    px, py = vis["panel_max_jnd_at_mm"]
    return (
        f" in the viewing area; the whole panel's largest {jnd_text(vis['panel_max_jnd'])} "
        f"at ({px:.2f}, {py:.2f}) mm"
    )


if __name__ == "__main__":  # pragma: no cover
    main()
