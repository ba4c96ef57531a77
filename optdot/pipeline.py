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

import contextlib
import time
from collections.abc import Callable, Iterator, Mapping
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from . import stages
from .config.job import Job, QAParams
from .errors import JobError, QAGateError, ResourceError
from .geometry.morton import spatial_order
from .io.atomic import transaction
from .io.dataset import manifest_of, write_dataset
from .io.outputs import check_outputs
from .pattern import Pattern
from .quality.gate import QAResult, run_qa, run_qa_dataset
from .quality.provenance import mask_lines, provenance
from .relax.formulation import Formulation
from .relax.optdot import Progress
from .runtime.cluster import connect, embedded_workers, scheduler_address
from .runtime.cost import Cost, estimate_cost
from .runtime.memory import BASE_BYTES, available_bytes, check_memory, estimate_bytes
from .runtime.stop import check_interrupt
from .tiling.plan import TilePlan, plan_tiles
from .tiling.run import InProcess, OnDask, TiledRun, TileProgress, run_tiles, warm_up

#: Densest fill a random non-overlapping pattern reaches in practice, counting the gap
#: (fill x ((diameter + gap) / diameter)²): OptDot's guarantee holds at 0.78 and fails at
#: 0.80 on uniform maps (measured, 3 x 2 mm, 46 µm); random close packing of disks is
#: ~0.82 (Berryman 1983), the hexagonal lattice 0.9069. Denser means a lattice: moiré.
MAX_RANDOM_FILL = 0.80


def _check_fill(job: Job, where: str) -> None:
    """Refuse, before any work, a map whose densest cell cannot hold a random pattern at
    the job's spacing (a gap of 5 mm between 46 µm dots allows a fill of 0.0001)."""
    grid = job.density.grid
    k = int(np.argmax(grid))
    iy, ix = divmod(k, grid.shape[1])
    spread = (job.min_distance / job.diameter) ** 2
    eff = float(grid[iy, ix]) * spread
    if eff >= MAX_RANDOM_FILL:
        raise JobError(
            f"{where}: fill {float(grid[iy, ix]):.4g} at row {iy}, column {ix} with centres "
            f"{job.min_distance * 1e3:.4g} µm apart for {job.diameter * 1e3:.4g} µm dots "
            f"is an effective fill of {eff:.4g}; a random non-overlapping pattern reaches "
            f"at most {MAX_RANDOM_FILL:g} (the fill can be at most "
            f"{MAX_RANDOM_FILL / spread:.4g} here)"
        )


def _check_room(job: Job, n: int, where: str) -> None:
    """Refuse, before any work, a job whose dots cannot be placed at all."""
    if n == 0:
        raise JobError(
            f"{where}: the map asks for 0 dots (mean fill fraction x panel area is under half "
            f"a dot of {job.diameter:g} mm)"
        )
    if job.sizes is None:
        _check_fill(job, where)
    if job.domain.rectangle and job.domain.edge_margin == 0:
        return  # fill fractions below the packing limit always fit
    room = job.domain.max_dots(0.5 * job.diameter, job.min_distance)
    if n > room:
        margin = job.domain.edge_margin
        what = f"domain.edge_margin = {margin:g} mm leaves" if margin > 0 else "the panel has"
        raise JobError(
            f"{where}: {what} room for at most {room:,} dots {job.diameter * 1e3:.4g} µm "
            f"across (centres {job.min_distance * 1e3:.4g} µm apart), the map asks for {n:,}"
        )


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

    stage("throwing darts")
    xy_init = stages.throw(job, n, opt.seed, None, where)
    order = spatial_order(xy_init)
    xy0 = np.ascontiguousarray(xy_init[order])
    timings["initial_s"] = time.perf_counter() - t0

    t1 = time.perf_counter()
    stage("relaxing")
    relaxed = stages.relax(job, xy0, progress=progress, formulation=formulation)
    info, history = relaxed.info, relaxed.history
    timings["relax_s"] = time.perf_counter() - t1

    t2 = time.perf_counter()
    stage("guarantee pass")
    done = stages.finish(job, relaxed.xy, xy0, where)
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
    return Pattern(xy=xy, diameter=diameter, box=job.box, meta=meta, stats=stats, outline=outline)


#: ``tiles="auto"`` tiles a job of at least this many dots even when one process would
#: hold it: above it the tiled run on this 2-core machine is faster (BENCHMARKS.md,
#: ``benchmarks/panels.py --break-even``).
TILE_BREAK_EVEN = 2_000_000
#: ``announce(line)``: what a tiled run tells the user before it starts (cluster, tiles).
Announce = Callable[[str], None]


def use_tiles(job: Job, mode: str = "auto") -> bool:
    """Whether ``job`` runs tiled: ``on``, ``off``, or ``auto`` (when one process would
    not fit, or from :data:`TILE_BREAK_EVEN` dots; the MD baseline never tiles)."""
    if mode == "on":
        if job.optimize.method != "optdot":
            raise JobError(f"{job.name}: tiles need optimize.method = 'optdot' (MD is a baseline)")
        return True
    if mode == "off" or job.optimize.method != "optdot":
        return False
    n = job.n_dots
    return n >= TILE_BREAK_EVEN or estimate_bytes(n, job.optimize.lbfgs_memory) > 0.9 * (
        available_bytes()
    )


@dataclass(frozen=True)
class JobCheck:
    """What :func:`check_job` found: the job would run, and what it would cost.

    Attributes:
        n_dots: dots the map asks for. plan: the tiling, or None for one process.
        workers: processes the tiles would run on (1 for one process).
        cost: the estimate (:class:`optdot.runtime.cost.Cost`).
        available_bytes: memory available now, bytes.
    """

    n_dots: int
    plan: TilePlan | None
    workers: int
    cost: Cost
    available_bytes: int


def check_job(
    job: Job,
    tiles: str = "auto",
    tile_size: float | None = None,
    workers: int | None = None,
    formats: tuple[str, ...] = ("parquet", "gds", "oas", "dxf"),
) -> JobCheck:
    """Every check :func:`generate` and :func:`generate_tiled` make before they start
    (room, fill, memory, tile size, workers), without running anything, and the cost.

    Raises:
        JobError, GeometryError, ResourceError: what the run itself would refuse.
    """
    where = str(job.source) if job.source else job.name
    n = job.n_dots
    _check_room(job, n, where)
    opt = job.optimize
    if not use_tiles(job, tiles):
        check_memory(n, opt.lbfgs_memory, where)
        cost = estimate_cost(n, opt.max_iter, opt.lbfgs_memory, formats=formats)
        return JobCheck(n, None, 1, cost, available_bytes())
    plan = plan_tiles(job, tile_size)
    k, per_worker = embedded_workers(workers, None)
    k = min(k, plan.count)
    _check_tile_memory(job, plan, per_worker)
    biggest = int(plan.quotas.max())
    cost = estimate_cost(n, opt.max_iter, opt.lbfgs_memory, biggest, k, formats)
    return JobCheck(n, plan, k, cost, available_bytes())


def _tiled_meta(job: Job, plan: TilePlan) -> dict:
    opt = job.optimize
    return {
        "job": job.name,
        "method": opt.method,
        "formulation": opt.formulation,
        "seed": opt.seed,
        "max_iter": opt.max_iter,
        "n": int(plan.quotas.sum()),
        "tiles": f"{plan.nx}x{plan.ny}",
        "tiling": {"xs": [float(v) for v in plan.xs], "ys": [float(v) for v in plan.ys]},
    }


#: Bytes per dot of a tiled run gathered into one pattern in the command's process
#: (positions, the order of tiles, the pattern, what the writer formats).
GATHERED_BYTES_PER_DOT = 64
#: Bytes per dot of a dataset on disk (three float64 columns, zstd), an upper bound.
DATASET_BYTES_PER_DOT = 26


def _check_gathered(job: Job, output: str | Path | None, where: str) -> None:
    """Refuse, before any work, a tiled run whose result cannot be held or stored: in
    memory when gathered (CSV/NPZ), on disk for a dataset."""
    import shutil

    n = job.n_dots
    if output is None:
        need = BASE_BYTES + n * GATHERED_BYTES_PER_DOT
        have = available_bytes()
        if need > 0.9 * have:
            raise ResourceError(
                f"{where}: {n:,} dots gathered into one pattern need about "
                f"{need / 2**30:.1f} GiB but only {have / 2**30:.1f} GiB is available; "
                "write a .parquet dataset instead"
            )
        return
    parent = Path(output).resolve().parent
    free = shutil.disk_usage(parent).free
    need = n * DATASET_BYTES_PER_DOT
    if need > free:
        raise ResourceError(
            f"{where}: the dataset of {n:,} dots needs about {need / 1e9:.1f} GB on disk, "
            f"{parent} has {free / 1e9:.1f} GB free"
        )


def _check_tile_memory(job: Job, plan: TilePlan, per_worker: int) -> None:
    """Refuse tiles that cannot fit a worker's memory limit (0 = no limit)."""
    biggest = int(plan.quotas.max())
    need = estimate_bytes(biggest, job.optimize.lbfgs_memory)
    if per_worker and need > 0.8 * per_worker:
        raise ResourceError(
            f"{job.name}: a tile of {biggest:,} dots needs about {need / 2**30:.2f} GiB but "
            f"each worker has {per_worker / 2**30:.2f} GiB; choose smaller tiles (--tile-size)"
        )


def generate_tiled(
    job: Job,
    output: str | Path | None = None,
    *,
    plan: TilePlan | None = None,
    tile_size: float | None = None,
    scheduler: str | None = None,
    workers: int | None = None,
    worker_memory: int | None = None,
    executor: InProcess | OnDask | None = None,
    announce: Announce | None = None,
    progress: TileProgress | None = None,
) -> Pattern | TiledRun:
    """Generate ``job`` in tiles (:mod:`optdot.tiling.tasks`) on a Dask cluster.

    Args:
        output: a ``.parquet`` dataset to stream the tiles into (the result is then the
            :class:`TiledRun`); None gathers them into a :class:`Pattern` (tile order).
        plan: the tiling (default: :func:`plan_tiles` with ``tile_size``).
        tile_size: tile side, mm (default: about 150k dots per tile).
        scheduler: an existing Dask scheduler's address (default: a LocalCluster).
        workers: LocalCluster worker processes (default: the cores).
        worker_memory: LocalCluster memory limit per worker, bytes.
        executor: run on this instead of a cluster (tests: :class:`InProcess`).
        announce: told the cluster's dashboard and the tiling before the run.
        progress: ``progress(fraction, line)`` as tiles finish.

    Raises:
        ClusterError: the scheduler cannot be reached or the cluster cannot start.
        ResourceError: a tile would not fit a worker.
        GuaranteeError: a tile could not be made legal.
        ExportError: the dataset cannot be written (the previous one is left as it was).
    """
    where = str(job.source) if job.source else job.name
    _check_room(job, job.n_dots, where)
    _check_gathered(job, output, where)
    plan = plan or plan_tiles(job, tile_size)
    address = scheduler_address(scheduler)
    if executor is None and address is None:  # before any worker is spawned
        _check_tile_memory(job, plan, embedded_workers(workers, worker_memory)[1])
    if executor is not None:
        return _run_tiled(job, plan, contextlib.nullcontext(executor), output, progress)
    on_cluster = _on_cluster(job, plan, address, workers, worker_memory, announce)
    return _run_tiled(job, plan, on_cluster, output, progress)


@contextlib.contextmanager
def _on_cluster(job, plan, scheduler, workers, worker_memory, announce) -> Iterator[OnDask]:
    """An :class:`OnDask` executor on a connected cluster, kernels compiled on it."""
    with connect(scheduler, workers, worker_memory) as cluster:
        _check_tile_memory(job, plan, cluster.memory_per_worker)
        if announce is not None:
            kind = "local cluster" if cluster.embedded else "cluster"
            announce(
                f"{kind}: {cluster.workers} workers, dashboard {cluster.dashboard or 'n/a'}; "
                f"{plan.count} tiles ({plan.nx} x {plan.ny}) of ~{int(plan.quotas.mean()):,} dots"
            )
        warm = cluster.client.submit(_warm, pure=False)  # compile once, not per worker
        while not warm.done():  # a first run compiles for a minute: stay stoppable
            check_interrupt()
            time.sleep(0.1)
        warm.result()
        yield OnDask(cluster.client)


def _warm() -> int:
    from .runtime.cluster import single_threaded

    single_threaded()
    return warm_up()


def _run_tiled(job, plan, executor_cm, output, progress) -> Pattern | TiledRun:
    """Run the tiles on the executor ``executor_cm`` yields. A dataset is committed only
    after the executor was closed (a cluster shut down): a signal during the shutdown
    stops the run before the commit, never after it."""
    meta = _tiled_meta(job, plan)
    outline = None if job.domain.rectangle else job.domain
    one = job.diameter if job.sizes is None else None  # sizes: known once written
    if output is not None:
        manifest = manifest_of(
            job.name, job.optimize.seed, one, one, job.box, meta, outline, plan.to_json()
        )
        with write_dataset(output, manifest) as w:

            def to_part(tile, xy, diameter):
                w.write_part(plan.index(*tile), tile, xy, diameter)

            with executor_cm as executor:
                run = run_tiles(job, plan, executor, to_part, progress)
        return run
    got: dict = {}
    with executor_cm as executor:
        run = run_tiles(job, plan, executor, lambda t, xy, d: got.__setitem__(t, (xy, d)), progress)
    xy = np.concatenate([got[t][0] for t in plan.tiles()])
    d = np.concatenate([np.broadcast_to(got[t][1], (len(got[t][0]),)) for t in plan.tiles()])
    stats = {"total_s": run.seconds, "history": []}
    return Pattern(xy=xy, diameter=d, box=job.box, meta=meta, stats=stats, outline=outline)


def with_job_panel(pattern: Pattern, job: Job | None) -> Pattern:
    """The pattern with the job's panel box and outline (the job is the authority)."""
    if job is None:
        return pattern
    return replace(pattern, box=job.box, outline=None if job.domain.rectangle else job.domain)


def qa(
    pattern: Pattern | None,
    job: Job | None = None,
    collision: float | None = None,
    close: float | None = None,
    dataset=None,
    close_gap: float | None = None,
    view: dict[str, Any] | None = None,
) -> QAResult:
    """Measure ``pattern`` (or ``dataset``) and judge it (see
    :func:`optdot.quality.gate.run_qa`).

    Args:
        pattern: the dots in memory, or None to measure ``dataset``.
        job: the target map and thresholds (None: defaults, no map checks); its panel
            box and outline are the panel's.
        collision: collision distance, mm (default: the job's diameter + gap, else the
            pattern's nominal diameter).
        close: too-close distance, mm (default: the job's ``qa.close_distance``).
            ``collision`` and ``close`` are centre distances for dots of one size; dots of
            varying size are judged by edge gaps: ``close_gap`` (default the job's
            ``qa.close_gap``, else 14 µm) and the job's ``optimize.gap``.
        dataset: an opened :class:`~optdot.io.dataset.Dataset`, measured tile by tile in
            bounded memory (:func:`optdot.quality.gate.run_qa_dataset`).
        view: overrides of the visibility check, keys of :class:`QAParams`
            (``view``, ``view_distance``, ``view_luminance``, ``psf``, ``max_jnd``).
    """
    params = job.qa if job else QAParams()
    if view:
        params = replace(params, **view)
    if (pattern or dataset).uniform_diameter is None and (collision, close) != (None, None):
        raise JobError(
            "--collision/--close are centre distances for dots of one size; these dots vary "
            "in size and are judged by edge gaps (--close-gap, the job's optimize.gap)"
        )
    if close is not None:
        params = replace(params, close_distance=close)
    if close_gap is not None:
        params = replace(params, close_gap=close_gap)
    if collision is None:
        if job:
            collision = job.collision_distance
        else:
            collision = (pattern or dataset).nominal_diameter
    gap = job.optimize.gap if job else 0.0  # dots of varying size collide below it
    density = job.density if job else None
    if pattern is not None:
        result = run_qa(pattern, density, params, collision, gap)
        source, meta = pattern.meta.get("source"), pattern.meta
    elif job is None:
        result = run_qa_dataset(dataset, density, params, collision, collision_gap=gap)
        source, meta = dataset.path, dataset.manifest
    else:
        outline = None if job.domain.rectangle else job.domain
        result = run_qa_dataset(
            dataset, density, params, collision, box=job.box, outline=outline, collision_gap=gap
        )
        source, meta = dataset.path, dataset.manifest
    seed = meta.get("seed") if isinstance(meta, dict) else None
    if seed is None and job is not None and pattern is not None and source is None:
        seed = job.optimize.seed  # made from this job in this run
    result.provenance = provenance(job, source, seed)
    return result


#: Formats written straight from a dataset's parts (hierarchical masks).
STREAMED = ("gds", "oas", "dxf", "speos")


def export(
    pattern: Pattern | None,
    outputs: Mapping[str, str | Path],
    job: Job | None = None,
    options=None,
    force: bool = False,
    stream=None,
    reports: Mapping[str, str | Path] | None = None,
    written: Callable[[str, Path, str], None] | None = None,
    stage: Callable[[str], None] | None = None,
) -> QAResult:
    """Run the QA gate, then write ``pattern`` in each format of ``outputs``.

    Args:
        pattern: the dots, or None when ``stream`` is given (then read from it only if a
            format needs the whole pattern in memory).
        outputs: ``{format: path}``, formats of :data:`optdot.exporters.FORMATS`.
        job: thresholds and map of the gate (None: default thresholds).
        options: :class:`optdot.exporters.ExportOptions` (None: defaults).
        force: write even if the gate fails.
        stream: the :class:`~optdot.io.dataset.Dataset` the pattern is read from: the gate
            then measures it tile by tile and the masks (:data:`STREAMED`) are written
            from it tile by tile, hierarchically.
        reports: the gate's report, ``{"html": path, "json": path}`` (either or both),
            written with the outputs, also when the gate fails (then alone).
        written: told ``(format, path, what the file holds)`` for each output once all
            were put in place.
        stage: told ``"QA gate"`` and ``"writing"`` as they start.

    Returns:
        The gate's result (check ``passed``: with ``force`` it may have failed).

    Raises:
        QAGateError: the gate failed and ``force`` is off; nothing was written.
        ExportError: an output cannot be written, is given twice, or is an input of the
            export (the job's files, the pattern's or dataset's own file); none was
            replaced (one transaction).
    """
    from . import exporters
    from .quality.report import write_reports

    if pattern is None and stream is None:
        raise ValueError("export needs a pattern or a dataset")
    reports = dict(reports or {})
    inputs = tuple(job.inputs) if job else ()
    source = stream.path if stream is not None else pattern.meta.get("source")
    inputs += (Path(source),) if source else ()
    check_outputs({**outputs, **reports}, inputs)
    title = f"optdot QA: {Path(source).name if source else 'pattern'}"
    stage = stage or (lambda name: None)
    stage("QA gate")
    result = qa(pattern, job, dataset=stream)
    if not result.passed and not force:
        if reports:
            with transaction():
                write_reports(result, reports, title)
        raise QAGateError(result)
    from .exporters import ExportOptions

    options = replace(options or ExportOptions(), provenance=mask_lines(result.provenance))
    done: list[tuple[str, Path, str]] = []
    stage("writing")
    with transaction():  # all outputs replaced together, or none
        for fmt, path in outputs.items():
            if stream is not None and fmt in STREAMED:
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


def dataset_pattern(ds, job: Job | None) -> Pattern:
    """The whole dataset ``ds`` in memory, on the job's panel when there is a job."""
    from .io.dataset import load_dataset

    return with_job_panel(load_dataset(ds.path, box=job.box if job else None), job)
