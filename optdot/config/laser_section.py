"""``[laser]``: a laser dotting machine (``export --laser``)::

    sizes = [0.10, 0.14, 0.18]   # mm: the dot diameters it makes (a pulse set each)
    speed = 300                  # mm/s: the stage's travel speed (for the time estimate)
    acceleration = 3000          # mm/s²
    dwell = 0.002                # s a dot takes at its place

With ``sizes``, every dot takes the nearest size the machine makes, and the job is
generated with those sizes: the guarantee and the coverage hold for the dots it dots.
"""

from __future__ import annotations

import math
from dataclasses import replace
from typing import Any

from ..errors import JobError
from ..geometry.sizes import DotSizes
from ..printing.laser import Laser

LASER_KEYS: dict[str, tuple[type, ...]] = {
    "sizes": (list,),
    "speed": (int, float),
    "acceleration": (int, float),
    "dwell": (int, float),
}
#: How far a one-size job's diameter may lie from the laser's nearest size, as a share.
LASER_FIT = 0.25


def laser_from(sec: dict[str, Any], where: str) -> Laser:
    """The ``[laser]`` section as a :class:`Laser`.

    Raises:
        JobError: one line naming the key and its range.
    """
    sizes = sec.get("sizes")
    if sizes is not None:
        ok = len(sizes) > 0 and all(
            isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) and v > 0
            for v in sizes
        )
        if not ok:
            raise JobError(f"{where}: laser.sizes = {sizes!r} must be dot diameters in mm, > 0")
        sizes = tuple(sorted(float(v) for v in sizes))
    out = {}
    for key in ("speed", "acceleration", "dwell"):
        if key in sec:
            v = float(sec[key])
            least = "0 <= x" if key == "dwell" else "x > 0"
            if not (math.isfinite(v) and (v >= 0 if key == "dwell" else v > 0)):
                raise JobError(f"{where}: laser.{key} = {sec[key]!r} must be a number, {least}")
            out[key] = v
    return Laser(sizes=sizes, **out)


def laser_sizes(
    laser: Laser, diameter: float, sizes: DotSizes | None, shaped: bool, where: str
) -> tuple[float, DotSizes | None]:
    """``(diameter, sizes)`` of a job whose dots a laser of ``sizes`` makes: one size
    takes the laser's nearest; a range takes the laser's sizes within it (one of them: one
    size).

    Raises:
        JobError: shaped dots, or no laser size that fits the job's dots.
    """
    if laser.sizes is None:
        return diameter, sizes
    listed = ", ".join(f"{v * 1e3:g}" for v in laser.sizes)
    if shaped:
        raise JobError(f"{where}: laser.sizes: a laser dots round craters; [dots] has a shape")
    if sizes is None:
        near = float(laser.nearest([diameter])[0])
        if abs(near - diameter) > LASER_FIT * diameter:
            raise JobError(
                f"{where}: laser.sizes = [{listed}] µm: none fits dots.diameter = "
                f"{diameter * 1e3:g} µm (the nearest is {LASER_FIT:.0%} or more off)"
            )
        return near, None
    inside = tuple(v for v in laser.sizes if sizes.low - 1e-9 <= v <= sizes.high + 1e-9)
    if not inside:
        raise JobError(
            f"{where}: laser.sizes = [{listed}] µm: none fits the dots' range "
            f"{sizes.low * 1e3:g}-{sizes.high * 1e3:g} µm"
        )
    if len(inside) == 1:
        return inside[0], None
    return inside[0], replace(sizes, low=inside[0], high=inside[-1], levels=inside)
