"""Options shared by the commands (job overrides, layers, tiles), the number types they
parse with, the records a command's options reach it as, and the progress bar a run
draws."""

from __future__ import annotations

import dataclasses
import functools
import math
from pathlib import Path

import click


def record(cls: type, name: str):
    """Decorate a command so that its options named as the fields of the frozen
    dataclass ``cls`` reach it as one argument ``name``, a ``cls``: a command takes a
    few records, not a parameter per option."""
    fields = [f.name for f in dataclasses.fields(cls)]

    def wrap(fn):
        @functools.wraps(fn)
        def command(*args, **kwargs):
            kwargs[name] = cls(**{k: kwargs.pop(k) for k in fields})
            return fn(*args, **kwargs)

        return command

    return wrap


@dataclasses.dataclass(frozen=True)
class RunOptions:
    """How a job runs: ``--seed``, ``--max-iter``, ``--method``, ``--formulation``
    overriding its ``[optimize]`` (None: the job's), and ``--quiet`` (no progress bar)."""

    seed: int | None = None
    max_iter: int | None = None
    method: str | None = None
    formulation: str | None = None
    quiet: bool = False


@dataclasses.dataclass(frozen=True)
class Tiling:
    """``--tiles`` (auto, on, off), ``--tile-size`` (mm), ``--scheduler`` (a Dask
    address), ``--workers`` and ``--worker-memory`` (GiB per local worker)."""

    tiles: str = "auto"
    tile_size: float | None = None
    scheduler: str | None = None
    workers: int | None = None
    worker_memory: float | None = None


@dataclasses.dataclass(frozen=True)
class Layers:
    """Where dots and outline are in a GDSII/OASIS file: ``--layer``, ``--datatype``,
    ``--outline-layer``."""

    layer: int = 1
    datatype: int = 0
    outline_layer: int = 2


@dataclasses.dataclass(frozen=True)
class Reports:
    """The QA report files to write: ``--html``, ``--json`` (None: not written)."""

    html_path: Path | None = None
    json_path: Path | None = None

    def paths(self) -> dict[str, Path]:
        """``{"html": path, "json": path}`` of those given."""
        pairs = (("html", self.html_path), ("json", self.json_path))
        return {k: v for k, v in pairs if v is not None}


@dataclasses.dataclass(frozen=True)
class JobChoice:
    """``--job`` (the job the pattern is judged against, or None) and ``--no-job``
    (judge without one, knowingly)."""

    job_path: Path | None = None
    no_job: bool = False


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
            if number is None:
                self.fail(f"{value[:40]!r} is not a whole number (2000000, 2e6 or 2_000_000)",
                          param, ctx)  # fmt: skip
            if "e" in text.lower():
                if not (number.is_integer() and abs(number) < 2**63):
                    self.fail(f"{value[:40]!r} is not a whole number in range", param, ctx)
                value = int(number)
        return super().convert(value, param, ctx)


#: A number > 0 (mm, cd/m², JND...); a GDS/OAS layer or datatype number.
POSITIVE = Finite(0.0, None, min_open=True)
LAYER = click.IntRange(0, 65535)


def job_options(fn):
    """``--seed``, ``--max-iter``, ``--method``, ``--formulation``, ``--quiet``: reach the
    command as ``run``, a :class:`RunOptions`."""
    fn = record(RunOptions, "run")(fn)
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


def load_job_with(job_path: Path, run: RunOptions):
    """The job with the command line's optimizer overrides."""
    from ..config.schema import load_job

    return load_job(job_path).with_overrides(
        seed=run.seed, max_iter=run.max_iter, method=run.method, formulation=run.formulation
    )


def layer_options(fn):
    """``--layer``, ``--datatype``, ``--outline-layer``: where dots and outline are in a
    GDSII/OASIS file (written by ``export``, read by ``qa``); they reach the command as
    ``layers``, a :class:`Layers`."""
    fn = record(Layers, "layers")(fn)
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
    from ..orchestration.pipeline import generate

    bar, progress, _ = progress_bar(job, quiet)
    try:
        pattern = generate(job, progress=progress, stage=bar.stage)
    finally:
        bar.close()
    return pattern


def tile_options(fn):
    """``--tiles``, ``--tile-size``, ``--scheduler``, ``--workers``, ``--worker-memory``:
    tiled runs on Dask; they reach the command as ``tiling``, a :class:`Tiling`."""
    fn = record(Tiling, "tiling")(fn)
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
