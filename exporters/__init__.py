"""Mask and preview writers (installed as ``optdot.exporters``). They read a
:class:`optdot.pattern.Pattern` and never reach into the optimizer or QA. Each format's
record (:data:`optdot.formats.FORMATS`) names its writer and reader; :func:`write` calls
the writer it names.
"""

from __future__ import annotations

import importlib
from collections.abc import Callable
from pathlib import Path

from optdot.formats import EXPORTED
from optdot.formats import FORMATS as ALL
from optdot.pattern import DotSource

from .options import ExportOptions

#: The formats :func:`write` writes (their records: :data:`optdot.formats.FORMATS`).
FORMATS = EXPORTED


def write(pattern: DotSource, fmt: str, path: str | Path, opts: ExportOptions | None = None) -> str:
    """Write ``pattern`` as ``fmt`` (one of :data:`FORMATS`) to ``path``, atomically, with
    the writer its record names.

    Masks (GDSII, OASIS, DXF) and Speos files take any :class:`~optdot.pattern.DotSource`
    (a pattern, or a dataset streamed tile by tile); CSV and previews need a
    :class:`~optdot.pattern.Pattern` in memory.

    Returns:
        What the file holds, for the user: ``"GDS, 111,215 dots"``, or for a preview of
        a large pattern ``"SVG preview of a 2.00 x 2.00 mm window: 171 of 281,025 dots"``.
    """
    if fmt not in FORMATS:
        raise ValueError(f"unknown format {fmt!r}")
    said = named(ALL[fmt].writer)(pattern, path, opts or ExportOptions())
    return said or f"{fmt.upper()}, {pattern.n:,} dots"


def named(ref: str) -> Callable:
    """The function a format's record names, ``"module:function"`` under ``optdot``."""
    module, name = ref.split(":")
    return getattr(importlib.import_module(f"optdot.{module}"), name)


__all__ = ["FORMATS", "ExportOptions", "named", "write"]
