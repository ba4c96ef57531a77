"""The optdot exception tree.

Every error a user can cause derives from :class:`OptdotError`; the CLI turns it into one
line on stderr and the exit code stored on the class (see README, "Exit codes").
"""

from __future__ import annotations


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
