"""Command line: ``optdot generate | export | qa``.

Exit codes (README, "Exit codes"): 0 success; 1 the QA gate failed; 2 bad input (job,
grid, pattern file, option, unwritable output, too big for memory); 3 the optimizer could
not meet the spacing guarantee; 70 internal error (a bug: traceback in a log file);
130 interrupted. Every failure is one line on stderr.
"""

from __future__ import annotations

import functools
import math
import os
import platform
import signal
import sys
import tempfile
import time
import traceback
import warnings
from pathlib import Path

import click

from ..config.viewing import VIEW_PRESETS
from ..errors import OptdotError, QAGateError, one_line, shorten
from ..io.outputs import check_outputs

#: Exit code of an unexpected internal error (sysexits' EX_SOFTWARE).
EXIT_INTERNAL = 70


def _user_errors(fn):
    """Turn :class:`OptdotError` into one line on stderr and its exit code."""

    @functools.wraps(fn)
    def wrapper(*args, **kwargs):
        from ..runtime.stop import interrupted

        previous = {s: signal.signal(s, _terminate) for s in (signal.SIGTERM, signal.SIGINT)}
        try:
            out = fn(*args, **kwargs)
            if interrupted():  # the interrupt was swallowed inside compiled code
                raise KeyboardInterrupt
            return out
        except QAGateError as e:
            click.echo(f"optdot: {one_line(e)}", err=True)
            sys.exit(e.exit_code)
        except OptdotError as e:
            click.echo(f"optdot: error: {shorten(str(e))}", err=True)
            sys.exit(e.exit_code)
        except KeyboardInterrupt:
            click.echo("optdot: interrupted", err=True)
            sys.exit(130)
        except Exception as e:
            if not _caused_by_interrupt(e):
                raise
            # numba turns an interrupt raised while it calls back into Python (cache
            # loading) into SystemError "returned a result with an exception set"
            click.echo("optdot: interrupted", err=True)
            sys.exit(130)
        finally:
            for s, handler in previous.items():
                signal.signal(s, handler)

    return wrapper


def _terminate(signum, frame):
    """SIGTERM and SIGINT: from now on no output replaces anything, and the run stops at
    its next safe point (the next iteration, or before any file is replaced). An exception
    raised at an arbitrary point can land inside numba's compiler or cache loader, which
    then crashes the process (SIGSEGV seen in testing); a second signal stops at once."""
    from ..runtime.stop import interrupted, mark_interrupted

    if interrupted():
        raise KeyboardInterrupt
    mark_interrupted()


def _caused_by_interrupt(e: BaseException) -> bool:
    from ..runtime.stop import interrupted

    seen = set()
    while e is not None and id(e) not in seen:
        if isinstance(e, KeyboardInterrupt):
            return True
        seen.add(id(e))
        e = e.__cause__ or e.__context__
    return interrupted()


class _Command(click.Group):
    """The ``optdot`` group: one top-level handler, so that every failure, a usage error
    or a bug, ends as one line and a documented exit code (never a traceback)."""

    def main(self, args=None, prog_name=None, complete_var=None, standalone_mode=True, **extra):
        if not standalone_mode:
            return super().main(args, prog_name, complete_var, False, **extra)
        try:
            with warnings.catch_warnings():
                # numeric warnings are not a user's business: results are checked
                warnings.simplefilter("ignore", RuntimeWarning)
                code = super().main(args, prog_name, complete_var, False, **extra)
        except click.exceptions.NoArgsIsHelpError as e:
            click.echo(e.ctx.get_help() if e.ctx else str(e), err=True)
            sys.exit(e.exit_code)
        except click.ClickException as e:
            click.echo(f"optdot: error: {shorten(_usage_line(e))}", err=True)
            sys.exit(e.exit_code)
        except (click.Abort, KeyboardInterrupt):
            click.echo("optdot: interrupted", err=True)
            sys.exit(130)
        except MemoryError:
            click.echo(
                "optdot: error: out of memory; the input is larger than this machine", err=True
            )
            sys.exit(2)
        except OSError as e:
            name = f"{e.filename}: " if e.filename else ""
            click.echo(f"optdot: error: {name}{e.strerror or e}", err=True)
            sys.exit(2)
        except Exception as e:  # noqa: BLE001 - the last line of defence, logged in full
            log = _write_crash_log(e, args)
            click.echo(
                f"optdot: internal error: {one_line(e, True)} (a bug; traceback in {log})",
                err=True,
            )
            sys.exit(EXIT_INTERNAL)
        sys.exit(code if isinstance(code, int) else 0)


def _usage_line(e: click.ClickException) -> str:
    """click's usage error as one line, naming the command and where help is."""
    msg = " ".join(e.format_message().split())
    ctx = getattr(e, "ctx", None)
    if isinstance(e, click.UsageError) and ctx is not None:
        return f"{ctx.command_path}: {msg} (see '{ctx.command_path} --help')"
    return msg


def _write_crash_log(e: BaseException, args) -> str:
    """Write the traceback of an internal error to a log file; its path (or why not)."""
    from importlib.metadata import version

    stamp = time.strftime("%Y%m%d-%H%M%S")
    try:
        fd, path = tempfile.mkstemp(prefix=f"optdot-error-{stamp}-", suffix=".log")
        with os.fdopen(fd, "w", encoding="utf-8") as fh:
            fh.write(f"optdot {version('optdot')}, Python {platform.python_version()}, ")
            fh.write(f"{platform.platform()}\n")
            fh.write(f"command: optdot {' '.join(sys.argv[1:] if args is None else args)}\n\n")
            fh.write("".join(traceback.format_exception(e)))
    except OSError as err:
        return f"<not written: {err.strerror}>"
    return path


@click.group(cls=_Command, context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(package_name="optdot")
def main() -> None:
    """Non-overlapping random dot patterns for light guides, their masks, and QA."""


class Finite(click.FloatRange):
    """A float option that is a real number: ``nan`` and ``inf`` are refused (they pass
    every range comparison), like values outside ``[min, max]``."""

    name = "number"

    def convert(self, value, param, ctx):
        v = super().convert(value, param, ctx)
        if not math.isfinite(v):
            self.fail(f"{value!r} is not a finite number", param, ctx)
        return v


#: A number > 0 (mm, cd/m², JND...); a GDS/OAS layer or datatype number.
POSITIVE = Finite(0.0, None, min_open=True)
LAYER = click.IntRange(0, 65535)


def _job_options(fn):
    fn = click.option("--seed", type=click.IntRange(0, 2**63 - 1), help="Override optimize.seed.")(
        fn
    )
    fn = click.option(
        "--max-iter", type=click.IntRange(0, 100_000), help="Override optimize.max_iter."
    )(fn)
    fn = click.option(
        "--method", type=click.Choice(["optdot", "md"]), help="Override optimize.method."
    )(fn)
    fn = click.option(
        "--formulation",
        type=click.Choice(["optdot", "paper"]),
        help="Override optimize.formulation.",
    )(fn)
    fn = click.option("--quiet", "-q", is_flag=True, help="No progress bar.")(fn)
    return fn


def load_job_with(job_path: Path, seed, max_iter, method, formulation):
    """The job with the command line's optimizer overrides."""
    from ..config.schema import load_job

    return load_job(job_path).with_overrides(
        seed=seed, max_iter=max_iter, method=method, formulation=formulation
    )


def _layer_options(fn):
    """``--layer``, ``--datatype``, ``--outline-layer``: where dots and outline are in a
    GDSII/OASIS file (written by ``export``, read by ``qa``)."""
    fn = click.option(
        "--outline-layer",
        type=LAYER,
        default=2,
        show_default=True,
        help="GDS/OAS layer of the outline.",
    )(fn)
    fn = click.option(
        "--datatype", type=LAYER, default=0, show_default=True, help="GDS/OAS datatype of the dots."
    )(fn)
    return click.option(
        "--layer", type=LAYER, default=1, show_default=True, help="GDS/OAS layer of the dots."
    )(fn)


def _bar(job, quiet: bool):
    """A progress bar for ``job`` and the callbacks that draw on it: ``(bar,
    progress(iteration, value), tile_progress(fraction, line))``; a signal that came
    stops the run at the next call, in plain Python."""
    from ..runtime.stop import interrupted
    from .progress import ProgressBar

    bar = ProgressBar(
        job.optimize.max_iter, label=job.optimize.method, enabled=False if quiet else None
    )

    def progress(iteration: int, value: float) -> None:
        bar(iteration, value)
        if interrupted():
            raise KeyboardInterrupt

    def tile_progress(fraction: float, line: str) -> None:
        bar.line(fraction, line)
        if interrupted():
            raise KeyboardInterrupt

    return bar, progress, tile_progress


def run_job(job, quiet: bool):
    """Generate the job's pattern with a progress bar."""
    from ..pipeline import generate

    bar, progress, _ = _bar(job, quiet)
    try:
        pattern = generate(job, progress=progress, stage=bar.stage)
    finally:
        bar.close()
    return pattern


def _tile_options(fn):
    """``--tiles``, ``--tile-size``, ``--scheduler``, ``--workers``: tiled runs on Dask."""
    fn = click.option(
        "--worker-memory",
        type=Finite(0.01, 4096),
        metavar="GIB",
        help="Memory limit of each local worker, GiB (default: 85 % of the available "
        "memory shared evenly).",
    )(fn)
    fn = click.option(
        "--workers",
        type=click.IntRange(1, 1024),
        help="Worker processes of the embedded local cluster (default: the cores).",
    )(fn)
    fn = click.option(
        "--scheduler",
        metavar="ADDRESS",
        help="Run the tiles on this Dask scheduler (tcp://HOST:8786; default: "
        "$DASK_SCHEDULER_ADDRESS, else a local cluster started here).",
    )(fn)
    fn = click.option(
        "--tile-size",
        type=Finite(0.5, 10_000),
        metavar="MM",
        help="Side of a tile, mm (default: about 150,000 dots per tile).",
    )(fn)
    return click.option(
        "--tiles",
        type=click.Choice(["auto", "on", "off"]),
        default="auto",
        show_default=True,
        help="Tiled generation on Dask: auto = when one process would not fit, or from "
        "2 million dots.",
    )(fn)


@main.command()
@click.argument("job_file", type=click.Path(path_type=Path))
@_job_options
@_tile_options
@_user_errors
def check(
    job_file,
    seed,
    max_iter,
    method,
    formulation,
    quiet,
    tiles,
    tile_size,
    scheduler,
    workers,
    worker_memory,
):
    """Check JOB_FILE without running it: is it valid, how many dots, one process or
    tiles, and about how long, how much memory and disk it will take (exit 0: it would
    run; otherwise the one-line reason the run itself would give)."""
    from ..pipeline import check_job

    job = load_job_with(job_file, seed, max_iter, method, formulation)
    got = check_job(job, tiles, tile_size, workers)
    d = job.density.grid
    x0, y0, x1, y1 = job.box
    opt = job.optimize
    gib = 2**30
    if got.plan is None:
        how = "one process"
    else:
        p = got.plan
        how = (
            f"{p.count} tiles ({p.nx} x {p.ny}) of ~{int(p.quotas.mean()):,} dots "
            f"on {got.workers} local workers"
        )
    click.echo(f"{job_file}: valid")
    click.echo(
        f"panel {x1 - x0:g} x {y1 - y0:g} mm"
        + ("" if job.domain.rectangle else " (outline)")
        + f", map {d.shape[1]} x {d.shape[0]} cells, fill {d.min():.3g}..{d.max():.3g}"
    )
    click.echo(
        f"dots: {got.n_dots:,} of {_diameter_text(job)} ({opt.method}, seed {opt.seed}, "
        f"{opt.max_iter} iterations)"
    )
    click.echo(f"run: {how}")
    c = got.cost
    click.echo(
        f"estimate: {_duration(c.seconds)}, {c.peak_bytes / gib:.2f} GiB peak memory "
        f"({got.available_bytes / gib:.1f} GiB available)"
    )
    click.echo(
        "disk: "
        + ", ".join(f"{fmt.upper()} {size / 1e6:,.1f} MB" for fmt, size in c.disk_bytes.items())
    )


def _diameter_text(job) -> str:
    if job.sizes is None:
        return f"{job.diameter * 1e3:.4g} µm"
    return f"{job.sizes.low * 1e3:.4g}..{job.sizes.high * 1e3:.4g} µm"


def _duration(seconds: float) -> str:
    if seconds < 90:
        return f"about {seconds:.0f} s"
    if seconds < 5400:
        return f"about {seconds / 60:.0f} min"
    return f"about {seconds / 3600:.1f} h"


@main.command()
@click.argument("job_file", type=click.Path(path_type=Path))
@click.option(
    "-o",
    "--output",
    type=click.Path(path_type=Path),
    required=True,
    help="Pattern to write: .csv, .npz, or .parquet (a dataset directory, for large ones).",
)
@_job_options
@_tile_options
@_user_errors
def generate(
    job_file,
    output,
    seed,
    max_iter,
    method,
    formulation,
    quiet,
    tiles,
    tile_size,
    scheduler,
    workers,
    worker_memory,
):
    """Generate the dot pattern of JOB_FILE and write it to OUTPUT."""
    from ..pipeline import PATTERN_SUFFIXES, generate_to

    if output.suffix.lower() not in PATTERN_SUFFIXES:
        raise click.BadParameter(
            "must end in .csv, .npz or .parquet", param_hint="'-o' / '--output'"
        )
    job = load_job_with(job_file, seed, max_iter, method, formulation)
    bar, progress, tile_progress = _bar(job, quiet)

    def announce(line: str) -> None:
        if not quiet:
            click.echo(line, err=True)

    try:
        done = generate_to(
            job,
            output,
            tiles=tiles,
            tile_size=tile_size,
            scheduler=scheduler,
            workers=workers,
            worker_memory=None if worker_memory is None else int(worker_memory * 2**30),
            progress=progress,
            tile_progress=tile_progress,
            stage=bar.stage,
            announce=announce,
        )
    finally:
        bar.close()
    if not quiet:
        how = " in tiles" if done.tiles else f", {done.iterations} iterations"
        click.echo(f"{output}: {done.n:,} dots{how}, {done.seconds:.1f} s", err=True)


def _inputs(source: Path, job_path) -> tuple:
    """(job or None, every input file): the job is ``source`` when it is a .toml file."""
    from ..config.schema import load_job

    if job_path is None and source.suffix.lower() == ".toml":
        job_path = source
    job = load_job(job_path) if job_path else None
    return job, (source, *(job.inputs if job else ()))


def _read_with_job(path: Path, job, opts=None):
    """The pattern read from ``path``, on the job's panel when there is a job."""
    from ..exporters.readback import read_any
    from ..pipeline import with_job_panel

    return with_job_panel(read_any(path, opts, box=job.box if job else None), job)


@main.command()
@click.argument("source", type=click.Path(path_type=Path))
@click.option("--gds", type=click.Path(path_type=Path), help="GDSII mask to write.")
@click.option("--oas", type=click.Path(path_type=Path), help="OASIS mask to write.")
@click.option("--dxf", type=click.Path(path_type=Path), help="DXF drawing to write.")
@click.option("--csv", type=click.Path(path_type=Path), help="CSV pattern to write.")
@click.option("--svg", type=click.Path(path_type=Path), help="SVG preview to write.")
@click.option("--png", type=click.Path(path_type=Path), help="PNG preview to write.")
@click.option(
    "--speos",
    type=click.Path(path_type=Path),
    help="Ansys Speos 3D-texture mapping to write (.OPT3DMapping: position and scale per dot).",
)
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
@_layer_options
@click.option("--top-cell", default="TOP", show_default=True, help="Name of the top cell.")
@click.option(
    "--dxf-version", default="R2010", show_default=True, help="DXF release: R2010, R2000, R12, ..."
)
@click.option("--force", is_flag=True, help="Write masks even if the QA gate fails.")
@click.option(
    "--html", "html_path", type=click.Path(path_type=Path), help="QA report (HTML) to write."
)
@click.option(
    "--json", "json_path", type=click.Path(path_type=Path), help="QA report (JSON) to write."
)
@_job_options
@_user_errors
def export(
    source,
    gds,
    oas,
    dxf,
    csv,
    svg,
    png,
    speos,
    speos_reference_diameter,
    job_path,
    tolerance,
    flatten,
    layer,
    datatype,
    outline_layer,
    top_cell,
    dxf_version,
    force,
    html_path,
    json_path,
    seed,
    max_iter,
    method,
    formulation,
    quiet,
):
    """Write masks and previews of SOURCE (a job file, or a pattern .csv/.npz/.parquet).

    Existing output files are replaced (atomically: a failed run leaves them as they were).
    Masks are written only if the QA gate passes, unless --force; the verdict is printed,
    and --html/--json keep the gate's report (written also when the gate fails).
    """
    from ..exporters.options import ExportOptions
    from ..pipeline import export as export_pattern

    outputs = {
        k: v
        for k, v in (
            ("gds", gds),
            ("oas", oas),
            ("dxf", dxf),
            ("csv", csv),
            ("svg", svg),
            ("png", png),
            ("speos", speos),
        )
        if v is not None
    }
    if not outputs:
        raise click.UsageError("give at least one of --gds --oas --dxf --csv --svg --png --speos")
    opts = ExportOptions(
        tolerance_um=tolerance,
        flatten=flatten,
        layer=layer,
        datatype=datatype,
        outline_layer=outline_layer,
        top_cell=top_cell,
        dxf_version=dxf_version,
        speos_reference_mm=speos_reference_diameter,
    )
    if source.suffix.lower() == ".toml":
        job = load_job_with(source, seed, max_iter, method, formulation)
        inputs = (source, *job.inputs)
    else:
        job, inputs = _inputs(source, job_path)
    reports = {k: v for k, v in (("html", html_path), ("json", json_path)) if v is not None}
    check_outputs({**outputs, **reports}, inputs)
    stream = pattern = None
    if source.suffix.lower() == ".toml":
        pattern = run_job(job, quiet)
    elif source.suffix.lower() == ".parquet":
        from ..io.dataset import open_dataset

        stream = open_dataset(source)  # gate and masks tile by tile
    else:
        pattern = _read_with_job(source, job)
    lines: list[str] = []
    from .progress import ProgressBar

    bar = ProgressBar(1, label="optdot", enabled=False if quiet else None)
    try:
        result = export_pattern(
            pattern,
            outputs,
            job,
            opts,
            force=force,
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


@main.command()
@click.argument("pattern_file", type=click.Path(path_type=Path))
@click.option(
    "--job",
    "job_path",
    type=click.Path(path_type=Path),
    help="Job file: target map and thresholds.",
)
@click.option("--html", "html_path", type=click.Path(path_type=Path), help="HTML report to write.")
@click.option("--json", "json_path", type=click.Path(path_type=Path), help="JSON report to write.")
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
@click.option("--max-jnd", type=POSITIVE, help="Gate: largest allowed |JND| (default: not gated).")
@_layer_options
@click.option("--quiet", "-q", is_flag=True, help="Only the exit code.")
@_user_errors
def qa(
    pattern_file,
    job_path,
    html_path,
    json_path,
    collision,
    close,
    close_gap,
    view,
    distance,
    luminance,
    psf,
    max_jnd,
    layer,
    datatype,
    outline_layer,
    quiet,
):
    """Check PATTERN_FILE (csv, npz, gds, oas, dxf) before tooling: exit 0 pass, 1 fail."""
    from ..io.atomic import transaction
    from ..pipeline import qa as run_gate
    from ..quality.report import write_reports

    if close_gap is not None and not 0 <= close_gap < 10:
        raise click.BadParameter("must be an edge gap in mm, 0 <= x < 10", param_hint="--close-gap")
    from ..exporters.options import ExportOptions

    opts = ExportOptions(layer=layer, datatype=datatype, outline_layer=outline_layer)
    outs = {k: v for k, v in (("html", html_path), ("json", json_path)) if v is not None}
    looks = {
        k: v
        for k, v in (
            ("view", view),
            ("view_distance", distance),
            ("view_luminance", luminance),
            ("psf", psf),
            ("max_jnd", max_jnd),
        )
        if v is not None
    }
    job, inputs = _inputs(pattern_file, job_path)
    check_outputs(outs, inputs)
    if pattern_file.suffix.lower() == ".parquet":
        from ..io.dataset import open_dataset

        # a dataset is measured tile by tile with halos, in bounded memory
        dataset = open_dataset(pattern_file)
        result = run_gate(
            None, job, collision, close, dataset=dataset, close_gap=close_gap, view=looks
        )
    else:
        pattern = _read_with_job(pattern_file, job, opts)
        result = run_gate(pattern, job, collision, close, close_gap=close_gap, view=looks)
    with transaction():  # both reports replaced together, or neither
        write_reports(result, outs, title=f"optdot QA: {pattern_file.name}")
    if not quiet:
        _print_checks(result)
    sys.exit(0 if result.passed else 1)


def _print_checks(result, echo=click.echo) -> None:
    """The gate as a user reads it: one line per check (PASS, FAIL, or WARN for an
    advisory one over its level), the checks skipped, the visibility summary, and the
    verdict (PASS, PASS WITH WARNINGS or FAIL) last."""
    from ..quality.gate import number_text as _num

    for c in result.checks:
        mark = "PASS" if c.passed else ("WARN" if c.advisory else "FAIL")
        where = f"  at {c.where[:3]}" if (c.where and not c.passed) else ""
        echo(f"{mark}  {c.name}: {_num(c.value)} (limit {_num(c.limit)}){where}")
    for s in result.skipped:
        echo(f"SKIP  {s}")
    vis = result.metrics.get("visibility")
    if vis:
        x, y = vis["max_jnd_at_mm"]
        echo(
            f"visibility ({vis['view']}, {vis['distance_mm']:g} mm, "
            f"{vis['luminance_cd_m2']:g} cd/m², PSF sigma {vis['psf_sigma_mm']:g} mm): "
            f"largest |JND| {vis['max_jnd']:.2f} at ({x:.2f}, {y:.2f}) mm, "
            f"{vis['blobs_over_1_jnd']} blobs over 1 JND"
        )
    echo(f"verdict: {result.verdict}")


if __name__ == "__main__":  # pragma: no cover
    main()
