"""Mask and preview writers (installed as ``optdot.exporters``). They read a
:class:`optdot.pattern.Pattern` and never reach into the optimizer or QA.

=========  ======================================================
format     writer
=========  ======================================================
GDSII      :func:`optdot.exporters.gds.write_gds` (gdstk)
OASIS      :func:`optdot.exporters.gds.write_oas` (gdstk)
DXF        :func:`optdot.exporters.dxf.write_dxf` (streamed, ezdxf template)
CSV        :func:`optdot.io.patterns.write_csv`
SVG/PNG    :func:`optdot.exporters.preview.write_svg`, :func:`optdot.exporters.preview.write_png`
Speos      :func:`optdot.exporters.speos.write_speos` (``.OPT3DMapping``, streamed)
=========  ======================================================
"""

from __future__ import annotations

from pathlib import Path

from optdot.io.patterns import write_csv
from optdot.pattern import Pattern

from .options import ExportOptions

FORMATS = ("gds", "oas", "dxf", "csv", "svg", "png", "speos")


def write(pattern: Pattern, fmt: str, path: str | Path, opts: ExportOptions | None = None) -> None:
    """Write ``pattern`` as ``fmt`` (one of :data:`FORMATS`) to ``path``, atomically."""
    opts = opts or ExportOptions()
    if fmt == "gds":
        from .gds import write_gds

        write_gds(pattern, path, opts)
    elif fmt == "oas":
        from .gds import write_oas

        write_oas(pattern, path, opts)
    elif fmt == "dxf":
        from .dxf import write_dxf

        write_dxf(pattern, path, opts)
    elif fmt == "csv":
        write_csv(pattern, path)
    elif fmt == "speos":
        from .speos import write_speos

        write_speos(pattern, path, opts)
    elif fmt == "svg":
        from .preview import write_svg

        write_svg(pattern, path)
    elif fmt == "png":
        from .preview import write_png

        write_png(pattern, path)
    else:
        raise ValueError(f"unknown format {fmt!r}")


__all__ = ["FORMATS", "ExportOptions", "write"]
