"""The Dask cluster a tiled job runs on: one started by the command, or one it is pointed at.

* **Embedded** (default): a ``distributed.LocalCluster`` of single-threaded worker
  processes, one per core (at most one per tile), each with an even share of the memory
  available now. Workers get ``NUMBA_NUM_THREADS=1`` (and the BLAS/OpenMP equivalents)
  through Dask's ``distributed.nanny.environ``, set in each worker process as it starts
  (before numba is imported there), so numba's threads do not fight Dask's processes, and
  ``NUMBA_CACHE_DIR`` in the user's cache directory, so compiled kernels are cached
  without writing into site-packages. Not ``pre-spawn-environ``: Dask applies that to the
  *command's own* environment and never restores it, and numba in the command then
  refuses to compile anything ("Cannot set NUMBA_NUM_THREADS to a different value once
  the threads have been launched": exit 70 on a cold cache after a tiled run).
* **Existing** (``--scheduler tcp://HOST:8786`` or ``DASK_SCHEDULER_ADDRESS``): a
  ``distributed.Client`` to it; its workers must have optdot installed. Every task sets
  numba to one thread per Dask thread itself (:func:`single_threaded`).

Before the job, one worker runs a tiny tiled job (:func:`optdot.orchestration.tiling.run.warm_up`),
so
kernels are compiled and cached once, not raced for by every worker.
"""

from __future__ import annotations

import contextlib
import logging
import os
import shutil
import signal
import tempfile
import threading
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from ..errors import ClusterError, ResourceError, one_line
from .memory import available_bytes
from .stop import check_interrupt


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


def settle_numba_threads() -> None:
    """Make this process's ``NUMBA_NUM_THREADS`` the size of numba's running thread pool.

    numba reads the variable when it is imported and again before every compile, and
    refuses a compile ("Cannot set NUMBA_NUM_THREADS to a different value once the
    threads have been launched") when it changed after the pool started. A worker whose
    nanny sets it to 1 after something imported numba and started the pool (or a
    process whose environment a library changed) would then fail at its first compile,
    as a cold cache's tiled run does. Before the pool starts, the variable is adopted;
    after, the variable is put back to the pool's size (``numba.set_num_threads``, not
    the variable, is what limits the threads a kernel uses)."""
    from numba.core import config
    from numba.np.ufunc import parallel

    if parallel._is_initialized:
        os.environ["NUMBA_NUM_THREADS"] = str(config.NUMBA_NUM_THREADS)
    else:
        config.reload_config()


def single_threaded() -> None:
    """Run numba's parallel kernels on one thread in this Dask thread (results do not
    depend on it; the thread count of the cluster is Dask's)."""
    import numba

    settle_numba_threads()
    if numba.get_num_threads() != 1:
        numba.set_num_threads(1)


def dashboard_of(client, sched: dict) -> str:
    """The dashboard's address when the scheduler serves one, else "". A scheduler started
    with ``--no-dashboard`` still serves HTTP on the dashboard's port (health, metrics),
    so ``services`` names it and the client's link template makes up an address: the
    page is asked for (2 s at most, no proxy) and the address given only when it is
    there."""
    import urllib.request

    link = client.dashboard_link or ""
    if not link or "dashboard" not in (sched.get("services") or {}):
        return ""
    opener = urllib.request.build_opener(urllib.request.ProxyHandler({}))
    try:
        with opener.open(link, timeout=2) as r:
            return link if r.status == 200 else ""
    except (OSError, ValueError):
        return ""


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
    """The scheduler to use: the option, else ``DASK_SCHEDULER_ADDRESS``, else None,
    checked to be a TCP or TLS address with a host and a port (``tcp://HOST:8786``; a
    bare ``HOST:8786`` is taken as tcp).

    Raises:
        ClusterError: anything else (``inproc://``, no port, not an address), naming
            where the address came from.
    """
    source = "--scheduler"
    address = option
    if not address:
        address = os.environ.get("DASK_SCHEDULER_ADDRESS") or None
        source = "DASK_SCHEDULER_ADDRESS"
    if address is None:
        return None
    from distributed.comm.addressing import parse_address, parse_host_port

    shown = address if len(address) <= 80 else address[:77] + "..."
    try:
        scheme, location = parse_address(address, strict=False)
        if scheme not in ("tcp", "tls"):
            raise ValueError(f"the {scheme}:// transport cannot reach another process")
        host, port = parse_host_port(location)
        if not host or not port:
            raise ValueError("a host and a port are needed")
    except (ValueError, TypeError) as e:
        raise ClusterError(
            f"{source} {shown!r} is not a Dask scheduler address ({one_line(e)}); "
            "use tcp://HOST:PORT"
        ) from None
    return address


#: Largest first message a Dask scheduler's handshake may announce, bytes (it is a few
#: hundred): a server announcing more is not a scheduler, and Dask would allocate it.
MAX_HANDSHAKE_BYTES = 1 << 24


def _announced_bytes(address: str, seconds: float) -> int | None:
    """The length a plain-TCP server at ``address`` announces in the first 8 bytes it
    sends on a new connection (a Dask scheduler sends its handshake at once, framed by its
    byte count as a native uint64), or None: TLS, nothing sent within ``seconds``, or the
    connection refused (then Dask's own connect says why)."""
    import socket
    import struct

    from distributed.comm.addressing import parse_address, parse_host_port

    scheme, location = parse_address(address, strict=False)
    if scheme != "tcp":
        return None
    host, port = parse_host_port(location)
    try:
        with socket.create_connection((host, port), timeout=seconds) as s:
            s.settimeout(seconds)
            head = b""
            while len(head) < 8:
                got = s.recv(8 - len(head))
                if not got:
                    return None
                head += got
    except OSError:
        return None
    return struct.unpack("Q", head)[0]


#: Seconds without a heartbeat after which the embedded scheduler drops a worker (a
#: frozen one: stopped, swapped out, deadlocked) and gives its tasks to the others; Dask's
#: own default is 5 minutes. ``DASK_DISTRIBUTED__SCHEDULER__WORKER_TTL`` overrides it.
WORKER_TTL = "60s"
#: Log level of Dask's loggers: above CRITICAL, so nothing. The scheduler runs in the
#: command's process and logs a CRITICAL "Closed comm" traceback per pending result when a
#: Ctrl-C closes the client; the command says what happened in one line of its own.
SILENT = logging.CRITICAL + 1
#: Seconds the embedded cluster may take to start its workers.
START_TIMEOUT = 120.0


def _within(fn: Callable[[], Any], seconds: float, what: str) -> Any:
    """``fn()`` or, when it has not returned after ``seconds``, a :class:`ClusterError`.

    Dask's connect timeout covers opening the connection, not a peer that accepts it and
    then says nothing (a silent server hung the client for as long as it stayed up); the
    call runs in a daemon thread that is left behind if it never returns. The wait
    wakes every 0.2 s, so a signal stops it at once."""
    box: dict[str, Any] = {}

    def call() -> None:
        try:
            box["value"] = fn()
        except BaseException as e:  # noqa: BLE001 - handed to the caller
            box["error"] = e

    t = threading.Thread(target=call, name="optdot-connect", daemon=True)
    t.start()
    deadline = time.monotonic() + seconds
    while t.is_alive() and time.monotonic() < deadline:
        t.join(0.2)
        check_interrupt()
    if t.is_alive():
        raise ClusterError(f"{what} did not answer within {seconds:.0f} s")
    if "error" in box:
        raise box["error"]
    return box["value"]


#: Least memory an embedded worker process needs to start and run a small tile (the
#: interpreter, numpy, numba, distributed: ~250 MB resident), bytes.
MIN_WORKER_BYTES = 400 * 2**20


def embedded_workers(workers: int | None, memory_per_worker: int | None) -> tuple[int, int]:
    """``(processes, memory limit each in bytes)`` of the embedded cluster, checked before
    any process is spawned: by default one per core sharing 85 % of the available memory.

    Raises:
        ResourceError: the workers would get less than :data:`MIN_WORKER_BYTES` each.
    """
    n = workers or os.cpu_count() or 1
    mem = memory_per_worker or int(0.85 * available_bytes() / n)
    if mem < MIN_WORKER_BYTES:
        raise ResourceError(
            f"{n} local workers would have {mem / 2**20:,.0f} MiB each; a worker needs at "
            f"least {MIN_WORKER_BYTES / 2**20:.0f} MiB: use fewer (--workers)"
        )
    return n, mem


def _restore_environment(saved: dict[str, str]) -> None:
    """Put this process's environment back as it was: Dask's nannies set their
    ``pre-spawn-environ`` (OMP_NUM_THREADS=1, MALLOC_TRIM_THRESHOLD_, ...) in the spawning
    process and leave it there."""
    for key in set(os.environ) - set(saved):
        del os.environ[key]
    for key, value in saved.items():
        if os.environ.get(key) != value:
            os.environ[key] = value


@contextlib.contextmanager
def _workers_deaf_to_ctrl_c() -> Iterator[None]:
    """SIGINT ignored in this process while the workers are spawned: a new process
    keeps an ignored SIGINT (Python installs its KeyboardInterrupt handler only over the
    default one), so a Ctrl-C in the terminal, which reaches the whole process group, does
    not print a traceback from a worker still importing its modules. SIGTERM still stops
    the command; a Ctrl-C during these seconds is lost. Restarted workers get the same
    from :mod:`optdot.runtime.worker_init`."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)


@contextlib.contextmanager
def connect(
    address: str | None = None,
    workers: int | None = None,
    memory_per_worker: int | None = None,
    timeout: float = 10.0,
) -> Iterator[Cluster]:
    """A Dask cluster for the duration of the block.

    The embedded cluster is private to this command: scheduler, workers and dashboard
    listen on the loopback interface only, every connection is TLS with a certificate
    made for this run and held only in this process and its workers (Dask's
    ``Security.temporary()``: another local process cannot submit code to our workers),
    and workers keep their scratch files in a private (0700) temporary directory removed
    afterwards. A worker silent for :data:`WORKER_TTL` is dropped and its tasks retried
    elsewhere.

    Args:
        address: an existing scheduler (``tcp://host:8786``); None starts a LocalCluster.
        workers: embedded worker processes (default: the cores).
        memory_per_worker: embedded workers' memory limit, bytes (default: 85 % of the
            available memory shared evenly).
        timeout: seconds to wait for a scheduler and its workers, silent ones included.

    Raises:
        ClusterError: the scheduler cannot be reached, does not answer, has no workers,
            or the local cluster cannot start.
    """
    import dask
    from distributed import Client, LocalCluster

    logging.getLogger("distributed").setLevel(SILENT)
    if address:
        claim = _announced_bytes(address, min(timeout, 2.0))
        if claim is not None and claim > MAX_HANDSHAKE_BYTES:
            raise ClusterError(
                f"{address} does not answer as a Dask scheduler (its first message "
                f"announces {claim:,} bytes): is it the scheduler's address and port?"
            )
        with dask.config.set({"distributed.comm.timeouts.connect": f"{timeout}s"}):
            try:
                client = _within(
                    lambda: Client(address, timeout=f"{timeout}s"),
                    timeout + 5,
                    f"the Dask scheduler at {address}",
                )
            except (OSError, TimeoutError) as e:
                raise ClusterError(
                    f"cannot reach the Dask scheduler at {address} ({one_line(e)})"
                ) from None
            except Exception as e:  # noqa: BLE001 - a server that is not a scheduler
                # (garbage for Dask's decoder, or a frame length it could not allocate)
                what = "a reply it cannot read" if isinstance(e, MemoryError) else one_line(e)
                raise ClusterError(
                    f"{address} does not answer as a Dask scheduler ({what}): is it the "
                    "scheduler's address and port?"
                ) from None
        try:
            _within(
                lambda: client.wait_for_workers(1, timeout=timeout),
                timeout + 5,
                f"the Dask scheduler at {address}",
            )
            sched = client.scheduler_info(n_workers=-1)
            info = sched["workers"]
            limits = [w.get("memory_limit") or 0 for w in info.values()]
            yield Cluster(client, len(info), min(limits), dashboard_of(client, sched), False)
        except TimeoutError:
            raise ClusterError(f"the Dask scheduler at {address} has no workers") from None
        finally:
            with contextlib.suppress(Exception):
                client.close(timeout=5)
        return
    n, mem = embedded_workers(workers, memory_per_worker)
    ttl = dask.config.get("distributed.scheduler.worker-ttl")
    config = {
        "distributed.nanny.environ": worker_environment(),
        "distributed.worker.daemon": False,
        "distributed.scheduler.work-stealing": True,
        "distributed.scheduler.worker-ttl": WORKER_TTL if ttl == "5 minutes" else ttl,
        "distributed.worker.preload": ["optdot.runtime.worker_init"],
        "logging.distributed": SILENT,
    }
    saved_env = dict(os.environ)  # Dask's nannies write into it (pre-spawn-environ)
    scratch = tempfile.mkdtemp(prefix="optdot-dask-")  # mode 0700: ours alone
    config["temporary-directory"] = scratch  # the scheduler's scratch space too
    with dask.config.set(config):
        try:
            from distributed.security import Security

            with _workers_deaf_to_ctrl_c():
                cluster = _within(
                    lambda: LocalCluster(
                        n_workers=n,
                        threads_per_worker=1,
                        processes=True,
                        memory_limit=mem,
                        host="127.0.0.1",
                        dashboard_address="127.0.0.1:0",
                        security=Security.temporary(),
                        local_directory=scratch,
                        silence_logs=SILENT,  # the command reports failures itself
                    ),
                    START_TIMEOUT,
                    "the local Dask cluster (a worker that never started)",
                )
        except ClusterError:
            shutil.rmtree(scratch, ignore_errors=True)
            _restore_environment(saved_env)
            raise
        except Exception as e:  # noqa: BLE001 - any failure to start is one line
            shutil.rmtree(scratch, ignore_errors=True)
            _restore_environment(saved_env)
            raise ClusterError(f"cannot start a local Dask cluster ({one_line(e)})") from None
        _restore_environment(saved_env)
        try:
            client = Client(cluster)
            try:
                yield Cluster(client, n, mem, client.dashboard_link or "", True)
            finally:
                client.close()
        finally:
            with contextlib.suppress(Exception):
                cluster.close(timeout=10)
            shutil.rmtree(scratch, ignore_errors=True)
            _restore_environment(saved_env)
