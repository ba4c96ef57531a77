"""Preloaded into every embedded Dask worker process (``distributed.worker.preload``).

Its numba thread count is settled to the worker's environment (see :func:`dask_setup`).

A Ctrl-C in the terminal reaches the whole process group: the command stops the run
itself (one line, exit 130) and closes the cluster, so a worker has nothing to do with
the signal but print a traceback. Workers therefore ignore SIGINT; they still stop when
the cluster closes them, or on SIGTERM/SIGKILL from their nanny.
"""

from __future__ import annotations

import signal
import threading


def _ignore_interrupts() -> None:
    if threading.current_thread() is threading.main_thread():
        signal.signal(signal.SIGINT, signal.SIG_IGN)


_ignore_interrupts()


def dask_setup(worker) -> None:  # noqa: ARG001 - Dask's preload hook
    """Dask calls this in the worker once it starts, after its nanny set the worker's
    environment: interrupts ignored (the import above did it too), and numba's thread
    count settled to that environment before any kernel compiles here
    (:func:`optdot.runtime.cluster.settle_numba_threads`)."""
    from .cluster import settle_numba_threads

    _ignore_interrupts()
    settle_numba_threads()
