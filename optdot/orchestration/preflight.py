"""Checks before any work: whether a job can run at all, how (one process or tiles),
and what it would cost. :func:`check_job` is every check
:func:`optdot.orchestration.pipeline.generate`
and :func:`optdot.orchestration.tiled.generate_tiled` make before they start, without running
anything.
"""

from __future__ import annotations

import shutil
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..config.job import Job
from ..config.shaping import check_shaped_fill
from ..errors import JobError, ResourceError
from ..geometry.limits import MAX_RANDOM_FILL
from ..runtime.cluster import embedded_workers
from ..runtime.cost import SHAPED_MEMORY, Cost, estimate_cost
from ..runtime.memory import BASE_BYTES, available_bytes, check_memory, estimate_bytes
from .tiling.plan import TilePlan, plan_tiles


def _check_fill(job: Job, where: str) -> None:
    """Refuse, before any work, a map whose densest cell cannot hold a random pattern at
    the job's spacing (a gap of 5 mm between 46 µm dots allows a fill of 0.0001)."""
    grid = job.density.grid
    k = int(np.argmax(grid))
    iy, ix = divmod(k, grid.shape[1])
    if not job.shape.kind.round:
        check_shaped_fill(job, float(grid[iy, ix]), where, " " + _cell(job, iy, ix))
        return
    spread = (job.min_distance / job.diameter) ** 2
    eff = float(grid[iy, ix]) * spread
    if eff >= MAX_RANDOM_FILL:
        raise JobError(
            f"{where}: fill {float(grid[iy, ix]):.4g} {_cell(job, iy, ix)} with centres "
            f"{job.min_distance * 1e3:.4g} µm apart for {job.diameter * 1e3:.4g} µm dots "
            f"is an effective fill of {eff:.4g}; a random non-overlapping pattern reaches "
            f"at most {MAX_RANDOM_FILL:g} (the fill can be at most "
            f"{MAX_RANDOM_FILL / spread:.4g} here){_gap_source(job)}"
        )


def _gap_source(job: Job) -> str:
    """Where the job's gap comes from, when its ``[process]`` set it: ``; the gap is
    process.min_space ...``; else nothing."""
    p = job.process
    if p is None:
        return ""
    return (
        f"; the gap of {job.optimize.gap * 1e3:.4g} µm is [process]'s: min_space "
        f"{p.min_space * 1e3:g} µm (or min_feature less twice the gain) plus "
        f"{p.snap_margin * 1e3:.3g} µm for the grid"
    )


def _cell(job: Job, iy: int, ix: int) -> str:
    """Where cell ``(iy, ix)`` of the job's map is, for a message: its row and column in
    the file, or, for a map read as a smooth field (whose cells are sub-cells of the
    file's), its centre in mm."""
    if job.interpolation == "nearest":
        return f"at row {iy}, column {ix}"
    d = job.density
    cw, ch = d.cell_size
    return f"of the smooth map near ({d.x0 + (ix + 0.5) * cw:.4g}, {d.y0 + (iy + 0.5) * ch:.4g}) mm"


def _check_room(job: Job, n: int, where: str) -> None:
    """Refuse, before any work, a job whose dots cannot be placed at all, or whose
    graded caps the design has not sized yet (``cap_ink = "design"``)."""
    leds = job.backlight.leds if job.backlight is not None else None
    if leds is not None and leds.cap_ink == "design":
        raise JobError(
            f'{where}: backlight.leds.cap_ink = "design": the caps\' rings are not sized '
            "yet; run 'optdot design' and generate the job it writes"
        )
    if n == 0:
        raise JobError(
            f"{where}: the map asks for 0 dots (mean fill fraction x panel area is under half "
            f"a dot of {job.diameter:g} mm)"
        )
    if job.sizes is None or not job.shape.kind.round:  # shaped: at the rule's size there
        _check_fill(job, where)
    if job.domain.rectangle and job.domain.edge_margin == 0:
        return  # fill fractions below the packing limit always fit
    room = job.domain.max_dots(job.dot_radius, job.min_distance)
    if n > room:
        margin = job.domain.edge_margin
        what = f"domain.edge_margin = {margin:g} mm leaves" if margin > 0 else "the panel has"
        raise JobError(
            f"{where}: {what} room for at most {room:,} dots {job.diameter * 1e3:.4g} µm "
            f"across (centres {job.min_distance * 1e3:.4g} µm apart), the map asks for {n:,}"
        )


#: ``tiles="auto"`` tiles a job of at least this many dots even when one process would
#: hold it: above it the tiled run on this 2-core machine is faster (BENCHMARKS.md,
#: ``benchmarks/panels.py --break-even``).
TILE_BREAK_EVEN = 2_000_000


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
    return n >= TILE_BREAK_EVEN or _bytes(job, n) > 0.9 * available_bytes()


def _bytes(job: Job, n: int) -> float:
    """Peak bytes of a process relaxing ``n`` of ``job``'s dots (shaped dots: their
    measured share more, :data:`~optdot.runtime.cost.SHAPED_MEMORY`)."""
    scale = 1.0 if job.shape.kind.round else SHAPED_MEMORY
    return estimate_bytes(n, job.optimize.lbfgs_memory) * scale


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
    shaped = not job.shape.kind.round
    if not use_tiles(job, tiles):
        check_memory(n, opt.lbfgs_memory, where)
        cost = estimate_cost(n, opt.max_iter, opt.lbfgs_memory, formats=formats, shaped=shaped)
        return JobCheck(n, None, 1, cost, available_bytes())
    plan = plan_tiles(job, tile_size)
    k, per_worker = embedded_workers(workers, None)
    k = min(k, plan.count)
    _check_tile_memory(job, plan, per_worker)
    biggest = int(plan.quotas.max())
    cost = estimate_cost(n, opt.max_iter, opt.lbfgs_memory, biggest, k, formats, shaped)
    return JobCheck(n, plan, k, cost, available_bytes())


#: Bytes per dot of a tiled run gathered into one pattern in the command's process
#: (positions, the order of tiles, the pattern, what the writer formats).
GATHERED_BYTES_PER_DOT = 64
#: Bytes per dot of a dataset on disk (three float64 columns, zstd), an upper bound.
DATASET_BYTES_PER_DOT = 26


def _check_gathered(job: Job, output: str | Path | None, where: str) -> None:
    """Refuse, before any work, a tiled run whose result cannot be held or stored: in
    memory when gathered (CSV/NPZ), on disk for a dataset."""
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
    need = _bytes(job, biggest)
    if per_worker and need > 0.8 * per_worker:
        raise ResourceError(
            f"{job.name}: a tile of {biggest:,} dots needs about {need / 2**30:.2f} GiB but "
            f"each worker has {per_worker / 2**30:.2f} GiB; choose smaller tiles (--tile-size)"
        )
