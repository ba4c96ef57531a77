"""Command line: ``optdot generate | export | qa``.

Exit codes (README, "Exit codes"): 0 success; 1 the QA gate failed; 2 bad input (job,
grid, pattern file, option, unwritable output, too big for memory); 3 the optimizer could
not meet the spacing guarantee; 130 interrupted.
"""

from __future__ import annotations

import functools
import signal
import sys
from pathlib import Path

import click

from ..errors import OptdotError, QAGateError


def _user_errors(fn):
    """Turn :class:`OptdotError` into one line on stderr and its exit code."""

    @functools.wraps(fn)
    def wrapper(*args, **kwargs):
        from ..io.atomic import interrupted

        previous = {s: signal.signal(s, _terminate) for s in (signal.SIGTERM, signal.SIGINT)}
        try:
            out = fn(*args, **kwargs)
            if interrupted():  # the interrupt was swallowed inside compiled code
                raise KeyboardInterrupt
            return out
        except QAGateError as e:
            click.echo(f"optdot: {e}", err=True)
            sys.exit(e.exit_code)
        except OptdotError as e:
            click.echo(f"optdot: error: {e}", err=True)
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
    from ..io.atomic import interrupted, mark_interrupted

    if interrupted():
        raise KeyboardInterrupt
    mark_interrupted()


def _caused_by_interrupt(e: BaseException) -> bool:
    from ..io.atomic import interrupted

    seen = set()
    while e is not None and id(e) not in seen:
        if isinstance(e, KeyboardInterrupt):
            return True
        seen.add(id(e))
        e = e.__cause__ or e.__context__
    return interrupted()


@click.group(context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(package_name="optdot")
def main() -> None:
    """Non-overlapping random dot patterns for light guides, their masks, and QA."""


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


def run_job(job_path: Path, seed, max_iter, method, formulation, quiet):
    """Load a job, apply CLI overrides and generate its pattern with a progress bar."""
    from ..config.schema import load_job
    from ..io.atomic import interrupted
    from ..pipeline import generate
    from .progress import ProgressBar

    job = load_job(job_path).with_overrides(
        seed=seed, max_iter=max_iter, method=method, formulation=formulation
    )
    bar = ProgressBar(
        job.optimize.max_iter, label=job.optimize.method, enabled=False if quiet else None
    )

    def progress(iteration: int, value: float) -> None:
        bar(iteration, value)
        if interrupted():  # a signal came: stop here, in plain Python
            raise KeyboardInterrupt

    try:
        pattern = generate(job, progress=progress)
    finally:
        bar.close()
    return job, pattern


@main.command()
@click.argument("job_file", type=click.Path(path_type=Path))
@click.option(
    "-o",
    "--output",
    type=click.Path(path_type=Path),
    required=True,
    help="Pattern file to write (.csv or .npz).",
)
@_job_options
@_user_errors
def generate(job_file, output, seed, max_iter, method, formulation, quiet):
    """Generate the dot pattern of JOB_FILE and write it to OUTPUT."""
    from ..io.patterns import save_pattern

    if output.suffix.lower() not in (".csv", ".npz"):
        raise click.BadParameter("must end in .csv or .npz", param_hint="'-o' / '--output'")
    _, pattern = run_job(job_file, seed, max_iter, method, formulation, quiet)
    save_pattern(pattern, output)
    m = pattern.meta
    if not quiet:
        click.echo(
            f"{output}: {pattern.n} dots, {m['iterations']} iterations, "
            f"{pattern.stats['total_s']:.1f} s",
            err=True,
        )


def _load_source(source: Path, job_path, seed, max_iter, method, formulation, quiet):
    """(job or None, pattern) from a job file (generated now) or a pattern/mask file."""
    if source.suffix.lower() == ".toml":
        return run_job(source, seed, max_iter, method, formulation, quiet)
    return _read_with_job(source, job_path)


def _read_with_job(path: Path, job_path):
    """(job or None, pattern read from ``path`` with the job's panel)."""
    from ..config.schema import load_job
    from ..exporters.readback import read_any
    from ..pipeline import with_job_panel

    job = load_job(job_path) if job_path else None
    return job, with_job_panel(read_any(path, box=job.box if job else None), job)


def _check_outputs(outputs: dict[str, Path]) -> None:
    from ..errors import ExportError

    seen: dict[Path, str] = {}
    for fmt, p in outputs.items():
        rp = p.resolve()
        if rp in seen:
            raise ExportError(f"{p}: given for both --{seen[rp]} and --{fmt}")
        seen[rp] = fmt
        if not p.parent.resolve().is_dir():
            raise ExportError(f"{p}: output directory {p.parent} does not exist")
        if p.exists() and p.is_dir():
            raise ExportError(f"{p}: is a directory")


@main.command()
@click.argument("source", type=click.Path(path_type=Path))
@click.option("--gds", type=click.Path(path_type=Path), help="GDSII mask to write.")
@click.option("--oas", type=click.Path(path_type=Path), help="OASIS mask to write.")
@click.option("--dxf", type=click.Path(path_type=Path), help="DXF drawing to write.")
@click.option("--csv", type=click.Path(path_type=Path), help="CSV pattern to write.")
@click.option("--svg", type=click.Path(path_type=Path), help="SVG preview to write.")
@click.option("--png", type=click.Path(path_type=Path), help="PNG preview to write.")
@click.option(
    "--job",
    "job_path",
    type=click.Path(path_type=Path),
    help="Job file for the QA gate when SOURCE is a pattern.",
)
@click.option(
    "--tolerance",
    type=float,
    default=0.01,
    show_default=True,
    help="Circle polygon tolerance, µm (GDS/OAS).",
)
@click.option("--flatten", is_flag=True, help="Plain polygons instead of a dot cell + references.")
@click.option("--layer", type=int, default=1, show_default=True, help="GDS/OAS layer of the dots.")
@click.option(
    "--datatype", type=int, default=0, show_default=True, help="GDS/OAS datatype of the dots."
)
@click.option(
    "--outline-layer", type=int, default=2, show_default=True, help="GDS/OAS layer of the outline."
)
@click.option("--top-cell", default="TOP", show_default=True, help="Name of the top cell.")
@click.option(
    "--dxf-version", default="R2010", show_default=True, help="DXF release: R2010, R2000, R12, ..."
)
@click.option("--force", is_flag=True, help="Write masks even if the QA gate fails.")
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
    job_path,
    tolerance,
    flatten,
    layer,
    datatype,
    outline_layer,
    top_cell,
    dxf_version,
    force,
    seed,
    max_iter,
    method,
    formulation,
    quiet,
):
    """Write masks and previews of SOURCE (a job file, or a pattern .csv/.npz).

    Existing output files are replaced (atomically: a failed run leaves them as they were).
    Masks are written only if the QA gate passes, unless --force.
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
        )
        if v is not None
    }
    if not outputs:
        raise click.UsageError("give at least one of --gds --oas --dxf --csv --svg --png")
    opts = ExportOptions(
        tolerance_um=tolerance,
        flatten=flatten,
        layer=layer,
        datatype=datatype,
        outline_layer=outline_layer,
        top_cell=top_cell,
        dxf_version=dxf_version,
    )
    _check_outputs(outputs)
    job, pattern = _load_source(source, job_path, seed, max_iter, method, formulation, quiet)
    result = export_pattern(pattern, outputs, job, opts, force=force)
    if not result.passed:
        click.echo(
            f"optdot: warning: QA gate failed ({result.failures()}); writing anyway (--force)",
            err=True,
        )
    if not quiet:
        for fmt, path in outputs.items():
            click.echo(f"{path}: {fmt.upper()}, {pattern.n} dots", err=True)


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
    "--collision", type=float, help="Collision distance, mm (default: dot diameter + gap)."
)
@click.option("--close", type=float, help="Too-close distance, mm (default 0.060).")
@click.option("--quiet", "-q", is_flag=True, help="Only the exit code.")
@_user_errors
def qa(pattern_file, job_path, html_path, json_path, collision, close, quiet):
    """Check PATTERN_FILE (csv, npz, gds, oas, dxf) before tooling: exit 0 pass, 1 fail."""
    from ..io.atomic import transaction
    from ..pipeline import qa as run_gate
    from ..quality.report import write_html, write_json

    for v, name in ((collision, "--collision"), (close, "--close")):
        if v is not None and not v > 0:
            raise click.BadParameter("must be > 0 mm", param_hint=name)
    outs = {k: v for k, v in (("html", html_path), ("json", json_path)) if v is not None}
    _check_outputs(outs)
    job, pattern = _read_with_job(pattern_file, job_path)
    result = run_gate(pattern, job, collision, close)
    with transaction():  # both reports replaced together, or neither
        if json_path:
            write_json(result, json_path)
        if html_path:
            write_html(result, pattern, html_path, title=f"optdot QA: {pattern_file.name}")
    if not quiet:
        for c in result.checks:
            mark = "PASS" if c.passed else "FAIL"
            where = f"  at {c.where[:3]}" if (c.where and not c.passed) else ""
            click.echo(f"{mark}  {c.name}: {_num(c.value)} (limit {_num(c.limit)}){where}")
        click.echo(f"verdict: {'PASS' if result.passed else 'FAIL'}")
    sys.exit(0 if result.passed else 1)


def _num(v) -> str:
    return f"{v:.4g}" if isinstance(v, float) else str(v)


if __name__ == "__main__":  # pragma: no cover
    main()
