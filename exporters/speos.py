"""Ansys Speos 3D-texture mapping (``*.OPT3DMapping``): the dots back into the ray tracer.

The format (Speos user guide, "Mapping File"): a text file whose first line is the number
of elements, then one line per element ``x y z ix iy iz jx jy jz kx ky kz``: the
element's origin in the texture's axis system, its X and Y directions, and its scale
along x, y and z (1 = 100 % of the pattern element's size).

optdot writes, per dot: its centre in mm with z = 0, X = (cos a, sin a, 0) and Y =
(-sin a, cos a, 0) for its footprint's orientation a (a circle's is 0: the panel's
axes), and the scale ``d_i / reference`` on all three axes, ``reference`` being
the diameter the Speos pattern element was drawn at (default: the pattern's nominal
diameter, so fixed-size dots all have scale 1). Scaling z too keeps the element's shape
(a moulded micro-dot's depth follows its diameter); for a job whose caps have one height
whatever their size (``[dots] profile = "bump"`` or ``"dimple"``,
:attr:`ExportOptions.fixed_depth`) z is 1. Caps over LEDs (:mod:`optdot.geometry.caps`)
follow the dots, each a disc element scaled to its diameter. Numbers have 6 decimals (1
nm in position). The file is written part by part (a dataset streams tile by tile) and
verified by size before it replaces anything.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from optdot.errors import ExportError
from optdot.io.atomic import atomic_path, expect_size
from optdot.io.patterns import format_fixed6
from optdot.pattern import DotSource, caps_of

from .options import ExportOptions

#: Rows formatted at once (memory of one batch, not of the pattern).
BATCH = 200_000


def write_speos(pattern: DotSource, path: str | Path, opts: ExportOptions) -> None:
    """Write ``pattern`` (a :class:`~optdot.pattern.DotSource`: a pattern or a dataset) as an
    ``.OPT3DMapping`` file, atomically.

    Raises:
        ExportError: no dots, or the file cannot be written whole.
    """
    if pattern.n == 0:
        raise ExportError(f"{path}: the pattern has no dots")
    caps = caps_of(pattern)
    if len(caps) and pattern.outline.cap_rings is not None:
        raise ExportError(
            f"{path}: the pattern prints graded caps over its LEDs (rings), which a mapping "
            "of elements cannot hold; export the caps' rings from the GDSII/OASIS or DXF mask"
        )
    if len(caps) and not pattern.kind.round:
        raise ExportError(
            f"{path}: the pattern prints caps over its LEDs, which a mapping of "
            f"{pattern.kind.name} elements cannot scale into discs; export the caps' "
            "discs separately (gds, oas, dxf)"
        )
    ref = opts.speos_reference_mm or pattern.nominal_diameter
    written = 0

    def lines(xy: np.ndarray, d: np.ndarray, angle: np.ndarray) -> bytes:
        n = len(xy)
        rows = np.zeros((n, 12))
        rows[:, :2] = xy
        c, s = np.cos(angle), np.sin(angle)
        rows[:, 3], rows[:, 4] = c, s  # X direction
        rows[:, 6], rows[:, 7] = 0.0 - s, c  # Y direction (0 - s: no "-0.000000")
        rows[:, 9:] = (d / ref)[:, None]
        if opts.fixed_depth:  # caps of one height on dots of any size
            rows[:, 11] = 1.0
        return format_fixed6(rows).replace(b",", b" ")

    head = f"{pattern.n + len(caps)}\n".encode("ascii")
    with atomic_path(path, _verify(path, lambda: written)) as tmp, open(tmp, "wb") as fh:
        fh.write(head)
        written += len(head)
        for _, xy, footprints in pattern.chunks():  # one part, or one per tile (datasets)
            d, angle = footprints.diameter, footprints.angles
            for a in range(0, len(xy), BATCH):
                data = lines(xy[a : a + BATCH], d[a : a + BATCH], angle[a : a + BATCH])
                fh.write(data)
                written += len(data)
        if len(caps):  # after the dots: a disc element scaled to each cap's diameter
            data = lines(caps[:, :2], caps[:, 2], np.zeros(len(caps)))
            fh.write(data)
            written += len(data)


def _verify(path, size):
    def check(tmp: Path) -> None:
        expect_size(size(), str(path))(tmp)

    return check
