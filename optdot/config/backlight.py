"""The ``[backlight]`` section of a job: the stack around the printed dots, as validated values.

A backlight is a stack. ``[light_guide]`` alone is today's edge-lit guide (its dots on the
guide's bottom face). ``[backlight]`` describes the rest:

``kind = "direct"``: a direct-lit (mini-LED) backlight. LEDs on a reflector sheet shine up
through an air cavity onto the film the dots are printed on (dots facing the LEDs), and
diffuser sheets above it send light on or back (recycled).

``kind = "edge"``: the ``[light_guide]`` with a film (and sheets) above it, as in the paper's
Figure 1. ``print`` says which face carries the job's dots; the other face's fill comes
from ``other_map`` (a CSV grid over the panel box, or one number).

Keys (every length in mm, panel coordinates; reflectances and transmittances 0..1)

``[backlight]``

- ``kind``: ``"direct"`` or ``"edge"`` (required).
- ``print``: ``"film"`` (default) or, for ``"edge"``, ``"guide"``: the face the job's
  pattern is printed on.
- ``other_map``: ``"edge"`` only: the fill of the face the job does not print (the guide's
  designed map when the film is printed; the film's when the guide is), a CSV path or a
  number (default 0: bare).
- ``frame``: reflectance of the frame around the cavity, film and sheets (default 0.9).
- ``frame_finish``: ``"diffuse"`` (default), ``"specular"`` or ``"absorbing"``.

``[backlight.leds]`` (``"direct"``; on the reflector)

- ``pitch = [px, py]`` and ``offset = [x, y]`` (the first LED's centre; default half a
  pitch from the panel box's corner): a grid filling the panel box; or ``positions =
  [[x, y], ...]``.
- ``size``: the side of each square emitter (default 0.2).
- ``power``: relative flux of each (default 1).
- ``profile``: ``"lambertian"`` (default), ``"batwing"`` (``I ∝ cos θ (1 + 3 sin² θ)``,
  peaking at 55°, the side-emitting mini-LED of DBR-capped chips), or a table
  ``[[angle_deg, intensity], ...]`` about the normal.
- ``cap``: the diameter of a disc of solid ink printed on the film over each LED
  (default 0: none; :mod:`optdot.geometry.caps`). The dots keep out of each cap and a
  ring of QA's close gap around it; the cap plus that ring must fit between the LEDs and
  inside the panel.
- ``cap_ink``: grade the caps (default: solid). A list of ink shares in [0, 1], one for
  each band of equal width from the cap's centre out, each printed as a ring of that
  share of the band's area (:func:`optdot.geometry.caps.ring_table`); or ``"design"``:
  ``optdot design`` sizes them (bands of :data:`~optdot.geometry.caps.RING_PITCH` mm) and
  writes the list into the job it writes. A job whose caps are still ``"design"`` cannot
  be generated.

``[backlight.cavity]`` (``"direct"``)

- ``gap``: reflector to the printed face of the film, the optical distance (required).
- ``reflector``: reflectance of the sheet carrying the LEDs (default 0.95).
- ``reflector_finish``: ``"diffuse"`` (default: a white sheet) or ``"specular"`` (a metal
  or multilayer mirror film: light back at the angle it came).

``[backlight.film]`` (the film or plate the dots are printed on, on its bottom face)

- ``thickness`` (required), ``refractive_index`` (default 1.59, PC), ``absorption``
  (1/mm, default 0).
- ``dot_reflectance`` (default 0.85) and ``dot_transmittance`` (default 0.10): the white
  ink's diffuse reflectance and transmittance; the rest is absorbed.
- ``haze``: the film's top face: ``"none"`` (default, clear), ``"lambertian"`` (what it
  transmits leaves Lambertian) or a number, a Gaussian spread in degrees.
- ``gap``: ``"edge"`` only: the air between the guide's top face and the film (default 0).

``[[backlight.sheets]]`` (above the film, bottom to top)

- ``kind = "diffuser"``; ``transmittance`` (required), ``reflectance`` (default: the rest,
  ``1 - transmittance``; diffuse, recycled); ``spread``: ``"lambertian"`` (default) or a
  Gaussian spread of what it transmits, degrees; ``gap``: air under the sheet (default 0).
- ``kind = "prism"``: a prism sheet (BEF): a flat base under straight prisms, traced
  surface by surface (:mod:`optdot.optics.faces.prism_sheet`); ``refractive_index``
  (default 1.58), ``apex_angle`` (degrees, default 90), ``grooves``: the axis the prisms
  run along, ``"x"`` (default) or ``"y"`` (two crossed sheets: one of each); ``gap``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import JobError
from .light_guide import EDGE_FINISH, led_profile, number_in, reflector_finish, typed_keys

KINDS = ("direct", "edge")
PRINTS = ("film", "guide")
SHEET_KINDS = ("diffuser", "prism")
#: Most LEDs of a direct-lit grid (a 65-inch mini-LED TV has ~20,000 zones).
MAX_LEDS = 1_000_000

BACKLIGHT_KEYS: dict[str, tuple[type, ...]] = {
    "kind": (str,),
    "print": (str,),
    "other_map": (str, int, float),
    "frame": (int, float),
    "frame_finish": (str,),
    "leds": (dict,),
    "cavity": (dict,),
    "film": (dict,),
    "sheets": (list,),
}
GRID_LED_KEYS: dict[str, tuple[type, ...]] = {
    "pitch": (list,),
    "offset": (list,),
    "positions": (list,),
    "size": (int, float),
    "power": (int, float),
    "profile": (str, list),
    "cap": (int, float),
    "cap_ink": (str, list),
}
CAVITY_KEYS: dict[str, tuple[type, ...]] = {
    "gap": (int, float),
    "reflector": (int, float),
    "reflector_finish": (str,),
}
FILM_KEYS: dict[str, tuple[type, ...]] = {
    "thickness": (int, float),
    "refractive_index": (int, float),
    "absorption": (int, float),
    "dot_reflectance": (int, float),
    "dot_transmittance": (int, float),
    "haze": (str, int, float),
    "gap": (int, float),
}
SHEET_KEYS: dict[str, tuple[type, ...]] = {
    "kind": (str,),
    "transmittance": (int, float),
    "reflectance": (int, float),
    "spread": (str, int, float),
    "gap": (int, float),
    "refractive_index": (int, float),
    "apex_angle": (int, float),
    "grooves": (str,),
}
#: The keys of each sheet kind (``kind`` and ``gap`` every kind's).
SHEET_KIND_KEYS = {
    "diffuser": ("transmittance", "reflectance", "spread"),
    "prism": ("refractive_index", "apex_angle", "grooves"),
}


@dataclass(frozen=True)
class GridLeds:
    """LEDs on the reflector of a direct-lit backlight.

    Attributes:
        positions: ``[k, 2]`` centres, mm.
        size: side of each square emitter, mm.
        power: relative flux of each.
        profile: ``"lambertian"``, ``"batwing"`` or a table ``((angle_deg, intensity),
            ...)`` about the normal.
        pitch: ``(px, py)`` of the grid, mm, or None for a list.
        cap: diameter of the ink cap printed over each LED, mm (0: none).
        cap_ink: ``(share, ...)`` of each band of a graded cap, ``"design"`` (the design
            sizes them), or None for solid caps.
    """

    positions: np.ndarray = field(compare=False)
    size: float = 0.2
    power: float = 1.0
    profile: str | tuple[tuple[float, float], ...] = "lambertian"
    pitch: tuple[float, float] | None = None
    cap: float = 0.0
    cap_ink: tuple[float, ...] | str | None = None


@dataclass(frozen=True)
class Film:
    """The printed film or plate (see the module doc). haze: ``"none"``,
    ``"lambertian"`` or a Gaussian spread in degrees."""

    thickness: float
    refractive_index: float = 1.59
    absorption: float = 0.0
    dot_reflectance: float = 0.85
    dot_transmittance: float = 0.10
    haze: str | float = "none"
    gap: float = 0.0


@dataclass(frozen=True)
class Sheet:
    """A sheet above the film: a diffuser (``transmittance``, ``reflectance``, ``spread``:
    ``"lambertian"`` or degrees) or a prism sheet (``refractive_index``, ``apex_angle``
    degrees, ``grooves``: the axis the prisms run along, ``"x"`` or ``"y"``)."""

    transmittance: float
    reflectance: float
    spread: str | float = "lambertian"
    gap: float = 0.0
    kind: str = "diffuser"
    refractive_index: float = 1.58
    apex_angle: float = 90.0
    grooves: str = "x"


@dataclass(frozen=True)
class Backlight:
    """The stack (see the module doc).

    Attributes:
        kind: ``"direct"`` or ``"edge"``.
        film: the printed film (None only for ``"edge"`` without one: not allowed).
        sheets: diffuser sheets above the film, bottom to top.
        leds: the direct-lit LEDs, or None for ``"edge"``.
        gap: reflector to the film's printed face (direct), mm.
        reflector: the reflector's reflectance (direct).
        frame, frame_finish: the frame around the air layers, film and sheets.
        print: the face the job's pattern is printed on: ``"film"`` or ``"guide"``.
        other_map: the fill of the other printed face (edge): a number or ``[ny, nx]``
            grid over the panel box (row 0 = bottom).
        other_file: the file ``other_map`` came from, or None.
        reflector_finish: how the reflector returns light (direct): ``"diffuse"`` or
            ``"specular"``.
    """

    kind: str
    film: Film
    sheets: tuple[Sheet, ...] = ()
    leds: GridLeds | None = None
    gap: float = 0.0
    reflector: float = 0.95
    frame: float = 0.9
    frame_finish: str = "diffuse"
    print: str = "film"
    other_map: float | np.ndarray = field(default=0.0, compare=False)
    other_file: Path | None = None
    reflector_finish: str = "diffuse"

    @property
    def direct(self) -> bool:
        """Direct-lit: LEDs in a cavity under the printed film (else edge-lit: a guide)."""
        return self.kind == "direct"

    @property
    def on_film(self) -> bool:
        """The job's pattern is printed on the film (else on the guide's face)."""
        return self.print == "film"

    @property
    def ink_contrast(self) -> float:
        """``k`` of the film's relative transmission ``1 - k phi`` at fill ``phi``: ``1 -
        T_ink / T_clear`` (the ink's diffuse transmittance over the clear face's share of
        Lambertian light), at least 0.05. The film rule of ``design`` steps on it, and QA
        reads a coverage error through it."""
        t_clear = clear_transmittance(self.film.refractive_index)
        return max(0.05, 1.0 - self.film.dot_transmittance / t_clear)

    @property
    def pitch(self) -> float | None:
        """The smaller LED pitch of a direct-lit grid, mm (None for a list or edge-lit)."""
        if self.leds is None or self.leds.pitch is None:
            return None
        return min(self.leds.pitch)


def clear_transmittance(n: float) -> float:
    """Share of Lambertian light a clear face of index ``n`` lets through from air (1 -
    the hemispherical mean of the unpolarised Fresnel reflectance)."""
    theta = np.linspace(0.0, 0.5 * math.pi, 2001)[:-1]
    c = np.cos(theta)
    s = np.sin(theta) / n
    t = np.sqrt(1 - s * s)
    rs = (c - n * t) / (c + n * t)
    rp = (t - n * c) / (t + n * c)
    r = 0.5 * (rs * rs + rp * rp)
    w = np.sin(2 * theta)
    return float(1.0 - np.sum(r * w) / np.sum(w))


def backlight_from(
    sec: dict[str, Any],
    box: tuple[float, float, float, float],
    has_guide: bool,
    base: Path,
    where: str,
) -> Backlight:
    """Validate ``[backlight]`` against the panel box ``(xmin, ymin, xmax, ymax)``, mm.

    Args:
        has_guide: the job has a ``[light_guide]`` (what ``kind = "edge"`` needs).

    Raises:
        JobError: one line naming the key and the problem.
    """
    lab = "backlight"
    typed_keys(sec, BACKLIGHT_KEYS, lab, where)
    if "kind" not in sec:
        raise JobError(f"{where}: missing required key backlight.kind ({' or '.join(KINDS)})")
    kind = sec.get("kind")
    if kind not in KINDS:
        raise JobError(f"{where}: backlight.kind = {kind!r} must be one of {', '.join(KINDS)}")
    printed = sec.get("print", "film")
    if printed not in PRINTS or (kind == "direct" and printed != "film"):
        allowed = "film" if kind == "direct" else "film or guide"
        raise JobError(
            f"{where}: backlight.print = {printed!r} must be {allowed} (the face the job's dots "
            "are printed on)"
        )
    if "film" not in sec:
        raise JobError(
            f"{where}: [backlight] has no film to print on (add [backlight.film] with its "
            "thickness)"
        )
    frame = number_in(sec, "frame", 0.9, 0, 1, where, lab)
    finish = sec.get("frame_finish", "diffuse")
    if finish not in EDGE_FINISH:
        raise JobError(
            f"{where}: backlight.frame_finish = {finish!r} must be one of {', '.join(EDGE_FINISH)}"
        )
    film = _film(sec["film"], kind, where)
    sheets = tuple(_sheet(s, k, where) for k, s in enumerate(sec.get("sheets", [])))
    if kind == "edge":
        if not has_guide:
            raise JobError(f'{where}: backlight.kind = "edge" needs a [light_guide] under the film')
        for key in ("leds", "cavity"):
            if key in sec:
                raise JobError(
                    f'{where}: backlight.{key} is for kind = "direct" (an edge-lit guide has '
                    "its LEDs in [[light_guide.leds]])"
                )
        other, other_file = _other_map(sec.get("other_map", 0.0), base, where)
        return Backlight(
            kind, film, sheets, None, 0.0, 0.95, frame, finish, printed, other, other_file
        )
    if "other_map" in sec:
        raise JobError(f'{where}: backlight.other_map is for kind = "edge" (one printed face)')
    if "leds" not in sec:
        raise JobError(f"{where}: [backlight] of kind direct has no [backlight.leds]")
    if "cavity" not in sec:
        raise JobError(f"{where}: [backlight] of kind direct has no [backlight.cavity] (its gap)")
    cav = sec["cavity"]
    typed_keys(cav, CAVITY_KEYS, "backlight.cavity", where)
    if "gap" not in cav:
        raise JobError(f"{where}: missing required key backlight.cavity.gap (mm)")
    gap = number_in(cav, "gap", 0, 0, 1000, where, "backlight.cavity", "in mm, ", lo_open=True)
    refl = number_in(cav, "reflector", 0.95, 0, 1, where, "backlight.cavity")
    mirror = reflector_finish(cav, where, "backlight.cavity")
    leds = _grid_leds(sec["leds"], box, where)
    return Backlight(
        kind, film, sheets, leds, gap, refl, frame, finish, printed, reflector_finish=mirror
    )


def _film(sec: Any, kind: str, where: str) -> Film:
    lab = "backlight.film"
    if not isinstance(sec, dict):
        raise JobError(f"{where}: {lab} must be a table ([backlight.film])")
    typed_keys(sec, FILM_KEYS, lab, where)
    if "thickness" not in sec:
        raise JobError(f"{where}: missing required key {lab}.thickness (mm)")
    t = number_in(sec, "thickness", 0, 0, 100, where, lab, "in mm, ", lo_open=True)
    n = number_in(sec, "refractive_index", 1.59, 1.0, 4.0, where, lab)
    a = number_in(sec, "absorption", 0.0, 0, 10, where, lab, "in 1/mm, ")
    r = number_in(sec, "dot_reflectance", 0.85, 0, 1, where, lab)
    tr = number_in(sec, "dot_transmittance", 0.10, 0, 1, where, lab)
    if r + tr > 1 + 1e-12:
        raise JobError(
            f"{where}: {lab}.dot_reflectance + dot_transmittance = {r + tr:g} must be <= 1 "
            "(the rest is absorbed in the ink)"
        )
    haze = _spread(sec.get("haze", "none"), f"{lab}.haze", where, allow_none=True)
    if "gap" in sec and kind != "edge":
        raise JobError(
            f'{where}: {lab}.gap is for kind = "edge" (a direct-lit film\'s distance is '
            "backlight.cavity.gap)"
        )
    gap = number_in(sec, "gap", 0.0, 0, 1000, where, lab, "in mm, ")
    return Film(t, n, a, r, tr, haze, gap)


def _spread(value: Any, lab: str, where: str, allow_none: bool = False) -> str | float:
    names = ("none", "lambertian") if allow_none else ("lambertian",)
    if isinstance(value, str):
        if value not in names:
            raise JobError(
                f"{where}: {lab} = {value!r} must be {' or '.join(repr(n) for n in names)} or a "
                "Gaussian spread in degrees"
            )
        return value
    v = float(value)
    if not (math.isfinite(v) and 0 < v <= 90):
        raise JobError(f"{where}: {lab} = {value!r} must be a spread in degrees, 0 < x <= 90")
    return v


#: The sharpest prism sheet traced, degrees (films are made 60-110°): of Lambertian light
#: from below, a 0.01° apex holds 89 % between its facets past 4,096 surfaces (counted
#: absorbed, by a film that absorbs nothing), 1° 0.3 %, 10° 3 in 10⁶, 20° none of 10⁶.
MIN_APEX = 10.0


def _sheet(sec: Any, k: int, where: str) -> Sheet:
    lab = f"backlight.sheets[{k}]"
    if not isinstance(sec, dict):
        raise JobError(f"{where}: {lab} must be a table ([[backlight.sheets]])")
    kind = sec.get("kind", "diffuser")
    if not isinstance(kind, str) or kind not in SHEET_KINDS:
        raise JobError(f"{where}: {lab}.kind = {kind!r} must be one of {', '.join(SHEET_KINDS)}")
    mine = ("kind", "gap", *SHEET_KIND_KEYS[kind])
    other = [k for k in sec if k in SHEET_KEYS and k not in mine]
    if other:  # another kind's key
        raise JobError(f"{where}: {lab}.{other[0]} is not a key of a {kind} sheet")
    typed_keys(sec, {k: SHEET_KEYS[k] for k in mine}, lab, where)  # unknown: this kind's listed
    gap = number_in(sec, "gap", 0.0, 0, 1000, where, lab, "in mm, ")
    if kind == "prism":
        n = number_in(sec, "refractive_index", 1.58, 1.0, 3.0, where, lab, "", lo_open=True)
        apex = number_in(
            sec, "apex_angle", 90.0, MIN_APEX, 180, where, lab, "in degrees, ", hi_open=True
        )
        grooves = sec.get("grooves", "x")
        if grooves not in ("x", "y"):
            raise JobError(f'{where}: {lab}.grooves = {grooves!r} must be "x" or "y"')
        return Sheet(1.0, 0.0, "lambertian", gap, kind, n, apex, grooves)
    if "transmittance" not in sec:
        raise JobError(f"{where}: missing required key {lab}.transmittance")
    t = number_in(sec, "transmittance", 0, 0, 1, where, lab, "", lo_open=True)
    r = number_in(sec, "reflectance", 1.0 - t, 0, 1, where, lab)
    if t + r > 1 + 1e-12:
        raise JobError(
            f"{where}: {lab}.transmittance + reflectance = {t + r:g} must be <= 1 (the rest is "
            "absorbed)"
        )
    spread = _spread(sec.get("spread", "lambertian"), f"{lab}.spread", where)
    return Sheet(t, r, spread, gap, kind)


def _pair(value: Any, lab: str, where: str) -> tuple[float, float]:
    ok = (
        isinstance(value, list)
        and len(value) == 2
        and all(isinstance(v, int | float) and not isinstance(v, bool) for v in value)
        and all(math.isfinite(v) for v in value)
    )
    if not ok:
        raise JobError(f"{where}: {lab} = {value!r} must be [x, y] in mm")
    return float(value[0]), float(value[1])


def _grid_leds(sec: Any, box, where: str) -> GridLeds:
    lab = "backlight.leds"
    if not isinstance(sec, dict):
        raise JobError(f"{where}: {lab} must be a table ([backlight.leds])")
    typed_keys(sec, GRID_LED_KEYS, lab, where)
    size = number_in(sec, "size", 0.2, 0, 100, where, lab, "in mm, ", lo_open=True)
    power = number_in(sec, "power", 1.0, 0, 1e9, where, lab, "", lo_open=True)
    profile = led_profile(sec.get("profile", "lambertian"), ("lambertian", "batwing"), lab, where)
    cap = number_in(sec, "cap", 0.0, 0, 100, where, lab, "in mm, ")
    cap_ink = _cap_ink(sec, cap, where)
    x0, y0, x1, y1 = box
    pitch = None
    if "positions" in sec:
        if "pitch" in sec or "offset" in sec:
            raise JobError(f"{where}: {lab}: give positions or pitch (and offset), not both")
        rows = sec["positions"]
        pos = [_pair(r, f"{lab}.positions[{k}]", where) for k, r in enumerate(rows)]
        if not pos:
            raise JobError(f"{where}: {lab}.positions is empty")
        xy = np.array(pos, np.float64)
    else:
        if "pitch" not in sec:
            raise JobError(f"{where}: {lab} needs pitch = [px, py] or positions = [[x, y], ...]")
        px, py = _pair(sec["pitch"], f"{lab}.pitch", where)
        if min(px, py) <= size:
            raise JobError(
                f"{where}: {lab}.pitch = [{px:g}, {py:g}] mm must be larger than the LEDs "
                f"({size:g} mm)"
            )
        ox, oy = _pair(sec.get("offset", [0.5 * px, 0.5 * py]), f"{lab}.offset", where)
        fx = math.floor((x1 - 0.5 * size - ox) / px + 1e-9) + 1.0
        fy = math.floor((y1 - 0.5 * size - oy) / py + 1e-9) + 1.0
        if fx >= 1 and fy >= 1 and fx * fy > MAX_LEDS:
            raise JobError(
                f"{where}: {lab}.pitch = [{px:g}, {py:g}] mm puts more than {MAX_LEDS:,} LEDs "
                "on the panel"
            )
        nx, ny = int(max(fx, 0)), int(max(fy, 0))
        if nx < 1 or ny < 1:
            raise JobError(
                f"{where}: {lab}.offset = [{ox:g}, {oy:g}] mm puts no LED on the panel "
                f"({x0:g}..{x1:g} x {y0:g}..{y1:g} mm)"
            )
        if nx * ny > MAX_LEDS:
            raise JobError(f"{where}: {lab}: {nx * ny:,} LEDs, more than {MAX_LEDS:,}")
        gx, gy = np.meshgrid(ox + px * np.arange(nx), oy + py * np.arange(ny))
        xy = np.column_stack([gx.ravel(), gy.ravel()])
        pitch = (px, py)
    if len(xy) > MAX_LEDS:
        raise JobError(f"{where}: {lab}: {len(xy):,} LEDs, more than {MAX_LEDS:,}")
    h = 0.5 * size
    bad = (xy[:, 0] - h < x0 - 1e-9) | (xy[:, 0] + h > x1 + 1e-9)
    bad |= (xy[:, 1] - h < y0 - 1e-9) | (xy[:, 1] + h > y1 + 1e-9)
    if bad.any():
        k = int(np.argmax(bad))
        raise JobError(
            f"{where}: {lab}: the LED at ({xy[k, 0]:g}, {xy[k, 1]:g}) mm ({size:g} mm square) "
            f"is outside the panel ({x0:g}..{x1:g} x {y0:g}..{y1:g} mm)"
        )
    if pitch is None and len(xy) > 1:
        from scipy.spatial import cKDTree

        d, _ = cKDTree(xy).query(xy, k=2)
        if float(d[:, 1].min()) < size:
            k = int(np.argmin(d[:, 1]))
            raise JobError(
                f"{where}: {lab}.positions: the LED at ({xy[k, 0]:g}, {xy[k, 1]:g}) mm is "
                f"{d[k, 1]:.3g} mm from the next, closer than its size ({size:g} mm)"
            )
    return GridLeds(xy, size, power, profile, pitch, cap, cap_ink)


#: Most bands a graded cap may have.
MAX_CAP_BANDS = 10_000


def _cap_ink(sec: dict, cap: float, where: str) -> tuple[float, ...] | str | None:
    """``backlight.leds.cap_ink`` checked: None, ``"design"`` or the bands' shares."""
    if "cap_ink" not in sec:
        return None
    lab = "backlight.leds.cap_ink"
    v = sec["cap_ink"]
    if cap <= 0:
        raise JobError(f"{where}: {lab} grades caps, but backlight.leds.cap is 0 (no caps)")
    if isinstance(v, str):
        if v != "design":
            raise JobError(f'{where}: {lab} = {v!r} must be "design" or a list of ink shares')
        return v
    ok = 0 < len(v) <= MAX_CAP_BANDS and all(
        isinstance(f, (int, float)) and not isinstance(f, bool) and 0 <= f <= 1 for f in v
    )
    if not ok:
        raise JobError(
            f"{where}: {lab} must be 1 to {MAX_CAP_BANDS:,} ink shares in [0, 1] (one a band "
            "from the centre out)"
        )
    return tuple(float(f) for f in v)


def led_caps(backlight: Backlight | None, domain, gap: float, where: str):
    """``domain`` (a :class:`~optdot.geometry.domain.Domain`) with the caps of
    ``backlight.leds.cap`` cut out (:func:`optdot.geometry.caps.with_caps`), or
    ``domain`` when there are none.

    Raises:
        JobError: a cap with its ring of QA's close gap ``gap`` (mm) reaches another
            LED's, or a cap reaches past the panel outline.
    """
    if backlight is None or backlight.leds is None or backlight.leds.cap <= 0:
        return domain
    import shapely

    from ..geometry.caps import cap_array, design_bands, ring_table, with_caps

    leds = backlight.leds
    xy = leds.positions
    lab = "backlight.leds.cap"
    if len(xy) > 1:
        from scipy.spatial import cKDTree

        d, _ = cKDTree(xy).query(xy, k=2)
        k = int(np.argmin(d[:, 1]))
        if leds.cap + gap >= d[k, 1]:
            raise JobError(
                f"{where}: {lab} = {leds.cap:g} mm: the cap and QA's close gap "
                f"({gap * 1e3:.3g} µm) need more than the {d[k, 1]:.3g} mm between the LEDs "
                f"at ({xy[k, 0]:g}, {xy[k, 1]:g}) mm and the next"
            )
    panel = domain.slab if domain.slab is not None else domain.geometry
    outer = shapely.Polygon(panel.exterior) if hasattr(panel, "exterior") else panel
    inside = shapely.covers(
        outer.buffer(1e-9), shapely.buffer(shapely.points(xy), 0.5 * leds.cap, quad_segs=16)
    )
    if not inside.all():
        k = int(np.argmin(inside))
        raise JobError(
            f"{where}: {lab} = {leds.cap:g} mm: the cap over the LED at ({xy[k, 0]:g}, "
            f"{xy[k, 1]:g}) mm reaches past the panel outline"
        )
    rings = None
    if leds.cap_ink == "design":  # the design's start: bare bands
        rings = ring_table(leds.cap, np.zeros(design_bands(leds.cap)))
    elif leds.cap_ink is not None:
        rings = ring_table(leds.cap, np.array(leds.cap_ink))
    return with_caps(domain, cap_array(xy, leds.cap), gap, rings)


def check_leds_inside(backlight: Backlight, geometry, where: str) -> None:
    """Refuse direct-lit LEDs whose emitter is not inside the panel outline (in a hole, a
    notch or a keep-out is allowed: the film is clear there; off the outline is not)."""
    if backlight.leds is None:
        return
    import shapely

    leds = backlight.leds
    h = 0.5 * leds.size
    xy = leds.positions
    squares = shapely.box(xy[:, 0] - h, xy[:, 1] - h, xy[:, 0] + h, xy[:, 1] + h)
    outer = shapely.Polygon(geometry.exterior) if hasattr(geometry, "exterior") else geometry
    inside = shapely.covers(outer.buffer(1e-9), squares)
    if not inside.all():
        k = int(np.argmin(inside))
        raise JobError(
            f"{where}: backlight.leds: the LED at ({xy[k, 0]:g}, {xy[k, 1]:g}) mm is outside "
            "the panel outline"
        )


def _other_map(value: Any, base: Path, where: str) -> tuple[float | np.ndarray, Path | None]:
    if isinstance(value, str):
        from .grids import load_grid

        path = base / value
        grid = load_grid(path, "backlight.other_map grid")
        if not (np.all(np.isfinite(grid)) and grid.min() >= 0 and grid.max() <= 1):
            raise JobError(f"{path}: backlight.other_map must hold fill fractions 0..1")
        return grid, path
    v = float(value)
    if not (math.isfinite(v) and 0 <= v <= 1):
        raise JobError(f"{where}: backlight.other_map = {value!r} must be a fill 0..1 or a CSV")
    return v, None
