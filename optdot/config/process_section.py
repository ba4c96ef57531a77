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
from ..printing.process import DATABASE_UNIT_MM, MAX_SHRINK, MIRRORS, Process

PROCESS_KEYS: dict[str, tuple[type, ...]] = {
    "dot_gain": (int, float),
    "gain_tolerance": (int, float),
    "min_feature": (int, float),
    "min_space": (int, float),
    "grid": (int, float),
    "shrink": (int, float, list),
    "mirror": (str,),
}
#: The share of a curved footprint's smallest radius of curvature a gain may take: nearer
#: the radius, the mask's ends sharpen to a point no writer draws and no reader fits.
CURVATURE_SHARE = 0.9
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
    grid = number("grid", 0.0, 1.0)
    if 0 < grid < DATABASE_UNIT_MM:
        raise JobError(
            f"{where}: process.grid = {sec['grid']!r} is finer than the masks' 1 nm "
            "database unit: give 0 (the 1 nm) or at least 0.000001 mm"
        )
    return Process(
        dot_gain=gain,
        gain_tolerance=number("gain_tolerance", 0.0, MAX_GAIN_MM),
        min_feature=number("min_feature", 0.0, 10.0),
        min_space=number("min_space", 0.0, 10.0),
        grid=grid,
        shrink=(float(pair[0]), float(pair[1])),
        mirror=mirror,
    )


def check_printable(process: Process, kind, smallest: np.ndarray, where: str) -> None:
    """Refuse, before any work, dots that cannot print: ``smallest`` (``[k]`` mm, the
    job's smallest footprint of ``kind``, as printed) shrunk by the gain must keep a
    width of ``min_feature`` after the grid (``√2 grid`` less at most) and be exact (the
    gain within its smallest radius of curvature), the gain and its tolerance must not
    close the gap, and the grid must be finer than the gap it keeps.

    Raises:
        JobError: one line naming the key, the figure and what would print.
    """
    g, tol = process.dot_gain, process.gain_tolerance
    size = np.asarray(smallest, float)[None, :]
    width = float(size[0, 1] if len(size[0]) > 1 else size[0, 0])
    um = 1e3
    mask_width = width - 2.0 * g
    snapped = math.sqrt(2.0) * process.grid  # what the grid may take from a width
    if mask_width - snapped <= max(process.min_feature, 0.0) or mask_width <= 0:
        least = max(process.min_feature, 0.0) + 2.0 * g + snapped
        key = "min_feature" if process.min_feature > 0 else "dot_gain"
        raise JobError(
            f"{where}: process.{key}: the smallest dot ({width * um:.4g} µm wide) less "
            f"twice the dot_gain ({g * um:g} µm) is {mask_width * um:.4g} µm wide on the "
            f"mask, under min_feature = {process.min_feature * um:g} µm; the narrowest dot "
            f"that prints is over {least * um:.4g} µm wide"
        )
    floor = float(kind.curvature_floor(size)[0])
    closed = kind.parallel(size, -g) is not None
    if g > 0 and not closed and floor == 0:
        raise JobError(
            f"{where}: process.dot_gain = {g * um:g} µm rounds every corner of the "
            f"{kind.name} on the print (to {g * um:g} µm): sharp corners print exactly "
            "only with a gain of 0 or less (an etch's bias); round them in the job "
            "(a rounded_rectangle) or give dot_gain <= 0"
        )
    if g > 0 and not closed and g > CURVATURE_SHARE * floor:
        raise JobError(
            f"{where}: process.dot_gain = {g * um:g} µm is over {CURVATURE_SHARE:.0%} of the "
            f"{kind.name}'s smallest radius of curvature ({floor * um:.4g} µm): its mask "
            "would come to a point at each end (none at all past it); the largest gain it "
            f"allows is {CURVATURE_SHARE * floor * um:.4g} µm"
        )
    if g > 0 and floor < g:
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
    need = gap - process.snap_margin  # what the grid may leave of the printed gap
    if g < 0 and need + 2.0 * g <= 0:
        raise JobError(
            f"{where}: process.dot_gain = {g * um:g} µm closes the mask's gap between "
            f"dots {need * um:.4g} µm apart when printed; give min_space or min_feature "
            f"over {-2.0 * g * um:.4g} µm"
        )
    if tol > 0 and process.min_space > 0 and 2.0 * tol >= gap - process.snap_margin:
        raise JobError(
            f"{where}: process.gain_tolerance = ±{tol * um:g} µm closes the "
            f"{(gap - process.snap_margin) * um:.4g} µm gap at its upper end; the printed "
            "gap must outlast the tolerance (raise min_space)"
        )
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


def check_caps(process: Process, rings, where: str) -> None:
    """Refuse caps whose printed rings (``[k, 2]`` ``(r_in, r_out)`` mm, or None) the
    process cannot draw: a ring narrower on the mask than ``min_feature`` (its edges
    each move in by the gain: a ring under twice the gain turns inside out), a clear
    space between rings that a negative gain closes, or a scale per axis (the rings
    would be ellipses).

    Raises:
        JobError: one line naming the ring and the width it needs.
    """
    if rings is None or not len(rings):
        return
    um, g = 1e3, process.dot_gain
    if not process.isotropic:
        raise JobError(
            f"{where}: process.shrink = [{process.shrink[0]:g}, {process.shrink[1]:g}] "
            "scales x and y apart, which would turn the graded caps' rings into ellipses; "
            "give one shrink"
        )
    least = max(process.min_feature, 0.0)
    for k, (r_in, r_out) in enumerate(rings):
        width = (r_out - r_in) if r_in > 0 else 2.0 * r_out  # a disc: its diameter
        on_mask = width - 2.0 * g
        if on_mask <= least or on_mask <= 0:
            raise JobError(
                f"{where}: process.dot_gain = {g * um:g} µm: the caps' ring {k + 1} "
                f"({r_in * um:.4g}-{r_out * um:.4g} µm) is {on_mask * um:.4g} µm wide on the "
                f"mask, not over min_feature = {least * um:g} µm; rings must be over "
                f"{(least + 2.0 * g) * um:.4g} µm wide"
            )
    if g < 0:
        for k in range(1, len(rings)):
            clear = rings[k][0] - rings[k - 1][1] + 2.0 * g
            if rings[k][0] > rings[k - 1][1] and clear <= least:
                raise JobError(
                    f"{where}: process.dot_gain = {g * um:g} µm closes the clear space "
                    f"between the caps' rings {k} and {k + 1} on the mask"
                )
