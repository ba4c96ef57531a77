"""Write files so that a failure never leaves a wrong file behind.

Every output is written to a temporary file beside the target, flushed to disk
(``fsync``), checked by a verifier that reads it back cheaply (size, closing record,
record count), given the permissions of the file it replaces, and only then renamed over
the target. A write error (full disk, file-size limit, read-only place) or a failed check
removes the temporary file, leaves the target as it was and raises
:class:`~optdot.errors.ExportError` naming the file and the reason.
"""

from __future__ import annotations

import contextlib
import os
import stat
import tempfile
from collections.abc import Callable, Iterator
from pathlib import Path

from ..errors import ExportError

#: ``verify(tmp_path)``: raise :class:`ExportError` (or ``OSError``) if the file is wrong.
Verifier = Callable[[Path], None]


@contextlib.contextmanager
def atomic_path(target: str | Path, verify: Verifier | None = None) -> Iterator[Path]:
    """Yield a temporary path in the target's directory; on success, flush it to disk,
    verify it and rename it onto ``target``.

    On any exception the temporary file is removed and ``target`` is left untouched.

    Raises:
        ExportError: the directory does not exist or is not writable, writing failed
            (the OS reason), or ``verify`` found the file wrong.
    """
    target = Path(target)
    directory = target.parent if str(target.parent) else Path(".")
    if not directory.is_dir():
        raise ExportError(f"{target}: output directory {directory} does not exist")
    try:
        fd, tmp = tempfile.mkstemp(prefix=f".{target.name}.", suffix=".tmp", dir=directory)
    except OSError as e:
        raise ExportError(f"{target}: cannot write here ({e.strerror})") from None
    os.close(fd)
    tmp_path = Path(tmp)
    try:
        yield tmp_path
        _fsync(tmp_path)
        if verify is not None:
            verify(tmp_path)
        os.chmod(tmp_path, _mode_of(target))
        os.replace(tmp_path, target)
        _fsync_dir(directory)
    except OSError as e:
        with contextlib.suppress(OSError):
            tmp_path.unlink()
        reason = e.strerror or str(e) or type(e).__name__
        raise ExportError(f"{target}: cannot write ({reason})") from None
    except BaseException:
        with contextlib.suppress(OSError):
            tmp_path.unlink()
        raise


def expect_size(size: int, what: str) -> Verifier:
    """A verifier: the file holds exactly ``size`` bytes (what was handed to the OS)."""

    def check(path: Path) -> None:
        got = path.stat().st_size
        if got != size:
            raise ExportError(f"{what}: wrote {got:,} of {size:,} bytes (disk full?)")

    return check


def expect_tail(tail: bytes, what: str) -> Verifier:
    """A verifier: the file ends with ``tail`` (a format's closing record)."""

    def check(path: Path) -> None:
        with open(path, "rb") as fh:
            fh.seek(0, os.SEEK_END)
            n = fh.tell()
            fh.seek(max(n - len(tail), 0))
            if fh.read() != tail:
                raise ExportError(f"{what}: the file is incomplete (no closing record)")

    return check


def _mode_of(target: Path) -> int:
    """The permissions the new file gets: those of the file it replaces, else 0644."""
    try:
        return stat.S_IMODE(target.stat().st_mode)
    except OSError:
        return 0o644


def _fsync(path: Path) -> None:
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def _fsync_dir(directory: Path) -> None:
    with contextlib.suppress(OSError):  # not every file system can sync a directory
        fd = os.open(directory, os.O_RDONLY)
        try:
            os.fsync(fd)
        finally:
            os.close(fd)
