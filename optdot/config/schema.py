"""The TOML job format: its schema, and the reader that turns a file into a :class:`Job`.

The job format is a public contract documented in the README. Unknown sections or keys
are errors, so a typo is never silently ignored. Adding an option: one line in
:data:`SCHEMA` and one field in :mod:`optdot.config.job`.
"""

from __future__ import annotations

import dataclasses
import math
import tomllib
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import GeometryError, JobError, one_line
from ..files import input_problem
from ..geometry.density import INTERPOLATIONS, DensityMap
from ..geometry.domain import DEFAULT_TOLERANCE, Domain, orient_all
from ..geometry.outline_io import keep_out_is_wkt, load_outline, parse_keep_out
from ..geometry.profile import PRISM
from ..geometry.shapes import DotShape
from ..geometry.sizes import DEFAULT_STEP, DotSizes
from .backlight import BACKLIGHT_KEYS, backlight_from, check_leds_inside, led_caps
from .grids import load_grid, validate_grid
from .images import IMAGE_SUFFIXES, check_ranges, load_image
from .job import Job, OptimizeParams, QAParams
from .laser_section import LASER_KEYS, laser_from, laser_sizes
from .light_guide import (
    DESIGN_KEYS,
    LIGHT_GUIDE_KEYS,
    check_leds_on,
    design_from,
    light_guide_from,
)
from .process_section import PROCESS_KEYS, check_caps, check_printable, process_from
from .shaping import (
    DOT_SHAPE_KEYS,
    ORIENTATION_KEYS,
    PROFILE_KEYS,
    dot_kind,
    dot_profile,
    dot_shape,
    orientation,
    shape_sizes,
)
from .sheet_section import SHEET_KEYS, sheet_from

#: The TOML types a record's field annotation takes (a float field takes an integer too).
FIELD_TYPES: dict[str, tuple[type, ...]] = {
    "str": (str,),
    "int": (int,),
    "float": (int, float),
    "float | None": (int, float),
}


def spec_keys(record) -> dict[str, tuple[type, ...]]:
    """The keys of a job section that is one frozen record (``[optimize]``:
    :class:`~optdot.config.job.OptimizeParams`, ``[qa]``), with the TOML types each
    field's annotation takes: the record declares the key once."""
    return {f.name: FIELD_TYPES[str(f.type)] for f in dataclasses.fields(record)}


SCHEMA: dict[str, dict[str, tuple[type, ...]]] = {
    "": {"name": (str,)},
    "domain": {
        "width": (int, float),
        "height": (int, float),
        "outline": (str,),
        "outline_tolerance": (int, float),
        "keep_out": (list,),
        "keep_out_layer": (str,),
        "edge_margin": (int, float),
        "active_area": (list,),
        "bezel": (int, float, list),
    },
    "density": {
        "grid": (str,),
        "image": (str,),
        "fill_range": (list,),
        "value_range": (list,),
        "interpolation": (str,),
    },
    "dots": {
        "diameter": (int, float, list),
        "spacing": (int, float),
        "diameter_grid": (str,),
        "diameter_step": (int, float),
        **DOT_SHAPE_KEYS,
        **PROFILE_KEYS,
    },
    "orientation": ORIENTATION_KEYS,
    "optimize": spec_keys(OptimizeParams),
    "qa": spec_keys(QAParams),
    "light_guide": LIGHT_GUIDE_KEYS,
    "backlight": BACKLIGHT_KEYS,
    "design": DESIGN_KEYS,
    "process": PROCESS_KEYS,
    "laser": LASER_KEYS,
    "sheet": SHEET_KEYS,
}
_REQUIRED: dict[str, tuple[str, ...]] = {"dots": ()}
#: The keys of the records' sections whose fields are integers (kept as integers).
INT_KEYS = frozenset(
    k for rec in ("optimize", "qa") for k, t in SCHEMA[rec].items() if t == FIELD_TYPES["int"]
)


#: Largest job file read, bytes (a job is a few hundred bytes; values are short).
MAX_JOB_BYTES = 1 << 20


def load_job(path: str | Path, need_map: bool = True) -> Job:
    """Read and validate a TOML job file.

    Args:
        need_map: False lets a job with a ``[light_guide]`` leave out ``[density]`` (what
            ``optdot design`` makes); its map is then a uniform placeholder at the middle
            of ``design.fill_range``, which nothing but the design loop's start reads.

    Raises:
        JobError: one-line message naming the file, the field and the problem.
    """
    path = Path(path)
    problem = input_problem(path, MAX_JOB_BYTES)
    if problem is not None:
        raise JobError(f"{path}: job file {problem.replace('file not found', 'not found')}")
    try:
        raw = tomllib.loads(path.read_text(encoding="utf-8-sig"))
    except (OSError, UnicodeDecodeError) as e:
        raise JobError(f"{path}: cannot read job file ({one_line(e)})") from None
    except tomllib.TOMLDecodeError as e:
        raise JobError(f"{path}: malformed TOML ({one_line(e)})") from None
    except RecursionError:
        raise JobError(f"{path}: malformed TOML (arrays or tables nested too deep)") from None
    return job_from_dict(raw, base=path.parent, source=path, need_map=need_map)


#: TOML integers are 64-bit; a longer one is refused before any number is read from it.
INT64 = 2**63


def _check_integers(value: Any, key: str, where: str) -> None:
    """Refuse an integer outside 64 bits anywhere in the parsed tree (TOML allows none;
    Python's reader takes them, and ``float()`` of one overflows)."""
    if isinstance(value, dict):
        for k, v in value.items():
            _check_integers(v, f"{key}.{k}" if key else str(k), where)
    elif isinstance(value, list):
        for i, v in enumerate(value):
            _check_integers(v, f"{key}[{i}]", where)
    elif isinstance(value, int) and not isinstance(value, bool) and not -INT64 <= value < INT64:
        digits = len(str(abs(value)))
        raise JobError(
            f"{where}: {key} is an integer of {digits} digits; TOML integers are 64-bit "
            "(write a float, e.g. 1e30, if you mean a huge number)"
        )


def job_from_dict(
    raw: dict[str, Any], base: Path = Path("."), source: Path | None = None, need_map: bool = True
) -> Job:
    """Build a :class:`Job` from the parsed TOML tree (see :func:`load_job`)."""
    where = str(source) if source else "job"
    _check_integers(raw, "", where)
    sections: dict[str, dict[str, Any]] = {"": {}}
    for key, value in raw.items():
        if isinstance(value, dict):
            if key not in SCHEMA or key == "":
                raise JobError(f"{where}: unknown section [{key}] (allowed: {_sections()})")
            sections[key] = value
        else:
            sections[""][key] = value
    for sec, values in sections.items():
        allowed = SCHEMA[sec]
        for key, value in values.items():
            label = f"{sec}.{key}" if sec else key
            if key not in allowed:
                raise JobError(
                    f"{where}: unknown key {label!r} (allowed in [{sec or 'top level'}]: "
                    f"{', '.join(allowed)})"
                )
            types = allowed[key]
            if (isinstance(value, bool) and bool not in types) or not isinstance(value, types):
                names = " or ".join(t.__name__ for t in types)
                raise JobError(f"{where}: {label} = {value!r} must be {names}")
    for sec, keys in _REQUIRED.items():
        for key in keys:
            if key not in sections.get(sec, {}):
                raise JobError(f"{where}: missing required key {sec}.{key}")

    dom = sections.get("domain", {})
    domain = _load_domain(dom, base, where)
    if domain is None:
        for key in ("width", "height"):
            if key not in dom:
                raise JobError(f"{where}: missing required key domain.{key} (or domain.outline)")
        x0 = y0 = 0.0
        width, height = float(dom["width"]), float(dom["height"])
    else:
        x0, y0, x1, y1 = domain.box
        width, height = x1 - x0, y1 - y0
        for key, size in (("width", width), ("height", height)):
            if key in dom and abs(float(dom[key]) - size) > 1e-6 * max(size, 1.0):
                raise JobError(
                    f"{where}: domain.{key} = {dom[key]} differs from the outline's bounding "
                    f"box ({size:.6g} mm); with an outline the density grid covers that box, "
                    "so leave width/height out or check the outline's units (mm)"
                )
    area = viewing_area(dom, (x0, y0, x0 + width, y0 + height), where)
    guide = None
    if "light_guide" in sections:
        guide = light_guide_from(sections["light_guide"], (x0, y0, x0 + width, y0 + height), where)
        if domain is not None:
            check_leds_on(guide, domain.slab or domain.geometry, domain.box, where)
    backlight = None
    if sections.get("backlight", {}).get("kind") == "direct" and guide is not None:
        raise JobError(
            f"{where}: a [light_guide] and a direct-lit [backlight] are two different "
            'backlights; keep one (kind = "edge" puts a film over the guide)'
        )
    if "backlight" in sections:
        backlight = backlight_from(
            sections["backlight"],
            (x0, y0, x0 + width, y0 + height),
            guide is not None,
            base,
            where,
        )
        if domain is not None:
            check_leds_inside(backlight, domain.slab or domain.geometry, where)
    optics = "light_guide" in sections or "backlight" in sections
    film = backlight is not None and backlight.on_film
    design = design_from(sections.get("design", {}), base, where, film)
    if "density" not in sections and optics and not need_map:
        grid_path, grid = None, np.full((1, 1), 0.5 * sum(design.fill_range))
    elif "density" not in sections and optics:
        raise JobError(
            f"{where}: no [density] map yet; 'optdot design {where} -o map.csv' designs one "
            "for the backlight and writes a job that uses it"
        )
    else:
        grid_path, grid = _load_density(sections.get("density", {}), base, where)
    try:
        opt = OptimizeParams(**_floats(sections.get("optimize", {})))
        qa = QAParams(**_floats(sections.get("qa", {})))
    except JobError as e:
        raise JobError(f"{where}: {e}") from None
    if not (math.isfinite(width) and math.isfinite(height) and width > 0 and height > 0):
        raise JobError(f"{where}: domain.width/height = {width}, {height} must be > 0 mm")
    if backlight is not None and backlight.leds is not None and backlight.leds.cap > 0:
        panel = domain or Domain.rect(x0, y0, x0 + width, y0 + height)
        domain = led_caps(backlight, panel, qa.effective_close_gap, where)
    validate_grid(grid, str(grid_path))
    density = DensityMap(grid, width, height, x0, y0)
    interpolation = sections.get("density", {}).get("interpolation", "nearest")
    if interpolation not in INTERPOLATIONS:
        raise JobError(
            f"{where}: density.interpolation = {interpolation!r} must be one of "
            f"{', '.join(INTERPOLATIONS)}"
        )
    if interpolation == "linear":
        density = density.interpolated()
    dots = sections["dots"]
    kind = dot_kind(dots, where)
    if kind.round:
        if "diameter" not in dots:
            raise JobError(f"{where}: missing required key dots.diameter")
        diameter, sizes, size_file = _dot_sizes(dots, sections.get("qa", {}), qa, base, where)
    else:
        shape = dot_shape(dots, kind, where)
        sizes = shape_sizes(dots, shape, sections.get("qa", {}), qa, where)
        diameter = shape.equivalent_diameter if sizes is None else sizes.low
        size_file = None
    laser = None
    if "laser" in sections:
        laser = laser_from(sections["laser"], where)
        diameter, sizes = laser_sizes(laser, diameter, sizes, not kind.round, where)
    if kind.round:  # a round dot's size is its (smallest) diameter
        shape = DotShape(kind, (diameter,))
    process = None
    if "process" in sections:
        process = process_from(sections["process"], where)
        low = np.asarray(shape.size) * (diameter / shape.equivalent_diameter)
        check_printable(process, shape.kind, low, where)
        try:
            opt = replace(opt, gap=process.relaxation_gap(opt.gap))
        except JobError as e:
            raise JobError(f"{where}: {e}") from None
        check_caps(process, None if domain is None else domain.cap_rings, where)
        if process.grid > 0:  # dots kept off the walls by what the grid may move them
            panel = domain or Domain.rect(x0, y0, x0 + width, y0 + height)
            domain = replace(panel, edge_margin=panel.edge_margin + process.snap_margin)
    sheet = None
    if "sheet" in sections:
        scale = process.scale if process is not None else np.ones(2)
        sheet = sheet_from(sections["sheet"], (x0, y0, x0 + width, y0 + height), scale, where)
    profile = dot_profile(dots, shape, sizes, guide, backlight, where)
    turn = orientation(
        sections.get("orientation", {}),
        shape,
        guide,
        (x0, y0, x0 + width, y0 + height),
        base,
        opt.seed,
        where,
        directed=profile.code >= PRISM and profile.facets[0] != profile.facets[1],
    )
    return Job(
        domain=domain,
        width=width,
        height=height,
        density=density,
        diameter=diameter,
        optimize=opt,
        qa=qa,
        name=str(sections[""].get("name", source.stem if source else "optdot")),
        source=source,
        inputs=tuple(
            p
            for p in (
                source,
                grid_path,
                size_file,
                *_outline_files(dom, base),
                design.target_file,
                backlight.other_file if backlight is not None else None,
            )
            if p is not None
        ),
        sizes=sizes,
        interpolation=interpolation,
        light_guide=guide,
        backlight=backlight,
        design=design,
        viewing_area=area,
        shape=shape,
        profile=profile,
        orientation=turn,
        process=process,
        laser=laser,
        sheet=sheet,
    )


def viewing_area(
    dom: dict[str, Any], box: tuple[float, float, float, float], where: str
) -> tuple[float, float, float, float] | None:
    """The part of the panel a viewer sees, from ``[domain]``: ``active_area = [x0, y0,
    x1, y1]`` (mm, panel coordinates) or ``bezel`` (mm hidden at every edge, or ``[left,
    bottom, right, top]``), at most one; None when neither is given (the whole panel)."""
    if "active_area" in dom and "bezel" in dom:
        raise JobError(f"{where}: give domain.active_area or domain.bezel, not both")
    bx0, by0, bx1, by1 = box
    if "active_area" in dom:
        v = dom["active_area"]
        if len(v) != 4 or not all(_number(t) for t in v):
            raise JobError(f"{where}: domain.active_area = {v!r} must be [x0, y0, x1, y1] in mm")
        x0, y0, x1, y1 = (float(t) for t in v)
        if not (x0 < x1 and y0 < y1):
            raise JobError(
                f"{where}: domain.active_area = {v!r} must have x0 < x1 and y0 < y1 (mm)"
            )
        tol = 1e-9 * max(bx1 - bx0, by1 - by0, 1.0)
        if x0 < bx0 - tol or y0 < by0 - tol or x1 > bx1 + tol or y1 > by1 + tol:
            raise JobError(
                f"{where}: domain.active_area = {v!r} reaches past the panel "
                f"[{bx0:g}, {by0:g}, {bx1:g}, {by1:g}] mm"
            )
        return (max(x0, bx0), max(y0, by0), min(x1, bx1), min(y1, by1))
    if "bezel" in dom:
        v = dom["bezel"]
        sides = [v] * 4 if _number(v) else v
        if not isinstance(sides, list) or len(sides) != 4 or not all(_number(t) for t in sides):
            raise JobError(
                f"{where}: domain.bezel = {v!r} must be mm hidden at every edge, or "
                "[left, bottom, right, top] in mm"
            )
        left, bottom, right, top = (float(t) for t in sides)
        if min(left, bottom, right, top) < 0:
            raise JobError(f"{where}: domain.bezel = {v!r} must be >= 0 mm")
        if left + right >= bx1 - bx0 or bottom + top >= by1 - by0:
            raise JobError(
                f"{where}: domain.bezel = {v!r} hides the whole panel "
                f"({bx1 - bx0:g} x {by1 - by0:g} mm)"
            )
        return (bx0 + left, by0 + bottom, bx1 - right, by1 - top)
    return None


def _number(v: Any) -> bool:
    """A finite int or float, not a bool."""
    return isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v)


def _dot_sizes(
    dots: dict[str, Any], qa_sec: dict[str, Any], qa: QAParams, base: Path, where: str
) -> tuple[float, DotSizes | None, Path | None]:
    """``[dots]``: one diameter, or a range with its rule (see :mod:`optdot.geometry.sizes`).

    Returns ``(diameter or the range's low end, sizes or None, diameter grid file)``.
    """
    value = dots["diameter"]
    extra = [k for k in ("spacing", "diameter_grid", "diameter_step") if k in dots]
    if not isinstance(value, list):
        if extra:
            raise JobError(
                f"{where}: dots.{extra[0]} needs a diameter range, dots.diameter = [low, high]"
            )
        return float(value), None, None
    if len(value) != 2 or not all(
        isinstance(v, int | float) and not isinstance(v, bool) for v in value
    ):
        raise JobError(f"{where}: dots.diameter = {value!r} must be a number or [low, high] (mm)")
    low, high = (float(v) for v in value)
    if not (math.isfinite(low) and math.isfinite(high) and low < high):
        raise JobError(f"{where}: dots.diameter = {value!r} must be [low, high] with low < high")
    for key in ("close_distance", "collision_distance"):
        if key in qa_sec:
            raise JobError(
                f"{where}: qa.{key} is a centre distance, which cannot apply to dots of "
                "varying size; use qa.close_gap (edge gap, mm) and optimize.gap"
            )
    if "spacing" in dots and "diameter_grid" in dots:
        raise JobError(f"{where}: give dots.spacing or dots.diameter_grid, not both")
    step = float(dots.get("diameter_step", DEFAULT_STEP))
    if not (math.isfinite(step) and 1e-6 <= step <= high - low):
        raise JobError(
            f"{where}: dots.diameter_step = {step!r} must be in mm, 0.000001 <= step <= "
            f"high - low ({high - low:g})"
        )
    spacing = None
    if "spacing" in dots:
        spacing = float(dots["spacing"])
        if not (math.isfinite(spacing) and low < spacing <= 10.0):
            raise JobError(
                f"{where}: dots.spacing = {spacing!r} must be in mm, {low:g} < spacing <= 10"
            )
    grid = path = None
    if "diameter_grid" in dots:
        path = base / dots["diameter_grid"]
        grid = load_grid(path)
        bad = ~(np.isfinite(grid) & (grid >= low - 1e-9) & (grid <= high + 1e-9))
        if bad.any():
            iy, ix = np.argwhere(bad)[0]
            raise JobError(
                f"{path}: dots.diameter_grid: row {iy + 1}, column {ix + 1}: "
                f"{float(grid[iy, ix])!r} is not a diameter in the range [{low:g}, {high:g}] mm"
            )
    sizes = DotSizes(low, high, step, spacing, qa.effective_close_gap, grid)
    return low, sizes, path


def _load_density(sec: dict[str, Any], base: Path, where: str) -> tuple[Path, np.ndarray]:
    """The ``[density]`` map: ``grid`` (CSV/.npy, row 0 = bottom) or ``image`` (PNG/TIFF,
    top-down; see :mod:`optdot.config.images`), exactly one. Returns ``(file, [ny, nx])``."""
    given = [k for k in ("grid", "image") if k in sec]
    if len(given) != 1:
        why = "both given" if given else "missing"
        raise JobError(f"{where}: give one of density.grid or density.image ({why})")
    path = base / sec[given[0]]
    fill_range, value_range = sec.get("fill_range"), sec.get("value_range")
    if given[0] == "grid":
        if fill_range is not None or value_range is not None:
            raise JobError(
                f"{where}: density.fill_range/value_range apply to density.image only "
                "(grid values are fill fractions)"
            )
        return path, load_grid(path)
    check_ranges(fill_range, value_range, where)
    if path.suffix.lower() not in IMAGE_SUFFIXES:
        raise JobError(
            f"{path}: density.image must be {', '.join(IMAGE_SUFFIXES)} "
            "(CSV and .npy grids go in density.grid)"
        )
    return path, load_image(
        path,
        None if fill_range is None else tuple(map(float, fill_range)),
        None if value_range is None else tuple(map(float, value_range)),
    )


def _outline_files(dom: dict[str, Any], base: Path) -> list[Path]:
    """The outline and keep-out files a ``[domain]`` section names."""
    files = [base / dom["outline"]] if "outline" in dom else []
    for item in dom.get("keep_out", []):
        if isinstance(item, str) and not keep_out_is_wkt(item):
            files.append(base / item.strip())
    return files


def _load_domain(dom: dict[str, Any], base: Path, where: str) -> Domain | None:
    """The ``[domain]`` outline, keep-outs and edge margin (None: plain rectangle)."""
    margin = float(dom.get("edge_margin", 0.0))
    if not (math.isfinite(margin) and 0.0 <= margin < 100.0):
        raise JobError(f"{where}: domain.edge_margin = {margin!r} must be in mm, 0 <= x < 100")
    tol = float(dom.get("outline_tolerance", DEFAULT_TOLERANCE))
    if not (1e-6 <= tol <= 1.0):
        raise JobError(f"{where}: domain.outline_tolerance = {tol!r} is out of range (1e-6..1 mm)")
    if "outline" not in dom:
        for key in ("keep_out", "keep_out_layer"):
            if key in dom:
                raise JobError(f"{where}: domain.{key} needs domain.outline")
        if margin > 0:
            w, h = float(dom.get("width", 0)), float(dom.get("height", 0))
            if w > 0 and h > 0:
                return Domain.rect(0.0, 0.0, w, h, margin)
        return None
    try:
        panel, keep = load_outline(base / dom["outline"], tol, dom.get("keep_out_layer"))
        for item in dom.get("keep_out", []):
            if not isinstance(item, str):
                raise JobError(f"{where}: domain.keep_out entries must be strings (WKT or file)")
            keep += parse_keep_out(item, base, tol)
    except GeometryError as e:
        raise GeometryError(f"{where}: {e}") from None
    x0, y0, x1, y1 = panel.bounds
    size = max(x1 - x0, y1 - y0)
    if not 0.5 <= size <= 5000:
        raise GeometryError(
            f"{where}: {dom['outline']}: the outline spans {size:.4g} mm; optdot expects "
            "0.5 .. 5000 mm (are the drawing's units, DXF $INSUNITS, right?)"
        )
    geom = panel
    for k in keep:
        if not k.intersects(panel):
            c = k.representative_point()
            raise GeometryError(
                f"{where}: keep-out near ({c.x:.4g}, {c.y:.4g}) mm lies outside the panel"
            )
        geom = geom.difference(k)
    if geom.is_empty or geom.area <= 0:
        raise GeometryError(f"{where}: nothing of the panel is left after the keep-outs")
    geom = orient_all(geom)
    slab = orient_all(panel) if keep else None
    return Domain(geom, margin, False, str(base / dom["outline"]), slab)


def _floats(d: dict[str, Any]) -> dict[str, Any]:
    """A section's values for its record: numbers as floats, where the record's field is
    not an ``int`` (:func:`spec_keys`)."""
    return {k: (v if k in INT_KEYS or isinstance(v, str) else float(v)) for k, v in d.items()}


def _sections() -> str:
    return ", ".join(s for s in SCHEMA if s)
