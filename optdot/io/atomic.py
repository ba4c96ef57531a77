"""Write files so that a failure never leaves a wrong file behind.

Every output is written to a temporary file beside the target, flushed to disk
(``fsync``), checked by a verifier that reads it back cheaply (size, closing record,
record count), given the permissions of the file it replaces, and only then renamed over
the target. A write error (full disk, file-size limit, read-only place) or a failed check
removes the temporary file, leaves the target as it was and raises
:class:`~optdot.errors.ExportError` naming the file and the reason.

A directory output (a dataset) is built beside its target and put in place whole by
:func:`install_directory`.

Several outputs of one command form one :func:`transaction`: each is written and verified
to its temporary file, and only when all are ready are they renamed, together; a failure or
an interrupt before that replaces none of them and leaves no temporary file. A
transaction keeps masks (a target named like one, and the targets it is told to keep): an
existing one is replaced only by the same bytes, else none of the outputs is.
"""

from __future__ import annotations

import contextlib
import contextvars
import ctypes
import ctypes.util
import filecmp
import os
import shutil
import stat
import tempfile
from collections.abc import Callable, Iterable, Iterator
from pathlib import Path

from ..errors import ExportError
from ..files import KINDS
from ..formats import looks_like_mask
from ..runtime.stop import check_interrupt, interrupted, mark_interrupted

__all__ = [
    "atomic_path",
    "expect_size",
    "expect_tail",
    "interrupted",
    "mark_interrupted",
    "fsync_dir",
    "install_directory",
    "refuse_read_only",
    "short_name",
    "transaction",
    "writable_target",
]

#: ``verify(tmp_path)``: raise :class:`ExportError` (or ``OSError``) if the file is wrong.
Verifier = Callable[[Path], None]


def writable_target(target: str | Path) -> Path:
    """The path a file output really replaces: ``target``, or the file a symbolic link
    points to (the link is kept, as ``cp`` writes through it).

    Only a regular file or a new name is ever replaced: renaming onto a device node
    (``/dev/null``), a FIFO or a socket would put a regular file in its place.

    Raises:
        ExportError: something other than a regular file is in the way.
    """
    target = Path(target)
    if target.is_symlink():
        target = Path(os.path.realpath(target))
    try:
        mode = os.lstat(target).st_mode
    except FileNotFoundError:
        return target
    except OSError as e:
        raise ExportError(f"{target}: cannot check ({e.strerror or e})") from None
    if not stat.S_ISREG(mode):
        kind = KINDS.get(stat.S_IFMT(mode), "not a regular file")
        raise ExportError(
            f"{target}: is {kind}; optdot replaces only regular files (choose a file name)"
        )
    return target


def lacks_text(path: Path, text: bytes, block: int = 1 << 20) -> bool:
    """Whether the file ``path`` does not hold the bytes ``text`` anywhere (read in
    blocks that overlap by ``len(text)``; an unreadable file holds nothing)."""
    tail = b""
    try:
        with open(path, "rb") as fh:
            while chunk := fh.read(block):
                if text in tail + chunk:
                    return False
                tail = chunk[-len(text) :]
    except OSError:
        return True
    return True


def refuse_read_only(target: Path) -> None:
    """A file whose write bits are all off was protected on purpose: never replace it
    (checked on the mode, so that it holds for root too)."""
    try:
        mode = target.stat().st_mode
    except OSError:
        return
    if stat.S_ISREG(mode) and not mode & 0o222:
        raise ExportError(
            f"{target}: is read-only (mode {stat.S_IMODE(mode):04o}); "
            "make it writable to replace it"
        )


def short_name(name: str, limit: int = 120) -> str:
    """At most ``limit`` bytes of a file name, for temporaries beside long-named files."""
    raw = os.fsencode(name)[:limit]
    return os.fsdecode(raw.decode("utf-8", "ignore").encode("utf-8"))


@contextlib.contextmanager
def atomic_path(target: str | Path, verify: Verifier | None = None) -> Iterator[Path]:
    """Yield a temporary path in the target's directory; on success, flush it to disk,
    verify it and rename it onto ``target``.

    On any exception the temporary file is removed and ``target`` is left untouched.

    Raises:
        ExportError: the directory does not exist or is not writable, writing failed
            (the OS reason), or ``verify`` found the file wrong.
    """
    target = writable_target(target)
    directory = target.parent if str(target.parent) else Path(".")
    if not directory.is_dir():
        raise ExportError(f"{target}: output directory {directory} does not exist")
    refuse_read_only(target)
    try:
        fd, tmp = tempfile.mkstemp(
            prefix=f".{short_name(target.name)}.", suffix=".tmp", dir=directory
        )
    except OSError as e:
        raise ExportError(f"{target}: cannot write here ({e.strerror})") from None
    os.close(fd)
    tmp_path = Path(tmp)
    pending = _PENDING.get()
    try:
        yield tmp_path
        _fsync(tmp_path)
        if verify is not None:
            verify(tmp_path)
        os.chmod(tmp_path, _mode_of(target))
        check_interrupt()
        if pending is not None:
            pending.append((tmp_path, target))  # renamed when the transaction commits
            return
        writable_target(target)  # still a regular file (or nothing) just before the rename
        os.replace(tmp_path, target)
        fsync_dir(directory)
    except OSError as e:
        with contextlib.suppress(OSError):
            tmp_path.unlink()
        reason = e.strerror or str(e) or type(e).__name__
        raise ExportError(f"{target}: cannot write ({reason})") from None
    except BaseException:
        with contextlib.suppress(OSError):
            tmp_path.unlink()
        raise


#: The outputs of the open :func:`transaction`: (temporary file, target), in write order.
_PENDING: contextvars.ContextVar[list[tuple[Path, Path]] | None] = contextvars.ContextVar(
    "optdot_pending_outputs", default=None
)


@contextlib.contextmanager
def transaction(
    keep: Iterable[str | Path] = (), hint: str = "", replace_masks: bool = False
) -> Iterator[None]:
    """Make every :func:`atomic_path` inside the block one all-or-nothing set of outputs.

    Each file is written and verified as usual, but renamed onto its target only when the
    block ends without an exception; on any exception (``KeyboardInterrupt`` included)
    every temporary file is removed and no target changes. Nested blocks join the outer one.

    Args:
        keep: targets that must not change: when one exists and its new content differs
            byte for byte, nothing is replaced (writing the same bytes again is allowed,
            so a repeated run succeeds). Every target named like a mask
            (:func:`optdot.formats.looks_like_mask`) is kept too, unless ``replace_masks``.
        hint: what the user gives to replace a kept file anyway (for the message).
        replace_masks: let targets named like masks be replaced (``export --overwrite``).

    Raises:
        ExportError: a kept target would change (one line naming it and ``hint``).
    """
    if _PENDING.get() is not None:
        yield
        return
    kept = {_real(p) for p in keep}
    pending: list[tuple[Path, Path]] = []
    token = _PENDING.set(pending)
    try:
        yield
    except BaseException:
        for tmp, _ in pending:
            with contextlib.suppress(OSError):
                tmp.unlink()
        raise
    finally:
        _PENDING.reset(token)
    if interrupted():
        for tmp, _ in pending:
            with contextlib.suppress(OSError):
                tmp.unlink()
        raise KeyboardInterrupt
    done = 0
    try:
        for tmp, target in pending:
            writable_target(target)
            guarded = _real(target) in kept or (not replace_masks and looks_like_mask(target))
            if guarded and target.exists() and not filecmp.cmp(tmp, target, False):
                raise ExportError(
                    f"{target}: a different file is already there and is kept"
                    f" ({hint or 'a mask is not replaced here: give another name'}); "
                    "nothing was written"
                )
        for tmp, target in pending:
            os.replace(tmp, target)
            done += 1
    except (OSError, ExportError) as e:
        for later, _ in pending[done:]:
            with contextlib.suppress(OSError):
                later.unlink()
        if isinstance(e, ExportError):
            raise
        raise ExportError(f"{target}: cannot replace ({e.strerror})") from None
    for directory in {target.parent for _, target in pending}:
        fsync_dir(directory)


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


def _real(path: str | Path) -> Path:
    """``path`` with symbolic links and ``..`` resolved (how two names of one file compare)."""
    return Path(os.path.realpath(path))


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


def fsync_dir(directory: Path) -> None:
    with contextlib.suppress(OSError):  # not every file system can sync a directory
        fd = os.open(directory, os.O_RDONLY)
        try:
            os.fsync(fd)
        finally:
            os.close(fd)


def _exchange(a: Path, b: Path) -> bool:
    """Swap two paths atomically (Linux ``renameat2(RENAME_EXCHANGE)``); False where the
    system or the file system cannot."""
    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c"), use_errno=True)
        fn = libc.renameat2
    except (OSError, AttributeError, TypeError):
        return False
    at_fdcwd, rename_exchange = -100, 2
    return fn(at_fdcwd, os.fsencode(a), at_fdcwd, os.fsencode(b), rename_exchange) == 0


def install_directory(new: Path, target: Path) -> None:
    """Put the finished directory ``new`` (beside ``target``) at ``target``.

    A new name is a rename. A directory already at ``target`` (the caller has checked it
    is one it may replace) is exchanged with ``new`` in one step where Linux can
    (``renameat2``), so readers see the old directory or the new one, never neither;
    elsewhere it is moved aside to ``.NAME.old``, ``new`` renamed in, and on a failure
    moved back. The previous directory is then removed and the parent synced.

    Raises:
        ExportError: a rename failed; ``target`` is as it was.
    """
    directory = target.parent if str(target.parent) else Path(".")
    try:
        if not target.is_dir():
            os.rename(new, target)
        elif _exchange(new, target):
            shutil.rmtree(new, ignore_errors=True)  # the previous directory, now at ``new``
        else:
            old = directory / f".{short_name(target.name)}.old"
            os.rename(target, old)
            try:
                os.rename(new, target)
            except OSError:
                os.rename(old, target)
                raise
            shutil.rmtree(old, ignore_errors=True)
    except OSError as e:
        raise ExportError(
            f"{target}: cannot put the new directory in place ({e.strerror})"
        ) from None
    fsync_dir(directory)
