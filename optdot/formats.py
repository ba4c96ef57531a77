"""The file formats optdot writes and reads: one record each, read by every place that
needs to know about formats (the ``export`` command's options, the writer and reader of a
file by its name, the cost estimate, the choice between writing from a dataset tile by
tile or from a pattern in memory, which outputs are masks kept from being overwritten).

The writers and readers live downstream (:mod:`optdot.io`, :mod:`optdot.exporters`); a
record names them (``"module:function"`` under ``optdot``) and
:func:`optdot.exporters.write` and :func:`optdot.exporters.readback.read_any` call what it
names. A new format is one :class:`Format` here and its writer there.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path


@dataclass(frozen=True)
class Format:
    """One file format.

    Attributes:
        name: its key and ``export`` option (``"gds"`` → ``--gds``).
        help: the option's help line.
        suffixes: the file name endings it is known by (lower case, the first its own).
        bytes_per_dot: bytes on disk per dot, measured on the led sample (111,215 dots),
            for the cost estimate; None for a preview, whose size does not grow with dots.
        shaped_bytes_per_dot: the same for shaped dots (a reference rotated by its own
            angle, a size and an angle per row), measured on samples/prisms (15,946
            dots); None: not estimated.
        writer: ``"module:function"`` (under ``optdot``) writing a
            :class:`~optdot.pattern.DotSource` to a path, ``(source, path, options)``,
            returning what the file holds in words or None; None: written by ``generate``
            only.
        reader: ``"module:function"`` reading the file back as a pattern: a mask's
            ``(path, options)``, a pattern file's ``(path, box)``; None: not read.
        streamed: written from a dataset tile by tile (the pattern never whole in memory);
            False: the writer needs the whole pattern.
        mask: a tooling deliverable (GDSII, OASIS, DXF): ``export`` keeps an existing one
            that would change unless told ``--overwrite``.
        exported: an ``export`` output (False: written by ``generate`` only).
    """

    name: str
    help: str
    suffixes: tuple[str, ...]
    bytes_per_dot: int | None
    shaped_bytes_per_dot: int | None = None
    writer: str | None = None
    reader: str | None = None
    streamed: bool = False
    mask: bool = False
    exported: bool = True


#: Every format, in the order the ``export`` command lists them.
FORMATS: dict[str, Format] = {
    f.name: f
    for f in (
        Format(
            "gds", "GDSII mask to write.", (".gds", ".gds2", ".gdsii"), 28, 64,
            "exporters.gds:write_gds", "exporters.readback:read_layout", streamed=True, mask=True,
        ),
        Format(
            "oas", "OASIS mask to write.", (".oas", ".oasis"), 6, 16,
            "exporters.gds:write_oas", "exporters.readback:read_layout", streamed=True, mask=True,
        ),
        Format(
            "dxf", "DXF drawing to write.", (".dxf",), 112, 150,
            "exporters.dxf:write_dxf", "exporters.readback:read_dxf", streamed=True, mask=True,
        ),
        Format(
            "csv", "CSV pattern to write.", (".csv",), 29, 55,
            "io.patterns:write_csv", "io.patterns:load_pattern",
        ),
        Format(
            "svg", "SVG preview to write.", (".svg",), None, None,
            "exporters.preview:write_svg",
        ),
        Format(
            "png", "PNG preview to write.", (".png",), None, None,
            "exporters.preview:write_png",
        ),
        Format(
            "speos",
            "Ansys Speos 3D-texture mapping to write (.OPT3DMapping: position and scale per dot).",
            (".opt3dmapping",), 110, None, "exporters.speos:write_speos", streamed=True,
        ),
        Format(
            "laser",
            "Laser dotting path to write: G-code (.nc, .gcode), HPGL/2 (.plt) or a CSV point "
            "list (.csv), one point per dot with its pulse set, along a short path.",
            (".nc", ".gcode", ".ngc", ".plt", ".hpgl"), 24, None,
            "exporters.laser_path:write_laser",
        ),
        Format(
            "parquet", "Parquet dataset (a directory of parts).", (".parquet",), 19, 30,
            reader="io.patterns:load_pattern", exported=False,
        ),
        Format(
            "npz", "NumPy archive of the pattern.", (".npz",), 16, 20,
            reader="io.patterns:load_pattern", exported=False,
        ),
    )
}  # fmt: skip

#: The formats ``export`` writes, in its order.
EXPORTED: tuple[str, ...] = tuple(k for k, f in FORMATS.items() if f.exported)
#: The formats written tile by tile from a dataset.
STREAMED: tuple[str, ...] = tuple(k for k, f in FORMATS.items() if f.streamed)
#: The formats that are masks.
MASKS: tuple[str, ...] = tuple(k for k, f in FORMATS.items() if f.mask)
#: File name endings of masks (any case): a file so named is kept from being replaced by
#: a different one, whatever option names it (a report or a CSV given a mask's name).
MASK_SUFFIXES: tuple[str, ...] = tuple(x for f in FORMATS.values() if f.mask for x in f.suffixes)
#: The formats read back, in the order messages list them.
READ: tuple[str, ...] = tuple(k for k, f in FORMATS.items() if f.reader is not None)


def format_of(path: str | Path) -> Format | None:
    """The format whose name ends ``path`` (any case), or None."""
    suffix = Path(path).suffix.lower()
    return next((f for f in FORMATS.values() if suffix in f.suffixes), None)


def looks_like_mask(path) -> bool:
    """Whether ``path``'s name ends like a mask's (:data:`MASK_SUFFIXES`, any case)."""
    return str(path).lower().endswith(MASK_SUFFIXES)


__all__ = [
    "EXPORTED",
    "FORMATS",
    "MASKS",
    "MASK_SUFFIXES",
    "READ",
    "STREAMED",
    "Format",
    "format_of",
    "looks_like_mask",
]
