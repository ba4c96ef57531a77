"""Job files: TOML in, a validated frozen :class:`Job` out.

The job format is a public contract documented in the README. Unknown sections or keys
are errors, so a typo is never silently ignored.
"""

from __future__ import annotations

import csv
import math
import tomllib
from dataclasses import dataclass, field, replace
from functools import cached_property
from pathlib import Path
from typing import Any

import numpy as np

from .density import HEX_PACKING_LIMIT, DensityMap
from .domain import DEFAULT_TOLERANCE, Domain, load_outline, orient_all, parse_keep_out
from .errors import GeometryError, JobError

METHODS = ("optdot", "md")
FORMULATIONS = ("paper", "optdot")


@dataclass(frozen=True)
class OptimizeParams:
    """How the dots are relaxed.

    Attributes:
        method: ``"optdot"`` (L-BFGS on penalty (3), the paper's method) or ``"md"``
            (the molecular-dynamics baseline of Idé et al. 2003, see :mod:`optdot.md`).
        max_iter: iterations of L-BFGS or MD steps (paper: 200).
        seed: seed of the scrambled low-discrepancy sequence.
        formulation: ``"paper"`` reproduces the paper exactly (radius factor 1, panel
            penalty with the circle radius); ``"optdot"`` is our default, see README.
        radius_factor: multiplies the paper's circle radius r = r0 sqrt(pi/(sqrt3 rho));
            ``None`` takes the formulation's (see :mod:`optdot.formulation`).
        container_factor: container side / circle radius (paper: 4); ``None`` takes the
            formulation's.
        lbfgs_memory: L-BFGS history length m (paper: 6).
        ftol: stop when the penalty fell by less than ``ftol`` (relative) over 10
            iterations; 0 runs all ``max_iter`` iterations.
        gap: manufacturing gap, mm: dot centres keep at least ``diameter + gap``.
        skin: Verlet skin as a fraction of each circle's radius.
        md_step: MD only: dt / c as a fraction of the collision distance.
        md_decay: MD only: decay length L of the force tail / hexagonal spacing.
        md_cutoff: MD only: the tail is cut at D = b + md_cutoff * L.
    """

    method: str = "optdot"
    max_iter: int = 200
    seed: int = 1
    formulation: str = "optdot"
    radius_factor: float | None = None
    container_factor: float | None = None
    lbfgs_memory: int = 6
    ftol: float = 1e-3
    gap: float = 0.0
    skin: float = 0.3
    md_step: float = 0.02
    md_decay: float = 0.25
    md_cutoff: float = 3.0

    def __post_init__(self) -> None:
        _check(self.method in METHODS, "optimize.method", self.method, f"one of {METHODS}")
        _check(
            self.formulation in FORMULATIONS,
            "optimize.formulation",
            self.formulation,
            f"one of {FORMULATIONS}",
        )
        _check(0 <= self.max_iter <= 100_000, "optimize.max_iter", self.max_iter, "0..100000")
        _check(0 <= self.seed < 2**63, "optimize.seed", self.seed, "0..2^63-1")
        if self.radius_factor is not None:
            _check(
                0.5 <= self.radius_factor <= 3.0,
                "optimize.radius_factor",
                self.radius_factor,
                "0.5..3",
            )
        _check(
            self.container_factor is None or 1.0 <= self.container_factor <= 100.0,
            "optimize.container_factor",
            self.container_factor,
            "1..100",
        )
        _check(1 <= self.lbfgs_memory <= 50, "optimize.lbfgs_memory", self.lbfgs_memory, "1..50")
        _check(0.0 <= self.ftol < 1.0, "optimize.ftol", self.ftol, "0 <= ftol < 1")
        _check(0.0 <= self.gap < 10.0, "optimize.gap", self.gap, "0 <= gap < 10 mm")
        _check(0.01 <= self.skin <= 2.0, "optimize.skin", self.skin, "0.01..2")
        _check(0.0 < self.md_step <= 0.5, "optimize.md_step", self.md_step, "0 < md_step <= 0.5")
        _check(0.01 <= self.md_decay <= 2.0, "optimize.md_decay", self.md_decay, "0.01..2")
        _check(0.0 <= self.md_cutoff <= 20.0, "optimize.md_cutoff", self.md_cutoff, "0..20")


@dataclass(frozen=True)
class QAParams:
    """Pass/fail thresholds of the QA gate (all distances in mm; None = from the job).

    Attributes:
        collision_distance: centres closer than this collide (default: dot diameter + gap).
        close_distance: centres closer than this are "too close" (default 0.060).
        max_collisions: allowed pairs below ``collision_distance`` (default 0).
        max_close_fraction: allowed share of dots in a too-close pair (default 1.0 = off).
        max_protruding: allowed dots protruding from the panel (default 0).
        max_in_empty: allowed dots in zero-density cells (default 0).
        max_coverage_rms: allowed RMS relative coverage error after 1 mm smoothing.
        max_psi6_coherence: allowed |mean psi6| over 2 mm patches (moire risk).
        smoothing: Gaussian sigma for the visible-coverage check, mm.
    """

    collision_distance: float | None = None
    close_distance: float = 0.060
    max_collisions: int = 0
    max_close_fraction: float = 1.0
    max_protruding: int = 0
    max_in_empty: int = 0
    max_coverage_rms: float = 0.05
    max_psi6_coherence: float = 0.10
    smoothing: float = 1.0

    def __post_init__(self) -> None:
        if self.collision_distance is not None:
            _check(
                self.collision_distance > 0, "qa.collision_distance", self.collision_distance, "> 0"
            )
        _check(self.close_distance > 0, "qa.close_distance", self.close_distance, "> 0")
        _check(self.max_collisions >= 0, "qa.max_collisions", self.max_collisions, ">= 0")
        _check(
            0 <= self.max_close_fraction <= 1,
            "qa.max_close_fraction",
            self.max_close_fraction,
            "0..1",
        )
        _check(self.max_protruding >= 0, "qa.max_protruding", self.max_protruding, ">= 0")
        _check(self.max_in_empty >= 0, "qa.max_in_empty", self.max_in_empty, ">= 0")
        _check(self.max_coverage_rms > 0, "qa.max_coverage_rms", self.max_coverage_rms, "> 0")
        _check(
            0 < self.max_psi6_coherence <= 1,
            "qa.max_psi6_coherence",
            self.max_psi6_coherence,
            "0 < x <= 1",
        )
        _check(self.smoothing > 0, "qa.smoothing", self.smoothing, "> 0")


@dataclass(frozen=True, eq=False)
class Job:
    """A validated job: panel, fill-fraction map, dot size and optimizer settings.

    Attributes:
        width, height: size of the density grid, mm. Without an outline the panel is
            ``[0, width] x [0, height]``; with one, the grid covers its bounding box.
        density: the fill-fraction map over the panel.
        diameter: dot diameter, mm.
        optimize: optimizer settings.
        qa: QA gate thresholds.
        name: a label carried into outputs.
        source: the job file this came from, if any.
        domain: where dots may go (default: the rectangle of the grid).
    """

    width: float
    height: float
    density: DensityMap
    diameter: float
    optimize: OptimizeParams = field(default_factory=OptimizeParams)
    qa: QAParams = field(default_factory=QAParams)
    name: str = "optdot"
    source: Path | None = None
    domain: Domain | None = None

    def __post_init__(self) -> None:
        where = str(self.source) if self.source else "job"
        if self.domain is None:
            d = self.density
            object.__setattr__(
                self, "domain", Domain.rect(d.x0, d.y0, d.x0 + self.width, d.y0 + self.height)
            )
        for key, v in (("domain.width", self.width), ("domain.height", self.height)):
            if not (math.isfinite(v) and 0 < v <= 10_000):
                raise JobError(f"{where}: {key} = {v!r} must be a size in mm, 0 < x <= 10000")
        if not (math.isfinite(self.diameter) and 0 < self.diameter <= 10):
            raise JobError(f"{where}: dots.diameter = {self.diameter!r} must be in mm, 0 < d <= 10")
        if self.diameter >= min(self.width, self.height):
            raise JobError(f"{where}: dots.diameter = {self.diameter} does not fit the panel")
        _validate_grid(self.density.grid, f"{where}: density.grid")

    @property
    def min_distance(self) -> float:
        """Smallest allowed centre distance, mm (diameter + gap)."""
        return self.diameter + self.optimize.gap

    @property
    def collision_distance(self) -> float:
        """QA collision threshold, mm."""
        c = self.qa.collision_distance
        return self.min_distance if c is None else c

    @property
    def dot_area(self) -> float:
        """Area of one dot, mm²."""
        return math.pi * (0.5 * self.diameter) ** 2

    @property
    def box(self) -> tuple[float, float, float, float]:
        """Bounding box of the panel ``(xmin, ymin, xmax, ymax)``, mm."""
        return self.domain.box

    @cached_property
    def cell_weights(self) -> np.ndarray | None:
        """``[ny, nx]`` share of each grid cell inside the domain (None: all of it)."""
        if self.domain.rectangle:
            return None
        d = self.density
        return self.domain.cell_fractions(d.x0, d.y0, *d.cell_size, d.shape[1], d.shape[0])

    @property
    def n_dots(self) -> int:
        """Number of dots the map asks for over the domain (paper §2.1)."""
        return self.density.dot_count(self.dot_area, self.cell_weights)

    def with_overrides(self, **optimize: Any) -> Job:
        """A copy with some :class:`OptimizeParams` fields replaced (None = keep)."""
        kw = {k: v for k, v in optimize.items() if v is not None}
        if not kw:
            return self
        try:
            opt = replace(self.optimize, **kw)
        except JobError:
            raise
        return replace(self, optimize=opt)


# --------------------------------------------------------------------------- loading

_SCHEMA: dict[str, dict[str, tuple[type, ...]]] = {
    "": {"name": (str,)},
    "domain": {
        "width": (int, float),
        "height": (int, float),
        "outline": (str,),
        "outline_tolerance": (int, float),
        "keep_out": (list,),
        "keep_out_layer": (str,),
        "edge_margin": (int, float),
    },
    "density": {"grid": (str,)},
    "dots": {"diameter": (int, float)},
    "optimize": {
        "method": (str,),
        "max_iter": (int,),
        "seed": (int,),
        "formulation": (str,),
        "radius_factor": (int, float),
        "container_factor": (int, float),
        "lbfgs_memory": (int,),
        "ftol": (int, float),
        "gap": (int, float),
        "skin": (int, float),
        "md_step": (int, float),
        "md_decay": (int, float),
        "md_cutoff": (int, float),
    },
    "qa": {
        "collision_distance": (int, float),
        "close_distance": (int, float),
        "max_collisions": (int,),
        "max_close_fraction": (int, float),
        "max_protruding": (int,),
        "max_in_empty": (int,),
        "max_coverage_rms": (int, float),
        "max_psi6_coherence": (int, float),
        "smoothing": (int, float),
    },
}
_REQUIRED = {"density": ("grid",), "dots": ("diameter",)}


def load_job(path: str | Path) -> Job:
    """Read and validate a TOML job file.

    Raises:
        JobError: one-line message naming the file, the field and the problem.
    """
    path = Path(path)
    try:
        raw = tomllib.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise JobError(f"{path}: job file not found") from None
    except (OSError, UnicodeDecodeError) as e:
        raise JobError(f"{path}: cannot read job file ({e})") from None
    except tomllib.TOMLDecodeError as e:
        raise JobError(f"{path}: malformed TOML ({e})") from None
    return job_from_dict(raw, base=path.parent, source=path)


def job_from_dict(raw: dict[str, Any], base: Path = Path("."), source: Path | None = None) -> Job:
    """Build a :class:`Job` from the parsed TOML tree (see :func:`load_job`)."""
    where = str(source) if source else "job"
    sections: dict[str, dict[str, Any]] = {"": {}}
    for key, value in raw.items():
        if isinstance(value, dict):
            if key not in _SCHEMA or key == "":
                raise JobError(f"{where}: unknown section [{key}] (allowed: {_sections()})")
            sections[key] = value
        else:
            sections[""][key] = value
    for sec, values in sections.items():
        allowed = _SCHEMA[sec]
        for key, value in values.items():
            label = f"{sec}.{key}" if sec else key
            if key not in allowed:
                raise JobError(
                    f"{where}: unknown key {label!r} (allowed in [{sec or 'top level'}]: "
                    f"{', '.join(allowed)})"
                )
            types = allowed[key]
            if isinstance(value, bool) or not isinstance(value, types):
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
    grid_path = base / sections["density"]["grid"]
    grid = load_grid(grid_path)
    try:
        opt = OptimizeParams(**_floats(sections.get("optimize", {})))
        qa = QAParams(**_floats(sections.get("qa", {})))
    except JobError as e:
        raise JobError(f"{where}: {e}") from None
    if not (math.isfinite(width) and math.isfinite(height) and width > 0 and height > 0):
        raise JobError(f"{where}: domain.width/height = {width}, {height} must be > 0 mm")
    _validate_grid(grid, str(grid_path))
    density = DensityMap(grid, width, height, x0, y0)
    return Job(
        domain=domain,
        width=width,
        height=height,
        density=density,
        diameter=float(sections["dots"]["diameter"]),
        optimize=opt,
        qa=qa,
        name=str(sections[""].get("name", source.stem if source else "optdot")),
        source=source,
    )


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
            f"{where}: {dom['outline']}: the outline spans {size:.4g} units; optdot expects mm "
            "(0.5 .. 5000)"
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
    return Domain(geom, margin, False, str(base / dom["outline"]))


def load_grid(path: Path) -> np.ndarray:
    """Read a fill-fraction grid from CSV (comma-separated, row 0 = bottom) or ``.npy``.

    Returns:
        ``[ny, nx]`` float64 (not yet range-checked; see :func:`_validate_grid`).
    """
    if not path.exists():
        raise JobError(f"{path}: density grid file not found")
    if path.suffix.lower() == ".npy":
        try:
            g = np.load(path, allow_pickle=False)
        except (OSError, ValueError) as e:
            raise JobError(f"{path}: not a readable .npy array ({e})") from None
        if g.ndim != 2 or g.size == 0:
            raise JobError(f"{path}: grid must be a non-empty 2-D array, got shape {g.shape}")
        if not np.issubdtype(g.dtype, np.number) or np.iscomplexobj(g):
            raise JobError(f"{path}: grid must hold real numbers, got dtype {g.dtype}")
        return np.asarray(g, dtype=np.float64)
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as e:
        raise JobError(f"{path}: cannot read density grid ({e})") from None
    rows: list[list[float]] = []
    for lineno, row in enumerate(csv.reader(text.splitlines()), start=1):
        if not row or all(not c.strip() for c in row):
            continue
        if row[0].lstrip().startswith("#"):
            continue
        try:
            rows.append([float(c) for c in row])
        except ValueError:
            bad = next(c for c in row if not _is_float(c))
            raise JobError(f"{path}: line {lineno}: {bad.strip()!r} is not a number") from None
        if len(rows[-1]) != len(rows[0]):
            raise JobError(
                f"{path}: line {lineno}: wrong grid shape, {len(rows[-1])} columns where "
                f"line 1 has {len(rows[0])}"
            )
    if not rows:
        raise JobError(f"{path}: density grid is empty")
    return np.array(rows, dtype=np.float64)


def _validate_grid(g: np.ndarray, where: str) -> None:
    if not np.all(np.isfinite(g)):
        iy, ix = np.argwhere(~np.isfinite(g))[0]
        raise JobError(f"{where}: NaN or infinite fill fraction at row {iy}, column {ix}")
    if np.any(g < 0):
        iy, ix = np.argwhere(g < 0)[0]
        raise JobError(f"{where}: negative fill fraction {g[iy, ix]} at row {iy}, column {ix}")
    if np.any(g >= HEX_PACKING_LIMIT):
        iy, ix = np.argwhere(g >= HEX_PACKING_LIMIT)[0]
        raise JobError(
            f"{where}: fill fraction {g[iy, ix]} at row {iy}, column {ix} is at or above the "
            f"hexagonal packing limit {HEX_PACKING_LIMIT:.4f}"
        )
    if not np.any(g > 0):
        raise JobError(f"{where}: the map is all zero, there is nothing to place")


def _check(ok: bool, name: str, value: Any, allowed: str) -> None:
    if not ok:
        raise JobError(f"{name} = {value!r} is out of range ({allowed})")


def _floats(d: dict[str, Any]) -> dict[str, Any]:
    ints = {"max_iter", "seed", "lbfgs_memory", "max_collisions", "max_protruding", "max_in_empty"}
    return {k: (v if k in ints or isinstance(v, str) else float(v)) for k, v in d.items()}


def _is_float(s: str) -> bool:
    try:
        float(s)
    except ValueError:
        return False
    return True


def _sections() -> str:
    return ", ".join(s for s in _SCHEMA if s)
