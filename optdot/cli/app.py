"""The command group, ``optdot generate | export | qa | check``: exit codes, one-line errors,
signals, crash logs.

Exit codes (README, "Exit codes"): 0 success; 1 the QA gate failed; 2 bad input (job,
grid, pattern file, option, unwritable output, too big for memory); 3 the optimizer could
not meet the spacing guarantee; 70 internal error (a bug: traceback in a log file);
130 interrupted. Every failure is one line on stderr.
"""

from __future__ import annotations

import functools
import os
import platform
import signal
import sys
import tempfile
import time
import traceback
import warnings

import click

from ..errors import OptdotError, QAGateError, one_line, shorten

#: Exit code of an unexpected internal error (sysexits' EX_SOFTWARE).
EXIT_INTERNAL = 70


def user_errors(fn):
    """Turn :class:`OptdotError` into one line on stderr and its exit code."""

    @functools.wraps(fn)
    def wrapper(*args, **kwargs):
        from ..runtime.stop import interrupted

        previous = {s: signal.signal(s, _terminate) for s in (signal.SIGTERM, signal.SIGINT)}
        done = False
        try:
            if interrupted():  # a signal before this handler (while modules loaded)
                raise KeyboardInterrupt
            out = fn(*args, **kwargs)
            if interrupted():  # the interrupt was swallowed inside compiled code
                raise KeyboardInterrupt
            done = True
            return out
        except QAGateError as e:
            click.echo(f"optdot: {one_line(e)}", err=True)
            sys.exit(e.exit_code)
        except OptdotError as e:
            click.echo(f"optdot: error: {shorten(str(e))}", err=True)
            sys.exit(e.exit_code)
        except KeyboardInterrupt:
            from ..runtime.stop import stop_note

            note = stop_note()
            click.echo("optdot: interrupted" + (f"; {note}" if note else ""), err=True)
            sys.exit(130)
        except Exception as e:
            if not _caused_by_interrupt(e):
                raise
            # numba turns an interrupt raised while it calls back into Python (cache
            # loading) into SystemError "returned a result with an exception set"
            click.echo("optdot: interrupted", err=True)
            sys.exit(130)
        finally:
            for s, handler in previous.items():
                # the default action (SIGTERM's: die, exit 143) would hide how the
                # command ended from a signal that comes while the process exits
                signal.signal(s, handler if handler != signal.SIG_DFL else _after(done))

    return wrapper


def _after(done: bool):
    """The handler for a signal that comes after the command ended: its outputs are
    complete (exit 0) or it is already exiting with its error's code (ignored)."""
    if not done:
        return signal.SIG_IGN

    def finished(signum, frame):
        sys.exit(0)

    return finished


def _terminate(signum, frame):
    """SIGTERM and SIGINT: from now on no output replaces anything, and the run stops at
    its next safe point (the next iteration, or before any file is replaced). An exception
    raised at an arbitrary point can land inside numba's compiler or cache loader, which
    then crashes the process (SIGSEGV seen in testing); a second signal stops at once."""
    from ..runtime.stop import interrupted, mark_interrupted

    if interrupted():
        raise KeyboardInterrupt
    mark_interrupted()


def _caused_by_interrupt(e: BaseException) -> bool:
    from ..runtime.stop import interrupted

    seen = set()
    while e is not None and id(e) not in seen:
        if isinstance(e, KeyboardInterrupt):
            return True
        seen.add(id(e))
        e = e.__cause__ or e.__context__
    return interrupted()


class _Command(click.Group):
    """The ``optdot`` group: one top-level handler, so that every failure, a usage error
    or a bug, ends as one line and a documented exit code (never a traceback)."""

    def invoke(self, ctx):
        """The command; an ``EOFError`` out of it passed on as the failure it is. click
        reads one as a prompt's input ended (an abort: "interrupted", exit 130, after a
        blank line); optdot prompts for nothing, so one is a file or a library cut short."""
        try:
            return super().invoke(ctx)
        except EOFError as e:
            if _caused_by_interrupt(e):
                raise KeyboardInterrupt from e
            raise RuntimeError(f"EOFError: {one_line(e) or 'input ended early'}") from e

    def main(self, args=None, prog_name=None, complete_var=None, standalone_mode=True, **extra):
        if not standalone_mode:
            return super().main(args, prog_name, complete_var, False, **extra)
        try:
            with warnings.catch_warnings():
                # numeric warnings are not a user's business: results are checked
                warnings.simplefilter("ignore", RuntimeWarning)
                code = super().main(args, prog_name, complete_var, False, **extra)
        except click.exceptions.NoArgsIsHelpError as e:
            click.echo(e.ctx.get_help() if e.ctx else str(e), err=True)
            sys.exit(e.exit_code)
        except click.ClickException as e:
            click.echo(f"optdot: error: {shorten(_usage_line(e))}", err=True)
            sys.exit(e.exit_code)
        except (click.Abort, KeyboardInterrupt):
            click.echo("optdot: interrupted", err=True)
            sys.exit(130)
        except MemoryError:
            click.echo(
                "optdot: error: out of memory; the input is larger than this machine", err=True
            )
            sys.exit(2)
        except OSError as e:
            name = f"{e.filename}: " if e.filename else ""
            click.echo(f"optdot: error: {name}{e.strerror or e}", err=True)
            sys.exit(2)
        except Exception as e:  # noqa: BLE001 - the last line of defence, logged in full
            log = _write_crash_log(e, args)
            click.echo(
                f"optdot: internal error: {one_line(e, True)} (a bug; traceback in {log})",
                err=True,
            )
            sys.exit(EXIT_INTERNAL)
        sys.exit(code if isinstance(code, int) else 0)


def _usage_line(e: click.ClickException) -> str:
    """click's usage error as one line, naming the command and where help is."""
    msg = " ".join(e.format_message().split())
    ctx = getattr(e, "ctx", None)
    if isinstance(e, click.UsageError) and ctx is not None:
        return f"{ctx.command_path}: {msg} (see '{ctx.command_path} --help')"
    return msg


def _write_crash_log(e: BaseException, args) -> str:
    """Write the traceback of an internal error to a log file; its path (or why not)."""
    from importlib.metadata import version

    stamp = time.strftime("%Y%m%d-%H%M%S")
    try:
        fd, path = tempfile.mkstemp(prefix=f"optdot-error-{stamp}-", suffix=".log")
        with os.fdopen(fd, "w", encoding="utf-8") as fh:
            fh.write(f"optdot {version('optdot')}, Python {platform.python_version()}, ")
            fh.write(f"{platform.platform()}\n")
            fh.write(f"command: optdot {' '.join(sys.argv[1:] if args is None else args)}\n\n")
            fh.write("".join(traceback.format_exception(e)))
    except OSError as err:
        return f"<not written: {err.strerror}>"
    return path


@click.group(cls=_Command, context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(package_name="optdot")
def main() -> None:
    """Non-overlapping random dot patterns for light guides, their masks, and QA."""
