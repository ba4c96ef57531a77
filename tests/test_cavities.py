"""Cut dots' cavities met wherever a ray's path passes through one
(:mod:`optdot.optics.faces.cavities`): closed forms for a hemispherical dimple met beyond
its rim coming down, and from beside it going up; against pvtrace in
``tests/test_dot_profile_pvtrace.py``."""

from __future__ import annotations

import math

import numba as nb
import numpy as np
import pytest

from optdot.geometry.profile import DIMPLE
from optdot.optics import tables as t
from optdot.optics.faces.cavities import meet_cut
from optdot.optics.marks import BARE
from optdot.optics.rays import ray_state, uniform
from optdot.optics.scene import dot_grid
from optdot.optics.trace import _off_wall
from optdot.pattern import Pattern

N = 1.49
R = 0.1  # the hemisphere's radius, mm
CENTRE = (1.5, 1.0)
H = math.sqrt(0.5)
NO_WALLS = np.zeros((0, 4))


def _setup() -> tuple[tuple, tuple]:
    """A face row of hemispherical dimples (radius :data:`R`) over a white sheet, and the
    print's ``dot_tables`` with one real dimple at :data:`CENTRE`."""
    row = np.zeros(t.F_COLS)
    row[t.F_KIND], row[t.F_PROFILE], row[t.F_PROF_K] = t.BOTTOM_FACE, DIMPLE, 1.0
    row[[t.F_PROF_U, t.F_PROF_V, t.F_PROF_C]] = R, R, 0.0
    row[t.F_COS_DOWN], row[t.F_REFL] = math.sqrt(1 - 1 / N**2), 0.9
    p = Pattern(np.array([CENTRE]), 2 * R, (0.0, 0.0, 3.0, 2.0))
    pr = (True, np.ones((1, 1)), np.array([0.0, 0.0, 3.0, 2.0]), *dot_grid(p, p.box))
    return tuple(float(v) for v in row), (*pr, np.zeros((0, 3)))


def _meet(f, pr, x, y, z, d, rays, walls=NO_WALLS, run=0.0):
    """``meet_cut`` for ``rays`` rays at ``(x, y, z)`` going ``d`` (the panel's ``walls``,
    none by default; ``run`` how far the ray came on its course, 0: not known):
    ``[rays, 7]`` (act, x, y, z, dx, dy, dz). Every argument handed to the compiled
    :func:`_meet_rays`: a default array there is typed anew in each process, so its
    cache is never found."""
    return _meet_rays(f, pr, float(x), float(y), float(z), d, rays, walls, float(run))


@nb.njit(cache=True)
def _meet_rays(f, pr, x, y, z, d, rays, walls, run):  # pragma: no cover - compiled
    """:func:`_meet`'s rays."""
    out = np.zeros((rays, 7))
    for i in range(rays):
        _, act, ex, ey, ez, a, b, c = meet_cut(
            ray_state(5, i), f, N, t.var_int(BARE), x, y, z, pr, walls, d[0], d[1], d[2], run
        )
        out[i, 0], out[i, 1], out[i, 2], out[i, 3] = act, ex, ey, ez
        out[i, 4], out[i, 5], out[i, 6] = a, b, c
    return out


def _tir(m: np.ndarray, d: np.ndarray) -> np.ndarray:
    """``d`` reflected off a surface of unit normal ``m``."""
    return d - 2 * (d @ m) * m


@pytest.mark.slow
def test_light_coming_down_beyond_a_dimple_s_rim_is_turned_by_its_wall():
    """A ray at 45° crossing the face's plane 0.12 mm from a hemispherical cavity's
    centre (0.02 beyond its rim) passes through the cavity first: it meets the wall at
    the height z solving (0.12 - z)² + z² = R², 58° from its normal, over the critical
    angle, and is sent up off it. Had the cavity been met only on its footprint, the
    flat face would have sent it back up at 45°."""
    assert BARE == -1
    f, pr = _setup()
    d = np.array([H, 0.0, -H])
    out = _meet(f, pr, CENTRE[0] + 0.12, CENTRE[1], 0.0, d, 50)
    z = (0.24 + math.sqrt(0.24**2 - 8 * (0.12**2 - R**2))) / 4  # the higher root
    m = np.array([0.12 - z, 0.0, z]) / R  # out of the cavity, into the glass
    assert math.degrees(math.acos(-(d @ m))) > math.degrees(math.asin(1 / N))
    want = _tir(m, d)
    assert np.all(out[:, 0] == t.NEW_LEG)
    assert np.allclose(out[:, 4:], want, atol=1e-9)
    assert np.allclose(out[:, 3], R)  # up out of the layer, at the deepest cavity's depth
    back = (out[:, 3] - z) / want[2]  # back along the ray: the point it met the wall at
    assert np.allclose(out[:, 1] - back * want[0], CENTRE[0] + 0.12 - z, atol=1e-9)
    assert np.allclose(out[:, 2], CENTRE[1])


def test_light_born_beside_a_dimple_going_up_meets_its_wall():
    """The same ray turned over: from the face 0.12 mm short of the centre going up at
    45°, it meets the cavity's wall at the lower root, totally reflected; a ray born
    over the cavities' layer, or going up beside it and missing it, goes on as it came."""
    f, pr = _setup()
    d = np.array([H, 0.0, H])
    out = _meet(f, pr, CENTRE[0] - 0.12, CENTRE[1], 1e-12, d, 50)
    z = (0.24 - math.sqrt(0.24**2 - 8 * (0.12**2 - R**2))) / 4
    m = np.array([z - 0.12, 0.0, z]) / R
    assert np.all(out[:, 0] == t.NEW_LEG)
    assert np.allclose(out[:, 4:], _tir(m, d), atol=1e-9)
    over = _meet(f, pr, CENTRE[0] - 0.12, CENTRE[1], 0.2, d, 5)
    assert np.all(over[:, 0] == t.SAME_LEG) and np.allclose(over[:, 1:4], [1.38, 1.0, 0.2])
    away = _meet(f, pr, CENTRE[0] - 0.12, CENTRE[1], 1e-12, -np.array([H, 0.0, -H]), 5)
    assert np.allclose(away[:, 4:], [-H, 0.0, H]) and np.allclose(away[:, 3], R)


def test_light_coming_down_short_of_a_dimple_meets_its_wall_after_the_face():
    """A ray at 45° crossing the face 0.12 mm short of the centre, going toward the
    cavity, meets nothing on its way down; the face reflects it totally and it meets the
    wall going up, at the lower root, as the ray born there does (the walk down followed
    on past the face, :func:`~optdot.optics.faces.dot_profile.next_dot`'s ``fold``). Had
    the walk stopped at the face, the flat face alone would have sent it up at 45°."""
    f, pr = _setup()
    out = _meet(f, pr, CENTRE[0] - 0.12, CENTRE[1], 0.0, np.array([H, 0.0, -H]), 50)
    z = (0.24 - math.sqrt(0.24**2 - 8 * (0.12**2 - R**2))) / 4
    m = np.array([z - 0.12, 0.0, z]) / R
    assert np.all(out[:, 0] == t.NEW_LEG)
    assert np.allclose(out[:, 4:], _tir(m, np.array([H, 0.0, H])), atol=1e-9)
    assert np.allclose(out[:, 3], R)


def _refract(d: np.ndarray, m: np.ndarray, n1: float, n2: float) -> np.ndarray:
    """``d`` through a surface of unit normal ``m`` (pointing the way it goes), Snell."""
    cos_i = d @ m
    eta = n1 / n2
    return eta * d + (math.sqrt(1 - eta**2 * (1 - cos_i**2)) - eta * cos_i) * m


def test_light_down_through_a_dimple_s_open_base_comes_back_up_into_it():
    """Straight down 0.05 mm off a hemispherical cavity's centre: the wall turns it
    (glass into air), it leaves through the cavity's open base, a mirror against the face
    sends it back up into the same cavity and its wall turns it again (air into glass),
    where a flat face would have let it in at the tilt it left at. Most rays do just
    that (no Fresnel reflection at either wall); every ray comes back up (the mirror
    loses nothing)."""
    f, pr = _setup()
    row = np.array(f)
    row[t.F_REFL], row[t.F_REFL_FINISH] = 1.0, 1.0
    b = 0.05
    out = _meet(tuple(row), pr, CENTRE[0] + b, CENTRE[1], 0.0, np.array([0.0, 0.0, -1.0]), 4000)
    assert np.all(out[:, 0] == t.NEW_LEG) and np.all(out[:, 6] > 0)
    z1 = math.sqrt(R**2 - b**2)
    d1 = _refract(np.array([0.0, 0.0, -1.0]), -np.array([b, 0.0, z1]) / R, N, 1.0)
    base = b + d1[0] * z1 / -d1[2]  # where it leaves the base (from the centre)
    d2 = d1 * [1, 1, -1]  # the mirror
    q = base * d2[0]  # up to the wall: |(base, 0, 0) + s d2| = R
    s2 = -q + math.sqrt(q * q - (base**2 - R**2))
    m2 = np.array([base + s2 * d2[0], 0.0, s2 * d2[2]]) / R
    d3 = _refract(d2, m2, 1.0, N)
    flat = _refract(d2, np.array([0.0, 0.0, 1.0]), 1.0, N)
    assert np.linalg.norm(d3 - flat) > 0.05
    seen = np.isclose(out[:, 4:], d3, atol=1e-9).all(axis=1).mean()
    assert seen > 0.8, seen
    assert not np.isclose(out[:, 4:], flat, atol=1e-6).all(axis=1).any()


def test_a_ray_coming_down_off_the_panel_s_wall_meets_the_cavity_by_the_wall():
    """A ray sent down off the panel's left wall 0.05 mm over the face, 88° from the
    normal, crosses the face 1.43 mm on, on the footprint of a dimple standing there (one
    of a grid 0.3 mm apart up to it, the print's cells 0.4 mm): it
    meets the cavity (its path began at the wall, inside the cavities' layer), and is not
    reflected by the flat face as when its path was taken back to the layer's top, 1.4 mm
    beyond the wall and off the print's cells (a reviewer's find)."""
    f, pr = _setup()
    a = math.radians(88)
    d = np.array([math.sin(a), 0.0, -math.cos(a)])
    x = 0.05 * math.tan(a)  # where it crosses the face, from the wall at x = 0
    gx, gy = np.meshgrid(np.arange(x - 0.05 - 0.3 * 4, x, 0.3), np.arange(0.1, 2.0, 0.3))
    p = Pattern(np.column_stack([gx.ravel(), gy.ravel()]), 2 * R, (0.0, 0.0, 3.0, 2.0))
    pr = (*pr[:3], *dot_grid(p, p.box), pr[-1])
    walls = np.array([[0.0, 0.0, 0.0, 2.0], [0.0, 2.0, 3.0, 2.0], [3.0, 2.0, 3.0, 0.0],
                      [3.0, 0.0, 0.0, 0.0]])  # fmt: skip
    out = _meet(f, pr, x, 1.0, 0.0, d, 200, walls)  # y = 1.0: the row of dots there
    flat = d * [1, 1, -1]
    assert not np.isclose(out[:, 4:], flat, atol=1e-6).all(axis=1).any()
    assert np.isin(out[:, 0], (t.NEW_LEG, t.BOTTOM)).all()  # the sheet under its base: 0.9
    # told it came from the wall less far than the layer reaches back (the tracer's run:
    # 1.43 of 2.86 mm), it looks the wall up: the same
    np.testing.assert_array_equal(_meet(f, pr, x, 1.0, 0.0, d, 200, walls, x * 0.999), out)
    # told it came from farther than the wall (which cannot be): taken back past it
    beyond = _meet(f, pr, x, 1.0, 0.0, d, 200, walls, 10.0)
    assert np.isclose(beyond[:, 4:], flat, atol=1e-6).all(axis=1).all()


def _first_on_sphere(p: np.ndarray, d: np.ndarray) -> np.ndarray:
    """Where the path through ``p`` going ``d`` first meets the sphere of radius
    :data:`R` about the dimple's centre on the face (coming from far behind)."""
    c = np.array([*CENTRE, 0.0])
    q = (p - c) @ d
    s = -q - math.sqrt(q * q - ((p - c) @ (p - c) - R * R))
    return p + s * d


def test_a_ray_coming_down_onto_the_wall_meets_the_cavity_its_path_passes_first():
    """A ray at 45° coming down onto the panel's wall 0.02 mm beyond a dimple's rim, 0.01
    mm over the face: its path went through the cavity on the way (the wall's point is
    not on the face; ``meet_cut`` with ``z > 0`` going down), so the cavity's wall turns
    it, by total internal reflection at its normal there. A ray that reaches the wall
    before any cavity goes on to the wall as it came (``SAME_LEG``, still down), though
    its path would pass through one beyond the wall."""
    f, pr = _setup()
    walls = np.array([[1.62, 0.0, 1.62, 2.0]])
    d = np.array([H, 0.0, -H])
    out = _meet(f, pr, 1.62 - 1e-9, CENTRE[1], 0.01, d, 20, walls)
    hit = _first_on_sphere(np.array([1.62, CENTRE[1], 0.01]), d)
    m = (hit - [*CENTRE, 0.0]) / R  # out of the cavity, into the glass
    assert math.degrees(math.acos(-(d @ m))) > math.degrees(math.asin(1 / N))
    assert np.all(out[:, 0] == t.NEW_LEG)
    assert np.allclose(out[:, 4:], _tir(m, d), atol=1e-9)
    # turned by the cavity, it leaves the layer past the wall: it goes on from where it
    # meets the wall (0.095 mm over the face), not from the height it came down onto it
    turned = _tir(m, d)
    assert np.allclose(
        out[:, 1:4], [1.62, CENTRE[1], hit[2] + (1.62 - hit[0]) / turned[0] * turned[2]]
    )
    # short of the dimple, 0.08 mm over the face: its path would pass through the cavity
    # 0.046 mm beyond the wall (0.065 mm on along it), before it reaches the face's plane
    before = _meet(f, pr, 1.36 - 1e-9, CENTRE[1], 0.08, d, 5, np.array([[1.36, 0.0, 1.36, 2.0]]))
    assert np.all(before[:, 0] == t.SAME_LEG)
    assert np.allclose(before[:, 1:4], [1.36 - 1e-9, CENTRE[1], 0.08])
    assert np.allclose(before[:, 4:], d)


def _turned_down_toward_the_wall() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A ray at 45° that meets the dimple 30° from its top on the far side (incidence 75°:
    total internal reflection): where it meets it, its course, and where that turns it:
    15° down toward +x."""
    phi = math.radians(30)
    hit = np.array([CENTRE[0] + R * math.sin(phi), CENTRE[1], R * math.cos(phi)])
    d = np.array([H, 0.0, -H])
    m = (hit - [*CENTRE, 0.0]) / R
    return hit, d, _tir(m, d)


def test_a_ray_turned_down_toward_the_panel_s_wall_meets_it_before_the_face():
    """The ray of :func:`_turned_down_toward_the_wall` crosses the face's plane 0.017 mm
    short of the panel's wall at x = 1.7; the cavity turns it down at 15° toward the
    wall, which it meets 0.046 mm over the face (``AT_WALL``, on the same course), before
    the face it would come down onto 0.17 mm beyond the wall (where it was reflected, and
    went on from where it crossed the face's plane)."""
    f, pr = _setup()
    hit, d, turned = _turned_down_toward_the_wall()
    at = hit + hit[2] / H * d  # where it crosses the face's plane
    assert turned[2] < 0 and at[0] < 1.7
    out = _meet(f, pr, at[0], at[1], 0.0, d, 20, np.array([[1.7, 0.0, 1.7, 2.0]]))
    z_wall = hit[2] + (1.7 - hit[0]) / turned[0] * turned[2]
    assert np.all(out[:, 0] == t.AT_WALL)
    assert np.allclose(out[:, 1:4], [1.7, CENTRE[1], z_wall], atol=1e-8), out[0]
    assert np.allclose(out[:, 4:], turned, atol=1e-9)
    assert 0.04 < z_wall < 0.05
    # with the wall beyond where it comes down (x = 1.9): reflected by the face (TIR)
    out = _meet(f, pr, at[0], at[1], 0.0, d, 20, np.array([[1.9, 0.0, 1.9, 2.0]]))
    assert np.all(out[:, 0] == t.NEW_LEG) and np.allclose(out[:, 4:], turned * [1, 1, -1])


def test_the_tracer_turns_a_ray_its_walk_brought_onto_the_wall_off_that_wall():
    """The tracer's side of ``AT_WALL``: an LED on the left wall sends rays 40° down onto
    a dimple by a black right wall (x = 1.7, in optical contact: it takes all it meets);
    the dimple turns each 20° down toward the wall (total internal reflection 30° from its
    top), which the ray meets before the face, and takes. Its end is there, on its
    turned course; had the tracer asked for a cavity before the wall (as for a ray that
    came down onto the wall on its own), its path, walked back into the dimple that
    turned it, would have been turned again. The other half of the rays go up, and meet
    the wall after the top face reflects them (or are reflected at birth)."""
    from optdot.optics.tables import Print, Scene, Sources, Stack
    from optdot.optics.trace import trace

    f, _ = _setup()
    a, phi = math.radians(40), math.radians(30)
    d = np.array([math.cos(a), 0.0, -math.sin(a)])
    hit = np.array([CENTRE[0] + R * math.sin(phi), CENTRE[1], R * math.cos(phi)])
    m = (hit - [*CENTRE, 0.0]) / R
    turned = _tir(m, d)
    assert -(d @ m) < math.sqrt(1 - 1 / N**2) and turned[2] < 0  # beyond the critical angle
    assert hit[0] + hit[2] / math.tan(a) < 1.7 < hit[0] - hit[2] / turned[2] * turned[0]
    layer = np.zeros((1, t.L_COLS))
    layer[0, [t.L_Z0, t.L_Z1, t.L_N, t.L_WALL_MODE]] = 0.0, 2.0, N, 2.0  # black walls
    top = np.zeros(t.F_COLS)
    top[t.F_KIND], top[t.F_COS_UP] = t.INTERFACE, math.sqrt(1 - 1 / N**2)
    box = (0.0, 0.0, 1.7, 2.0)
    walls = np.array([[0, 0, 1.7, 0], [1.7, 0, 1.7, 2], [1.7, 2, 0, 2], [0, 2, 0, 0]], float)
    normals = np.array([[0, 1], [-1, 0], [0, -1], [1, 0]], float)
    emit = np.zeros((1, t.E_COLS))
    emit[0, t.E_C : t.E_C + 3] = 0.0, CENTRE[1], hit[2] + hit[0] * math.tan(a)
    emit[0, t.E_A], emit[0, t.E_B + 2] = 1.0, -1.0  # along +x, half down at 40°
    theta = math.asin(N * math.sin(a))  # in air
    sources = Sources(
        emit, np.array([0, 400]), np.linspace(0, 1, 3), np.ones((1, 3)), np.array([[1.0, theta]])
    )
    stack = Stack(layer, np.array([f, top]), walls, normals, 4)
    p = Pattern(np.array([CENTRE]), 2 * R, box)
    no_cap = np.zeros(2, np.int64), np.zeros((0, 3)), np.array([0, 0, 1, 1, 1, 1, 0.0])
    pr = Print(
        True, np.zeros((1, 1)), np.ones(4), *dot_grid(p, box), np.zeros((1, 1)), np.ones(4),
        *no_cap, np.array([[0.0, np.inf]]), np.full((1, 3), np.nan),
    )  # fmt: skip
    fate, ex, ey, ed = trace(7, 0, 400, Scene(sources, stack, pr))
    mine = np.isclose(ed, turned, atol=1e-6).all(axis=1)
    assert 150 < mine.sum() < 250, mine.sum()
    assert np.all(fate[mine] == t.EDGE)
    assert np.allclose(ex[mine], 1.7, atol=1e-6) and np.allclose(ey[mine], CENTRE[1], atol=1e-6)
    edge = fate == t.EDGE  # the others: up, or reflected back at birth (not coupled)
    assert np.all(fate[~edge] == t.UNCOUPLED) and np.isclose(ed[edge & ~mine], d, atol=1e-6).all()


@nb.njit(cache=True)
def _at_the_wall(layer, face, pr, x, z, d, walls, ask):  # pragma: no cover - compiled
    """The tracer's ``_off_wall`` for a ray at ``(x, CENTRE[1], z)`` going ``d`` onto a
    wall facing -x (``layer``'s, ``face`` its faces, ``pr`` the print's tables):
    ``(end, [x, y, z, dx, dy, dz])``. At module level and cached: compiled in the test,
    the tracer's inlined kernels took 90 s a run."""
    n = np.array([-1.0, 0.0])
    _, end, _, ex, ey, ez, a, b, c = _off_wall(
        ray_state(3, 0), layer, 0, face, n, N, x, CENTRE[1], z, pr, walls, 5.0, ask, d[0],
        d[1], d[2],
    )  # fmt: skip
    return end, np.array([ex, ey, ez, a, b, c])


@pytest.mark.slow
def test_the_tracer_turns_a_ray_by_the_cavity_it_passed_before_the_wall():
    """The tracer's wall (``_off_wall``): the ray of the test above, met at the wall by
    the tracer, is turned by the cavity its path passed through, not reflected by the
    wall (a polished glass wall would send it back at -45°, total internal reflection);
    the ray that reaches the wall before any cavity is."""
    f, pr = _setup()
    face = np.array([f, f])
    layer = np.zeros((1, t.L_COLS))
    layer[0, [t.L_Z0, t.L_Z1, t.L_N]] = 0.0, 2.0, N
    layer[0, [t.L_WALL_R, t.L_WALL_MODE, t.L_WALL_COS]] = 0.9, 0.0, math.sqrt(1 - 1 / N**2)

    def wall(x, z, d, walls, ask=True):
        return _at_the_wall(layer, face, pr, x, z, d, walls, ask)

    d = np.array([H, 0.0, -H])
    end, out = wall(1.62, 0.01, d, np.array([[1.62, 0.0, 1.62, 2.0]]))
    hit = _first_on_sphere(np.array([1.62, CENTRE[1], 0.01]), d)
    assert end == t.UNFINISHED
    assert np.allclose(out[3:], _tir((hit - [*CENTRE, 0.0]) / R, d), atol=1e-9)
    end, out = wall(1.35, 0.01, d, np.array([[1.35, 0.0, 1.35, 2.0]]))
    assert end == t.UNFINISHED and np.allclose(out[3:], [-H, 0.0, -H])
    # brought onto the wall by its walk among the cavities (not asked): the wall's own
    end, out = wall(1.62, 0.01, d, np.array([[1.62, 0.0, 1.62, 2.0]]), False)
    assert end == t.UNFINISHED and np.allclose(out[3:], [-H, 0.0, -H])


def test_the_tracer_looks_the_wall_up_behind_a_ray_that_turned_off_it():
    """The tracer's ``run`` (how far a ray came on its course, the wall looked up behind
    it only past that) starts again where its course turns. A ray born on the right wall
    0.2 mm over the face, 2° down and 45° across, comes down 4.2 mm on onto the left
    wall inside the cavities' layer (0.05 mm over the face; no cavity on its way), is
    turned by it, and would cross the face 1.43 mm on, along a row of dimples (0.3 mm
    apart, none near its first course; more far from both, the print's cells 1.1 mm).
    Its path comes down into the layer 2.9 mm back, beyond the wall it turned off:
    walked from the wall, it meets a dimple and is sent up at a new angle; taken back
    past the wall (a ``run`` kept from its first course), off the print's cells, the
    flat face alone would have turned it up. The tracer stops each ray after the two
    events (``max_events``) and tells its direction then."""
    from optdot.optics.tables import Print, Scene, Sources, Stack
    from optdot.optics.trace import trace

    f, _ = _setup()
    box = (0.0, 0.0, 3.0, 5.0)
    a = math.radians(2.0)
    course = np.array([-H, H])  # horizontal: toward the left wall, across
    zw = 0.05  # over the face at the left wall
    s1 = 3.0 / H  # horizontal path to the left wall
    y_w = 0.5 + 3.0  # where it meets the left wall
    s2 = zw / math.tan(a)  # on to the face: 1.43 mm
    line = np.arange(0.15, 1.2, 0.3 * H)  # dimples along its second course
    gx, gy = np.meshgrid(np.arange(2.0, 2.9, 0.25), np.arange(3.6, 4.9, 0.25))
    far = np.column_stack([gx.ravel(), gy.ravel()])  # far from both courses: the cells small
    p = Pattern(np.vstack([np.column_stack([line, y_w + line]), far]), 2 * R, box)
    row = np.array(f)
    row[t.F_REFL] = 1.0  # the sheet under a cavity loses nothing: every ray unfinished
    top = np.zeros(t.F_COLS)
    top[t.F_KIND], top[t.F_COS_UP] = t.INTERFACE, math.sqrt(1 - 1 / N**2)
    layer = np.array([[0.0, 1.0, N, 0.0, 1.0, 1.0, math.sqrt(1 - 1 / N**2)]])
    walls = np.array([[0, 0, 3, 0], [3, 0, 3, 5], [3, 5, 0, 5], [0, 5, 0, 0]], float)
    normals = np.array([[0, 1], [-1, 0], [0, -1], [1, 0]], float)
    emit = np.zeros((1, t.E_COLS))
    emit[0, t.E_C : t.E_C + 3] = 3.0, 0.5, zw + s1 * math.tan(a)
    emit[0, t.E_A : t.E_A + 2] = course
    emit[0, t.E_B + 2] = -1.0  # half the rays 2° down (the others up, ending elsewhere)
    theta = math.asin(N * math.sin(a))  # in air
    sources = Sources(
        emit, np.array([0, 400]), np.linspace(0, 1, 3), np.ones((1, 3)), np.array([[1.0, theta]])
    )
    stack = Stack(layer, np.array([row, top]), walls, normals, 2)
    start, x, y, foot, cg = dot_grid(p, box)
    no_cap = np.zeros(2, np.int64), np.zeros((0, 3)), np.array([0, 0, 1, 1, 1, 1, 0.0])
    pr = Print(
        True, np.zeros((1, 1)), np.ones(4), start, x, y, foot, cg, np.zeros((1, 1)),
        np.ones(4), *no_cap, np.array([[0.0, np.inf]]), np.full((1, 3), np.nan),
    )  # fmt: skip
    fate, ex, ey, d = trace(7, 0, 400, Scene(sources, stack, pr))
    here = np.isclose(ey - ex, y_w, atol=1e-5) & (ex < s2 * H + 1e-5)  # down: its 2nd course
    assert here.sum() > 150 and np.all(fate[here] == t.UNFINISHED)
    flat = np.array([H * math.cos(a), H * math.cos(a), math.sin(a)])
    assert not np.isclose(d[here], flat, atol=1e-5).all(axis=1).any()
    assert np.all(d[here, 2] > 0)


@nb.njit(cache=True)
def _met_before_wall(f, pr, walls, rays):  # pragma: no cover - compiled
    """Of ``rays`` rays coming down onto the wall ``x = 6`` (0.02 to 0.74 of a unit in
    ``-z``, within 80° of the wall's normal, anywhere along it, at any height in the
    cavities' layer 0.075 mm deep), the share that meets a cavity before the wall."""
    met = 0
    for r in range(rays):
        st = ray_state(9, r)
        st, u1 = uniform(st)
        st, u2 = uniform(st)
        st, u3 = uniform(st)
        st, u4 = uniform(st)
        phi, dz = (u2 - 0.5) * math.radians(160), -(0.02 + 0.72 * u3)
        h = math.sqrt(1 - dz * dz)
        st, act, _, _, _, _, _, _ = meet_cut(
            st, f, N, t.var_int(BARE), 6.0 - 1e-9, 1.0 + 4.0 * u4, u1 * 0.075, pr, walls,
            h * math.cos(phi), h * math.sin(phi), dz, 50.0,
        )  # fmt: skip
        met += act != t.SAME_LEG
    return met / rays


@pytest.mark.slow
def test_as_the_coverage_a_ray_coming_down_onto_the_wall_meets_as_many_cavities_as_real():
    """Dimples 0.3 mm across, 0.075 mm deep, at a fill of 0.4: rays coming down onto the
    panel's wall inside their layer meet a cavity before it as often among the coverage's
    twins as among real dots on a hexagonal lattice of that fill standing inside the
    panel (0.29 and 0.30): the twins stand about the wall's point drawn over a twin with
    the fill's chance, as the print test draws it at the face. About a point drawn off
    them (as for a ray born in the layer) they met a third as many (0.09)."""
    r, fill = 0.15, 0.4
    row = np.zeros(t.F_COLS)
    row[t.F_KIND], row[t.F_PROFILE], row[t.F_PROF_K] = t.BOTTOM_FACE, DIMPLE, 0.5
    row[[t.F_PROF_U, t.F_PROF_V, t.F_PROF_C]] = r, r, 0.0
    row[t.F_COS_DOWN], row[t.F_REFL] = math.sqrt(1 - 1 / N**2), 0.9
    f = tuple(float(v) for v in row)
    box = (0.0, 0.0, 6.0, 6.0)
    walls = np.array([[0, 0, 0, 6], [0, 6, 6, 6], [6, 6, 6, 0], [6, 0, 0, 0]], float)
    one = Pattern(np.array([[1.0, 1.0]]), 2 * r, box)
    cover = (False, np.full((6, 6), fill), np.array([0.0, 0.0, 1.0, 1.0]), *dot_grid(one, box))
    cover = (*cover, np.full((36, 3), np.nan))
    sp = math.sqrt(2 * math.pi * r * r / (math.sqrt(3) * fill))
    ii, jj = np.meshgrid(np.arange(-40, 40), np.arange(-40, 40))
    th = math.radians(17)
    b1, b2 = (
        sp * np.array([math.cos(th), math.sin(th)]),
        sp * np.array([math.cos(th + 1.047), math.sin(th + 1.047)]),
    )
    xy = ii.ravel()[:, None] * b1 + jj.ravel()[:, None] * b2 + [0.123, 0.0456]
    xy = xy[(xy[:, 0] > r) & (xy[:, 0] < 6) & (xy[:, 1] > -r) & (xy[:, 1] < 6 + r)]
    p = Pattern(xy, 2 * r, box)
    real = (True, np.ones((1, 1)), np.array(box), *dot_grid(p, box), np.zeros((0, 3)))
    a, b = _met_before_wall(f, cover, walls, 40_000), _met_before_wall(f, real, walls, 40_000)
    assert b > 0.1 and abs(a - b) < 0.1 * b, (a, b)
