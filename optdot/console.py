"""The ``optdot`` console script and ``python -m optdot``: the command line, with a
SIGINT or SIGTERM that comes while its modules load (numpy, numba, scipy: the first half
second) answered as one at any later point: ``optdot: interrupted``, exit 130.

While the modules load, a signal only sets the stop flag (:mod:`optdot.runtime.stop`):
raised as an exception inside a library's import, an interrupt was swallowed there (the
run went on) or left CPython killing itself with SIGINT at exit.

Before numpy loads, the command turns off numpy's request for transparent huge pages
(``NUMPY_MADVISE_HUGEPAGE=0``, for itself and the workers it starts; a value the user set
is kept). numpy asks for them on every array of 4 MB or more, and where the kernel
defragments synchronously for such requests (``transparent_hugepage/defrag`` =
``madvise``, a common default) a first touch can stall on compaction: a 1.2M-dot map in one
process spends over a second more in the kernel with them (BENCHMARKS.md; numpy issue
31590)."""

from __future__ import annotations

import os
import signal
import sys

from .runtime.kernel_cache import discard_temporary
from .runtime.stop import interrupted, mark_interrupted

#: Exit code when the command line cannot load (a broken install): the internal error's,
#: sysexits' EX_SOFTWARE (:data:`optdot.cli.app.EXIT_INTERNAL`, which did not load).
EXIT_CANNOT_LOAD = 70


def _note(signum, frame) -> None:
    mark_interrupted()


def process_defaults() -> None:
    """Settings the command's process and its workers start with, unless set already:
    ``NUMPY_MADVISE_HUGEPAGE=0`` (see the module doc). Read by numpy when it loads."""
    os.environ.setdefault("NUMPY_MADVISE_HUGEPAGE", "0")


class QuietStdout:
    """``sys.stdout`` that stops writing, silently, once its reader has gone (a pipe
    closed early: ``optdot qa ... | head -1``): the command still finishes its work and
    exits with its own code (the gate's verdict), not 1 with nothing said."""

    def __init__(self, stream) -> None:
        self._stream = stream
        self.reader_gone = False

    def write(self, text):
        if not self.reader_gone:
            try:
                return self._stream.write(text)
            except BrokenPipeError:
                self._gone()
        return len(text)

    def flush(self) -> None:
        if not self.reader_gone:
            try:
                self._stream.flush()
            except BrokenPipeError:
                self._gone()

    def _gone(self) -> None:
        """Stop writing; what the stream still holds goes to the null device when
        Python flushes it at exit (a closed pipe would raise there)."""
        self.reader_gone = True
        try:
            null = os.open(os.devnull, os.O_WRONLY)
            os.dup2(null, self._stream.fileno())
            os.close(null)
        except (OSError, ValueError):
            pass

    def __getattr__(self, name):
        return getattr(self._stream, name)


def run() -> None:
    """Load the command line and run it; the command's own handlers take over from here
    (:func:`optdot.cli.app.user_errors`), and see a signal that came before them."""
    process_defaults()
    if sys.stdout is not None:
        sys.stdout = QuietStdout(sys.stdout)
    for s in (signal.SIGINT, signal.SIGTERM):
        signal.signal(s, _note)
    try:
        from .cli import main
    except Exception as e:  # noqa: BLE001 - a broken install: one line, not a traceback
        first = (str(e).strip().splitlines() or [""])[0]
        sys.stderr.write(
            f"optdot: internal error: cannot load the command line: {type(e).__name__}: {first}\n"
        )
        sys.stderr.flush()
        discard_temporary()
        os._exit(EXIT_CANNOT_LOAD)

    if interrupted():
        sys.stderr.write("optdot: interrupted\n")
        sys.stderr.flush()
        discard_temporary()
        os._exit(130)  # nothing is open yet
    try:
        main(prog_name="optdot")
    finally:
        ended()


def ended() -> None:
    """The command has ended and its exit code is decided: SIGINT and SIGTERM are ignored
    from here. Python resets a signal whose handler is a Python function to the default
    action as the interpreter shuts down, so a SIGTERM in those last moments killed the
    process (exit 143) after ``design`` wrote its outputs or ``export`` printed its
    refusal; an ignored signal is left ignored, and the command's own code stands."""
    for s in (signal.SIGINT, signal.SIGTERM):
        signal.signal(s, signal.SIG_IGN)
