"""The ``[light_guide]`` and ``[design]`` sections of a job: the slab, its LEDs, and how a
fill map is designed for it, as validated values.

An edge-lit light guide is a clear slab (PMMA) with the dots printed on its bottom face: LED
light enters an edge, is guided by total internal reflection, and leaves the top face where
dots scatter it. What :mod:`optdot.optics` needs to trace it:

``[light_guide]`` (every length in mm, in the job's panel coordinates)

- ``thickness``: slab thickness, mm (required; phones 0.3-0.5, notebooks 0.4-0.6).
- ``refractive_index``: of the slab (PMMA 1.49).
- ``absorption``: bulk absorption coefficient, 1/mm (PMMA ~1e-4..1e-3; default 2e-4).
- ``dot_albedo``: diffuse reflectance of a printed dot, 0..1 (default 0.9); the rest is
  absorbed in the ink.
- ``dot_scatter``: ``"lambertian"`` (default: a dot reflects diffusely back into the slab;
  what falls inside the escape cone leaves the top, the rest is guided on) or ``"extract"``
  (the idealised extractor of the 1-D model of Lee et al. 2005: a dot sends what it reflects
  straight out of the top at the hit point; for validation against the closed forms).
- ``reflector``: reflectance of the sheet under the guide, 0..1 (default 0.95; 0 for none
  or black).
- ``reflector_finish``: ``"diffuse"`` (default: a white sheet, light back Lambertian) or
  ``"specular"`` (a metal or multilayer mirror film: light back at the angle it left).
- ``edge_reflectance``: reflectance of what covers the edges, 0..1 (default 0.9, white
  tape; 0: nothing comes back). Light that total internal reflection or Fresnel keeps
  inside the slab stays inside.
- ``edge_finish``: ``"diffuse"`` (default: tape in air; what leaves an edge comes back
  Lambertian), ``"specular"`` (a mirror film in air) or ``"absorbing"`` (black paint in
  optical contact: every ray that reaches an edge is absorbed; ``edge_reflectance`` unused).

``[[light_guide.leds]]`` (one table per row of LEDs)

- ``edge``: ``"bottom"`` (y = ymin), ``"top"`` (y = ymax), ``"left"`` (x = xmin) or
  ``"right"`` (x = xmax) of the panel's box.
- ``positions``: LED centres along that edge, mm (x for bottom/top, y for left/right).
- ``width``: width of each LED's emitting face along the edge, mm (default 3).
- ``power``: relative flux of each LED of this row (default 1).
- ``profile``: angular distribution in air about the edge normal: ``"lambertian"``
  (default), a table ``[[angle_deg, intensity], ...]`` (0..90°, rotationally symmetric),
  or ``"collimated"`` (one angle, ``tilt`` degrees off the edge normal in the vertical
  plane, half upward, half downward: the one-angle source of the 1-D closed forms).
- ``tilt``: the collimated source's angle in air, degrees (default 30).

``[design]`` (``optdot design``)

- ``cell``: size of the designed map's cells, mm (default 1; a tenth of the LED pitch
  for a direct-lit grid).
- ``fill_range``: ``[min, max]`` fill fraction of the designed map (default
  ``[0, 0.4]``; ``[0, 0.7]`` on a film, see :mod:`optdot.config.backlight`); a guide's
  map is scaled so its largest fill reaches ``max`` (the most light a tool-able pattern
  extracts), a film's so its emptiest judged cell holds ``min``. Above ~0.45, 46 µm dots
  cannot keep 60 µm apart (at 0.45 2 % of the dots are in closer pairs, at 0.5 nearly
  all): a film's design then asks for larger dots.
- ``target``: optional CSV grid of relative luminance to follow (row 0 = bottom), any
  resolution over the panel box; default uniform.
- ``iterations``: most iterations (default 16).
- ``rays``: rays of the last iteration (default: 400 per cell); the first runs 1/16 of it.
- ``smoothing``: Gaussian sigma of the update, in cells (default 1).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import JobError
from ..geometry.limits import MAX_RANDOM_FILL

EDGES = ("bottom", "top", "left", "right")
DOT_SCATTER = ("lambertian", "extract")
EDGE_FINISH = ("diffuse", "specular", "absorbing")
#: How a reflector sheet returns light: Lambertian, or mirrored.
REFLECTOR_FINISH = ("diffuse", "specular")

LIGHT_GUIDE_KEYS: dict[str, tuple[type, ...]] = {
    "thickness": (int, float),
    "refractive_index": (int, float),
    "absorption": (int, float),
    "dot_albedo": (int, float),
    "dot_scatter": (str,),
    "reflector": (int, float),
    "reflector_finish": (str,),
    "edge_reflectance": (int, float),
    "edge_finish": (str,),
    "leds": (list,),
}
LED_KEYS: dict[str, tuple[type, ...]] = {
    "edge": (str,),
    "positions": (list,),
    "width": (int, float),
    "power": (int, float),
    "profile": (str, list),
    "tilt": (int, float),
}
DESIGN_KEYS: dict[str, tuple[type, ...]] = {
    "cell": (int, float),
    "fill_range": (list,),
    "target": (str,),
    "iterations": (int,),
    "rays": (int,),
    "smoothing": (int, float),
    "tolerance": (int, float),
}


@dataclass(frozen=True)
class Leds:
    """One row of LEDs on one edge.

    Attributes:
        edge: ``"bottom" | "top" | "left" | "right"``.
        positions: ``[k]`` centres along the edge, mm (panel coordinates).
        width: emitting width of each, mm.
        power: relative flux of each.
        profile: ``"lambertian"``, ``"collimated"`` or a table ``[m, 2]`` of (angle in
            degrees, relative intensity) in air.
        tilt: the collimated source's angle in air, degrees.
    """

    edge: str
    positions: tuple[float, ...]
    width: float = 3.0
    power: float = 1.0
    profile: str | tuple[tuple[float, float], ...] = "lambertian"
    tilt: float = 30.0


@dataclass(frozen=True)
class LightGuide:
    """The slab and its LEDs (units: mm, 1/mm; reflectances 0..1). See the module doc."""

    thickness: float
    leds: tuple[Leds, ...]
    refractive_index: float = 1.49
    absorption: float = 2e-4
    dot_albedo: float = 0.9
    dot_scatter: str = "lambertian"
    reflector: float = 0.95
    edge_reflectance: float = 0.9
    edge_finish: str = "diffuse"
    reflector_finish: str = "diffuse"

    @property
    def critical_angle(self) -> float:
        """Angle of total internal reflection from the face normal, radians."""
        return math.asin(1.0 / self.refractive_index)


@dataclass(frozen=True)
class DesignParams:
    """``[design]``: see the module doc.

    Attributes:
        cell: designed map cell, mm, or None for the default (a tenth of a direct-lit
            grid's LED pitch, else 1 mm).
        fill_range: ``(min, max)`` fill fraction.
        target: relative luminance ``[ny, nx]`` (row 0 = bottom) over the panel box, or None.
        iterations: most iterations.
        rays: rays of the last iteration, or None for 400 per cell.
        smoothing: Gaussian sigma of the update, cells.
        target_file: the file ``target`` came from.
        tolerance: the luminance RMS beyond the rays' noise (a share of the mean) at or
            under which a design may stop before ``iterations`` (once its map's updates
            also take turns: :class:`optdot.optics.design.Update`); None: 0.3 of the
            noise (:data:`optdot.optics.design.SETTLED_SHARE`); 0 runs every iteration.
    """

    cell: float | None = None
    fill_range: tuple[float, float] = (0.0, 0.4)
    target: np.ndarray | None = field(default=None, compare=False)
    iterations: int = 16
    rays: int | None = None
    smoothing: float = 1.0
    target_file: Path | None = None
    tolerance: float | None = None


def typed_keys(sec: dict[str, Any], keys: dict[str, tuple[type, ...]], label: str, where: str):
    """Refuse a key of table ``label`` not in ``keys`` or of a type it does not allow."""
    for key, value in sec.items():
        if key not in keys:
            raise JobError(
                f"{where}: unknown key '{label}.{key}' (allowed in [{label}]: {', '.join(keys)})"
            )
        types = keys[key]
        if isinstance(value, bool) or not isinstance(value, types):
            names = " or ".join(t.__name__ for t in types)
            raise JobError(f"{where}: {label}.{key} = {value!r} must be {names}")


def number_in(sec, key, default, lo, hi, where, label, unit="", lo_open=False, hi_open=False):
    """``sec[key]`` (or ``default``) as a float within ``lo..hi`` (open ends as asked), or
    a one-line :class:`JobError` naming ``label.key``."""
    try:
        v = float(sec.get(key, default))
    except OverflowError:  # an integer of hundreds of digits
        v = math.inf
    ok = math.isfinite(v) and (v > lo if lo_open else v >= lo) and (v < hi if hi_open else v <= hi)
    if not ok:
        a = f"{lo:g} {'<' if lo_open else '<='} x {'<' if hi_open else '<='} {hi:g}"
        raise JobError(f"{where}: {label}.{key} = {v!r} must be {unit}{a}")
    return v


def light_guide_from(
    sec: dict[str, Any], box: tuple[float, float, float, float], where: str
) -> LightGuide:
    """Validate ``[light_guide]`` against the panel box ``(xmin, ymin, xmax, ymax)``, mm.

    Raises:
        JobError: one line naming the key and the problem.
    """
    lab = "light_guide"
    typed_keys(sec, LIGHT_GUIDE_KEYS, lab, where)
    if "thickness" not in sec:
        raise JobError(f"{where}: missing required key light_guide.thickness (mm)")
    t = number_in(sec, "thickness", 0, 0, 100, where, lab, "in mm, ", lo_open=True)
    n = number_in(sec, "refractive_index", 1.49, 1.0, 4.0, where, lab, "", lo_open=True)
    a = number_in(sec, "absorption", 2e-4, 0, 10, where, lab, "in 1/mm, ")
    albedo = number_in(sec, "dot_albedo", 0.9, 0, 1, where, lab)
    refl = number_in(sec, "reflector", 0.95, 0, 1, where, lab)
    edge_r = number_in(sec, "edge_reflectance", 0.9, 0, 1, where, lab)
    scatter = sec.get("dot_scatter", "lambertian")
    if scatter not in DOT_SCATTER:
        raise JobError(
            f"{where}: light_guide.dot_scatter = {scatter!r} must be one of "
            f"{', '.join(DOT_SCATTER)}"
        )
    finish = sec.get("edge_finish", "diffuse")
    if finish not in EDGE_FINISH:
        raise JobError(
            f"{where}: light_guide.edge_finish = {finish!r} must be one of {', '.join(EDGE_FINISH)}"
        )
    mirror = reflector_finish(sec, where, lab)
    rows = sec.get("leds", [])
    if not rows:
        raise JobError(
            f"{where}: light_guide has no LEDs (add [[light_guide.leds]] with edge and positions)"
        )
    leds = tuple(_leds(row, k, box, where) for k, row in enumerate(rows))
    return LightGuide(t, leds, n, a, albedo, scatter, refl, edge_r, finish, mirror)


def reflector_finish(sec: dict[str, Any], where: str, lab: str) -> str:
    """``reflector_finish`` of a section (:data:`REFLECTOR_FINISH`, default diffuse).

    Raises:
        JobError: another value.
    """
    finish = sec.get("reflector_finish", "diffuse")
    if finish not in REFLECTOR_FINISH:
        raise JobError(
            f"{where}: {lab}.reflector_finish = {finish!r} must be one of "
            f"{', '.join(REFLECTOR_FINISH)}"
        )
    return finish


def check_leds_on(guide: LightGuide, geometry, box, where: str) -> None:
    """Refuse LEDs whose emitting face is not on the panel outline's outer boundary (an
    edge the outline does not have there: a notch, a chamfer, a rounded corner)."""
    import shapely
    from shapely.geometry import LineString, MultiPolygon

    polys = list(geometry.geoms) if isinstance(geometry, MultiPolygon) else [geometry]
    boundary = shapely.union_all([p.exterior for p in polys])
    x0, y0, x1, y1 = box
    tol = 1e-3 + 1e-6 * max(x1 - x0, y1 - y0)
    near = boundary.buffer(tol)
    for k, leds in enumerate(guide.leds):
        for p in leds.positions:
            a, b = p - 0.5 * leds.width, p + 0.5 * leds.width
            seg = {
                "bottom": ((a, y0), (b, y0)),
                "top": ((a, y1), (b, y1)),
                "left": ((x0, a), (x0, b)),
                "right": ((x1, a), (x1, b)),
            }[leds.edge]
            if not near.contains(LineString(seg)):
                raise JobError(
                    f"{where}: light_guide.leds[{k}]: the LED at {p:g} mm on the {leds.edge} "
                    f"edge is not on the panel outline (the outline has no {leds.edge} edge "
                    "there)"
                )


def _leds(row: Any, k: int, box, where: str) -> Leds:
    lab = f"light_guide.leds[{k}]"
    if not isinstance(row, dict):
        raise JobError(f"{where}: {lab} must be a table ([[light_guide.leds]])")
    typed_keys(row, LED_KEYS, lab, where)
    for key in ("edge", "positions"):
        if key not in row:
            raise JobError(f"{where}: missing required key {lab}.{key}")
    edge = row["edge"]
    if edge not in EDGES:
        raise JobError(f"{where}: {lab}.edge = {edge!r} must be one of {', '.join(EDGES)}")
    width = number_in(row, "width", 3.0, 0, 1000, where, lab, "in mm, ", lo_open=True)
    power = number_in(row, "power", 1.0, 0, 1e9, where, lab, "", lo_open=True)
    tilt = number_in(row, "tilt", 30.0, 0, 90, where, lab, "in degrees, ", hi_open=True)
    pos = row["positions"]
    if not pos or not all(isinstance(p, int | float) and not isinstance(p, bool) for p in pos):
        raise JobError(f"{where}: {lab}.positions = {pos!r} must be a list of numbers (mm)")
    x0, y0, x1, y1 = box
    lo, hi = (x0, x1) if edge in ("bottom", "top") else (y0, y1)
    for p in pos:
        if not (math.isfinite(p) and lo + 0.5 * width - 1e-9 <= p <= hi - 0.5 * width + 1e-9):
            raise JobError(
                f"{where}: {lab}.positions: an LED {width:g} mm wide at {p!r} mm is off the "
                f"{edge} edge, which runs from {lo:g} to {hi:g} mm"
            )
    profile = led_profile(
        row.get("profile", "lambertian"), ("lambertian", "collimated"), lab, where
    )
    if profile == "collimated" and tilt == 0:
        raise JobError(
            f"{where}: {lab}.tilt = 0 with a collimated profile: the light runs parallel to "
            "the guide's faces and never meets a dot (give a tilt > 0 degrees)"
        )
    return Leds(edge, tuple(float(p) for p in pos), width, power, profile, tilt)


def led_profile(value: Any, names: tuple[str, ...], lab: str, where: str):
    """An LED's ``profile``: one of ``names``, or a table (:func:`profile_table`)."""
    if isinstance(value, str):
        if value not in names:
            raise JobError(
                f"{where}: {lab}.profile = {value!r} must be "
                + ", ".join(repr(n) for n in names)
                + " or a table [[angle_deg, intensity], ...]"
            )
        return value
    return profile_table(value, lab, where)


def profile_table(rows: list, lab: str, where: str) -> tuple[tuple[float, float], ...]:
    """An LED's angular profile ``[[angle_deg, intensity], ...]`` validated (angles rising
    within 0..90, intensities >= 0, not all 0; numbers, not strings that read as them)."""
    numbers = isinstance(rows, list | tuple) and all(
        isinstance(r, list | tuple)
        and all(isinstance(v, int | float) and not isinstance(v, bool) for v in r)
        for r in rows
    )
    try:
        table = np.array(rows, dtype=np.float64) if numbers else np.zeros((0, 0))
    except (TypeError, ValueError):
        table = np.zeros((0, 0))
    ok = table.ndim == 2 and table.shape[1:] == (2,) and len(table) >= 2
    if ok:
        ang, inten = table[:, 0], table[:, 1]
        ok = (
            bool(np.all(np.isfinite(table)))
            and ang[0] >= 0
            and ang[-1] <= 90
            and bool(np.all(np.diff(ang) > 0))
            and bool(np.all(inten >= 0))
            and float(inten.max()) > 0
        )
    if not ok:
        raise JobError(
            f"{where}: {lab}.profile must be [[angle_deg, intensity], ...]: two or more rows "
            "of numbers, angles rising within 0..90, intensities >= 0 and not all 0"
        )
    return tuple((float(a), float(i)) for a, i in table)


#: The default ``[design] fill_range`` of a map printed on a film: ink over the LEDs of a
#: direct-lit backlight blocks most of their light (dots of the sizes a design asks for
#: keep QA's gap to a fill of 0.70).
FILM_FILL_RANGE = (0.0, 0.7)


def design_from(sec: dict[str, Any], base: Path, where: str, film: bool = False) -> DesignParams:
    """Validate ``[design]`` (see the module doc); ``film``: the map is printed on a film
    (its default fill range is :data:`FILM_FILL_RANGE`)."""
    from .grids import load_grid

    typed_keys(sec, DESIGN_KEYS, "design", where)
    cell = (
        number_in(sec, "cell", 1.0, 0.05, 100, where, "design", "in mm, ")
        if "cell" in sec
        else None
    )
    fr = sec.get("fill_range", list(FILM_FILL_RANGE) if film else [0.0, 0.4])
    if not (
        len(fr) == 2
        and all(isinstance(v, int | float) and not isinstance(v, bool) for v in fr)
        and 0 <= fr[0] < fr[1] < MAX_RANDOM_FILL
    ):
        raise JobError(
            f"{where}: design.fill_range = {fr!r} must be [min, max] with 0 <= min < max < "
            f"{MAX_RANDOM_FILL:g} (the densest fill a random pattern reaches; 0.4 keeps 46 µm "
            "dots 60 µm apart)"
        )
    iters = int(sec.get("iterations", 16))
    if not 1 <= iters <= 200:
        raise JobError(f"{where}: design.iterations = {iters} must be 1..200")
    rays = sec.get("rays")
    if rays is not None and not 1000 <= rays <= 10**10:
        raise JobError(f"{where}: design.rays = {rays} must be 1000..1e10")
    smooth = number_in(sec, "smoothing", 1.0, 0, 20, where, "design", "in cells, ")
    tolerance = None
    if "tolerance" in sec:
        tolerance = number_in(sec, "tolerance", 0.0, 0, 1, where, "design", "a share of the mean, ")
    target = None
    if "target" in sec:
        path = base / sec["target"]
        target = load_grid(path)
        if not (np.all(np.isfinite(target)) and target.min() >= 0 and target.max() > 0):
            raise JobError(f"{path}: design.target must hold relative luminances >= 0, not all 0")
    return DesignParams(
        cell,
        (float(fr[0]), float(fr[1])),
        target,
        iters,
        rays,
        smooth,
        base / sec["target"] if "target" in sec else None,
        tolerance,
    )
