"""``optdot check`` and ``optdot generate``: what a job would cost, and its pattern."""

from __future__ import annotations

from pathlib import Path

import click
import numpy as np

from .app import main, user_errors
from .records import (
    job_options,
    load_job_with,
    progress_bar,
    tile_options,
)


@main.command()
@click.argument("job_file", type=click.Path(path_type=Path))
@job_options
@tile_options
@user_errors
def check(job_file, run, tiling):
    """Check JOB_FILE without running it: is it valid, how many dots, one process or
    tiles, and about how long, how much memory and disk it will take (exit 0: it would
    run; otherwise the one-line reason the run itself would give)."""
    from ..orchestration.pipeline import check_job

    job = load_job_with(job_file, run)
    got = check_job(job, tiling.tiles, tiling.tile_size, tiling.workers)
    if run.quiet:
        return
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
    relief = "" if job.profile.kind == "ink" else f", {job.profile.words()}"
    click.echo(
        f"dots: {got.n_dots:,} of {_diameter_text(job)}{relief} ({opt.method}, seed "
        f"{opt.seed}, {opt.max_iter} iterations)"
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


for _param in check.params:  # the shared --quiet speaks of a progress bar check has not
    if _param.name == "quiet":
        _param.help = "Print nothing: the exit code (0: it would run) and errors only."


def _diameter_text(job) -> str:
    if not job.shape.kind.round:
        sizes = " × ".join(f"{v * 1e3:.4g}" for v in job.shape.size[:2])
        scaled = ""
        if job.sizes is not None:
            lo, hi = job.shape_scale(np.array([job.sizes.low, job.sizes.high]))
            scaled = f" scaled {lo:.4g}..{hi:.4g}x by the {job.sizes.rule} rule"
        turn = job.orientation.mode
        return f"{sizes} µm {job.shape.kind.name}s{scaled}, turned by [orientation] {turn}"
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
@job_options
@tile_options
@user_errors
def generate(job_file, output, run, tiling):
    """Generate the dot pattern of JOB_FILE and write it to OUTPUT."""
    from ..orchestration.pipeline import PATTERN_SUFFIXES, generate_to

    if output.suffix.lower() not in PATTERN_SUFFIXES:
        raise click.BadParameter(
            "must end in .csv, .npz or .parquet", param_hint="'-o' / '--output'"
        )
    job = load_job_with(job_file, run)
    quiet = run.quiet
    bar, progress, tile_progress = progress_bar(job, quiet)

    def announce(line: str) -> None:
        if not quiet:
            click.echo(line, err=True)

    memory = tiling.worker_memory
    try:
        done = generate_to(
            job,
            output,
            tiles=tiling.tiles,
            tile_size=tiling.tile_size,
            scheduler=tiling.scheduler,
            workers=tiling.workers,
            worker_memory=None if memory is None else int(memory * 2**30),
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
