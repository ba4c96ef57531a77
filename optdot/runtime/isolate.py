"""Run a reader that may crash the process (C code fed a hostile file) in a child.

gdstk's GDSII and OASIS readers are C++: a damaged file can make them abort or segfault
(about 7 % of random one-byte corruptions of a GDSII file, 20 % of an OASIS file, found
by ``tests/test_properties.py``), and a crash would take the command down with no line of
its own. :func:`in_child` runs such a call in a forked child process; only its result (a
pattern: arrays of 24 B per dot) comes back through a pipe. A child that dies becomes an
ordinary exception the caller turns into one line.
"""

from __future__ import annotations

import faulthandler
import multiprocessing
import signal
from collections.abc import Callable
from typing import Any, TypeVar

T = TypeVar("T")


class ChildCrashed(Exception):
    """The child process died without an answer (``signal``: the signal that killed it,
    or None)."""

    def __init__(self, signal_name: str | None, exitcode: int | None) -> None:
        self.signal_name = signal_name
        self.exitcode = exitcode
        what = f"killed by {signal_name}" if signal_name else f"exited with {exitcode}"
        super().__init__(f"the reader crashed ({what})")


def in_child(fn: Callable[..., T], *args: Any) -> T:
    """``fn(*args)`` computed in a forked child process.

    Returns:
        What ``fn`` returned (it must pickle).

    Raises:
        Whatever ``fn`` raised (re-raised here), or :class:`ChildCrashed` when the child
        died (a signal, or an exit without an answer).
    """
    ctx = multiprocessing.get_context("fork")
    receiver, sender = ctx.Pipe(duplex=False)
    child = ctx.Process(target=_run, args=(sender, fn, args), daemon=True)
    child.start()
    sender.close()
    try:
        ok, value = receiver.recv()
    except EOFError:
        ok, value = None, None
    finally:
        receiver.close()
        child.join()
    if ok is None:
        code = child.exitcode
        name = signal.Signals(-code).name if code is not None and code < 0 else None
        raise ChildCrashed(name, code)
    if not ok:
        raise value
    return value


def _run(sender, fn, args) -> None:
    faulthandler.disable()  # the parent reports the crash, in one line
    try:
        result = (True, fn(*args))
    except BaseException as e:  # noqa: BLE001 - handed to the parent, which re-raises it
        result = (False, e)
    try:
        sender.send(result)
    except Exception as e:  # noqa: BLE001 - an unpicklable answer is still an answer
        sender.send((False, RuntimeError(f"{type(e).__name__}: {e}")))
    sender.close()
