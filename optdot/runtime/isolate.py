"""Run a reader that may crash the process (C code fed a hostile file) in a child.

gdstk's GDSII and OASIS readers are C++: a damaged file can make them abort or segfault
(about 7 % of random one-byte corruptions of a GDSII file, 20 % of an OASIS file, found
by ``tests/test_properties.py``), and a crash would take the command down with no line of
its own. :func:`in_child` runs such a call in a forked child process; only its result (a
pattern: arrays of 24 B per dot) comes back through a pipe. A child that dies becomes an
ordinary exception the caller turns into one line.

A corrupted heap can also make the child *hang* instead of dying: glibc, finding the
damage inside ``free``, may wait forever on the lock it already holds (seen once in CI,
on a random one-byte corruption of a GDSII file). The parent therefore watches the
child's CPU time (``/proc``): a child that has used no CPU for :data:`STALL_SECONDS` is
killed and reported like a crash. A reader that is working, however slowly, is never
cut off.
"""

from __future__ import annotations

import faulthandler
import multiprocessing
import signal
import time
from collections.abc import Callable
from typing import Any, TypeVar

T = TypeVar("T")


#: A child that used no CPU for this long is stuck, s.
STALL_SECONDS = 30.0


class ChildCrashed(Exception):
    """The child process died without an answer (``signal``: the signal that killed it,
    or None), or hung (``hung``: it used no CPU for :data:`STALL_SECONDS` and was killed)."""

    def __init__(self, signal_name: str | None, exitcode: int | None, hung: bool = False) -> None:
        self.signal_name = signal_name
        self.exitcode = exitcode
        self.hung = hung
        if hung:
            what = f"no progress for {STALL_SECONDS:g} s, stopped"
            super().__init__(f"the reader hung ({what})")
            return
        what = f"killed by {signal_name}" if signal_name else f"exited with {exitcode}"
        super().__init__(f"the reader crashed ({what})")


def in_child(fn: Callable[..., T], *args: Any) -> T:
    """``fn(*args)`` computed in a forked child process.

    Returns:
        What ``fn`` returned (it must pickle).

    Raises:
        Whatever ``fn`` raised (re-raised here), or :class:`ChildCrashed` when the child
        died (a signal, or an exit without an answer) or hung.
    """
    ctx = multiprocessing.get_context("fork")
    receiver, sender = ctx.Pipe(duplex=False)
    child = ctx.Process(target=_run, args=(sender, fn, args), daemon=True)
    child.start()
    sender.close()
    try:
        if not _wait(receiver, child.pid):
            child.kill()
            child.join()
            raise ChildCrashed(None, None, hung=True)
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


def _wait(receiver, pid: int, stall: float | None = None) -> bool:
    """Wait until the child answers or dies (True), or has used no CPU for ``stall``
    seconds (False; default :data:`STALL_SECONDS`)."""
    stall = STALL_SECONDS if stall is None else stall
    last, since = _cpu_ticks(pid), time.monotonic()
    while not receiver.poll(min(1.0, stall)):
        now_ticks = _cpu_ticks(pid)
        if now_ticks is None or now_ticks != last:  # no /proc: never judged stuck
            last, since = now_ticks, time.monotonic()
        elif time.monotonic() - since >= stall:
            return False
    return True


def _cpu_ticks(pid: int) -> int | None:
    """User + system CPU time of process ``pid`` in clock ticks (Linux ``/proc``), or None."""
    try:
        with open(f"/proc/{pid}/stat", "rb") as fh:
            fields = fh.read().rsplit(b")", 1)[1].split()
        return int(fields[11]) + int(fields[12])  # utime, stime (fields 14, 15)
    except (OSError, IndexError, ValueError):
        return None


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
