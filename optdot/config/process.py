"""``[process]``: how the masks print (every length in mm)::

    dot_gain = 0.008          # per edge: the print's edge outside the mask's (negative:
                              # an etch that undercuts)
    gain_tolerance = 0.002    # ± on the gain, for the tolerance band
    min_feature = 0.010       # narrowest mask feature: a dot's width, a clear space
    min_space = 0.005         # narrowest printed gap between two dots
    grid = 0.0001             # the mask writer's address grid (default: 1 nm)
    shrink = 0.005            # the moulded part's shrink (or [x, y]): masks scaled 1/(1-s)
    mirror = "x"              # "none", "x" or "y": printed emulsion side down

The pattern is the print; masks (GDSII, OASIS, DXF) carry each footprint shrunk by the
gain (:mod:`optdot.printing`). A job whose dots cannot print is refused here.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from ..errors import JobError
from ..printing.process import MAX_SHRINK, MIRRORS, Process

PROCESS_KEYS: dict[str, tuple[type, ...]] = {
    "dot_gain": (int, float),
    "gain_tolerance": (int, float),
    "min_feature": (int, float),
    "min_space": (int, float),
    "grid": (int, float),
    "shrink": (int, float, list),
    "mirror": (str,),
}
#: Largest dot gain per edge taken, mm.
MAX_GAIN_MM = 1.0


def process_from(sec: dict[str, Any], where: str) -> Process:
    """The ``[process]`` section as a :class:`Process`.

    Raises:
        JobError: one line naming the key and its range.
    """

    def number(key: str, lo: float, hi: float, default: float = 0.0) -> float:
        v = float(sec.get(key, default))
        if not (math.isfinite(v) and lo <= v < hi):
            raise JobError(
                f"{where}: process.{key} = {sec[key]!r} must be in mm, {lo:g} <= x < {hi:g}"
            )
        return v

    gain = float(sec.get("dot_gain", 0.0))
    if not (math.isfinite(gain) and abs(gain) < MAX_GAIN_MM):
        raise JobError(
            f"{where}: process.dot_gain = {sec['dot_gain']!r} must be in mm per edge, "
            f"-{MAX_GAIN_MM:g} < g < {MAX_GAIN_MM:g}"
        )
    shrink = sec.get("shrink", 0.0)
    pair = shrink if isinstance(shrink, list) else [shrink, shrink]
    if len(pair) != 2 or not all(
        isinstance(v, (int, float)) and not isinstance(v, bool) for v in pair
    ):
        raise JobError(f"{where}: process.shrink = {shrink!r} must be a share or [x, y]")
    for v in pair:
        if not (math.isfinite(v) and 0.0 <= v < MAX_SHRINK):
            raise JobError(
                f"{where}: process.shrink = {shrink!r} must be a share, 0 <= s < "
                f"{MAX_SHRINK:g} (moulding resins shrink 0.002-0.008)"
            )
    mirror = sec.get("mirror", "none")
    if mirror not in MIRRORS:
        raise JobError(f"{where}: process.mirror = {mirror!r} must be one of {', '.join(MIRRORS)}")
    return Process(
        dot_gain=gain,
        gain_tolerance=number("gain_tolerance", 0.0, MAX_GAIN_MM),
        min_feature=number("min_feature", 0.0, 10.0),
        min_space=number("min_space", 0.0, 10.0),
        grid=number("grid", 0.0, 1.0),
        shrink=(float(pair[0]), float(pair[1])),
        mirror=mirror,
    )


def check_printable(process: Process, kind, smallest: np.ndarray, where: str) -> None:
    """Refuse, before any work, dots that cannot print: ``smallest`` (``[k]`` mm, the
    job's smallest footprint of ``kind``, as printed) shrunk by the gain must keep a
    width of ``min_feature`` and be exact (the gain within its smallest radius of
    curvature), the gain and its tolerance must not close the gap, and the grid must be
    finer than the gap it keeps.

    Raises:
        JobError: one line naming the key, the figure and what would print.
    """
    g, tol = process.dot_gain, process.gain_tolerance
    size = np.asarray(smallest, float)[None, :]
    width = float(size[0, 1] if len(size[0]) > 1 else size[0, 0])
    um = 1e3
    mask_width = width - 2.0 * g
    if mask_width <= max(process.min_feature, 0.0) or mask_width <= 0:
        least = max(process.min_feature, 0.0) + 2.0 * g
        raise JobError(
            f"{where}: process.dot_gain = {g * um:g} µm leaves the smallest dot "
            f"({width * um:.4g} µm wide) {mask_width * um:.4g} µm wide on the mask, under "
            f"min_feature = {process.min_feature * um:g} µm; the narrowest dot that prints "
            f"is over {least * um:.4g} µm wide"
        )
    floor = float(kind.curvature_floor(size)[0])
    if g > 0 and floor < g:
        if kind.parallel(size, -g) is None:
            raise JobError(
                f"{where}: process.dot_gain = {g * um:g} µm is over the {kind.name}'s "
                f"smallest radius of curvature ({floor * um:.4g} µm): no mask prints it; "
                f"the largest gain it allows is {floor * um:.4g} µm"
            )
        grown = kind.parallel(kind.parallel(size, -g), g)
        lost = float(kind.area(size)[0] - kind.area(grown)[0])
        share = lost / float(kind.area(size)[0])
        raise JobError(
            f"{where}: process.dot_gain = {g * um:g} µm is over the {kind.name}'s corner "
            f"radius ({floor * um:.4g} µm): its print comes out with corners of "
            f"{g * um:g} µm, {lost * um * um:.4g} µm² ({share:.2%}) less per dot; "
            f"give a corner radius of at least {g * um:g} µm"
        )
    gap = process.relaxation_gap(0.0)  # the process's own need, whatever optimize.gap
    if g < 0 and gap + 2.0 * g <= 0:
        raise JobError(
            f"{where}: process.dot_gain = {g * um:g} µm closes the mask's gap between "
            f"dots {gap * um:.4g} µm apart when printed; give min_space or min_feature "
            f"over {-2.0 * g * um:.4g} µm"
        )
    if tol > 0 and process.min_space > 0 and 2.0 * tol >= gap - process.snap_margin:
        raise JobError(
            f"{where}: process.gain_tolerance = ±{tol * um:g} µm closes the "
            f"{(gap - process.snap_margin) * um:.4g} µm gap at its upper end; the printed "
            "gap must outlast the tolerance (raise min_space)"
        )
    need = gap - process.snap_margin
    if process.grid > 0 and (
        process.grid >= 0.1 * mask_width or (need > 0 and process.grid >= need)
    ):
        what = (
            f"the {need * um:.4g} µm gap"
            if need > 0 and process.grid >= need
            else (f"a tenth of the smallest mask dot ({0.1 * mask_width * um:.4g} µm)")
        )
        raise JobError(
            f"{where}: process.grid = {process.grid * um:g} µm is coarser than {what}; "
            "a writer's address grid is a fraction of its smallest feature"
        )
