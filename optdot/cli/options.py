"""Options shared by the commands (job overrides, layers, tiles), the number types they
parse with, and the progress bar a run draws."""

from __future__ import annotations

import math
from pathlib import Path

import click


class Finite(click.FloatRange):
    """A float option that is a real number: ``nan`` and ``inf`` are refused (they pass
    every range comparison), like values outside ``[min, max]``."""

    name = "number"

    def convert(self, value, param, ctx):
        v = super().convert(value, param, ctx)
        if not math.isfinite(v):
            self.fail(f"{value!r} is not a finite number", param, ctx)
        return v


class Count(click.IntRange):
    """A whole number that may be written as a Monte Carlo user writes it: ``2000000``,
    ``2e6`` or ``2_000_000`` (a value with a fraction, ``2.5``, is refused)."""

    def convert(self, value, param, ctx):
        if isinstance(value, str):
            text = value.strip().replace("_", "")
            try:
                number = float(text)
            except ValueError:
                number = None
            if number is not None and "e" in text.lower():
                if not (number.is_integer() and abs(number) < 2**63):
                    self.fail(f"{value[:40]!r} is not a whole number in range", param, ctx)
                value = int(number)
        return super().convert(value, param, ctx)


#: A number > 0 (mm, cd/m², JND...); a GDS/OAS layer or datatype number.
POSITIVE = Finite(0.0, None, min_open=True)
LAYER = click.IntRange(0, 65535)


def job_options(fn):
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


def layer_options(fn):
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


def progress_bar(job, quiet: bool):
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

    bar, progress, _ = progress_bar(job, quiet)
    try:
        pattern = generate(job, progress=progress, stage=bar.stage)
    finally:
        bar.close()
    return pattern


def tile_options(fn):
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
