"""A job's backlight as the tracer's scene: sources, layers, faces, walls and what is printed.

:func:`scene_of` reads the job's ``[light_guide]`` and ``[backlight]`` (see
:mod:`optdot.config.backlight`) and lays out the stack bottom to top:

- the bare edge-lit guide: one slab, its dots on the bottom face over the reflector;
- the guide with a film: the slab, an air gap, the film (dots on its bottom face), then for
  each diffuser sheet the air under it and the sheet;
- direct-lit: the air cavity over the reflector (LEDs on it), the film, the sheets.

Each printed face is marked with the print it carries: 1 the job's (its map's coverage or
its real dots), 2 the other map of an edge-lit stack with a film. Units: mm, 1/mm, radians.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..config.backlight import Backlight
from ..config.bench import Bench
from ..config.light_guide import EDGE_FINISH, REFLECTOR_FINISH, LightGuide
from ..errors import JobError
from ..geometry.caps import cap_shares, no_caps
from ..geometry.profile import BUMP, DIMPLE, INK, PRISM, PRISM_CUT
from ..geometry.shapes import packed
from ..pattern import DotSource, caps_of
from .tables import (
    BOTTOM_FACE,
    E_A,
    E_B,
    E_C,
    E_COLS,
    E_LAYER,
    E_PROF,
    E_SPAN,
    E_START,
    E_T,
    E_W,
    F_COLS,
    F_COS_DOWN,
    F_COS_UP,
    F_DOT_R,
    F_DOT_T,
    F_EXTRACT,
    F_HAZE,
    F_HAZE_SIG,
    F_KIND,
    F_PRINT,
    F_PROF_C,
    F_PROF_H,
    F_PROF_K,
    F_PROF_T1,
    F_PROF_T2,
    F_PROF_U,
    F_PROF_V,
    F_PROFILE,
    F_REFL,
    F_REFL_FINISH,
    F_SHEET_R,
    F_SHEET_T,
    F_SPREAD,
    F_SPREAD_SIG,
    F_TEST,
    INTERFACE,
    L_ABS,
    L_COLS,
    L_N,
    L_WALL_COS,
    L_WALL_MODE,
    L_WALL_R,
    L_Z0,
    L_Z1,
    MAX_EVENTS,
    PRISM_FACE,
    SHEET_FACE,
    Print,
    Scene,
    Sources,
    Stack,
)

#: Samples of a profile's cumulative distribution over 0..90 degrees.
PROFILE_SAMPLES = 2049
#: The finest cell a coverage trace takes its dots' angles on, mm: the angle toward an
#: LED turns fast near it, faster than a map's cell.
TURN_CELL = 0.1
#: At most this many angle cells (24 MB).
TURN_CELLS = 1 << 20


@dataclass(frozen=True)
class Coverage:
    """A coverage raster: ``grid [ny, nx]`` (0..1) over cells of ``(dx, dy)`` mm from
    ``(x0, y0)``; ``fill [ny, nx]`` the map's fill before the share of each cell inside
    the panel (what sizes the dots of several sizes), or None (``grid``)."""

    grid: np.ndarray
    x0: float
    y0: float
    dx: float
    dy: float
    fill: np.ndarray | None = None


def coverage_of(bench: Bench) -> Coverage:
    """The job's map as a coverage raster: fill times the share of each cell inside the
    panel."""
    d = bench.density
    g = np.array(d.grid, dtype=np.float64)
    w = bench.cell_weights
    if w is not None:
        g = g * w
    dx, dy = d.cell_size
    return Coverage(np.clip(g, 0, 1), d.x0, d.y0, dx, dy, d.grid)


def is_direct(bench: Bench) -> bool:
    """The job's backlight is direct-lit (LEDs under the printed film)."""
    return bench.backlight is not None and bench.backlight.direct


def has_optics(bench: Bench) -> bool:
    """The job says what its dots are printed in (``[light_guide]`` or ``[backlight]``)."""
    return bench.light_guide is not None or bench.backlight is not None


def scene_of(
    bench: Bench,
    rays: int,
    dots: DotSource | None = None,
    coverage: Coverage | None = None,
    only_led: int | None = None,
) -> Scene:
    """The tracer's scene of a job's backlight (``bench``), ``rays`` rays shared among
    its LEDs.

    Args:
        dots: the real pattern on the printed face (None: the map's coverage).
        coverage: the raster of the coverage mode (default: the job's map).
        only_led: light one direct-lit LED only (its index in the grid), the others off.

    Raises:
        JobError: no light guide or backlight; a guide that is several pieces.
    """
    if not has_optics(bench):
        raise JobError(f"{bench.where}: no [light_guide] or [backlight] to trace")
    box = bench.box
    walls, normals = _walls(bench)
    bl = bench.backlight
    if bl is None or not bl.direct:
        guide = bench.light_guide
        assert guide is not None
        sources = _edge_sources(guide, rays, box)
        layer, face = _edge_stack(guide, bl)
        if bl is None or not bl.on_film:  # the guide's dots: ink, or 3-D
            _profile_row(face[0], bench)
    else:
        assert bl.leds is not None
        sources = _grid_sources(bl, rays, only_led)
        layer, face = _direct_stack(bl)
    face[:, F_TEST] = (face[:, F_KIND] == BOTTOM_FACE) | (face[:, F_PRINT] > 0)
    if dots is not None and face[0, F_PROFILE] in (DIMPLE, PRISM_CUT):
        face[0, F_TEST] = 0  # real cut dots are found along a ray's path, not by the test
    stack = Stack(layer, face, walls, normals, MAX_EVENTS)
    return Scene(sources, stack, _print(bench, dots, coverage))


def _profile_row(row: np.ndarray, bench: Bench) -> None:
    """The guide's printed face's 3-D dots in its row of the face table (ink: all 0)."""
    p = bench.profile
    row[F_PROFILE] = p.code
    if p.code == INK:
        return
    hu, hv, rc = bench.shape.kind.profile_frame(bench.shape.size)
    row[F_PROF_K] = p.aspect(hv)
    row[F_PROF_U], row[F_PROF_V], row[F_PROF_C] = hu, hv, rc
    row[F_PROF_T1], row[F_PROF_T2] = (math.tan(math.radians(f)) for f in p.facets)
    if p.code in (BUMP, PRISM):  # the reflector sheet lies on the tallest raised dots
        row[F_PROF_H] = p.height


def _turns(bench: Bench) -> bool:
    """Whether the guide's 3-D dots look different turned (a prism, a cap on an ellipse)
    or vary in size: a coverage trace then gives each the angle and the size its dot
    would have."""
    if bench.profile.code == INK:
        return False
    hu, hv, _ = bench.shape.kind.profile_frame(bench.shape.size)
    return bench.profile.code >= PRISM or hu != hv or bench.sizes is not None


def probe(scene: Scene, events: int) -> Scene:
    """The same scene with rays given up after ``events`` events."""
    return scene._replace(stack=scene.stack._replace(max_events=events))


# -- sources -----------------------------------------------------------------------------


def _profile(profile, tilt: float = 0.0) -> tuple[np.ndarray, tuple[float, float]]:
    """The CDF of ``I(theta) sin(theta)`` over :data:`PROFILE_SAMPLES` angles 0..90° and
    the mode row (collimated flag, tilt in rad)."""
    theta = np.linspace(0.0, 0.5 * math.pi, PROFILE_SAMPLES)
    mode = (0.0, 0.0)
    if profile == "collimated":
        intensity = np.cos(theta)  # unused: the tilt is the one angle
        mode = (1.0, math.radians(tilt))
    elif profile == "lambertian":
        intensity = np.cos(theta)
    elif profile == "batwing":
        intensity = np.cos(theta) * (1.0 + 3.0 * np.sin(theta) ** 2)
    else:
        table = np.array(profile)
        intensity = np.interp(np.degrees(theta), table[:, 0], table[:, 1], right=0.0)
    pdf = intensity * np.sin(theta)
    cdf = np.concatenate([[0.0], np.cumsum(0.5 * (pdf[1:] + pdf[:-1]))])
    cdf = cdf / cdf[-1] if cdf[-1] > 0 else np.linspace(0, 1, len(cdf))
    return cdf, mode


def _shares(power: list[float], rays: int) -> np.ndarray:
    """``[e + 1]`` first ray of each emitter: rays shared by power, largest remainder."""
    share = np.array(power) / sum(power) * rays
    n = np.floor(share).astype(np.int64)
    rest = rays - int(n.sum())
    if rest:
        n[np.argsort(-(share - n), kind="stable")[:rest]] += 1
    return np.concatenate([[0], np.cumsum(n)]).astype(np.int64)


def _edge_sources(guide: LightGuide, rays: int, box) -> Sources:
    """LEDs on the guide's edges: each a rectangle across the edge and the thickness."""
    rows, power, cdfs, modes = [], [], [], []
    for p, leds in enumerate(guide.leds):
        cdf, mode = _profile(leds.profile, leds.tilt)
        cdfs.append(cdf)
        modes.append(mode)
        for pos in leds.positions:
            tx, ty, nx, ny, cx, cy = edge_frame(leds.edge, pos, box)
            row = np.zeros(E_COLS)
            row[E_C : E_C + 3] = (cx, cy, 0.0)
            row[E_A : E_A + 3] = (nx, ny, 0.0)
            row[E_T : E_T + 3] = (tx, ty, 0.0)
            row[E_B : E_B + 3] = (0.0, 0.0, 1.0)
            row[E_W], row[E_SPAN], row[E_START] = leds.width, guide.thickness, 0.0
            row[E_PROF], row[E_LAYER] = p, 0
            rows.append(row)
            power.append(leds.power)
    theta = np.linspace(0.0, 0.5 * math.pi, PROFILE_SAMPLES)
    return Sources(np.array(rows), _shares(power, rays), theta, np.array(cdfs), np.array(modes))


def _grid_sources(bl: Backlight, rays: int, only_led: int | None) -> Sources:
    """Square LEDs on the reflector, shining up into the cavity (layer 0)."""
    leds = bl.leds
    assert leds is not None
    xy = leds.positions
    if only_led is not None:
        xy = xy[only_led : only_led + 1]
    rows = np.zeros((len(xy), E_COLS))
    rows[:, E_C] = xy[:, 0]
    rows[:, E_C + 1] = xy[:, 1]
    rows[:, E_A + 2] = 1.0
    rows[:, E_T] = 1.0
    rows[:, E_B + 1] = 1.0
    rows[:, E_W] = rows[:, E_SPAN] = leds.size
    rows[:, E_START] = -0.5 * leds.size
    cdf, mode = _profile(leds.profile)
    theta = np.linspace(0.0, 0.5 * math.pi, PROFILE_SAMPLES)
    start = _shares([leds.power] * len(xy), rays)
    return Sources(rows, start, theta, cdf[None, :], np.array([mode]))


def edge_frame(edge: str, pos: float, box):
    """Tangent, inward normal and centre of an LED at ``pos`` on ``edge`` of ``box``."""
    x0, y0, x1, y1 = box
    if edge == "bottom":
        return 1.0, 0.0, 0.0, 1.0, pos, y0
    if edge == "top":
        return 1.0, 0.0, 0.0, -1.0, pos, y1
    if edge == "left":
        return 0.0, 1.0, 1.0, 0.0, x0, pos
    return 0.0, 1.0, -1.0, 0.0, x1, pos


# -- the stack ---------------------------------------------------------------------------


def _critical(n1: float, n2: float) -> float:
    """Cosine of the critical angle from index n1 into n2 (0 when there is none)."""
    return math.sqrt(1.0 - (n2 * n2) / (n1 * n1)) if n1 > n2 else 0.0


def _layer(z0: float, z1: float, n: float, absorb: float, wall_r: float, finish: str):
    row = np.zeros(L_COLS)
    row[L_Z0], row[L_Z1], row[L_N], row[L_ABS] = z0, z1, n, absorb
    row[L_WALL_R], row[L_WALL_MODE] = wall_r, float(EDGE_FINISH.index(finish))
    row[L_WALL_COS] = math.sqrt(1.0 - 1.0 / (n * n))
    return row


def _faces(layer: np.ndarray) -> np.ndarray:
    """Blank faces for the layers (interfaces; face 0 the reflector), with their critical
    cosines."""
    count = len(layer)
    face = np.zeros((count + 1, F_COLS))
    face[:, F_KIND] = INTERFACE
    face[0, F_KIND] = BOTTOM_FACE
    for i in range(count + 1):
        below = layer[i - 1, L_N] if i > 0 else 1.0
        above = layer[i, L_N] if i < count else 1.0
        face[i, F_COS_UP] = _critical(below, above)
        face[i, F_COS_DOWN] = _critical(above, below)
    return face


def _film_and_sheets(bl: Backlight, z: float, layers: list) -> tuple[int, float]:
    """Append the film and the air under each sheet from height ``z``; the film's layer
    index and the stack's top."""
    f = bl.film
    film = len(layers)
    layers.append(
        _layer(z, z + f.thickness, f.refractive_index, f.absorption, bl.frame, bl.frame_finish)
    )
    z += f.thickness
    for sheet in bl.sheets:
        layers.append(_layer(z, z + sheet.gap, 1.0, 0.0, bl.frame, bl.frame_finish))
        z += sheet.gap
    return film, z


def _dress_film(face: np.ndarray, bl: Backlight, film: int, mark: int) -> None:
    """Print ``mark`` on the film's bottom face, its haze on its top, the sheets above."""
    f = bl.film
    face[film, F_PRINT] = mark
    face[film, F_DOT_R], face[film, F_DOT_T] = f.dot_reflectance, f.dot_transmittance
    if f.haze != "none":
        face[film + 1, F_HAZE] = 1.0 if f.haze == "lambertian" else 2.0
        face[film + 1, F_HAZE_SIG] = 0.0 if f.haze == "lambertian" else math.radians(f.haze)
    for k, sheet in enumerate(bl.sheets):
        SHEET_ROWS[sheet.kind](face[film + 2 + k], sheet)


def _diffuser_row(row: np.ndarray, sheet) -> None:
    """A diffuser sheet's face row: the columns :mod:`.faces.diffuser_sheet` reads."""
    row[F_KIND] = SHEET_FACE
    row[F_SHEET_T], row[F_SHEET_R] = sheet.transmittance, sheet.reflectance
    row[F_SPREAD] = 0.0 if sheet.spread == "lambertian" else 1.0
    row[F_SPREAD_SIG] = 0.0 if sheet.spread == "lambertian" else math.radians(sheet.spread)


def _prism_row(row: np.ndarray, sheet) -> None:
    """A prism sheet's face row: the columns :mod:`.faces.prism_sheet` reads."""
    row[F_KIND] = PRISM_FACE
    row[F_SHEET_T] = sheet.refractive_index
    row[F_SPREAD] = 1.0 if sheet.grooves == "y" else 0.0
    row[F_SPREAD_SIG] = math.radians(0.5 * sheet.apex_angle)


#: Each sheet kind (``[[backlight.sheets]] kind``) and how its face row is filled.
SHEET_ROWS = {"diffuser": _diffuser_row, "prism": _prism_row}


def _edge_stack(guide: LightGuide, bl: Backlight | None) -> tuple[np.ndarray, np.ndarray]:
    """The guide (layer 0), and with a film: the air gap, the film, the sheets."""
    layers = [
        _layer(
            0.0,
            guide.thickness,
            guide.refractive_index,
            guide.absorption,
            guide.edge_reflectance,
            guide.edge_finish,
        )
    ]
    film = -1
    if bl is not None:
        z = guide.thickness
        layers.append(_layer(z, z + bl.film.gap, 1.0, 0.0, bl.frame, bl.frame_finish))
        film, _ = _film_and_sheets(bl, z + bl.film.gap, layers)
    layer = np.array(layers)
    face = _faces(layer)
    on_guide = bl is None or not bl.on_film
    face[0, F_PRINT] = 1 if on_guide else 2
    face[0, F_DOT_R] = guide.dot_albedo
    face[0, F_EXTRACT] = 1.0 if guide.dot_scatter == "extract" else 0.0
    face[0, F_REFL] = guide.reflector
    face[0, F_REFL_FINISH] = REFLECTOR_FINISH.index(guide.reflector_finish)
    if bl is not None:
        _dress_film(face, bl, film, 2 if on_guide else 1)
    return layer, face


def _direct_stack(bl: Backlight) -> tuple[np.ndarray, np.ndarray]:
    """The cavity (layer 0, air over the reflector), the film, the sheets."""
    layers = [_layer(0.0, bl.gap, 1.0, 0.0, bl.frame, bl.frame_finish)]
    film, _ = _film_and_sheets(bl, bl.gap, layers)
    layer = np.array(layers)
    face = _faces(layer)
    face[0, F_REFL] = bl.reflector
    face[0, F_REFL_FINISH] = REFLECTOR_FINISH.index(bl.reflector_finish)
    _dress_film(face, bl, film, 1)
    return layer, face


def _walls(bench: Bench) -> tuple[np.ndarray, np.ndarray]:
    """The side walls: the panel outline's outer ring as segments, with inward normals.
    Holes and keep-outs are clear slab without dots (a keep-out touching the edge is no
    notch in the slab)."""
    polys = bench.domain.slab_polygons()
    if len(polys) != 1:
        raise JobError(
            f"{bench.where}: the panel is {len(polys)} separate pieces; a backlight is one stack"
        )
    ring = np.asarray(polys[0].exterior.coords)[:-1]  # counter-clockwise
    a, b = ring, np.roll(ring, -1, axis=0)
    e = b - a
    length = np.hypot(e[:, 0], e[:, 1])
    keep = length > 0
    a, b, e, length = a[keep], b[keep], e[keep], length[keep]
    normals = np.column_stack([-e[:, 1], e[:, 0]]) / length[:, None]  # left = inside
    return np.column_stack([a, b]), normals


# -- what is printed ---------------------------------------------------------------------


def _print(bench: Bench, dots: DotSource | None, coverage: Coverage | None) -> Print:
    """The printed faces: the job's dots (or the coverage of its map), the caps (the
    dots' own, else the job's), and the other face's coverage. A coverage raster holds
    the dots' share of each cell; with caps it is turned into the share of the cell
    outside its caps (the tracer tests the caps first)."""
    other = _other_coverage(bench)
    phi2 = np.ascontiguousarray(other.grid, dtype=np.float64)
    g2 = np.array([other.x0, other.y0, other.dx, other.dy], np.float64)
    printed = dots.outline if dots is not None else bench.domain  # the pattern's own caps
    caps = (
        caps_of(dots) if dots is not None else no_caps() if printed.caps is None else printed.caps
    )
    cap_start, cap, cap_g = cap_grid(caps, bench.box)
    if printed is None or printed.cap_rings is None:
        ring = np.array([[0.0, np.inf]])  # solid caps, whatever their diameters
    else:
        ring = np.ascontiguousarray(printed.cap_rings**2, np.float64)
    caps_part = (cap_start, cap, cap_g, ring)
    if dots is None:
        cov = coverage or coverage_of(bench)
        phi = np.ascontiguousarray(cov.grid, dtype=np.float64)
        if len(caps):
            ny, nx = phi.shape
            free = 1.0 - cap_shares(caps, cov.x0, cov.y0, cov.dx, cov.dy, nx, ny)
            phi = np.where(free > 1e-9, np.minimum(phi / np.maximum(free, 1e-9), 1.0), 0.0)
        g = np.array([cov.x0, cov.y0, cov.dx, cov.dy], np.float64)
        start, x, y = np.zeros(2, np.int64), np.zeros(1), np.zeros(1)
        dots_part = (False, phi, g, start, x, y, np.zeros((1, 6)), np.ones(7))
        turn = _coverage_frame(bench, cov) if _turns(bench) else np.full((1, 3), np.nan)
    else:
        start, x, y, foot, cg = dot_grid(dots, bench.box)
        dots_part = (True, np.zeros((1, 1)), np.ones(4), start, x, y, foot, cg)
        turn = np.full((1, 3), np.nan)
    return Print(*dots_part, phi2, g2, *caps_part, turn)


def _coverage_frame(bench: Bench, cov: Coverage) -> np.ndarray:
    """``[ny f nx f, 3]``, each coverage cell split ``f`` × ``f`` (row ``iy nx f + ix``
    over the finer cells): the cosine and sine of the angle the job's orientation gives a
    dot at the finer cell's centre (NaN when each dot's angle is its own draw,
    ``random``: the tracer draws one a ray) and the half width of the dot the coverage
    cell's fill gives (mm; NaN for one size); or ``[1, 3]`` NaN when neither varies.
    ``f`` makes the finer cells :data:`TURN_CELL` wide where the angle follows the
    position, at most :data:`TURN_CELLS` of them (1 otherwise)."""
    o, sizes = bench.orientation, bench.sizes
    if not o.follows_position and sizes is None:
        return np.full((1, 3), np.nan)
    ny, nx = cov.grid.shape
    f = 1
    if o.follows_position:
        f = math.ceil(max(cov.dx, cov.dy) / TURN_CELL - 1e-9)
        f = max(1, min(f, math.isqrt(TURN_CELLS // (nx * ny))))
    frame = np.full((ny * f * nx * f, 3), np.nan)
    if o.follows_position:
        cx = cov.x0 + (np.arange(nx * f) + 0.5) * (cov.dx / f)
        cy = cov.y0 + (np.arange(ny * f) + 0.5) * (cov.dy / f)
        gx, gy = np.meshgrid(cx, cy)
        a = o.at(np.column_stack([gx.ravel(), gy.ravel()]))
        frame[:, 0], frame[:, 1] = np.cos(a), np.sin(a)
    if sizes is not None:
        shape = bench.shape
        d = _cell_diameters(sizes, bench.density, cov)
        w = shape.kind.profile_frame(shape.size)[1] * shape.scale_of(d.ravel())
        frame[:, 2] = np.repeat(np.repeat(w.reshape(ny, nx), f, axis=0), f, axis=1).ravel()
    return np.ascontiguousarray(frame, np.float64)


def _cell_diameters(sizes, density, cov: Coverage) -> np.ndarray:
    """``[ny, nx]`` the (area-equivalent) diameter of the dots of each coverage cell, mm,
    as :meth:`~optdot.geometry.sizes.DotSizes.cell_diameters` gives ``generate``'s: the
    size rule's at the cell's fill (the job's map, or the one ``design`` is making), or
    the explicit grid (over the job map's box) at the cell's centre."""
    if sizes.grid is None:
        return sizes.at_fill(cov.grid if cov.fill is None else cov.fill)
    my, mx = sizes.grid.shape
    ny, nx = cov.grid.shape
    fx = (cov.x0 + (np.arange(nx) + 0.5) * cov.dx - density.x0) / density.width
    fy = (cov.y0 + (np.arange(ny) + 0.5) * cov.dy - density.y0) / density.height
    ix, iy = np.floor(fx * mx).astype(np.int64), np.floor(fy * my).astype(np.int64)
    return sizes.quantise(sizes.grid[np.ix_(np.clip(iy, 0, my - 1), np.clip(ix, 0, mx - 1))])


def cap_grid(caps: np.ndarray, box) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The caps ``[m, 3]`` ``(x, y, diameter)`` sorted into square cells at least one cap
    wide: ``(start, rows, grid)``, rows ``[m, 3]`` ``(x, y, r^2)`` (see :class:`Print`)."""
    r = 0.5 * caps[:, 2]
    start, order, grid = _cells(caps[:, 0], caps[:, 1], float(r.max()) if len(r) else 0.0, box)
    rows = np.column_stack([caps[:, 0], caps[:, 1], r * r])[order]
    return start, np.ascontiguousarray(rows, np.float64), grid


def _cells(x: np.ndarray, y: np.ndarray, rmax: float, box) -> tuple:
    """Points sorted into square cells over ``box``, at least ``2 rmax`` and 1.5 mean
    spacings wide: ``(start [cells + 1] CSR, order [n], grid [7])``, grid ``x0, y0, dx,
    dy, nx, ny, rmax``."""
    x0, y0, x1, y1 = box
    area = (x1 - x0) * (y1 - y0)
    cell = max(2.0 * rmax if len(x) else 1.0, 1.5 * math.sqrt(area / max(len(x), 1)))
    nx = max(1, int(math.ceil((x1 - x0) / cell)))
    ny = max(1, int(math.ceil((y1 - y0) / cell)))
    ix = np.clip(((x - x0) / cell).astype(np.int64), 0, nx - 1)
    iy = np.clip(((y - y0) / cell).astype(np.int64), 0, ny - 1)
    key = iy * nx + ix
    order = np.argsort(key, kind="stable")
    start = np.zeros(nx * ny + 1, np.int64)
    np.cumsum(np.bincount(key, minlength=nx * ny), out=start[1:])
    return start, order, np.array([x0, y0, cell, cell, nx, ny, rmax], np.float64)


def _other_coverage(bench: Bench) -> Coverage:
    """The second printed face's coverage (``backlight.other_map``), or an empty map."""
    x0, y0, x1, y1 = bench.box
    bl = bench.backlight
    value = bl.other_map if bl is not None and not bl.direct else 0.0
    grid = np.full((1, 1), float(value)) if np.isscalar(value) else np.asarray(value)
    ny, nx = grid.shape
    return Coverage(np.clip(grid, 0, 1), x0, y0, (x1 - x0) / nx, (y1 - y0) / ny)


def dot_grid(dots: DotSource, box) -> tuple:
    """The dots sorted into square cells at least one footprint wide (a point on a dot
    lies within the largest extent of the dot's cell): ``(start, x, y, foot, grid)``,
    foot ``[n, 6]`` the footprints as the tracer tests them (kind, size, angle:
    :func:`optdot.geometry.shapes.packed`)."""
    xs, ys, es, fs = [], [], [], []
    for _, xy, footprints in dots.chunks():
        xs.append(np.asarray(xy[:, 0], np.float64))
        ys.append(np.asarray(xy[:, 1], np.float64))
        es.append(footprints.extent())
        fs.append(packed(footprints.kind, footprints.size, footprints.angle))
    x = np.concatenate(xs) if xs else np.zeros(0)
    y = np.concatenate(ys) if ys else np.zeros(0)
    e = np.concatenate(es) if es else np.zeros(0)
    foot = np.concatenate(fs) if fs else np.zeros((0, 6))
    start, order, grid = _cells(x, y, float(e.max()) if len(e) else 0.0, box)
    return start, x[order], y[order], np.ascontiguousarray(foot[order]), grid
