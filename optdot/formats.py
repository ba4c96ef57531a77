"""The file formats optdot writes: one record each, read by every place that needs to
know about formats (the ``export`` command's options, the cost estimate, the choice
between writing from a dataset tile by tile or from a pattern in memory, which outputs are
masks kept from being overwritten).

The writers themselves live in :mod:`optdot.exporters` (downstream of this table); a new
format is one :class:`Format` here and one writer there.
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Format:
    """One output format.

    Attributes:
        name: its key and ``export`` option (``"gds"`` → ``--gds``).
        help: the option's help line.
        bytes_per_dot: bytes on disk per dot, measured on the led sample (111,215 dots),
            for the cost estimate; None for a preview, whose size does not grow with dots.
        streamed: written from a dataset tile by tile (the pattern never whole in memory);
            False: the writer needs the whole pattern.
        mask: a tooling deliverable (GDSII, OASIS, DXF): ``export`` keeps an existing one
            that would change unless told ``--overwrite``.
        exported: an ``export`` output (False: written by ``generate`` only).
    """

    name: str
    help: str
    bytes_per_dot: int | None
    streamed: bool = False
    mask: bool = False
    exported: bool = True


#: Every format, in the order the ``export`` command lists them.
FORMATS: dict[str, Format] = {
    f.name: f
    for f in (
        Format("gds", "GDSII mask to write.", 28, streamed=True, mask=True),
        Format("oas", "OASIS mask to write.", 6, streamed=True, mask=True),
        Format("dxf", "DXF drawing to write.", 112, streamed=True, mask=True),
        Format("csv", "CSV pattern to write.", 29),
        Format("svg", "SVG preview to write.", None),
        Format("png", "PNG preview to write.", None),
        Format(
            "speos",
            "Ansys Speos 3D-texture mapping to write (.OPT3DMapping: position and scale per dot).",
            110,
            streamed=True,
        ),
        Format("parquet", "Parquet dataset (a directory of parts).", 19, exported=False),
        Format("npz", "NumPy archive of the pattern.", 16, exported=False),
    )
}

#: The formats ``export`` writes, in its order.
EXPORTED: tuple[str, ...] = tuple(k for k, f in FORMATS.items() if f.exported)
#: The formats written tile by tile from a dataset.
STREAMED: tuple[str, ...] = tuple(k for k, f in FORMATS.items() if f.streamed)
#: The formats that are masks.
MASKS: tuple[str, ...] = tuple(k for k, f in FORMATS.items() if f.mask)
#: File name endings of masks (any case): a file so named is kept from being replaced by
#: a different one, whatever option names it (a report or a CSV given a mask's name).
MASK_SUFFIXES = (".gds", ".gds2", ".gdsii", ".oas", ".oasis", ".dxf")


def looks_like_mask(path) -> bool:
    """Whether ``path``'s name ends like a mask's (:data:`MASK_SUFFIXES`, any case)."""
    return str(path).lower().endswith(MASK_SUFFIXES)


__all__ = [
    "EXPORTED",
    "FORMATS",
    "MASKS",
    "MASK_SUFFIXES",
    "STREAMED",
    "Format",
    "looks_like_mask",
]
