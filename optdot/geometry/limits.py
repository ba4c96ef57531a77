"""The physical sizes optdot accepts, shared by the job reader and the pattern readers.

Anything outside is refused up front, before memory or time is sized from it.
"""

from __future__ import annotations

import numpy as np

from ..errors import PatternFileError

#: Largest panel side, mm (a 100-inch panel is 2.2 m wide).
MAX_EXTENT_MM = 10_000.0
#: Dot diameters, mm (1 µm .. 10 mm).
DIAMETER_RANGE_MM = (0.001, 10.0)

#: Densest fill a random non-overlapping pattern reaches in practice, counting the gap
#: (fill x ((diameter + gap) / diameter)²): OptDot's guarantee holds at 0.78 and fails at
#: 0.80 on uniform maps (measured, 3 x 2 mm, 46 µm); random close packing of disks is
#: ~0.82 (Berryman 1983), the hexagonal lattice 0.9069. Denser means a lattice: moiré.
MAX_RANDOM_FILL = 0.80
#: The same for shaped dots, on the fill of their footprints grown by half the gap
#: (fill x grown area / area): measured on uniform 3 x 3 mm maps, 5 µm gap, 2:1 ellipses
#: (80 x 40 µm) hold the guarantee to 0.78 (fill 0.65, slowly) and 4:1 rounded rectangles
#: (120 x 30 µm, r 5 µm) to 0.61 (fill 0.50) and fail at 0.70 (fill 0.58).
MAX_SHAPED_FILL = 0.66


def validate_dots(path, xy: np.ndarray, diam: np.ndarray, box) -> None:
    """Refuse dots a mask cannot hold before any work is sized from them: NaN, diameters
    outside :data:`DIAMETER_RANGE_MM`, a panel box or dot extent beyond
    :data:`MAX_EXTENT_MM` (QA's rasters would need terabytes).

    Args:
        path: the file, for messages.
        xy: ``[n, 2]`` centres, mm. diam: ``[n]`` diameters, mm.
        box: ``(xmin, ymin, xmax, ymax)`` panel box, mm, or None.

    Raises:
        PatternFileError: one line naming the file and the problem.
    """
    if not np.all(np.isfinite(xy)) or not np.all(np.isfinite(diam)):
        raise PatternFileError(f"{path}: NaN or infinite coordinate or diameter")
    lo_d, hi_d = DIAMETER_RANGE_MM
    if len(diam) and not (lo_d <= diam.min() and diam.max() <= hi_d):
        bad = diam.min() if diam.min() < lo_d else diam.max()
        raise PatternFileError(
            f"{path}: dot diameter {bad:.6g} mm is out of range ({lo_d:g}..{hi_d:g} mm)"
        )
    spans = []
    if len(xy):
        spans += [float(np.ptp(xy[:, 0])), float(np.ptp(xy[:, 1]))]
    if box is not None:
        b = np.asarray(box, dtype=np.float64)
        if not np.all(np.isfinite(b)):
            raise PatternFileError(f"{path}: the panel box {tuple(box)} is not finite")
        spans += [float(b[2] - b[0]), float(b[3] - b[1])]
    if spans and max(spans) > MAX_EXTENT_MM:
        raise PatternFileError(
            f"{path}: the dots or the panel span {max(spans):.4g} mm; optdot handles panels up "
            f"to {MAX_EXTENT_MM:.0f} mm (are the units mm?)"
        )
