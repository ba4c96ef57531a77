"""``[dots] shape`` and ``[orientation]``: a job's non-circular dot and where it points.

``[dots]``::

    shape = "ellipse"            # "circle" (default), or a kind of optdot.geometry.kinds
    length = 0.080               # mm, the long axis
    width = 0.040                # mm, across it (<= length)
    corner_radius = 0.005        # mm, rounded_rectangle only (0 .. width/2; width/2: capsule)
    scale = [1.0, 2.0]           # optional: sizes vary, each dot this footprint scaled by
                                 # a factor in the range, chosen by the map as a circle's
                                 # diameter is (dots.spacing for the hybrid pitch rule)

``[orientation]`` (one of, for shapes with a long axis; default ``angle = 0``)::

    angle = 30                   # degrees from +x, counter-clockwise, everywhere
    toward = "leds"              # the [light_guide]'s nearest LED ...
    relative = "perpendicular"   # ... long axis across ("perpendicular") or along it
    map = "angles.csv"           # degrees per cell over the panel box, row 0 = bottom
    random = true                # uniform, seeded by optimize.seed

With ``toward`` or ``map``, ``angle`` is added to the field (a turn of every dot).
"""

from __future__ import annotations

import math
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import JobError
from ..geometry.kinds import shaped_names
from ..geometry.limits import DIAMETER_RANGE_MM, MAX_SHAPED_FILL
from ..geometry.orientation import Orientation, led_centres
from ..geometry.profile import HEIGHT_KEY, PROFILES, DotProfile, prism_height
from ..geometry.shapes import CIRCLE, KINDS, DotShape, Kind
from .grids import load_grid

DOT_SHAPE_KEYS: dict[str, tuple[type, ...]] = {
    "shape": (str,),
    **{p: (int, float) for k in KINDS.values() if not k.round for p in k.params},
    **{key: t for k in KINDS.values() for key, t in k.keys.items()},
    "scale": (list,),
}
#: ``[dots]`` keys of a dot's 3-D profile (:mod:`optdot.geometry.profile`).
PROFILE_KEYS: dict[str, tuple[type, ...]] = {
    "profile": (str,),
    **{key: (int, float) for key in HEIGHT_KEY.values()},
    "facets": (list,),
    "cut": (bool,),
}
ORIENTATION_KEYS: dict[str, tuple[type, ...]] = {
    "angle": (int, float),
    "toward": (str,),
    "relative": (str,),
    "map": (str,),
    "random": (bool,),
}
#: Longest footprint drawn, as length over width.
MAX_ASPECT = 50.0


def _a(name: str) -> str:
    """``name`` with its indefinite article ("an ellipse", "a rounded_rectangle")."""
    return ("an " if name[0] in "aeiou" else "a ") + name


def dot_kind(dots: dict[str, Any], where: str) -> Kind:
    """The ``[dots]`` kind (``shape``, default the circle's). A round kind's dots are
    sized by ``dots.diameter`` (a number, a range or a size file); the others' by their
    own keys (:func:`dot_shape`).

    Raises:
        JobError: an unknown kind; a shaped dot's key given for a round kind.
    """
    name = dots.get("shape", CIRCLE.name)
    if name not in KINDS:
        raise JobError(f"{where}: dots.shape = {name!r} must be one of {', '.join(KINDS)}")
    kind = KINDS[name]
    sized = [k for k in DOT_SHAPE_KEYS if k not in ("shape", "scale") and k in dots]
    if kind.round and "scale" in dots:
        raise JobError(
            f"{where}: dots.scale scales a shaped dot; {kind.name}s vary by dots.diameter = "
            "[low, high]"
        )
    if kind.round and sized:
        raise JobError(
            f"{where}: dots.{sized[0]} is a shaped dot's size; {kind.name}s take dots.diameter "
            f"(or set dots.shape = {shaped_names()})"
        )
    return kind


def dot_shape(dots: dict[str, Any], kind: Kind, where: str) -> DotShape:
    """The ``[dots]`` shape of a kind that is not round (:func:`dot_kind`).

    Raises:
        JobError: a size that is missing, not a length or cannot be drawn (length under
            width, a corner radius over half the width, an aspect over
            :data:`MAX_ASPECT`).
    """
    name = kind.name
    sized = [k for k in DOT_SHAPE_KEYS if k not in ("shape", "scale") and k in dots]
    if "diameter" in dots:
        keys = kind.keys if kind.derived else kind.params
        raise JobError(
            f"{where}: dots.diameter is a circle's; {_a(name)} takes "
            + ", ".join(f"dots.{p}" for p in keys)
        )
    lo, hi = DIAMETER_RANGE_MM
    if kind.derived:
        return _derived_shape(kind, dots, sized, where)
    size = []
    for p in kind.params:
        if p not in dots:
            raise JobError(f"{where}: dots.shape = {name!r} needs dots.{p} (mm)")
        v = float(dots[p])
        least = 0.0 if p in kind.zero_params else lo
        if not (math.isfinite(v) and least <= v <= hi):
            raise JobError(
                f"{where}: dots.{p} = {dots[p]!r} must be in mm, {least:g} <= x <= {hi:g}"
            )
        size.append(v)
    for p in sized:
        if p not in kind.params and p not in kind.keys:
            raise JobError(f"{where}: dots.{p} does not apply to {_a(name)}")
    length, width = size[0], size[1]
    if width > length:
        raise JobError(
            f"{where}: dots.width = {width:g} exceeds dots.length = {length:g}: the length is "
            "the long axis (turn the dot with [orientation] angle instead)"
        )
    if length > MAX_ASPECT * width:
        raise JobError(
            f"{where}: dots.length / dots.width = {length / width:.4g} cannot be drawn "
            f"(at most {MAX_ASPECT:g})"
        )
    problem = kind.problem(tuple(size))
    if problem is not None:
        raise JobError(f"{where}: {problem}")
    return DotShape(kind, tuple(size))


def _derived_shape(kind, dots: dict[str, Any], sized: list[str], where: str) -> DotShape:
    """The ``[dots]`` shape of a kind whose sizes its own keys give (a polygon's
    vertices): refuse the size keys, then its sizes as every shape's.

    Raises:
        JobError: a size key given, the kind's keys wrong, a size out of range, an
            aspect over :data:`MAX_ASPECT`.
    """
    for p in sized:
        if p in kind.params:
            raise JobError(
                f"{where}: dots.{p} is not given for {_a(kind.name)}: its "
                f"{' and '.join(kind.params)} come from dots.{', dots.'.join(kind.keys)}"
            )
        if p not in kind.keys:
            raise JobError(f"{where}: dots.{p} does not apply to {_a(kind.name)}")
    try:
        kind, size = kind.from_job(dots, where)
    except ValueError as e:
        raise JobError(f"{where}: {e}") from None
    lo, hi = DIAMETER_RANGE_MM
    for p, v in zip(kind.params, size, strict=True):
        if not lo <= v <= hi:
            raise JobError(
                f"{where}: dots.{next(iter(kind.keys))} make a dot {v:g} mm in {p}; "
                f"it must be {lo:g} <= {p} <= {hi:g} mm"
            )
    narrow = float(kind.narrowest(np.array([size]))[0])
    if narrow < lo:
        raise JobError(
            f"{where}: dots.{next(iter(kind.keys))} make a dot {narrow:g} mm wide at its "
            f"narrowest; it must be at least {lo:g} mm"
        )
    aspect = float(kind.aspect(np.array([size]))[0])
    if aspect > MAX_ASPECT:
        raise JobError(
            f"{where}: dots.{next(iter(kind.keys))} make a dot {aspect:.4g} times longer than "
            f"wide, which cannot be drawn (at most {MAX_ASPECT:g})"
        )
    return DotShape(kind, tuple(size))


#: The lowest bump or dimple, mm (0.1 µm: a cap flatter is the flat face, and a sphere
#: of a vanishing height has no radius a float holds).
MIN_CAP_HEIGHT = 1e-4


def dot_profile(dots: dict[str, Any], shape: DotShape, sizes, guide, backlight, where: str):
    """The ``[dots]`` profile: ``profile = "ink"`` (default); ``"bump"`` with ``height`` or
    ``"dimple"`` with ``depth`` (mm), a cap on a circle's or an ellipse's footprint;
    ``"prism"`` with ``facets = [deg, deg]`` (and ``cut = true`` for one cut into the
    face) on a rectangle's. On dots of several sizes (``sizes``) every cap has the same
    height, and a prism its facets' angles (the longer, the higher).

    Raises:
        JobError: an unknown profile, a key it needs missing or one of another's given, a
            cap taller than a hemisphere on the (smallest) footprint's short axis, facets
            that do not close, a dot as deep or as high as the guide is thick (the
            largest), a footprint the profile does not fit, or a stack whose dots are
            printed on a film (a profile is the guide's).
    """
    name = dots.get("profile", PROFILES[0])
    if name not in PROFILES:
        raise JobError(f"{where}: dots.profile = {name!r} must be one of {', '.join(PROFILES)}")
    own = {**{p: (k,) for p, k in HEIGHT_KEY.items()}, "prism": PRISM_KEYS}
    for other, keys in own.items():
        for key in keys:
            if key in dots and other != name:
                whose = " or ".join(repr(p) for p, ks in own.items() if key in ks)
                raise JobError(
                    f"{where}: dots.{key} belongs to dots.profile = {whose}, not {name!r}"
                )
    if name == PROFILES[0]:
        return DotProfile()
    if name not in shape.kind.profiles:
        fits = [k.name for k in KINDS.values() if name in k.profiles]
        raise JobError(
            f"{where}: dots.profile = {name!r} stands on {' or '.join(fits)} footprints; "
            f"{shape.kind.name} dots take profile = {' or '.join(map(repr, shape.kind.profiles))}"
        )
    if guide is None or (backlight is not None and backlight.on_film):
        raise JobError(
            f"{where}: dots.profile = {name!r} shapes dots in a light guide's face; this job "
            "prints them on a film (or has no [light_guide])"
        )
    if guide.dot_scatter != "lambertian":
        raise JobError(
            f"{where}: light_guide.dot_scatter = {guide.dot_scatter!r} is what ink dots do; "
            f"dots.profile = {name!r} is traced as the structure it is"
        )
    hu, hv, _ = shape.kind.profile_frame(shape.size)
    if sizes is not None:  # the smallest dot bounds a cap, the largest a prism's height
        low, high = shape.scale_of(np.array([sizes.low, sizes.high]))
        hu, hv = hu * high, hv * low
    if name == "prism":
        profile = replace(_prism(dots, 2.0 * hu, where), sized=sizes is not None)
    else:
        profile = _cap(dots, name, hv, where)
    if profile.height >= guide.thickness:  # a dot as deep (or tall) as the guide is thick
        how = "deep" if profile.kind == "dimple" or profile.cut else "high"
        given = "dots.facets" if name == "prism" else f"dots.{HEIGHT_KEY[name]}"
        raise JobError(
            f"{where}: {given} = {dots[given[5:]]!r} makes {name}s {profile.height:.4g} mm "
            f"{how}, not less than the guide's thickness ({guide.thickness:g} mm)"
            + (": give lower facets or shorter dots" if name == "prism" else "")
        )
    return profile


def _cap(dots: dict[str, Any], name: str, hv: float, where: str) -> DotProfile:
    """A bump's or a dimple's profile on a footprint ``hv`` mm half wide
    (:func:`dot_profile`)."""
    key = HEIGHT_KEY[name]
    if key not in dots:
        raise JobError(f"{where}: dots.profile = {name!r} needs dots.{key} (mm)")
    h = float(dots[key])
    if not (math.isfinite(h) and MIN_CAP_HEIGHT <= h <= hv):
        raise JobError(
            f"{where}: dots.{key} = {dots[key]!r} must be in mm, {MIN_CAP_HEIGHT:g} <= {key} "
            f"<= {hv:g} (half the width of the (smallest) dots, {2 * hv:g} mm wide: a cap is "
            "at most a hemisphere)"
        )
    return DotProfile(name, h)


#: ``[dots]`` keys of a prism profile.
PRISM_KEYS = ("facets", "cut")


def _prism(dots: dict[str, Any], length: float, where: str) -> DotProfile:
    """A prism's profile from ``dots.facets`` (and ``dots.cut``) on a footprint ``length``
    mm long (:func:`dot_profile`)."""
    facets = dots.get("facets")
    if facets is None:
        raise JobError(
            f"{where}: dots.profile = 'prism' needs dots.facets = [deg, deg] (each facet's "
            "angle to the face, at the start and the end of the dot's length)"
        )
    ok = isinstance(facets, list) and len(facets) == 2
    ok = ok and all(isinstance(f, int | float) and not isinstance(f, bool) for f in facets)
    if not ok or not all(MIN_FACET <= f < 90.0 for f in facets):
        raise JobError(
            f"{where}: dots.facets = {facets!r} must be two angles in degrees, "
            f"{MIN_FACET:g} <= angle < 90 (a facet at 90 degrees or more does not close the "
            "prism over its footprint)"
        )
    cut = dots.get("cut", False)
    if not isinstance(cut, bool):
        raise JobError(f"{where}: dots.cut = {cut!r} must be true or false")
    pair = (float(facets[0]), float(facets[1]))
    return DotProfile("prism", prism_height(length, pair), pair, cut)


#: The lowest facet angle, degrees (a prism flatter than this is the flat face).
MIN_FACET = 0.5


def shape_sizes(dots: dict[str, Any], shape: DotShape, qa_sec: dict[str, Any], qa, where: str):
    """The size rule of shaped dots (``dots.scale = [low, high]``), as the rule of discs
    of the footprint's area-equivalent diameter scaled by the range
    (:class:`~optdot.geometry.sizes.DotSizes`: the claim rule, or ``dots.spacing``), or
    None when the dots have one size.

    Raises:
        JobError: a scale that is not ``[low, high]`` with ``0 < low < high``, a footprint
            scaled out of the drawable sizes, a circle's size key, a centre distance in
            ``[qa]`` (dots of varying size are judged by edge gaps).
    """
    from ..geometry.sizes import DEFAULT_STEP, DotSizes

    extra = [k for k in ("diameter_grid", "diameter_step") if k in dots]
    if extra:
        raise JobError(
            f"{where}: dots.{extra[0]} is for circles of varying diameter; shaped dots vary by "
            "dots.scale = [low, high] (with dots.spacing for the pitch rule)"
        )
    if "scale" not in dots:
        if "spacing" in dots:
            raise JobError(f"{where}: dots.spacing needs a size range, dots.scale = [low, high]")
        return None
    value = dots["scale"]
    ok = len(value) == 2 and all(
        isinstance(v, int | float) and not isinstance(v, bool) for v in value
    )
    low, high = (float(v) for v in value) if ok else (math.nan, math.nan)
    if not (math.isfinite(low) and math.isfinite(high) and 0 < low < high):
        raise JobError(f"{where}: dots.scale = {value!r} must be [low, high] with 0 < low < high")
    lo, hi = DIAMETER_RANGE_MM
    least, most = min(shape.size[:2]), max(shape.size[:2])
    if low * least < lo or high * most > hi:
        raise JobError(
            f"{where}: dots.scale = {value!r} makes dots {low * least:g} to "
            f"{high * most:g} mm; sizes must stay within {lo:g}..{hi:g} mm"
        )
    for key in ("close_distance", "collision_distance"):
        if key in qa_sec:
            raise JobError(
                f"{where}: qa.{key} is a centre distance, which cannot apply to dots of "
                "varying size; use qa.close_gap (edge gap, mm) and optimize.gap"
            )
    d = shape.equivalent_diameter
    spacing = None
    if "spacing" in dots:
        spacing = float(dots["spacing"])
        if not (math.isfinite(spacing) and low * d < spacing <= 10.0):
            raise JobError(
                f"{where}: dots.spacing = {spacing!r} must be in mm, {low * d:.4g} (the smallest "
                "dot's area-equivalent diameter) < spacing <= 10"
            )
    return DotSizes(low * d, high * d, DEFAULT_STEP, spacing, qa.effective_close_gap)


def orientation(
    sec: dict[str, Any],
    shape: DotShape,
    guide,
    box: tuple[float, float, float, float],
    base: Path,
    seed: int,
    where: str,
    directed: bool = False,
) -> Orientation:
    """The ``[orientation]`` field (default: every dot at 0°); ``directed``: the dots
    look different turned half a turn (prisms whose facets differ), so the field gives
    directions (modulo 2π), not axes.

    Raises:
        JobError: a section for round dots, two ways given, an unknown ``toward`` or
            ``relative``, ``toward = "leds"`` without LEDs, a non-finite angle, an angle
            map that cannot be read or holds NaN.
    """
    period = 2.0 * math.pi if directed else math.pi
    if not sec:
        return Orientation(period=period)
    if shape.kind.round:
        raise JobError(
            f"{where}: [orientation] turns shaped dots; circles have no long axis "
            f"(set dots.shape = {shaped_names()})"
        )
    ways = [k for k in ("toward", "map", "random") if k in sec and sec[k] is not False]
    if len(ways) > 1:
        raise JobError(f"{where}: give one of orientation.{', orientation.'.join(ways)}")
    if "relative" in sec and "toward" not in sec:
        raise JobError(f'{where}: orientation.relative needs orientation.toward = "leds"')
    angle = float(sec.get("angle", 0.0))
    if not (math.isfinite(angle) and abs(angle) <= 360.0):
        raise JobError(f"{where}: orientation.angle = {sec['angle']!r} must be degrees, -360..360")
    if sec.get("random"):
        if "angle" in sec:
            raise JobError(f"{where}: orientation.random and orientation.angle exclude each other")
        return Orientation("random", seed=seed, period=period)
    if "toward" in sec:
        if sec["toward"] != "leds":
            raise JobError(f'{where}: orientation.toward = {sec["toward"]!r} must be "leds"')
        rel = sec.get("relative", "perpendicular")
        if rel not in ("perpendicular", "parallel"):
            raise JobError(
                f'{where}: orientation.relative = {rel!r} must be "perpendicular" or "parallel"'
            )
        if guide is None:
            raise JobError(
                f'{where}: orientation.toward = "leds" needs a [light_guide] with its LEDs'
            )
        turn = 0.5 * math.pi if rel == "perpendicular" else 0.0
        return Orientation(
            "leds", math.radians(angle) + turn, leds=led_centres(guide, box), period=period
        )
    if "map" in sec:
        path = base / sec["map"]
        grid = load_grid(path, "orientation.map")
        bad = ~(np.isfinite(grid) & (np.abs(grid) <= 360.0))
        if bad.any():
            iy, ix = np.argwhere(bad)[0]
            raise JobError(
                f"{path}: orientation.map: row {iy + 1}, column {ix + 1} = "
                f"{float(grid[iy, ix])!r} is not an angle in degrees, -360..360"
            )
        return Orientation(
            "map", math.radians(angle), grid=np.radians(grid), box=box, period=period
        )
    return Orientation("constant", math.radians(angle), period=period)


def check_shaped_fill(job, fill: float, where: str, at: str = "") -> None:
    """Refuse a fill (a map's densest cell, said by ``at``; or ``design.fill_range``'s
    top) that ``job``'s shaped dots cannot be dealt at, naming the largest: their
    footprints grown by half the gap may cover at most :func:`shaped_fill_limit` of it.

    Raises:
        JobError: one line, the effective fill and the largest fill that runs.
    """
    import shapely

    shape = job.shape
    if job.sizes is not None:  # the footprint at the size the rule gives this fill
        scale = job.shape_scale(job.sizes.quantise(job.sizes.raw(np.array([fill]))))
        size = shape.footprints(np.zeros(1), scale).size[0]
        shape = DotShape(shape.kind, tuple(float(v) for v in size))
    ring = shape.kind.outline(np.asarray(shape.size), 0.0, 1e-4 * shape.extent)
    grown = shapely.Polygon(ring).buffer(0.5 * job.optimize.gap, quad_segs=32).area
    spread = grown / shape.area
    size = np.array([shape.size])
    limit = shaped_fill_limit(float(shape.kind.aspect(size)[0])) * float(
        shape.kind.fill_share(size)[0]
    )
    if fill * spread >= limit:
        sizes = " × ".join(f"{v * 1e3:.4g}" for v in shape.size[:2])
        most = limit / spread
        digits = 10 ** (3 - math.floor(math.log10(most)))
        most = math.floor(most * digits) / digits  # 4 digits, rounded down: it runs
        raise JobError(
            f"{where}: fill {fill:.4g}{at} of {sizes} µm "
            f"{shape.kind.name} dots {job.optimize.gap * 1e3:.4g} µm apart is an effective "
            f"fill of {fill * spread:.4g}; dots of this shape reach at most {limit:.3g} "
            f"without collisions (the fill can be at most {most:.4g} here)"
        )


def shaped_fill_limit(aspect: float) -> float:
    """The largest effective fill (footprints grown by half the gap) shaped dots of
    ``aspect`` (length / width) are dealt at: :data:`MAX_SHAPED_FILL` up to 4:1, then
    falling as ``(4 / aspect)^0.75``. Measured (uniform maps, 5 µm gap, random angles):
    2:1 ellipses hold to 0.78, 4:1 prisms to 0.61 and fail at 0.70, 10:1 ellipses fail
    at 0.52, 50:1 ellipses fail at 0.43 and hold at 0.13; the curve passes below every
    failure (10:1: 0.33, 50:1: 0.099), so it may refuse some fills that would run."""
    return MAX_SHAPED_FILL * min(1.0, (4.0 / aspect) ** 0.75)
