"""The pipeline: a :class:`~optdot.config.job.Job` becomes a :class:`~optdot.pattern.Pattern`,
which is checked and written.

* :func:`generate`: initial dots (§2.1) → circles and containers (§3.3, §3) → relaxation
  (OptDot, or the MD baseline of §2.2 on the same initial dots) → guarantee pass →
  Pattern.
* :func:`qa`: the QA gate of a pattern against the job's map and thresholds.
* :func:`export`: the gate, then the masks and files; nothing is written when the gate
  fails (unless ``force``).

This is the only module that sees every stage; it never prints (progress goes to a
callback) and the command line only parses options and prints what it returns.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from .. import stages
from ..config.job import Job, QAParams
from ..errors import ExportError, JobError, QAGateError
from ..formats import FORMATS
from ..geometry.caps import no_caps
from ..geometry.domain import Domain
from ..geometry.morton import spatial_order
from ..io.atomic import transaction
from ..io.dataset import is_dataset
from ..io.outputs import check_outputs
from ..io.patterns import save_pattern
from ..pattern import DotSource, Pattern, caps_of
from ..quality.conformance import TOLERANCE, DotRule, SizeBand
from ..relax.formulation import Formulation
from ..relax.optdot import Progress
from ..runtime.kernels import warm
from ..runtime.memory import check_memory
from .job_settings import stage_settings
from .preflight import (
    MAX_RANDOM_FILL,
    TILE_BREAK_EVEN,
    JobCheck,
    _check_room,
    check_job,
    use_tiles,
)
from .tiled import Announce, generate_tiled
from .tiling.run import TileProgress

if TYPE_CHECKING:  # QA (scipy.spatial among it) is loaded by the commands that judge
    from ..quality.gate import QAResult

__all__ = [
    "MAX_RANDOM_FILL",
    "TILE_BREAK_EVEN",
    "Generated",
    "JobCheck",
    "check_job",
    "dataset_pattern",
    "export",
    "generate",
    "generate_tiled",
    "generate_to",
    "qa",
    "use_tiles",
    "with_job_panel",
]


def generate(
    job: Job,
    progress: Progress | None = None,
    keep_stages: bool = False,
    formulation: Formulation | None = None,
    stage: Callable[[str], None] | None = None,
) -> Pattern:
    """Generate the dot pattern of ``job``.

    Args:
        job: a validated job.
        progress: optional ``progress(iteration, value)`` callback (penalty for OptDot,
            largest force for MD).
        keep_stages: also put ``initial_xy`` and ``relaxed_xy`` (``[n, 2]``, generation
            order, before the guarantee pass) in ``pattern.stats``, for comparisons.
        formulation: overrides the job's (benchmarks try variants this way).
        stage: told the name of each stage as it starts (``"throwing darts"``,
            ``"relaxing"``, ``"guarantee pass"``), for the user's display.

    Returns:
        The pattern, dots in generation order, positions rounded to 1 nm.

    Raises:
        ResourceError: the job would not fit in memory.
        GuaranteeError: the spacing/placement guarantee could not be met.
    """
    where = str(job.source) if job.source else job.name
    opt = job.optimize
    n = job.n_dots
    _check_room(job, n, where)
    check_memory(n, opt.lbfgs_memory, where)
    t0 = time.perf_counter()
    timings: dict[str, float] = {}
    stage = stage or (lambda name: None)
    if opt.method != "md":
        groups = "generate" if job.shape.kind.round else ("generate", "shapes")
        warm(groups, announce=stage)  # a first run: its kernels on all cores

    stage("throwing darts")
    settings = stage_settings(job, formulation)  # the values every stage takes
    xy_init = stages.throw(settings, n, opt.seed, None, where)
    order = spatial_order(xy_init)
    xy0 = np.ascontiguousarray(xy_init[order])
    timings["initial_s"] = time.perf_counter() - t0

    t1 = time.perf_counter()
    stage("relaxing")
    relaxed = stages.relax(settings, xy0, progress=progress)
    info, history = relaxed.run_info(), relaxed.history
    timings["relax_s"] = time.perf_counter() - t1

    t2 = time.perf_counter()
    stage("guarantee pass")
    done = stages.finish(settings, relaxed.xy, xy0, where)
    leg = done.legalize
    timings["legalize_s"] = time.perf_counter() - t2

    xy = np.empty_like(done.xy)
    xy[order] = done.xy
    diameter = done.diameter
    if np.ndim(diameter):
        diameter = np.empty_like(done.diameter)
        diameter[order] = done.diameter
    timings["total_s"] = time.perf_counter() - t0
    meta = {
        "job": job.name,
        "method": opt.method,
        "formulation": opt.formulation,
        "seed": opt.seed,
        "max_iter": opt.max_iter,
        "n": int(n),
        **info,
        "legalize_sweeps": int(leg.sweeps),
        "legalize_pair_fixes": int(leg.pair_fixes),
        "legalize_dot_fixes": int(leg.dot_fixes),
    }
    if job.sizes is not None:
        meta["diameter_rule"] = job.sizes.rule
    if job.interpolation != "nearest":
        meta["interpolation"] = job.interpolation
    stats: dict = {**timings, "history": history}
    if keep_stages:
        stats["initial_xy"] = xy_init
        stats["relaxed_xy"] = np.empty_like(relaxed.xy)
        stats["relaxed_xy"][order] = relaxed.xy
    outline = None if job.domain.rectangle else job.domain
    dots = None
    if done.dots is not None:
        dots = done.dots.take(np.argsort(order))  # back to generation order, as xy
        meta["shape"] = job.shape.kind.name
        meta["orientation"] = job.orientation.mode
    return Pattern(
        xy=xy, diameter=diameter, box=job.box, meta=meta, stats=stats, outline=outline, dots=dots
    )


#: Pattern files :func:`generate_to` writes, by suffix.
PATTERN_SUFFIXES = (".csv", ".npz", ".parquet")


@dataclass(frozen=True)
class Generated:
    """What :func:`generate_to` wrote.

    Attributes:
        path: the pattern file or dataset.
        n: dots written.
        seconds: wall time of the generation, s.
        iterations: iterations of a single-process run (None for tiles).
        tiles: ``"nx x ny"`` of a tiled run, or None.
    """

    path: Path
    n: int
    seconds: float
    iterations: int | None = None
    tiles: str | None = None


def generate_to(
    job: Job,
    output: str | Path,
    *,
    tiles: str = "auto",
    tile_size: float | None = None,
    scheduler: str | None = None,
    workers: int | None = None,
    worker_memory: int | None = None,
    progress: Progress | None = None,
    tile_progress: TileProgress | None = None,
    stage: Callable[[str], None] | None = None,
    announce: Announce | None = None,
) -> Generated:
    """Generate ``job`` and write it to ``output`` (``.csv``, ``.npz``, or a ``.parquet``
    dataset), in one process or in tiles (:func:`use_tiles` with ``tiles``; the other
    arguments as in :func:`generate` and :func:`generate_tiled`).

    The output is checked before any work (a writable name, not one of the job's own
    files) and written atomically: a failed or interrupted run leaves what was there.

    Raises:
        ExportError: the output cannot be written or is an input of the job.
        JobError, GeometryError, ResourceError, GuaranteeError, ClusterError: as the run.
    """
    output = Path(output)
    if output.suffix.lower() not in PATTERN_SUFFIXES:
        raise ExportError(
            f"{output}: pattern files end in .csv, .npz or .parquet, "
            f"not {output.suffix or 'no suffix'!r}"
        )
    check_outputs({"output": output}, tuple(job.inputs))
    t0 = time.perf_counter()
    if not use_tiles(job, tiles):
        pattern = generate(job, progress=progress, stage=stage)
        save_pattern(pattern, output)
        secs = pattern.stats["total_s"]
        return Generated(output, pattern.n, secs, iterations=pattern.meta["iterations"])
    result = generate_tiled(
        job,
        output if is_dataset(output) else None,
        tile_size=tile_size,
        scheduler=scheduler,
        workers=workers,
        worker_memory=worker_memory,
        announce=announce,
        progress=tile_progress,
    )
    if isinstance(result, Pattern):
        save_pattern(result, output)
        n, plan = result.n, result.meta["tiles"]
    else:
        n, plan = int(result.plan.quotas.sum()), f"{result.plan.nx}x{result.plan.ny}"
    return Generated(output, n, time.perf_counter() - t0, tiles=plan)


def with_job_panel(pattern: Pattern, job: Job | None) -> Pattern:
    """The pattern with the job's panel box and outline (the job is the authority), and
    its own caps over LEDs (what the file prints: QA holds them to the job's)."""
    if job is None:
        return pattern
    outline = None if job.domain.rectangle else job.domain
    own = caps_of(pattern)
    printed = own if len(own) else None
    rings = pattern.outline.cap_rings if printed is not None else None
    if outline is not None:
        outline = replace(outline, caps=printed, cap_rings=rings)
    elif printed is not None:
        outline = replace(Domain.rect(*job.box), caps=printed, cap_rings=rings)
    return replace(pattern, box=job.box, outline=outline)


def dot_rule(job: Job) -> DotRule:
    """The footprints ``job`` draws, as QA holds a file's dots to them; with sizes, the
    band of diameters each place may have (:func:`size_band`)."""
    shape = job.shape
    grid = job.process.grid if job.process is not None else 0.0
    return DotRule(shape, job.sizes, size_band(job), TOLERANCE + GRID_SIZE_SLACK * grid)


#: How far a footprint's size read off a mask on a process's grid may be off, in grid
#: steps: each vertex moved by up to half a step's diagonal, an extent by up to √2 steps,
#: a corner's radius (fitted over the few vertices of a short arc) by up to about 3.
GRID_SIZE_SLACK = 3.0


#: How far a dot may have moved from the cell whose rule diameter it was given, mm (at
#: least a map cell): relaxation moves dots a fraction of a spacing.
SIZE_REACH_MM = 0.5


def size_band(job: Job) -> SizeBand | None:
    """The diameters the size rule gives each map cell's dots, as a band: the smallest
    and largest rule diameter within :data:`SIZE_REACH_MM` (a dot is sized where it was
    thrown, then moves), widened by the size fit's freedom
    (:data:`optdot.relax.resize.FREEDOM`) and kept in the range; None for one size."""
    from scipy.ndimage import maximum_filter, minimum_filter

    from ..relax.resize import FREEDOM

    sizes = job.sizes
    if sizes is None:
        return None
    cells = np.asarray(job.cell_diameters, np.float64)
    dx, dy = job.density.cell_size
    kx, ky = (max(1, math.ceil(SIZE_REACH_MM / c)) for c in (dx, dy))
    size = (2 * ky + 1, 2 * kx + 1)
    low = np.maximum(minimum_filter(cells, size, mode="nearest") / (1 + FREEDOM), sizes.low)
    high = np.minimum(maximum_filter(cells, size, mode="nearest") * (1 + FREEDOM), sizes.high)
    d = job.density
    return SizeBand(low, high, (d.x0, d.y0, d.x0 + d.width, d.y0 + d.height))


def own_collision(dots: DotSource, job: Job | None) -> float:
    """The centre distance under which dots of one size collide, mm: the job's
    ``qa.collision_distance`` when it sets one, else the file's own diameter plus the
    job's gap (never the job's diameter: a file of larger dots than the job's would pass
    with overlaps; the footprint check fails it besides)."""
    if job is not None and job.qa.collision_distance is not None:
        return job.qa.collision_distance
    own = dots.uniform_diameter
    own = dots.nominal_diameter if own is None else own
    return own + (job.judged_gap if job is not None else 0.0)


def qa(
    pattern: DotSource | None,
    job: Job | None = None,
    collision: float | None = None,
    close: float | None = None,
    dataset: DotSource | None = None,
    close_gap: float | None = None,
    view: dict[str, Any] | None = None,
) -> QAResult:
    """Measure ``pattern`` and judge it (see :func:`optdot.quality.gate.run_qa`).

    Args:
        pattern: the dots: a :class:`Pattern`, or an opened
            :class:`~optdot.io.dataset.Dataset` (measured tile by tile in bounded memory);
            None to measure ``dataset`` (the older spelling).
        job: the target map and thresholds (None: defaults, no map checks); its panel
            box and outline are the panel's.
        collision: collision distance, mm (default: the job's ``qa.collision_distance``
            when set, else the dots' own diameter + the job's gap: :func:`own_collision`).
        close: too-close distance, mm (default: the job's ``qa.close_distance``).
            ``collision`` and ``close`` are centre distances for dots of one size; dots of
            varying size are judged by edge gaps: ``close_gap`` (default the job's
            ``qa.close_gap``, else 14 µm) and the job's ``optimize.gap``.
        view: overrides of the visibility check, keys of :class:`QAParams`
            (``view``, ``view_distance``, ``view_luminance``, ``psf``, ``max_jnd``).
    """
    from ..quality.gate import caps_check, run_qa

    dots = pattern if pattern is not None else dataset
    if dots is None:
        raise ValueError("qa needs the dots")
    params = job.qa if job else QAParams()
    if view:
        params = replace(params, **view)
    if dots.uniform_diameter is None and (collision, close) != (None, None):
        raise JobError(
            "--collision/--close are centre distances for dots of one size; these dots vary "
            "in size and are judged by edge gaps (--close-gap, the job's optimize.gap)"
        )
    if close is not None:
        params = replace(params, close_distance=close)
    if close_gap is not None:
        params = replace(params, close_gap=close_gap)
    if collision is None:
        collision = own_collision(dots, job)
    if job is None:
        result = run_qa(dots, None, params, collision)
    else:
        outline = None if job.domain.rectangle else job.domain
        gap = job.judged_gap  # dots of varying size collide below it
        if dots.uniform_diameter is None and job.shape.kind.round and job.sizes is None:
            # a one-size job's centre distances, as edge gaps: a file whose sizes differ
            # (by a nudge the footprint check lets through) is held to the same limits
            gap = job.collision_distance - job.diameter
            if params.close_gap is None:
                params = replace(params, close_gap=max(params.close_distance - job.diameter, 0))
        field = job.orientation if not job.shape.kind.round else None
        result = run_qa(
            dots,
            job.density,
            params,
            collision,
            gap,
            job.box,
            outline,
            job.viewing_area,
            field,
            job.ink,
            dot_rule(job),
        )
    wanted = job.domain.caps if job is not None else None
    if job is not None and (wanted is not None or len(caps_of(dots))):
        own = dots.outline.cap_rings if dots.outline is not None else None
        result.checks.append(
            caps_check(
                caps_of(dots),
                no_caps() if wanted is None else wanted,
                own,
                job.domain.cap_rings,
            )
        )
    if job is not None and job.process is not None:  # the print across the gain's tolerance
        from ..quality.printed import band_check, tolerance_band

        outline = None if job.domain.rectangle else job.domain
        band = tolerance_band(dots, job.process, job.density, outline, params.smoothing)
        result.metrics["tolerance_band"] = band
        if job.process.gain_tolerance > 0:
            result.checks.append(band_check(band, params.max_coverage_rms))
    result.provenance = provenance_of(dots, job)
    return result


def _refuse_kept_masks(dots: DotSource, job: Job | None, outputs, options, hint: str) -> None:
    """Refuse, before the gate runs, to write over a kept mask that cannot be what this
    run writes: a GDSII, or a DXF of a release with custom properties, carries the
    provenance digest of the run that wrote it as plain text, so a kept one without this
    run's digest has other bytes (the transaction would refuse it after the gate; the
    gate of a large pattern takes seconds to minutes). Other masks (OASIS, whose
    properties may be compressed; DXF R12 and R2000, which hold none) are compared after
    writing, as before.

    Raises:
        ExportError: the first such mask, in the transaction's words.
    """
    from ..io.atomic import lacks_text
    from ..quality.provenance import mask_lines

    version = "R2010" if options is None else str(getattr(options, "dxf_version", "R2010"))
    # ezdxf writes custom properties (the provenance) from R2004 on
    dxf_props = version[:1] == "R" and version[1:].isdigit() and int(version[1:]) >= 2004
    plain = [Path(p) for f, p in outputs.items() if f == "gds" or (f == "dxf" and dxf_props)]
    if not any(p.is_file() for p in plain):
        return
    head = mask_lines(provenance_of(dots, job))[0]
    digest = head.rsplit("sha256:", 1)[1] if "sha256:" in head else ""
    if len(digest) != 64:  # the head line cut short: nothing to look for
        return
    for path in plain:
        if path.is_file() and lacks_text(path, digest.encode()):
            raise ExportError(
                f"{path}: a different file is already there and is kept ({hint}); "
                "nothing was written"
            )


def provenance_of(dots: DotSource, job: Job | None) -> dict[str, Any]:
    """What made ``dots`` (:func:`optdot.quality.provenance.provenance`): the job, its
    inputs, the dots' file and the seed (the dots' own, else the job's when they were made
    in this run)."""
    from ..quality.provenance import provenance

    source = dots.label or None
    seed = dots.meta.get("seed")
    if seed is None and job is not None and source is None:
        seed = job.optimize.seed  # made from this job in this run
    if job is None:
        return provenance(None, (), source, seed)
    return provenance(job.source, job.inputs, source, seed)


def export(
    pattern: DotSource | None,
    outputs: Mapping[str, str | Path],
    job: Job | None = None,
    options=None,
    force: bool = False,
    stream=None,
    reports: Mapping[str, str | Path] | None = None,
    overwrite: bool = True,
    written: Callable[[str, Path, str], None] | None = None,
    stage: Callable[[str], None] | None = None,
) -> QAResult:
    """Run the QA gate, then write ``pattern`` in each format of ``outputs``.

    Args:
        pattern: the dots: a :class:`Pattern`, or an opened dataset (then streamed, as
            ``stream``); None when ``stream`` is given (then read from it only if a
            format needs the whole pattern in memory).
        outputs: ``{format: path}``, formats of :data:`optdot.exporters.FORMATS`.
        job: thresholds and map of the gate (None: default thresholds).
        options: :class:`optdot.exporters.ExportOptions` (None: defaults).
        force: write even if the gate fails.
        overwrite: replace an existing mask (:data:`~optdot.formats.MASKS`) by a
            different one; False keeps it (writing the same bytes again is allowed).
        stream: the :class:`~optdot.io.dataset.Dataset` the pattern is read from: the gate
            then measures it tile by tile and the streamed formats
            (:data:`~optdot.formats.STREAMED`) are written from it tile by tile.
        reports: the gate's report, ``{"html": path, "json": path}`` (either or both),
            written with the outputs, also when the gate fails (then alone).
        written: told ``(format, path, what the file holds)`` for each output once all
            were put in place.
        stage: told ``"QA gate"`` and ``"writing"`` as they start.

    Returns:
        The gate's result (check ``passed``: with ``force`` it may have failed).

    Raises:
        QAGateError: the gate failed and ``force`` is off; nothing was written.
        ExportError: an output cannot be written, is given twice, is an input of the
            export (the job's files, the pattern's or dataset's own file), or is a
            different mask kept (``overwrite`` False); none was replaced (one transaction).
    """
    from .. import exporters
    from ..quality.report import write_reports

    if pattern is not None and not isinstance(pattern, Pattern):
        stream, pattern = pattern, None  # a dataset given as the dots: streamed
    if pattern is None and stream is None:
        raise ValueError("export needs a pattern or a dataset")
    reports = dict(reports or {})
    inputs = tuple(job.inputs) if job else ()
    source = stream.path if stream is not None else pattern.meta.get("source")
    inputs += (Path(source),) if source else ()
    check_outputs({**outputs, **reports}, inputs)
    title = f"optdot QA: {Path(source).name if source else 'pattern'}"
    stage = stage or (lambda name: None)
    hint = "give --overwrite to replace it, or another name"
    if not overwrite:  # before the gate: a kept mask this run cannot write again
        _refuse_kept_masks(pattern or stream, job, outputs, options, hint)
    stage("QA gate")
    result = qa(pattern, job, dataset=stream)
    if not result.passed and not force:
        if reports:
            with transaction():
                write_reports(result, reports, title)
        raise QAGateError(result)
    from ..exporters import ExportOptions
    from ..quality.provenance import mask_lines

    options = replace(
        options or ExportOptions(),
        provenance=mask_lines(result.provenance),
        process=job.process if job is not None else None,
        laser=job.laser if job is not None else None,
        fixed_depth=job is not None and job.profile.keeps_height,
    )
    if job is not None and job.sheet is not None:
        options = replace(options, sheet=job.sheet, labels=sheet_labels(job, result.provenance))
    done: list[tuple[str, Path, str]] = []
    stage("writing")
    keep = () if overwrite else [p for f, p in outputs.items() if FORMATS[f].mask]
    with transaction(keep, hint, replace_masks=overwrite):
        for fmt, path in outputs.items():
            if stream is not None and FORMATS[fmt].streamed:
                src = stream
            else:
                if pattern is None:
                    pattern = dataset_pattern(stream, job)
                src = pattern
            done.append((fmt, Path(path), exporters.write(src, fmt, path, options)))
        write_reports(result, reports, title)
    for item in done:
        if written is not None:
            written(*item)
    return result


def sheet_labels(job: Job, prov: dict) -> tuple[str, ...]:
    """Each panel's label on the job's sheet, row by row: the job, optdot, the seed, the
    job file's SHA-256 prefix, the sheet's date, the process, the panel's place."""
    from ..printing.sheet import label_text

    sheet = job.sheet
    sha = (prov.get("job") or {}).get("sha256") or ""
    return tuple(
        label_text(
            job.name, str(prov.get("optdot")), prov.get("seed"), sha, sheet.date, job.process, r, c
        )  # fmt: skip
        for r in range(sheet.rows)
        for c in range(sheet.columns)
    )


def dataset_pattern(ds, job: Job | None) -> Pattern:
    """The whole dataset ``ds`` in memory, on the job's panel when there is a job."""
    from ..io.dataset import load_dataset

    return with_job_panel(load_dataset(ds.path, box=job.box if job else None), job)
