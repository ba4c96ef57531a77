"""The ``optdot`` console script and ``python -m optdot``: the command line, with a
SIGINT or SIGTERM that comes while its modules load (numpy, numba, scipy: the first half
second) answered as one at any later point: ``optdot: interrupted``, exit 130.

While the modules load, a signal only sets the stop flag (:mod:`optdot.runtime.stop`):
raised as an exception inside a library's import, an interrupt was swallowed there (the
run went on) or left CPython killing itself with SIGINT at exit."""

from __future__ import annotations

import os
import signal
import sys

from .runtime.stop import interrupted, mark_interrupted


def _note(signum, frame) -> None:
    mark_interrupted()


def run() -> None:
    """Load the command line and run it; the command's own handlers take over from here
    (:func:`optdot.cli.app.user_errors`), and see a signal that came before them."""
    for s in (signal.SIGINT, signal.SIGTERM):
        signal.signal(s, _note)
    from .cli import main

    if interrupted():
        sys.stderr.write("optdot: interrupted\n")
        sys.stderr.flush()
        os._exit(130)  # nothing is open yet
    main(prog_name="optdot")
