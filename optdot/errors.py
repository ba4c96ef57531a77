"""The optdot exception tree.

Every error a user can cause derives from :class:`OptdotError`; the CLI turns it into one
line on stderr and the exit code stored on the class (see README, "Exit codes").
"""

from __future__ import annotations


def one_line(e: BaseException, with_type: bool = False) -> str:
    """A third-party exception as one line for a message: its text with every run of
    whitespace (newlines included) made one space, at most 200 characters, optionally
    after its type name; the type name alone when it has no text."""
    text = " ".join(str(e).split())[:200]
    if not text:
        return type(e).__name__
    return f"{type(e).__name__}: {text}" if with_type else text


#: Longest message printed: a value echoed from a hostile file is cut in the middle.
MAX_MESSAGE = 600


def shorten(text: str, limit: int = MAX_MESSAGE) -> str:
    """``text`` as one line (whitespace runs made one space) of at most ``limit``
    characters, its middle replaced by `` ... `` when longer (the file name at the start
    and the reason at the end survive)."""
    text = " ".join(text.split())
    if len(text) <= limit:
        return text
    keep = (limit - 5) // 2
    return f"{text[:keep]} ... {text[-keep:]}"


class OptdotError(Exception):
    """Base class of every error optdot raises on purpose."""

    exit_code = 2


class JobError(OptdotError):
    """The job file (or a file it names) is missing, malformed or out of range."""


class GeometryError(OptdotError):
    """The panel outline, holes or keep-out zones are invalid."""


class PatternFileError(OptdotError):
    """A pattern file (CSV/NPZ/GDS/OAS/DXF) cannot be read."""


class ExportError(OptdotError):
    """An output file cannot be written."""


class ResourceError(OptdotError):
    """The job would need more memory than this machine has."""


class ClusterError(OptdotError):
    """The Dask cluster cannot be reached or started, or lost the job (exit 4)."""

    exit_code = 4


class QAGateError(OptdotError):
    """The QA gate failed, so nothing was written (``export`` without ``force``).

    Attributes:
        result: the :class:`~optdot.quality.gate.QAResult` that failed.
    """

    exit_code = 1

    def __init__(self, result) -> None:
        self.result = result
        super().__init__(
            f"QA gate failed, nothing written ({result.failures()}); use --force to write anyway"
        )


class GuaranteeError(OptdotError):
    """The optimizer could not deliver the spacing/placement guarantee (never silent)."""

    exit_code = 3
