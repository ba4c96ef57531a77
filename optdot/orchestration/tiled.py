"""Generation in tiles (:mod:`optdot.orchestration.tiling`) on a Dask cluster, or in process: the
cluster's life, the kernels compiled on it once, and the tiles streamed into a
``.parquet`` dataset or gathered into one :class:`~optdot.pattern.Pattern`.
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import tempfile
import time
from collections.abc import Callable, Iterator
from pathlib import Path

import numpy as np

from ..config.job import Job
from ..files import sha256_file
from ..geometry.shapes import Footprints
from ..io.dataset_write import write_dataset
from ..io.manifest import manifest_of
from ..pattern import Pattern
from ..runtime import kernels
from ..runtime.cluster import connect, embedded_workers, scheduler_address
from ..runtime.stop import check_interrupt
from .preflight import _check_gathered, _check_room, _check_tile_memory
from .tiling.plan import TilePlan, plan_tiles
from .tiling.run import InProcess, OnDask, TiledRun, TileProgress, run_tiles, warm_up
from .tiling.tasks import FinalDots

#: ``announce(line)``: what a tiled run tells the user before it starts (cluster, tiles).
Announce = Callable[[str], None]


def _code_digest() -> str:
    """sha256 of optdot's own source files (its exporters included): a resumed run must
    be made by the same code as the tiles it keeps."""
    root = Path(__file__).resolve().parent
    h = hashlib.sha256()
    for f in sorted(root.rglob("*.py")):
        h.update(str(f.relative_to(root)).encode())
        h.update(f.read_bytes())
    return h.hexdigest()


def resume_key(job: Job, plan: TilePlan) -> str | None:
    """The identity of a tiled run, for keeping its finished tiles across an interruption:
    optdot's code, the job file and every input file (their bytes), the job's settings
    with any overrides (seed, iterations, method), and the tiling. None for a job not read
    from a file (no resume)."""
    if job.source is None:
        return None
    h = hashlib.sha256(_code_digest().encode())
    for f in (Path(job.source), *job.inputs):
        h.update(str(f).encode())
        h.update(sha256_file(Path(f)).encode())
    h.update(repr(job.optimize).encode())
    h.update(repr(job.qa).encode())
    h.update(json.dumps(plan.to_json(), sort_keys=True).encode())
    h.update(plan.quotas.tobytes())
    return h.hexdigest()


def _tiled_meta(job: Job, plan: TilePlan) -> dict:
    opt = job.optimize
    shaped = {}
    if not job.shape.kind.round:
        shaped = {"shape": job.shape.kind.name, "orientation": job.orientation.mode}
    return {
        **shaped,
        "job": job.name,
        "method": opt.method,
        "formulation": opt.formulation,
        "seed": opt.seed,
        "max_iter": opt.max_iter,
        "n": int(plan.quotas.sum()),
        "tiles": f"{plan.nx}x{plan.ny}",
        "tiling": {"xs": [float(v) for v in plan.xs], "ys": [float(v) for v in plan.ys]},
    }


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
    """Generate ``job`` in tiles (:mod:`optdot.orchestration.tiling.tasks`) on a Dask cluster.

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
        return _run_tiled(job, plan, contextlib.nullcontext(executor), output, progress, announce)
    on_cluster = _on_cluster(job, plan, address, workers, worker_memory, announce)
    return _run_tiled(job, plan, on_cluster, output, progress, announce)


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
        _compile_on_workers(cluster.client, cluster.embedded)
        warm = cluster.client.submit(_warm, pure=False)  # the rest once, not per worker
        _wait([warm])
        warm.result()
        yield OnDask(cluster.client, cluster.memory_per_worker * cluster.workers)


def _wait(futures: list) -> None:
    """Wait for Dask ``futures``, stoppable (a first run compiles for half a minute)."""
    while not all(f.done() for f in futures):
        check_interrupt()
        time.sleep(0.1)


def _compile_on_workers(client, embedded: bool) -> None:
    """On a cold cache, the tiled run's listed kernels (:mod:`optdot.runtime.kernels`)
    compiled on all workers of the embedded cluster at once, each claiming the next unit
    in a folder they share (the workers of a cluster the run was pointed at may not
    share one); what is left is compiled by :func:`_warm`."""
    if not embedded:
        return
    try:
        workers = sorted(client.scheduler_info()["workers"])
        work = kernels.units(client.submit(kernels.cold, "tiles", pure=False).result())
        if len(work) < 2 or len(workers) < 2:
            return
        with tempfile.TemporaryDirectory(prefix="optdot-compile-") as claims:
            futures = [
                client.submit(kernels.compile_claimed, work, claims, workers=[w], pure=False)
                for w in workers[: len(work)]
            ]
            _wait(futures)
    except Exception:  # not needed for a correct run: what failed, _warm compiles
        return


def _warm() -> int:
    from ..runtime.cluster import single_threaded

    single_threaded()
    return warm_up()


def _run_tiled(job, plan, executor_cm, output, progress, announce=None) -> Pattern | TiledRun:
    """Run the tiles on the executor ``executor_cm`` yields. A dataset is committed only
    after the executor was closed (a cluster shut down): a signal during the shutdown
    stops the run before the commit, never after it. A dataset of a job read from files
    resumes: the tiles an interrupted run of the same job finished are kept (the
    staging directory of :func:`optdot.io.dataset.write_dataset`) and not made again,
    and the result is the bytes of an uninterrupted run."""
    meta = _tiled_meta(job, plan)
    outline = None if job.domain.rectangle else job.domain
    # sizes (and shaped dots' bounding discs) are known once written
    one = job.diameter if job.sizes is None and job.shape.kind.round else None
    kind = job.shape.kind
    if output is not None:
        manifest = manifest_of(
            job.name, job.optimize.seed, one, one, job.box, meta, outline, plan.to_json(), kind
        )
        with write_dataset(output, manifest, resume_key(job, plan)) as w:

            def to_part(tile, xy, dots):
                w.write_part(plan.index(*tile), tile, xy, dots)

            def loader(k: int):
                return lambda: FinalDots.read(job, *w.read_resumed(k, kind))

            finished = {tuple(e["tile"]): loader(k) for k, e in w.resumed.items()}
            if finished and announce is not None:
                announce(
                    f"resuming: {len(finished)} of {plan.count} tiles were finished by an "
                    f"interrupted run (kept in {w.tmp})"
                )
            with executor_cm as executor:
                run = run_tiles(job, plan, executor, to_part, progress, finished, w)
        return run
    got: dict = {}
    with executor_cm as executor:
        run = run_tiles(job, plan, executor, lambda t, xy, d: got.__setitem__(t, (xy, d)), progress)
    xy = np.concatenate([got[t][0] for t in plan.tiles()])
    dots = Footprints.concat([got[t][1] for t in plan.tiles()], kind)
    stats = {"total_s": run.seconds, "history": []}
    shaped = None if kind.round else dots
    return Pattern(
        xy=xy, diameter=dots.diameter, box=job.box, meta=meta, stats=stats, outline=outline,
        dots=shaped,
    )  # fmt: skip
