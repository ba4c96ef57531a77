"""What may be read as an input file: a regular file of a size this machine can parse.

A device (``/dev/zero``, ``/dev/urandom``), a FIFO or a directory named as a density grid,
outline, job or pattern would be read until the memory runs out or forever; a file much
larger than what its parser can hold in memory would take the machine down before any
message. Every reader asks :func:`input_problem` first and raises its own error with the
answer (one line naming the file).
"""

from __future__ import annotations

import hashlib
import os
import stat
from pathlib import Path

#: Kinds of file system entries that are not regular files, for messages.
KINDS = {
    stat.S_IFCHR: "a character device",
    stat.S_IFBLK: "a block device",
    stat.S_IFIFO: "a FIFO",
    stat.S_IFSOCK: "a socket",
    stat.S_IFDIR: "a directory",
}

#: Parsing text (CSV, WKT, GeoJSON, DXF) takes up to this many bytes of memory per byte
#: of file (Python floats and lists; ezdxf's entity objects).
TEXT_EXPANSION = 16


def sha256_file(path: str | Path) -> str:
    """SHA-256 of a file's bytes, read in 1 MiB blocks (hex)."""
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def input_problem(path: str | Path, max_bytes: int | None = None) -> str | None:
    """Why ``path`` cannot be read as an input, or None when it can.

    Args:
        path: the input file.
        max_bytes: the largest size accepted (None: the available memory divided by
            :data:`TEXT_EXPANSION`).

    Returns:
        ``"file not found"`` (with the absolute path looked for, when ``path`` is
        relative: a command pasted in another folder), ``"is a FIFO, not a regular
        file"``, ``"is 3.2 GB, more than ..."`` and the like, or None.
    """
    try:
        st = os.stat(path)
    except FileNotFoundError:
        if not os.path.isabs(path):
            return f"file not found (looked for {os.path.abspath(path)})"
        return "file not found"
    except OSError as e:
        return f"cannot read ({e.strerror or e})"
    if not stat.S_ISREG(st.st_mode):
        return f"is {KINDS.get(stat.S_IFMT(st.st_mode), 'not a regular file')}, not a file"
    why = "this reader accepts"
    if max_bytes is None:
        from .runtime.memory import available_bytes

        max_bytes = available_bytes() // TEXT_EXPANSION
        why = "this reader can hold in memory here"
    if st.st_size > max_bytes:
        return f"is {st.st_size / 1e6:,.1f} MB, more than the {max_bytes / 1e6:,.1f} MB {why}"
    return None
