"""3-D dots against a tracer no one here wrote: pvtrace (PyPI) with mesh geometry.

The same small guide in both: 3 x 3 x 0.3 mm of index 1.49, bare edges, nothing under it
(reflector 0), one Lambertian LED 1 mm wide on the left edge, and on the bottom face 25
dots on a 0.6 mm grid: spherical bumps 0.3 mm across and 0.075 mm high (half a
hemisphere), or raised micro-prisms 0.4 x 0.15 mm with facets of 30 and 45 degrees at
random angles. In pvtrace each dot is its own node, a closed triangle mesh of the guide's
material touching the guide's bottom face: the cap on 24 rings of 96 facets, the prism
its six exact planes. The shares of the fates (extracted, lost under the guide, lost at
the edges) and the polar histogram of what leaves the top must agree within pvtrace's
noise.

What pvtrace is asked to do differently, and why (`../shared` has no pvtrace of ours):

- Its meshes meet rays through trimesh, which uses embree (float32) when installed: that
  put a vertical ray's entry 3 um off a prism's base (session 36). :class:`ExactMesh`
  uses trimesh's own float64 intersector, and skips a mesh whose box the ray misses.
- Its tracer takes the material across a surface to be the *next node along the ray*
  (``photon_tracer.next_hit``; its ``Scene.intersections`` has the to-do "correctly order
  touching interfaces"). That holds for nested solids only: a ray leaving a bump's cap
  whose line later crosses the guide's face or another bump was refracted as if into
  glass (no total reflection: 38.5 % of a Lambertian flux went back into the guide against
  48.8 % by an exact cap in plain Python and 48.0 % by optdot). :func:`_next_hit` takes the
  material that holds the point just past the surface instead; pvtrace's own intersection,
  container, Fresnel and Snell are kept.

Light leaving one raised dot's surface into the air under the guide meets its neighbours
in both (optdot: ``dot_profile.among_dots``, and the ray goes on from the base it leaves
the guide's face through). It matters on a third guide: 36 bumps 0.4 mm across and 0.1 mm
high, 0.1 mm apart, where 7.8 % of pvtrace's rays meet a neighbour from the air; optdot
without them lost 4.4 points more under the guide (4.3 sigma), and agrees now. Over a
mirror lying on those bumps' tips, what the mirror returns comes up among the bumps in
both (optdot: ``dot_profile.under_dots``); a mirror flat against the face sent it
straight back in (12 points more extracted than pvtrace's)."""

from __future__ import annotations

import math

import numba as nb
import numpy as np
import pytest

from optdot.config.schema import job_from_dict
from optdot.geometry.kinds import KINDS
from optdot.geometry.shapes import Footprints
from optdot.optics.faces.dot_profile import meet_profile
from optdot.optics.marks import dot_at, dot_frame
from optdot.optics.rays import ray_state
from optdot.optics.scene import scene_of
from optdot.optics.simulate import simulate
from optdot.optics.tables import NEW_LEG
from optdot.pattern import Pattern

from .conftest import bare_guide, load_pvtrace, pvtrace_left_led

W, H, T, N = 3.0, 3.0, 0.3, 1.49
PITCH, D, HEIGHT = 0.6, 0.3, 0.075
LENGTH, WIDTH, FACETS = 0.4, 0.15, (30.0, 45.0)
RAYS = 3000
FATES = ("extracted", "lost_bottom", "lost_edges")
POLAR_EDGES = np.arange(0.0, 91.0, 15.0)


def _layout(pitch: float = PITCH) -> tuple[np.ndarray, np.ndarray]:
    """``([n, 2] centres mm, [n] angles rad)``: the grid (25 dots at 0.6 mm) and a seeded
    angle per dot."""
    g = np.arange(pitch / 2, W, pitch)
    cx, cy = np.meshgrid(g, g)
    xy = np.column_stack([cx.ravel(), cy.ravel()])
    return xy, np.random.default_rng(7).uniform(0.0, math.pi, len(xy))


def _cap_mesh(a: float, h: float, rings: int = 24, around: int = 96):
    """A closed trimesh of a spherical cap of base radius ``a`` and height ``h`` (mm) under
    the plane ``z = 0``: vertices on the sphere, the base a fan on the rim."""
    import trimesh

    r = (a * a + h * h) / (2 * h)
    top = math.asin(a / r)
    verts = [(0.0, 0.0, -h)]
    for i in range(1, rings + 1):
        al = top * i / rings
        z = 0.0 if i == rings else (r - h) - r * math.cos(al)
        for j in range(around):
            p = 2 * math.pi * j / around
            verts.append((r * math.sin(al) * math.cos(p), r * math.sin(al) * math.sin(p), z))
    verts.append((0.0, 0.0, 0.0))

    def ring(i, j):
        return 1 + (i - 1) * around + j % around

    faces = [(0, ring(1, j + 1), ring(1, j)) for j in range(around)]
    for i in range(1, rings):
        for j in range(around):
            faces += [(ring(i, j), ring(i, j + 1), ring(i + 1, j + 1))]
            faces += [(ring(i, j), ring(i + 1, j + 1), ring(i + 1, j))]
    faces += [(len(verts) - 1, ring(rings, j), ring(rings, j + 1)) for j in range(around)]
    mesh = trimesh.Trimesh(np.array(verts), np.array(faces), process=False)
    if mesh.volume < 0:
        mesh.invert()
    return mesh


def _dimple_mesh(a: float, h: float):
    """A dimple's cavity: :func:`_cap_mesh` turned over, the cap over the plane ``z = 0``
    (inside the guide), its base on it."""
    import trimesh

    cap = _cap_mesh(a, h)
    v = np.array(cap.vertices, dtype=float)
    v[:, 2] = -v[:, 2]
    mesh = trimesh.Trimesh(v, np.array(cap.faces)[:, ::-1], process=False)
    if mesh.volume < 0:
        mesh.invert()
    return mesh


def _prism_mesh(angle: float):
    """The raised prism's convex hull: its base rectangle on ``z = 0`` and its ridge
    below, the first facet rising from the ``-u`` end, turned by ``angle``."""
    import trimesh

    hu, hv = LENGTH / 2, WIDTH / 2
    t1, t2 = (math.tan(math.radians(a)) for a in FACETS)
    ridge, depth = hu * (t2 - t1) / (t1 + t2), 2 * hu * t1 * t2 / (t1 + t2)
    uvz = [(-hu, -hv, 0), (-hu, hv, 0), (hu, -hv, 0), (hu, hv, 0)]
    uvz += [(ridge, -hv, -depth), (ridge, hv, -depth)]
    c, s = math.cos(angle), math.sin(angle)
    turned = [(c * u - s * v, s * u + c * v, z) for u, v, z in uvz]
    return trimesh.convex.convex_hull(np.array(turned))


def _patched(
    fates: dict[str, int] | None = None, lose_neighbours: bool = False, cut: bool = False
) -> tuple:
    """pvtrace as the comparisons use it: ``(pv, ExactMesh, next_hit)``, the module,
    a mesh geometry met exactly and the ``photon_tracer.next_hit`` that takes the
    material past a surface to be the one holding the point just beyond it (the
    module's docstring). ``next_hit`` counts in ``fates["neighbour"]`` a dot met from
    the air under the guide (ending the ray there when ``lose_neighbours``). ``cut``:
    the dots are cavities of air in the guide (nodes inside its node, their bases on its
    face): the material a ray is in is then the node holding the point just before the
    surface too (pvtrace's ``find_container`` took a ray leaving a cavity through its
    base to be in the glass there, and refracted it as from glass into air)."""
    import trimesh
    from trimesh.ray.ray_triangle import RayMeshIntersector

    pv = load_pvtrace()
    tracer = pv.photon_tracer
    from pvtrace.geometry.utils import close_to_zero, distance_between

    class ExactMesh(pv.Mesh):
        """A convex pvtrace mesh met in float64, skipped when the ray misses its box."""

        def __init__(self, mesh, material):
            mesh = trimesh.Trimesh(mesh.vertices, mesh.faces, process=False, use_embree=False)
            super().__init__(mesh, material)
            tm = self.trimesh
            tm.ray = RayMeshIntersector(tm)
            self.lo, self.hi = tm.bounds
            self.planes = np.column_stack(
                [tm.face_normals, -(tm.face_normals * tm.triangles[:, 0]).sum(1)]
            )

        def intersections(self, position, direction):
            p, d = np.asarray(position), np.asarray(direction)
            with np.errstate(divide="ignore", invalid="ignore"):
                t1, t2 = (self.lo - 1e-9 - p) / d, (self.hi + 1e-9 - p) / d
            if np.nanmin(np.maximum(t1, t2)) < max(np.nanmax(np.minimum(t1, t2)), 0.0):
                return ()
            return super().intersections(position, direction)

        def contains(self, point):
            return bool(np.all(self.planes[:, :3] @ np.asarray(point) + self.planes[:, 3] <= 1e-12))

    def next_hit(scene, ray):
        hits = [x.to(scene.root) for x in scene.intersections(ray.position, ray.direction)]
        hits = [x for x in hits if not close_to_zero(x.distance)]
        if not hits:
            return None
        hit = hits[0]
        if len(hits) == 1:
            return hit.hit, (hit.hit, None), hit.point, hit.distance

        def holding(step):  # the deepest node holding the point a step past the surface
            at = tuple(np.asarray(hit.point) + step * np.asarray(ray.direction))
            best = scene.root
            for node in scene.root.descendants:
                if node.geometry is not None and node.depth > best.depth:
                    if node.geometry.contains(scene.root.point_to_node(at, node)):
                        best = node
            return best

        container = holding(-1e-7) if cut else tracer.find_container(hits)
        beyond = holding(1e-7)
        adjacent = beyond if beyond is not container else hit.hit
        if fates is not None and container is scene.root and hit.hit.name.startswith("dot"):
            fates["neighbour"] += 1
            if lose_neighbours:
                return None
        return hit.hit, (container, adjacent), hit.point, distance_between(ray.position, hit.point)

    return pv, ExactMesh, next_hit


def _world(pv, mesh_type, meshes: list, xy: np.ndarray, cut: bool = False):
    """pvtrace's world: the guide (a box of index ``N``) and a node of the guide's material
    for each dot's mesh under its face, at ``xy`` (``mesh_type``: :func:`_patched`'s);
    ``cut``: each a node of air inside the guide's node (a cavity over its face)."""
    import trimesh

    world = pv.Node(name="world", geometry=pv.Sphere(radius=100.0, material=pv.Material(1.0)))
    box = mesh_type(trimesh.creation.box((W, H, T)), pv.Material(N))
    guide = pv.Node(name="guide", geometry=box, parent=world)
    guide.location = (W / 2, H / 2, T / 2)
    parent, origin = (guide, (W / 2, H / 2, T / 2)) if cut else (world, (0.0, 0.0, 0.0))
    for k, ((x, y), mesh) in enumerate(zip(xy, meshes, strict=True)):
        cm = mesh.center_mass.copy()  # pvtrace centres a mesh on its centre of mass
        material = pv.Material(1.0 if cut else N)
        node = pv.Node(name=f"dot{k}", geometry=mesh_type(mesh, material), parent=parent)
        node.location = (x + cm[0] - origin[0], y + cm[1] - origin[1], cm[2] - origin[2])
    return world


def _pvtrace(
    meshes: list,
    xy: np.ndarray,
    setattr_,
    rays: int = RAYS,
    lose_neighbours: bool = False,
    mirror: float | None = None,
    cut: bool = False,
) -> tuple[dict[str, int], np.ndarray]:
    """Rays per fate traced by pvtrace (``neighbour``: rays that met a dot from the air
    under the guide) and the polar angles (degrees, in air) of those leaving the top.
    ``setattr_`` patches pvtrace (``monkeypatch.setattr``); ``lose_neighbours`` ends a
    ray there, as lost under the guide (what optdot does). ``mirror``: a perfect mirror
    under the guide's footprint, that far under its face (mm; on the dots' tips): every
    ray not extracted is then lost at the edges (out of the guide's sides, or sideways
    out of the gap over the mirror). A ray whose last surface lies under the face and
    sends it up has left the gap under the guide sideways, past its walls: lost at the
    edges, as optdot counts it (``under_dots``); 1.1 % of the rays on the close tall
    bumps, most from the outer ones, which were counted lost under the guide until
    session 42 (optdot's 22.7 % against 24.4 % there, 3 sigma). ``cut``: the meshes
    are cavities of air in the guide (:func:`_world`'s)."""
    import trimesh

    fates = dict.fromkeys((*FATES, "not_coupled", "other", "neighbour"), 0)
    pv, ExactMesh, next_hit = _patched(fates, lose_neighbours, cut)
    tracer = pv.photon_tracer
    setattr_(tracer, "next_hit", next_hit)
    world = _world(pv, ExactMesh, meshes, xy, cut)
    if mirror is not None:

        class Mirror(pv.SurfaceDelegate):
            """Every ray meeting it reflected, specularly."""

            def reflectivity(self, surface, ray, geometry, container, adjacent):
                return 1.0

            def reflected_direction(self, surface, ray, geometry, container, adjacent):
                d = np.asarray(ray.direction)
                return (float(d[0]), float(d[1]), float(-d[2]))

            def transmitted_direction(self, surface, ray, geometry, container, adjacent):
                raise AssertionError("a perfect mirror transmits nothing")

        sheet = pv.Material(1.0, surface=pv.Surface(delegate=Mirror()))
        node = pv.Node(
            name="mirror",
            geometry=ExactMesh(trimesh.creation.box((W, H, 0.5)), sheet),
            parent=world,
        )
        node.location = (W / 2, H / 2, -mirror - 0.25)
    pvtrace_left_led(pv, world, H / 2, 1.0, T)
    scene = pv.Scene(world)
    np.random.seed(1)
    polar = []
    for ray in scene.emit(rays):
        try:
            history = tracer.follow(scene, ray, maxsteps=5000)
        except pv.common.errors.GeometryError:  # a hit trimesh put 0.3 um off its facet
            fates["other"] += 1
            continue
        events = [e for _, e in history]
        if events[-1] == pv.Event.KILL:
            fates["other"] += 1
        elif events[1] == pv.Event.REFLECT:  # off the LED's edge
            fates["not_coupled"] += 1
        elif pv.Event.TRANSMIT not in events:  # passed beside the guide
            fates["other"] += 1
        else:
            last = history[-2 if events[-1] == pv.Event.EXIT else -1][0]  # its last surface
            x, y, z = last.position
            if abs(z - T) < 1e-9 and last.direction[2] > 0:
                fates["extracted"] += 1
                polar.append(math.degrees(math.acos(min(1.0, last.direction[2]))))
            elif (
                z < 1e-9
                and 0 <= x <= W
                and 0 <= y <= H
                and mirror is None
                and last.direction[2] <= 0
            ):
                fates["lost_bottom"] += 1
            else:  # out of a side, or up from under the face: out beside the guide
                fates["lost_edges"] += 1
    return fates, np.array(polar)


def _optdot(dots: dict, pattern: Pattern, rays: int = 1_000_000, mirror: bool = False):
    """optdot's trace of the guide with ``dots`` (the job's ``[dots]``) at ``pattern``
    (``mirror``: a perfect mirror under the guide, on the dots' tips)."""
    raw = bare_guide(W, H, T, N, dots, H / 2, 1.0)
    if mirror:
        raw["light_guide"] |= {"reflector": 1.0, "reflector_finish": "specular"}
    if dots.get("shape"):
        raw["orientation"] = {"random": True}
    return simulate(job_from_dict(raw, need_map=False).bench, rays, seed=3, dots=pattern)


def _agree(ours, theirs: dict[str, int], polar: np.ndarray) -> float:
    """Assert each fate's share within 2 sigma of pvtrace's and the polar histogram
    within its noise (chi-squared at the 2-sigma level, each bin within 3 sigma);
    return the largest fate's z."""
    from scipy.stats import chi2

    assert theirs["other"] <= sum(theirs.values()) // 200, theirs
    injected = sum(theirs[k] for k in FATES)
    shares = ours.summary()["shares"]
    worst = 0.0
    for key in FATES:
        p = theirs[key] / injected
        if p == 0:  # a fate the scene has none of (under a perfect mirror)
            assert shares[key] < 0.5 / injected, (key, shares[key])
            continue
        z = (shares[key] - p) / math.sqrt(p * (1 - p) / injected)
        assert abs(z) < 2.0, (key, shares[key], p, z)
        worst = max(worst, abs(z))
    mine = np.add.reduceat(ours.angles.counts.sum(axis=1), np.arange(0, 18, 3))
    expected = mine / (ours.rays - ours.fates["not_coupled"]) * injected
    seen = np.histogram(polar, bins=POLAR_EDGES)[0]
    z = (seen - expected) / np.sqrt(np.maximum(expected, 1.0))
    assert np.all(np.abs(z) < 3.0), (seen, expected.round(1))
    stat = float(np.sum((seen - expected) ** 2 / np.maximum(expected, 1.0)))
    assert chi2.sf(stat, len(seen)) > 0.0455, (seen, expected.round(1), stat)
    return worst


@pytest.mark.slow
def test_pvtrace_agrees_on_a_guide_with_bumps(monkeypatch):
    xy, _ = _layout()
    theirs, polar = _pvtrace([_cap_mesh(D / 2, HEIGHT) for _ in xy], xy, monkeypatch.setattr)
    pattern = Pattern(xy, D, (0.0, 0.0, W, H))
    ours = _optdot({"diameter": D, "profile": "bump", "height": HEIGHT}, pattern)
    _agree(ours, theirs, polar)
    # the comparison can tell: the same dots as white ink extract 1.8 times as much
    ink = _optdot({"diameter": D}, pattern, rays=200_000).summary()["shares"]
    injected = sum(theirs[k] for k in FATES)
    p = theirs["extracted"] / injected
    assert (ink["extracted"] - p) / math.sqrt(p * (1 - p) / injected) > 6


@pytest.mark.slow
def test_pvtrace_agrees_on_a_guide_with_raised_prisms(monkeypatch):
    xy, angle = _layout()
    theirs, polar = _pvtrace([_prism_mesh(a) for a in angle], xy, monkeypatch.setattr)
    size = np.tile([LENGTH, WIDTH, 0.0], (len(xy), 1))
    foot = Footprints(KINDS["rounded_rectangle"], size, angle)
    pattern = Pattern(xy, 0, (0.0, 0.0, W, H), dots=foot)
    dots = {"shape": "rounded_rectangle", "length": LENGTH, "width": WIDTH}
    dots |= {"corner_radius": 0.0, "profile": "prism", "facets": list(FACETS)}
    _agree(_optdot(dots, pattern), theirs, polar)


@pytest.mark.slow
def test_pvtrace_agrees_on_a_guide_with_dimples_whose_walls_light_meets_off_their_footprints(
    monkeypatch,
):
    """25 dimples 0.3 mm across and 0.075 mm deep (cavities of air in the guide, each a
    node of pvtrace's inside the guide's): light meets a cavity wherever its path passes
    through one, coming down beyond its rim or going up from its wall or from the LED
    beside it (:mod:`optdot.optics.faces.cavities`). Before session 43 optdot met a
    cavity only where a ray crossed the face's plane on its footprint and extracted
    6.2 % against pvtrace's 15.1 % (-15 sigma); it now agrees (4,000 of pvtrace's rays,
    about 8 minutes)."""
    xy, _ = _layout()
    fates, polar = _pvtrace(
        [_dimple_mesh(D / 2, HEIGHT) for _ in xy], xy, monkeypatch.setattr, 4000, cut=True
    )
    dots = {"diameter": D, "profile": "dimple", "depth": HEIGHT}
    _agree(_optdot(dots, Pattern(xy, D, (0.0, 0.0, W, H))), fates, polar)


@pytest.mark.slow
def test_pvtrace_agrees_on_close_tall_bumps_whose_light_meets_their_neighbours(monkeypatch):
    """Bumps 0.4 mm across and 0.1 mm high, 0.1 mm apart: a ray out of one bump's surface
    often meets the next (pvtrace counts 7.8 % of the rays); optdot follows it into the
    neighbour and agrees (ignoring it, optdot lost 29.4 % under the guide against
    pvtrace's 25.0 %, 4.3 sigma at 2000 rays). Twice the other tests' rays (4 min):
    the difference to find is a few points."""
    xy, _ = _layout(0.5)
    meshes = [_cap_mesh(0.2, 0.1) for _ in xy]
    theirs, polar = _pvtrace(meshes, xy, monkeypatch.setattr, rays=2 * RAYS)
    assert theirs["neighbour"] > 0.05 * sum(theirs[k] for k in FATES)
    pattern = Pattern(xy, 0.4, (0.0, 0.0, W, H))
    _agree(_optdot({"diameter": 0.4, "profile": "bump", "height": 0.1}, pattern), theirs, polar)


@pytest.mark.slow
def test_pvtrace_agrees_on_light_a_mirror_on_the_bumps_tips_returns_among_them(monkeypatch):
    """The close tall bumps over a perfect mirror lying on their tips (0.1 mm under the
    face): light out of the guide's bottom comes back up among the bumps, into them from
    the air as often as through the bare face between them. optdot follows it there
    and agrees; with the mirror taken flat against the face (session 40), optdot
    extracted 41.8 % against pvtrace's 29.4 % (14 sigma at 2,700 rays). 2,000 rays (4
    min): the rays live long between the mirror and the bumps."""
    xy, _ = _layout(0.5)
    meshes = [_cap_mesh(0.2, 0.1) for _ in xy]
    theirs, polar = _pvtrace(meshes, xy, monkeypatch.setattr, rays=2000, mirror=0.1)
    assert theirs["lost_bottom"] == 0
    pattern = Pattern(xy, 0.4, (0.0, 0.0, W, H))
    dots = {"diameter": 0.4, "profile": "bump", "height": 0.1}
    _agree(_optdot(dots, pattern, mirror=True), theirs, polar)


def _pv_comes_back(pv, scene, next_hit, start, d, steps: int = 200):
    """pvtrace's one ray from ``start`` (in the guide, just over its face) going ``d``
    (down), followed surface by surface until it comes back up into the guide (through a
    dot's base or the bare face: its direction then) or leaves the world (None)."""
    ray = pv.Ray(position=tuple(start), direction=tuple(d), wavelength=555.0)
    for _ in range(steps):
        info = next_hit(scene, ray)
        if info is None or info[0] is scene.root:
            return None
        hit, (container, adjacent), _, distance = info
        ray = ray.propagate(distance)
        surface, local = hit.geometry.material.surface, ray.representation(scene.root, hit)
        if surface.is_reflected(local, hit.geometry, container, adjacent):
            ray = surface.reflect(local, hit.geometry, container, adjacent)
        else:
            ray = surface.transmit(local, hit.geometry, container, adjacent)
            if adjacent is not None and adjacent.name == "guide":
                ray = ray.representation(hit, scene.root)
                if ray.direction[2] > 0:
                    return np.asarray(ray.direction)
                continue
        ray = ray.representation(hit, scene.root)
    raise AssertionError("a ray among the bumps took over 200 surfaces")


@nb.njit(cache=True)
def _meet_one(f, dots, walls, xy, d, seed):  # pragma: no cover - compiled
    """optdot's ``meet_profile`` for a ray from the guide going ``d`` onto the real dot
    at each point ``xy[i]``: ``[m, 4]`` (came back into the guide: 1, its direction)."""
    out = np.zeros((len(xy), 4))
    for i in range(len(xy)):
        x, y = xy[i, 0], xy[i, 1]
        k = dot_at(x, y, dots[3], dots[4], dots[5], dots[6], dots[7])
        _, act, _, _, a, b, c = meet_profile(
            ray_state(seed, i), f, N, dot_frame(x, y, k, dots), x, y, dots, walls, d[0], d[1], d[2]
        )
        out[i, 0], out[i, 1], out[i, 2], out[i, 3] = act == NEW_LEG, a, b, c
    return out


@pytest.mark.slow
def test_pvtrace_agrees_ray_by_ray_on_light_sent_down_onto_one_of_the_close_tall_bumps():
    """Event by event: light sent down from the guide onto the middle of the 36 close
    tall bumps at 20°, 60° and 70° from the normal (uniform over its footprint; no
    reflector) comes back into the guide as often in both tracers (within 3 sigma of
    pvtrace's 1,500 rays), going up as steeply (the mean of dz within 3 sigma): through
    the cap, out of it into the air, into a neighbour, onto the bare face and back in,
    the paths the whole guide's comparisons only sum. (Session 42: 14 directions from 0°
    to 85° agreed within 1.8 sigma; this found that the whole guide's difference was in
    the harness's count.) Without the walk among the neighbours (a ray out of a cap into
    the air going on as if none stood there) optdot brings back 0.563 at 60° and 0.674
    at 70°, against 0.611 and 0.978 with it."""
    xy, _ = _layout(0.5)
    centre = xy[np.argmin(np.hypot(xy[:, 0] - 1.25, xy[:, 1] - 1.25))]
    g = np.random.default_rng(12)
    r, p = 0.2 * np.sqrt(g.random(1500)), 2 * np.pi * g.random(1500)
    starts = centre + np.column_stack([r * np.cos(p), r * np.sin(p)])
    raw = bare_guide(W, H, T, N, {"diameter": 0.4, "profile": "bump", "height": 0.1}, 1.5, 1.0)
    scene = scene_of(job_from_dict(raw, need_map=False).bench, 1, Pattern(xy, 0.4, (0, 0, W, H)))
    pr = scene.print
    dots = (pr.explicit, pr.phi, pr.g, pr.start, pr.x, pr.y, pr.foot, pr.cg, pr.turn)
    f = tuple(float(v) for v in scene.stack.face[0])
    pv, ExactMesh, next_hit = _patched()
    world = pv.Scene(_world(pv, ExactMesh, [_cap_mesh(0.2, 0.1) for _ in xy], xy))
    for theta in (20.0, 60.0, 70.0):
        t = math.radians(theta)
        d = np.array([math.sin(t), 0.0, -math.cos(t)])
        theirs = [
            _pv_comes_back(pv, world, next_hit, (x - d[0] * 1e-7 / -d[2], y, 1e-7), d)
            for x, y in starts
        ]
        up = np.array([v[2] for v in theirs if v is not None])
        ours = _meet_one(f, dots, scene.stack.walls, np.repeat(starts, 40, axis=0), d, 5)
        share, mine = len(up) / len(starts), ours[:, 0].mean()
        z = (mine - share) / math.sqrt(share * (1 - share) / len(starts))
        assert abs(z) < 3.0, (theta, mine, share, z)
        dz = ours[ours[:, 0] > 0, 3].mean()
        assert abs(dz - up.mean()) < 3 * up.std() / math.sqrt(len(up)), (theta, dz, up.mean())
