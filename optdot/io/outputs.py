"""Checks of a run's outputs before any work: each can be written, none is given twice,
none is an input of the run (:func:`check_outputs`). A ``.parquet`` output is a dataset
directory (:func:`optdot.io.dataset.check_dataset_target`), anything else a file that only
a regular file or a new name may stand in the way of
(:func:`optdot.io.atomic.writable_target`)."""

from __future__ import annotations

import os
from pathlib import Path

from ..errors import ExportError
from .atomic import refuse_read_only, writable_target
from .dataset_write import check_dataset_target


def check_target(target: str | Path, inputs: tuple[Path, ...] = ()) -> None:
    """Refuse, before any work, an output that cannot be written or would overwrite an
    input: a symbolic link loop, a missing or unwritable directory, a directory in the
    way, anything but a regular file in the way (a device node, a FIFO, a socket), a name
    longer than the file system allows, or the same file as one of ``inputs``.

    Raises:
        ExportError: one line naming the file and the problem.
    """
    target = Path(target)
    try:
        target.resolve()
    except (RuntimeError, OSError):  # Python < 3.13 raises RuntimeError on a loop
        raise ExportError(
            f"{target}: is a symbolic link loop (it leads back to itself); remove the link "
            "or choose another name"
        ) from None
    directory = target.parent if str(target.parent) else Path(".")
    if not directory.is_dir():
        raise ExportError(f"{target}: output directory {directory} does not exist")
    try:
        name_max = os.pathconf(directory, "PC_NAME_MAX")
    except (OSError, ValueError):
        name_max = 255
    if len(os.fsencode(target.name)) > name_max:
        raise ExportError(
            f"{target.name[:40]}...: file name is {len(os.fsencode(target.name))} bytes, "
            f"longer than the {name_max} this file system allows"
        )
    if target.suffix.lower() == ".parquet":
        check_dataset_target(target)  # a dataset is a directory it replaces
    else:
        target = writable_target(target)
        directory = target.parent
    refuse_read_only(target)
    if not os.access(directory, os.W_OK | os.X_OK):
        raise ExportError(f"{target}: cannot write in {directory} (permission denied)")
    for src in inputs:
        if _same_file(target, Path(src)):
            raise ExportError(f"{target}: is an input of this run ({src}); choose another name")


def check_outputs(outputs: dict[str, str | Path], inputs: tuple = ()) -> None:
    """Refuse, before any work, a set of outputs (``{what: path}``) in which a path is
    given twice, cannot be written (see :func:`check_target`) or is one of ``inputs``.

    Raises:
        ExportError: one line naming the file and the problem.
    """
    seen: dict[Path, str] = {}
    for what, p in outputs.items():
        check_target(p, inputs)  # first: a link loop gets its own line, not resolve()'s
        rp = Path(p).resolve()
        if rp in seen:
            raise ExportError(f"{p}: given for both --{seen[rp]} and --{what}")
        seen[rp] = what


def _same_file(a: Path, b: Path) -> bool:
    try:
        if a.exists() and b.exists():
            return os.path.samefile(a, b)
    except OSError:
        pass
    return a.resolve() == b.resolve()
