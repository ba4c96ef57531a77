"""A stop was asked for (SIGTERM, SIGINT): the one flag every stage and writer consults.

The command's signal handler calls :func:`mark_interrupted`; from then on no output
replaces its target (:mod:`optdot.io.atomic`), loops stop at their next safe point
(:func:`check_interrupt`), and waits on other processes give up. The flag is
process-wide: a command runs one job.
"""

from __future__ import annotations

_interrupted = False
_note = ""


def mark_interrupted() -> None:
    """Record that the process was asked to stop (a signal handler calls this): from now
    on no output replaces its target, even where compiled code swallowed the exception
    the handler raised."""
    global _interrupted
    _interrupted = True


def interrupted() -> bool:
    """A stop was requested (see :func:`mark_interrupted`)."""
    return _interrupted


def check_interrupt() -> None:
    """Raise ``KeyboardInterrupt`` when a stop was requested (a safe point)."""
    if _interrupted:
        raise KeyboardInterrupt


def note_on_stop(text: str) -> None:
    """What the stop leaves behind, for the interrupt's one line (a tiled run's finished
    tiles kept for the rerun to resume from)."""
    global _note
    _note = text


def stop_note() -> str:
    """The note :func:`note_on_stop` left, or ""."""
    return _note
