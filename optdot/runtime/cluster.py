"""The Dask cluster a tiled job runs on: one started by the command, or one it is pointed at.

* **Embedded** (default): a ``distributed.LocalCluster`` of single-threaded worker
  processes, one per core (at most one per tile), each with an even share of the memory
  available now. Workers get ``NUMBA_NUM_THREADS=1`` (and the BLAS/OpenMP equivalents)
  through Dask's ``distributed.nanny.pre-spawn-environ``, so numba's threads do not fight
  Dask's processes, and ``NUMBA_CACHE_DIR`` in the user's cache directory, so compiled
  kernels are cached without writing into site-packages.
* **Existing** (``--scheduler tcp://HOST:8786`` or ``DASK_SCHEDULER_ADDRESS``): a
  ``distributed.Client`` to it; its workers must have optdot installed. Every task sets
  numba to one thread per Dask thread itself (:func:`single_threaded`).

Before the job, one worker runs a tiny tiled job (:func:`optdot.tiling.run.warm_up`), so
kernels are compiled and cached once, not raced for by every worker.
"""

from __future__ import annotations

import contextlib
import logging
import os
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from ..errors import ClusterError, one_line
from .memory import available_bytes


def numba_cache_dir() -> Path:
    """Where workers cache compiled kernels: ``$NUMBA_CACHE_DIR``, else
    ``$XDG_CACHE_HOME/optdot/numba`` (``~/.cache/optdot/numba``)."""
    if os.environ.get("NUMBA_CACHE_DIR"):
        return Path(os.environ["NUMBA_CACHE_DIR"])
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "optdot" / "numba"


def worker_environment() -> dict[str, str]:
    """Environment of every embedded worker process."""
    env = {
        "NUMBA_NUM_THREADS": "1",
        "OMP_NUM_THREADS": "1",
        "OPENBLAS_NUM_THREADS": "1",
        "MKL_NUM_THREADS": "1",
    }
    cache = numba_cache_dir()
    with contextlib.suppress(OSError):
        cache.mkdir(parents=True, exist_ok=True)
    if os.access(cache, os.W_OK):
        env["NUMBA_CACHE_DIR"] = str(cache)
    return env


def single_threaded() -> None:
    """Run numba's parallel kernels on one thread in this Dask thread (results do not
    depend on it; the thread count of the cluster is Dask's)."""
    import numba

    if numba.get_num_threads() != 1:
        numba.set_num_threads(1)


@dataclass
class Cluster:
    """A connected Dask client and what it runs on.

    Attributes:
        client: the ``distributed.Client``.
        workers: number of workers.
        memory_per_worker: the smallest worker memory limit, bytes (0: unlimited).
        dashboard: the dashboard's address, or "".
        embedded: the cluster was started by this command (and stops with it).
    """

    client: Any
    workers: int
    memory_per_worker: int
    dashboard: str
    embedded: bool


def scheduler_address(option: str | None) -> str | None:
    """The scheduler to use: the option, else ``DASK_SCHEDULER_ADDRESS``, else None."""
    return option or os.environ.get("DASK_SCHEDULER_ADDRESS") or None


@contextlib.contextmanager
def connect(
    address: str | None = None,
    workers: int | None = None,
    memory_per_worker: int | None = None,
    timeout: float = 10.0,
) -> Iterator[Cluster]:
    """A Dask cluster for the duration of the block.

    Args:
        address: an existing scheduler (``tcp://host:8786``); None starts a LocalCluster.
        workers: embedded worker processes (default: the cores).
        memory_per_worker: embedded workers' memory limit, bytes (default: 85 % of the
            available memory shared evenly).
        timeout: seconds to wait for a scheduler and its workers.

    Raises:
        ClusterError: the scheduler cannot be reached, has no workers, or the local
            cluster cannot start.
    """
    import dask
    from distributed import Client, LocalCluster

    logging.getLogger("distributed").setLevel(logging.ERROR)
    if address:
        try:
            client = Client(address, timeout=f"{timeout}s")
        except (OSError, TimeoutError) as e:
            raise ClusterError(
                f"cannot reach the Dask scheduler at {address} ({one_line(e)})"
            ) from None
        try:
            client.wait_for_workers(1, timeout=timeout)
            info = client.scheduler_info(n_workers=-1)["workers"]
            limits = [w.get("memory_limit") or 0 for w in info.values()]
            yield Cluster(client, len(info), min(limits), client.dashboard_link or "", False)
        except TimeoutError:
            raise ClusterError(f"the Dask scheduler at {address} has no workers") from None
        finally:
            client.close()
        return
    n = workers or os.cpu_count() or 1
    mem = memory_per_worker or int(0.85 * available_bytes() / n)
    config = {
        "distributed.nanny.pre-spawn-environ": worker_environment(),
        "distributed.worker.daemon": False,
        "distributed.scheduler.work-stealing": True,
        "logging.distributed": "error",
    }
    with dask.config.set(config):
        try:
            cluster = LocalCluster(
                n_workers=n,
                threads_per_worker=1,
                processes=True,
                memory_limit=mem,
                dashboard_address=":0",
                silence_logs=logging.ERROR,
            )
        except Exception as e:  # noqa: BLE001 - any failure to start is one line
            raise ClusterError(f"cannot start a local Dask cluster ({one_line(e)})") from None
        try:
            client = Client(cluster)
            try:
                yield Cluster(client, n, mem, client.dashboard_link or "", True)
            finally:
                client.close()
        finally:
            with contextlib.suppress(Exception):
                cluster.close(timeout=10)
