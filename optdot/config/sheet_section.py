"""``[sheet]``: the panel's mask repeated on a production sheet (mm, the mask's
coordinates; see :mod:`optdot.printing.sheet`)::

    rows = 2
    columns = 3
    pitch = [40.0, 30.0]          # from one panel's origin to the next
    fiducials = [[-5, -5], [115, -5], [-5, 55]]
    fiducial = "cross"            # or "disc"
    fiducial_size = 1.0           # a disc's diameter, a cross's span
    label_height = 0.5            # text under each panel (0: none)
    date = "2026-11-28"           # the date the labels state
    cut_width = 0.05              # the cut lines around each panel (0: none)
"""

from __future__ import annotations

import math
from typing import Any

from ..errors import JobError
from ..printing.sheet import FIDUCIALS, Sheet

SHEET_KEYS: dict[str, tuple[type, ...]] = {
    "rows": (int,),
    "columns": (int,),
    "pitch": (list,),
    "fiducials": (list,),
    "fiducial": (str,),
    "fiducial_size": (int, float),
    "label_height": (int, float),
    "date": (str,),
    "cut_width": (int, float),
}
#: Most panels on one sheet.
MAX_PANELS = 10_000


def _number(v) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)


def sheet_from(sec: dict[str, Any], box, scale, where: str) -> Sheet:
    """The ``[sheet]`` section as a :class:`Sheet` for a panel of ``box`` (mm, printed)
    whose mask is ``scale`` (``[2]``) times larger.

    Raises:
        JobError: one line naming the key: counts out of range, a pitch under the
            panel's mask (panels would overlap), bad fiducials or sizes.
    """
    rows, columns = sec.get("rows", 1), sec.get("columns", 1)
    for key, v in (("rows", rows), ("columns", columns)):
        if not 1 <= v <= MAX_PANELS:
            raise JobError(f"{where}: sheet.{key} = {v!r} must be 1..{MAX_PANELS}")
    if rows * columns > MAX_PANELS:
        raise JobError(f"{where}: sheet: {rows} x {columns} panels, more than {MAX_PANELS}")
    width = (box[2] - box[0]) * float(scale[0])
    height = (box[3] - box[1]) * float(scale[1])
    pitch = sec.get("pitch", [width, height])
    if not (len(pitch) == 2 and all(_number(v) and v > 0 for v in pitch)):
        raise JobError(f"{where}: sheet.pitch = {pitch!r} must be [x, y] in mm, > 0")
    for k, (key, n, size) in enumerate((("x", columns, width), ("y", rows, height))):
        if n > 1 and pitch[k] < size:
            raise JobError(
                f"{where}: sheet.pitch = {pitch!r}: {pitch[k]:g} mm along {key} is under the "
                f"panel's mask ({size:.6g} mm): the panels would overlap"
            )
    fid = sec.get("fiducials", [])
    if not all(isinstance(p, list) and len(p) == 2 and all(_number(v) for v in p) for p in fid):
        raise JobError(f"{where}: sheet.fiducials = {fid!r} must be [[x, y], ...] in mm")
    kind = sec.get("fiducial", "cross")
    if kind not in FIDUCIALS:
        raise JobError(f"{where}: sheet.fiducial = {kind!r} must be one of {', '.join(FIDUCIALS)}")
    out = {}
    for key, lo, default in (("fiducial_size", 0.0, 1.0), ("label_height", -1.0, 0.5),
                             ("cut_width", -1.0, 0.05)):  # fmt: skip
        v = sec.get(key, default)
        if not (_number(v) and (v > 0 if lo == 0.0 else v >= 0) and v < 100):
            rng = "0 < x < 100" if lo == 0.0 else "0 <= x < 100"
            raise JobError(f"{where}: sheet.{key} = {v!r} must be in mm, {rng}")
        out[key] = float(v)
    date = sec.get("date", "")
    if len(date) > 32 or not date.isprintable() or not date.isascii():
        raise JobError(f"{where}: sheet.date = {date!r}: at most 32 printable ASCII characters")
    return Sheet(
        rows=rows,
        columns=columns,
        pitch=(float(pitch[0]), float(pitch[1])),
        fiducials=tuple((float(x), float(y)) for x, y in fid),
        fiducial=kind,
        date=date,
        **out,
    )
