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

from optdot.formats import EXPORTED
from optdot.io.patterns import write_csv
from optdot.pattern import DotSource

from .options import ExportOptions

#: The formats :func:`write` writes (their records: :data:`optdot.formats.FORMATS`).
FORMATS = EXPORTED


def write(pattern: DotSource, fmt: str, path: str | Path, opts: ExportOptions | None = None) -> str:
    """Write ``pattern`` as ``fmt`` (one of :data:`FORMATS`) to ``path``, atomically.

    Masks (GDSII, OASIS, DXF) and Speos files take any :class:`~optdot.pattern.DotSource`
    (a pattern, or a dataset streamed tile by tile); CSV and previews need a
    :class:`~optdot.pattern.Pattern` in memory.

    Returns:
        What the file holds, for the user: ``"GDS, 111,215 dots"``, or for a preview of
        a large pattern ``"SVG preview of a 2.00 x 2.00 mm window: 171 of 281,025 dots"``.
    """
    opts = opts or ExportOptions()
    whole = f"{fmt.upper()}, {pattern.n:,} dots"
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

        shown, (x0, y0, x1, y1) = write_svg(pattern, path)
        if shown < pattern.n:
            return (
                f"SVG preview of a {x1 - x0:.2f} x {y1 - y0:.2f} mm window at ({x0:.2f}, "
                f"{y0:.2f}) mm: {shown:,} of {pattern.n:,} dots"
            )
        return whole
    elif fmt == "png":
        from .preview import write_png

        write_png(pattern, path)
        return f"PNG preview: coverage of {pattern.n:,} dots and a zoomed window"
    else:
        raise ValueError(f"unknown format {fmt!r}")
    return whole


__all__ = ["FORMATS", "ExportOptions", "write"]
