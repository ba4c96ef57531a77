"""Shaped, oriented dots end to end: the job's keys and their errors,
the orientation field, the exact guarantee (checked pair by pair with shapely, not with
optdot's own distance), pattern files and masks read back by independent readers
(KLayout, ezdxf), and QA catching what it must."""

from __future__ import annotations

import math

import numpy as np
import pytest
import shapely

from optdot.config.schema import load_job
from optdot.geometry.orientation import Orientation, axis
from optdot.geometry.shapes import KINDS as KINDS_
from optdot.io.patterns import load_pattern, save_pattern
from optdot.orchestration.pipeline import generate, qa

from .conftest import cli, one_error, write_job

ELLIPSE = {"shape": '"ellipse"', "length": 0.08, "width": 0.04, "diameter": None}
PRISM = {
    "shape": '"rounded_rectangle"',
    "length": 0.12,
    "width": 0.03,
    "corner_radius": 0.005,
    "diameter": None,
}
LEDS = {"thickness": 0.6}
LED_ROW = (
    '\n[[light_guide.leds]]\nedge = "bottom"\npositions = [0.25, 0.75, 1.25, 1.75]\nwidth = 0.2'
)


def _ramp(nx=8, ny=6, lo=0.05, hi=0.3):
    return np.tile(np.linspace(lo, hi, nx), (ny, 1))


def _job(tmp_path, dots, orientation=None, leds=False, grid=None, **more):
    sections = {"dots": dots, "optimize": {"max_iter": 60, "seed": 3, "gap": 0.005}, **more}
    if orientation:
        sections["orientation"] = orientation
    if leds:
        sections["light_guide"] = LEDS
    path = write_job(tmp_path, _ramp() if grid is None else grid, **sections)
    if leds:
        path.write_text(path.read_text() + LED_ROW + "\n")
    return path


def _check_gradient(term, xy, grad, dots, rel, atol, h=1e-7):
    """``grad`` (``[n, 2]``, the term's at ``xy``) against central finite differences of
    ``term`` at the ``dots`` given, both axes."""
    for k in dots:
        for ax in (0, 1):
            up, dn = xy.copy(), xy.copy()
            up[k, ax] += h
            dn[k, ax] -= h
            g = np.zeros_like(xy)
            fd = (term(up, g) - term(dn, g)) / (2 * h)
            assert grad[k, ax] == pytest.approx(fd, rel=rel, abs=atol)


def _polygons(p, tol=2e-5):
    return [shapely.Polygon(p.dots.outline(k, tol) + p.xy[k]) for k in range(p.n)]


def _check_guarantee_with_shapely(p, gap, box):
    """Every pair's distance by shapely on polygons inscribed within 0.02 µm (so a
    polygon gap slightly over-states the true one by at most 0.04 µm), every dot inside
    the panel: nothing here uses optdot's distance."""
    polys = _polygons(p)
    tree = shapely.STRtree(polys)
    a, b = tree.query(polys, predicate="dwithin", distance=gap)
    sel = a < b
    assert (
        not sel.any()
        or shapely.distance(np.take(polys, a[sel]), np.take(polys, b[sel])).min() >= gap - 4e-5
    )
    panel = shapely.box(*box)
    assert all(panel.covers(q) for q in polys)


@pytest.mark.parametrize("dots", [ELLIPSE, PRISM], ids=["ellipse", "rounded_rectangle"])
def test_shaped_dots_keep_the_gap_edge_to_edge_and_fill_the_map(tmp_path, dots):
    job = load_job(_job(tmp_path, dots, {"random": "true"}))
    p = generate(job)
    assert p.kind.name == dots["shape"].strip('"') and p.n == job.n_dots
    _check_guarantee_with_shapely(p, job.optimize.gap, job.box)
    # the count is the map's integral over one footprint's area
    want = job.density.grid.mean() * job.width * job.height / job.shape.area
    assert abs(p.n - want) <= 1
    assert len(set(np.round(p.dots.angles, 3))) > p.n // 2  # random: all different
    r = qa(p, job)
    assert r.metrics["pairs_below_collision"] == 0
    assert r.metrics["shape"]["shapely_disagreements"] == 0
    assert r.metrics["shape"]["shapely_checked_pairs"] > 0
    assert r.metrics["psi6_coherence_2mm"] < 0.1
    assert r.metrics["coverage_rel_rms_smoothed"] < 0.05


def test_dots_turn_toward_their_nearest_led_where_they_end(tmp_path):
    job = load_job(_job(tmp_path, PRISM, {"toward": '"leds"'}, leds=True))
    p = generate(job)
    leds = np.array([[x, 0.0] for x in (0.25, 0.75, 1.25, 1.75)])
    near = leds[np.argmin(np.hypot(*(p.xy[:, None] - leds[None]).transpose(2, 0, 1)), axis=1)]
    d = p.xy - near
    want = np.arctan2(d[:, 1], d[:, 0]) + math.pi / 2  # long axis across the light
    off = np.degrees(np.abs(axis(p.dots.angles - want)))
    assert off.max() < 1e-5  # angles are stored to 1e-6°
    _check_guarantee_with_shapely(p, job.optimize.gap, job.box)
    r = qa(p, job)
    assert r.metrics["orientation"]["field_error_max_deg"] < 1e-5
    # QA sees a dot turned off its field
    turned = p.dots.angles.copy()
    turned[5] += math.radians(3)
    bad = type(p)(p.xy, p.diameter, p.box, dots=type(p.dots)(p.dots.kind, p.dots.size, turned))
    r = qa(bad, job)
    assert r.metrics["orientation"]["field_error_max_deg"] == pytest.approx(3, abs=1e-4)
    assert not r.passed


def test_qa_counts_a_collision_of_shapes_whose_centres_are_far(tmp_path):
    """Two ellipses end to end, centres 70 µm apart (more than a circle of their area
    needs), overlap: QA counts them by the exact gap, and shapely agrees."""
    job = load_job(_job(tmp_path, ELLIPSE, {"angle": 0}))
    p = generate(job)
    xy = p.xy.copy()
    i = int(np.argmin(np.hypot(*(xy - [1.0, 0.75]).T)))
    xy[i] = [1.0, 0.75]
    far = np.hypot(*(xy - xy[i]).T) > 0.3
    xy[~far & (np.arange(p.n) != i)] += 5.0  # clear the neighbourhood ...
    keep = (xy[:, 0] < 2.0) & (xy[:, 1] < 1.5)
    j = int(np.flatnonzero(keep & far)[0])
    xy[j] = [1.07, 0.75]  # ... and put one dot 70 µm along the long axis
    dots = p.dots.take(keep)
    q = type(p)(np.round(xy[keep], 6), dots.diameter, p.box, dots=dots)
    r = qa(q, job)
    assert r.metrics["pairs_below_collision"] == 1
    assert not r.passed


def test_same_job_same_bytes(tmp_path):
    path = _job(tmp_path, PRISM, {"toward": '"leds"'}, leds=True)
    out = [tmp_path / "a.npz", tmp_path / "b.npz"]
    for o in out:
        rc, err, _ = cli("generate", path, "-o", o)
        assert rc == 0, err
    assert out[0].read_bytes() == out[1].read_bytes()


@pytest.mark.parametrize("dots", [ELLIPSE, PRISM], ids=["ellipse", "rounded_rectangle"])
def test_files_and_masks_read_back_the_same_footprints(tmp_path, dots):
    """CSV and NPZ exactly; GDSII, OASIS and DXF through optdot's reader to 1 nm and
    1e-6°; and KLayout (GDSII, OASIS) and ezdxf (DXF) on their own: the same count,
    angles within 0.01°, areas within 0.5 %."""
    kdb = pytest.importorskip("klayout.db")
    import ezdxf

    from optdot.exporters.readback import read_any

    path = _job(tmp_path, dots, {"random": "true"})
    p = generate(load_job(path))
    order = np.lexsort(p.xy.T)
    for suffix in ("csv", "npz"):
        save_pattern(p, tmp_path / f"p.{suffix}")
        q = load_pattern(tmp_path / f"p.{suffix}")
        np.testing.assert_array_equal(q.xy, p.xy)
        np.testing.assert_array_equal(q.dots.size, p.dots.size)
        np.testing.assert_allclose(q.dots.angles, p.dots.angles, atol=1e-15)
    save_pattern(p, tmp_path / "p.npz")
    for fmt in ("gds", "oas", "dxf"):
        mask = tmp_path / f"p.{fmt}"
        rc, err, _ = cli("export", tmp_path / "p.npz", "--job", path, f"--{fmt}", mask)
        assert rc == 0, err
        q = read_any(mask)
        back = np.lexsort(q.xy.T)
        np.testing.assert_allclose(q.xy[back], p.xy[order], atol=1e-9)
        np.testing.assert_allclose(q.dots.size, p.dots.size, atol=1.1e-6)
        off = np.degrees(axis(q.dots.angles[back] - p.dots.angles[order]))
        assert np.abs(off).max() < 2e-6
    want_area = p.dots.area()[0]
    for fmt in ("gds", "oas"):
        ly = kdb.Layout()
        ly.read(str(tmp_path / f"p.{fmt}"))
        it = ly.top_cell().begin_shapes_rec(ly.layer(1, 0))
        areas, angles, centres = [], [], []
        while not it.at_end():
            areas.append(it.shape().polygon.area() * ly.dbu**2 * 1e-6)  # µm² -> mm²
            t = it.dtrans()
            angles.append(t.angle)
            centres.append((t.disp.x * 1e-3, t.disp.y * 1e-3))
            it.next()
        assert len(areas) == p.n
        np.testing.assert_allclose(areas, want_area, rtol=5e-3)
        back = np.lexsort(np.array(centres).T)
        off = np.array(angles)[back] - np.degrees(p.dots.angles[order])
        assert np.abs((off + 90) % 180 - 90).max() < 0.01
    doc = ezdxf.readfile(tmp_path / "p.dxf")
    assert not doc.audit().has_errors
    inserts = doc.modelspace().query("INSERT[layer=='DOTS']")
    assert len(inserts) == p.n
    block = doc.blocks.get(inserts[0].dxf.name)
    shape = next(iter(block))
    assert shape.dxftype() == ("ELLIPSE" if dots is ELLIPSE else "LWPOLYLINE")
    centres = np.array([(e.dxf.insert.x, e.dxf.insert.y) for e in inserts])
    back = np.lexsort(centres.T)
    rot = np.array([e.dxf.rotation for e in inserts])[back]
    assert np.abs((rot - np.degrees(p.dots.angles[order]) + 90) % 180 - 90).max() < 0.01


def test_orientation_fields():
    # a map blends axes: 179° and 1° meet at 0°, not 90°
    grid = np.radians(np.array([[179.0, 1.0]]))
    f = Orientation("map", 0.0, grid=grid, box=(0.0, 0.0, 2.0, 1.0))
    assert abs(math.degrees(f.at(np.array([[1.0, 0.5]]))[0])) < 1e-9
    assert math.degrees(f.at(np.array([[0.5, 0.5]]))[0]) == pytest.approx(-1.0)
    # random: a function of where each dot was thrown, whatever the order
    r = Orientation("random", seed=7)
    xy = np.random.default_rng(1).uniform(0, 5, (500, 2))
    a = r.at(xy + 0.01, thrown=xy)
    np.testing.assert_array_equal(a[::-1], r.at(xy[::-1], thrown=xy[::-1]))
    assert np.histogram(np.degrees(a), bins=6, range=(-90, 90))[0].min() > 50
    assert not np.array_equal(a, Orientation("random", seed=8).at(xy))
    # toward an LED: along the direction from it, plus the turn
    led = Orientation("leds", math.pi / 2, leds=np.array([[0.0, 0.0], [10.0, 0.0]]))
    got = np.degrees(led.at(np.array([[1.0, 1.0], [9.0, 1.0]])))
    np.testing.assert_allclose(got, [-45.0, 45.0])


def test_a_prism_whose_facets_differ_points_a_direction_not_an_axis(tmp_path):
    """Turned half a turn, a prism with facets of 60° and 25° is another dot: its field
    gives directions (modulo 2π). Toward the LEDs, every prism's first facet faces its
    nearest LED on both sides of the line through it (an axis flipped them where the
    direction crossed 90°); random ones point every way; a map blends directions (179°
    and -179° meet at 180°). Prisms of equal facets keep axes."""
    two = 2 * math.pi
    led = Orientation("leds", 0.0, leds=np.array([[2.5, 0.0]]), period=two)
    got = np.degrees(led.at(np.array([[2.4, 3.0], [2.6, 3.0], [1.0, -1.0]])))
    want = np.degrees(np.arctan2([3.0, 3.0, -1.0], [-0.1, 0.1, -1.5]))
    np.testing.assert_allclose(got, want, atol=1e-9)
    a = np.degrees(
        Orientation("random", seed=7, period=two).at(
            np.random.default_rng(1).uniform(0, 5, (600, 2))
        )
    )
    assert np.histogram(a, bins=6, range=(-180, 180))[0].min() > 60
    grid = np.radians(np.array([[179.0, -179.0]]))
    f = Orientation("map", 0.0, grid=grid, box=(0.0, 0.0, 2.0, 1.0), period=two)
    assert abs(abs(math.degrees(f.at(np.array([[1.0, 0.5]]))[0])) - 180.0) < 1e-9
    for facets, period in (("[60, 25]", two), ("[45, 45]", math.pi)):
        text = PRISM_JOB.replace("FACETS", facets)
        (tmp_path / "j.toml").write_text(text)
        np.savetxt(tmp_path / "m.csv", np.full((4, 6), 0.2), delimiter=",")
        assert load_job(tmp_path / "j.toml").orientation.period == period


#: A guide of raised prisms toward its LEDs (facets given), for the direction test.
PRISM_JOB = """[domain]
width = 6.0
height = 4.0
[density]
grid = "m.csv"
[dots]
shape = "rounded_rectangle"
length = 0.12
width = 0.04
corner_radius = 0.005
profile = "prism"
facets = FACETS
[orientation]
toward = "leds"
relative = "parallel"
[light_guide]
thickness = 0.4
[[light_guide.leds]]
edge = "bottom"
positions = [1.5, 4.5]
width = 1.0
"""


@pytest.mark.parametrize(
    ("dots", "orientation", "words"),
    [
        ({"shape": '"hexagon"'}, None, ["dots.shape", "ellipse"]),
        ({**ELLIPSE, "diameter": 0.05}, None, ["dots.diameter is a circle's"]),
        ({**ELLIPSE, "width": None}, None, ["needs dots.width"]),
        ({**ELLIPSE, "width": 0.09}, None, ["exceeds dots.length"]),
        ({**PRISM, "corner_radius": 0.02}, None, ["corner_radius", "cannot be drawn"]),
        ({**ELLIPSE, "width": 0.001}, None, ["cannot be drawn", "at most 50"]),
        ({"diameter": 0.046}, {"angle": 30}, ["[orientation]", "circles"]),
        (ELLIPSE, {"toward": '"leds"'}, ["needs a [light_guide]"]),
        (ELLIPSE, {"toward": '"sun"'}, ["orientation.toward"]),
        (ELLIPSE, {"random": "true", "angle": 3}, ["exclude each other"]),
        (ELLIPSE, {"map": '"angles.csv"'}, ["angles.csv", "orientation.map", "not found"]),
        (ELLIPSE, {"angle": "nan"}, ["orientation.angle"]),
        (ELLIPSE, {"map": '"density.csv"', "toward": '"leds"'}, ["give one of"]),
        ({"diameter": 0.046, "scale": "[1, 2]"}, None, ["dots.scale", "circles vary"]),
        ({**ELLIPSE, "scale": "[2, 1]"}, None, ["dots.scale", "0 < low < high"]),
        ({**ELLIPSE, "scale": "[1]"}, None, ["dots.scale", "[low, high]"]),
        ({**ELLIPSE, "scale": "[0.01, 1]"}, None, ["dots.scale", "sizes must stay within"]),
        ({**ELLIPSE, "scale": "[1, 2]", "diameter_step": 0.001}, None, ["diameter_step"]),
        ({**ELLIPSE, "spacing": 0.2}, None, ["dots.spacing needs", "dots.scale"]),
        ({**ELLIPSE, "scale": "[1, 2]", "spacing": 0.01}, None, ["dots.spacing", "spacing <="]),
    ],
)
def test_shapes_that_cannot_be_drawn_get_one_line(tmp_path, dots, orientation, words):
    path = _job(tmp_path, dots, orientation)
    where = [] if "angles.csv" in words else [str(path)]  # the file at fault is named
    one_error(("generate", path, "-o", tmp_path / "p.csv"), 2, *where, *words)
    assert not (tmp_path / "p.csv").exists()


def test_an_angle_map_with_nan_and_a_fill_the_shape_cannot_reach(tmp_path):
    path = _job(tmp_path, ELLIPSE, {"map": '"angles.csv"'})
    (tmp_path / "angles.csv").write_text("0,10\n20,nan\n")
    one_error(("generate", path, "-o", tmp_path / "p.csv"), 2, "angles.csv", "row 2, column 2")
    # 2:1 ellipses 5 µm apart cannot be dealt at a fill of 0.6: the largest is named
    path = _job(tmp_path, ELLIPSE, grid=np.full((4, 4), 0.6))  # effective 0.72
    line = one_error(("generate", path, "-o", tmp_path / "p.csv"), 2, "fill")
    assert "at most" in line and "ellipse" in line


@pytest.mark.slow
@pytest.mark.parametrize("dots", [ELLIPSE, PRISM], ids=["ellipse", "rounded_rectangle"])
def test_the_tracer_meets_the_true_oriented_footprints(tmp_path, dots):
    """The tracer's test of a point on the bottom face (its dot grid and footprints, as
    ``simulate`` builds them) against shapely's polygons of the pattern."""
    from optdot.optics.marks import on_dot as _on_dot
    from optdot.optics.scene import dot_grid

    job = load_job(_job(tmp_path, dots, {"random": "true"}))
    p = generate(job)
    start, x, y, foot, cg = dot_grid(p, p.box)
    polys = shapely.MultiPolygon(_polygons(p, 1e-6))
    rng = np.random.default_rng(2)
    pts = rng.uniform([0, 0], [2.0, 1.5], (4000, 2))
    phi, g = np.zeros((1, 1)), np.ones(4)
    got = np.array([_on_dot(a, b, True, phi, g, start, x, y, foot, cg, 0.0) for a, b in pts])
    want = shapely.covers(polys, shapely.points(pts))
    near = shapely.distance(polys.boundary, shapely.points(pts)) < 2e-6  # polygon error
    assert (got != want)[~near].sum() == 0
    assert got.mean() == pytest.approx(p.dots.area().sum() / 3.0, abs=0.02)


@pytest.mark.parametrize("scaled", [False, True], ids=["one-size", "scaled"])
@pytest.mark.parametrize("dots", [ELLIPSE, PRISM], ids=["ellipse", "rounded_rectangle"])
def test_multisphere_penalty_gradient_and_pairs(dots, scaled):
    """The multi-sphere term against a brute-force sum over every pair of circles (each
    dot's circles scaled with its footprint when sizes vary), its gradient against
    central finite differences, and the circles within the footprint (ellipse:
    inscribed) or covering it (rounded rectangle)."""
    from optdot.geometry.shapes import KINDS, DotShape
    from optdot.relax.multisphere import MultiSphereTerm

    name = dots["shape"].strip('"')
    size = tuple(float(dots[k]) for k in KINDS[name].params)
    shape = DotShape(KINDS[name], size)
    rng = np.random.default_rng(4)
    n = 60
    xy = rng.uniform(0, 0.5, (n, 2))
    angle = rng.uniform(-np.pi, np.pi, n)
    active = np.ones(n, bool)
    active[3] = False  # a phantom: no footprint
    f = rng.uniform(0.7, 1.8, n) if scaled else np.ones(n)
    term = MultiSphereTerm(shape, angle, active, 0.005, 15.0, scale=f if scaled else None)
    grad = np.zeros((n, 2))
    e = term(xy, grad)
    t, r = shape.kind.spheres(np.asarray(shape.size, np.float64))
    c = np.stack([np.cos(angle)[:, None] * t, np.sin(angle)[:, None] * t], axis=2)
    c = c * f[:, None, None] + xy[:, None]
    want = 0.0
    for i in range(n):
        for j in range(i + 1, n):
            if active[i] and active[j]:
                d = np.hypot(*(c[i][:, None] - c[j][None]).transpose(2, 0, 1))
                pen = np.maximum(f[i] * r[:, None] + f[j] * r[None] + 0.005 - d, 0.0)
                want += 15.0 * (pen**2).sum()
    assert e > 0 and e == pytest.approx(want, rel=1e-12)
    _check_gradient(term, xy, grad, rng.choice(n, 8, replace=False), 1e-4, 1e-9)
    ring = shapely.Polygon(shape.kind.outline(np.array(size), 0.0, 1e-6))
    circles = shapely.union_all(
        [shapely.Point(tt, 0).buffer(rr, 256) for tt, rr in zip(t, r, strict=True)]
    )
    if name == "ellipse":
        assert ring.buffer(1e-6).covers(circles)
    else:
        assert circles.buffer(1e-6).covers(ring)


def test_hostile_round_on_shaped_dots(tmp_path):
    """What the hostile tester found, each refused or read right: mirrored placements
    in GDSII and DXF, a trapezoid on the dot layer, a round
    rounded rectangle through DXF, random = false beside an angle, an angle map of
    1e300, and 10:1 ellipses at a fill they cannot reach."""
    import ezdxf
    import gdstk

    from optdot.errors import PatternFileError
    from optdot.exporters.readback import read_any

    path = _job(tmp_path, PRISM, {"random": "true"})
    # an ellipse cell drawn at 30°, placed mirrored (and turned by 40°): axes at 150°, 10°
    kind = KINDS_["ellipse"]
    lib = gdstk.Library(unit=1e-6, precision=1e-9)
    dot = lib.new_cell("E")
    ring = kind.outline(np.array([80.0, 40.0]), math.radians(30), 0.01)
    dot.add(gdstk.Polygon(ring, layer=1))
    top = lib.new_cell("TOP")
    top.add(gdstk.Reference(dot, (0, 0), x_reflection=True))
    top.add(gdstk.Reference(dot, (500, 0), rotation=math.radians(40), x_reflection=True))
    lib.write_gds(str(tmp_path / "m.gds"))
    p = read_any(tmp_path / "m.gds")
    got = np.degrees(p.dots.angles[np.argsort(p.xy[:, 0])])
    np.testing.assert_allclose(np.abs(np.degrees(axis(np.radians(got - [150, 10])))), 0, atol=1e-3)
    doc = ezdxf.new("R2010", units=4)  # mm
    doc.layers.add("DOTS")
    blk = doc.blocks.new("E")
    blk.add_ellipse(
        (0, 0), major_axis=(0.04 * math.cos(0.5236), 0.04 * math.sin(0.5236)), ratio=0.5
    )
    msp = doc.modelspace()
    msp.add_blockref("E", (0.5, 0.5), dxfattribs={"layer": "DOTS", "xscale": -1})
    msp.add_blockref("E", (1.5, 0.5), dxfattribs={"layer": "DOTS", "xscale": -1, "rotation": 40})
    doc.saveas(tmp_path / "m.dxf")
    p = read_any(tmp_path / "m.dxf")
    got = np.degrees(p.dots.angles[np.argsort(p.xy[:, 0])])
    np.testing.assert_allclose(np.abs(np.degrees(axis(np.radians(got - [150, 10])))), 0, atol=1e-3)
    # a trapezoid's vertices lie on a rectangle, but it is not one
    lib = gdstk.Library(unit=1e-6, precision=1e-9)
    lib.new_cell("TOP").add(gdstk.Polygon([(0, 0), (100, 0), (80, 30), (20, 30)], layer=1))
    lib.write_gds(str(tmp_path / "t.gds"))
    with pytest.raises(PatternFileError, match="not a circle, an ellipse or a rounded"):
        read_any(tmp_path / "t.gds")
    # a rounded rectangle that is a disc survives DXF
    disc = {**PRISM, "length": 0.05, "width": 0.05, "corner_radius": 0.025}
    path = _job(tmp_path, disc)
    rc, err, _ = cli("export", path, "--dxf", tmp_path / "d.dxf", "-q")
    assert rc == 0, err
    rc, err, _ = cli("qa", tmp_path / "d.dxf", "--job", path, "-q")
    assert rc == 0, err
    # random = false leaves the angle; a map of 1e300 is refused; 10:1 at 0.3 is refused
    job = load_job(_job(tmp_path, ELLIPSE, {"random": "false", "angle": 20}))
    assert job.orientation.mode == "constant"
    path = _job(tmp_path, ELLIPSE, {"map": '"angles.csv"'})
    (tmp_path / "angles.csv").write_text("0,10\n20,1e300\n")
    one_error(("check", path), 2, "row 2, column 2", "-360..360")
    needles = {**ELLIPSE, "length": 0.1, "width": 0.01}
    path = _job(tmp_path, needles, grid=np.full((4, 4), 0.3))
    line = one_error(("check", path), 2, "at most")
    most = float(line.rsplit("at most ", 1)[1].split()[0])
    path = _job(tmp_path, needles, grid=np.full((4, 4), most))
    rc, err, _ = cli("check", path, "-q")  # the fill named is one the check lets run
    assert rc == 0, err


def test_check_and_design_know_shaped_dots(tmp_path):
    """``check`` estimates shaped dots at their measured cost (one process and tiled),
    and ``design`` refuses a fill range the dots cannot be dealt at."""
    from optdot.runtime.cost import SHAPED_MEMORY, SHAPED_TIME, estimate_cost

    disc, shaped = estimate_cost(10**6, 200, 6), estimate_cost(10**6, 200, 6, shaped=True)
    assert shaped.peak_bytes == pytest.approx(SHAPED_MEMORY * disc.peak_bytes, rel=1e-6)
    assert shaped.seconds - 1.0 == pytest.approx(SHAPED_TIME * (disc.seconds - 1.0))
    assert shaped.disk_bytes["parquet"] > disc.disk_bytes["parquet"]
    assert shaped.disk_bytes["gds"] > disc.disk_bytes["gds"]
    disc, shaped = (estimate_cost(10**7, 200, 6, 150_000, 2, shaped=s) for s in (False, True))
    assert shaped.seconds - 8.0 == pytest.approx(SHAPED_TIME * (disc.seconds - 8.0))
    assert shaped.peak_bytes > 1.4 * disc.peak_bytes - 0.5 * 2**30
    path = _job(tmp_path, PRISM, {"toward": '"leds"'}, leds=True)
    text = path.read_text().replace('[density]\ngrid = "density.csv"\n', "")
    path.write_text(text + "\n[design]\nfill_range = [0.0, 0.75]\n")
    one_error(("design", path, "-o", tmp_path / "m.csv"), 2, "design.fill_range", "at most")
    assert not (tmp_path / "m.csv").exists()


def test_shaped_dots_scale_with_the_map_as_circles_do(tmp_path):
    """``dots.scale`` with the pitch rule: every dot is the footprint scaled (its aspect
    and corner kept, sizes to 1 nm), larger where the fill is higher, within the range;
    the count follows each cell's size and the coverage the map; the exact gap holds by
    shapely; QA's cross-check reads dots of many sizes."""
    dots = {**PRISM, "scale": "[0.8, 1.6]", "spacing": 0.15}
    path = _job(tmp_path, dots, {"random": "true"}, grid=_ramp(lo=0.1, hi=0.4),
                domain={"width": 5.0, "height": 3.0})  # fmt: skip
    job = load_job(path)
    p = generate(job)
    scale = p.dots.size[:, 0] / 0.12
    np.testing.assert_allclose(p.dots.size, np.outer(scale, [0.12, 0.03, 0.005]), atol=1.1e-6)
    assert len(np.unique(p.dots.size[:, 0])) >= 10
    assert 0.8 - 1e-9 <= scale.min() and scale.max() <= 1.6 + 1e-9
    assert np.corrcoef(p.xy[:, 0], scale)[0, 1] > 0.8  # the map rises along x
    assert p.n == job.n_dots
    covered = float(p.dots.area().sum()) / (job.width * job.height)
    assert covered == pytest.approx(float(job.density.grid.mean()), rel=0.02)
    _check_guarantee_with_shapely(p, job.optimize.gap, job.box)
    r = qa(p, job)
    assert r.passed, r.failures()
    assert r.metrics["shape"]["shapely_checked_pairs"] > 0
    assert r.metrics["shape"]["shapely_disagreements"] == 0
    # one footprint size: the claim rule at low fills keeps the smallest, exactly the
    # footprint asked for (no 1 nm drift from the rule's rounding)
    path = _job(tmp_path, {**ELLIPSE, "scale": "[1, 2]"}, grid=np.full((2, 2), 0.1))
    q = generate(load_job(path))
    np.testing.assert_array_equal(np.unique(q.dots.size, axis=0), [[0.08, 0.04]])


@pytest.mark.parametrize("scaled", [False, True], ids=["one-size", "scaled"])
@pytest.mark.parametrize("dots", [ELLIPSE, PRISM], ids=["ellipse", "rounded_rectangle"])
def test_exact_gap_penalty_value_and_gradient(dots, scaled):
    """The exact-gap term against a brute-force sum over every pair (phantoms left out;
    the gaps shapely's where the footprints are apart), and its gradient
    against central finite differences; ellipses relax with it, rectangles with the
    multi-sphere circles (measured, relax/exactgap.py)."""
    from optdot.geometry.shapes import KINDS, DotShape
    from optdot.relax.exactgap import ExactGapTerm
    from optdot.relax.optdot import FOOTPRINT_TERMS

    assert FOOTPRINT_TERMS[KINDS["ellipse"].relaxation] is ExactGapTerm
    name = dots["shape"].strip('"')
    shape = DotShape(KINDS[name], tuple(float(dots[k]) for k in KINDS[name].params))
    rng = np.random.default_rng(5)
    n, gap, w = 50, 0.005, 5.0
    xy = rng.uniform(0, 0.45, (n, 2))
    angle = rng.uniform(-np.pi, np.pi, n)
    f = rng.uniform(0.7, 1.5, n) if scaled else None
    active = np.ones(n, bool)
    active[7] = False
    term = ExactGapTerm(shape, angle, active, gap, w, scale=f)
    grad = np.zeros((n, 2))
    e = term(xy, grad)
    feet = shape.footprints(angle, f)
    i, j = np.triu_indices(n, 1)  # every pair, not the pair list's
    live = active[i] & active[j]
    g = feet.gap(xy, i[live], j[live])
    assert e > 0 and e == pytest.approx(w * np.sum(np.maximum(gap - g, 0.0) ** 2), rel=1e-12)
    # the gaps it penalises are shapely's where the footprints do not overlap
    apart = (g > 0) & (g < gap)
    assert apart.sum() >= 3
    for a, b, gg in zip(i[live][apart], j[live][apart], g[apart], strict=True):
        pa, pb = (shapely.Polygon(feet.outline(k, 1e-7) + xy[k]) for k in (a, b))
        assert pa.distance(pb) == pytest.approx(gg, abs=3e-7)
    pushed = np.flatnonzero(np.abs(grad).sum(axis=1) > 0)
    _check_gradient(term, xy, grad, rng.choice(pushed, 8, replace=False), 1e-3, 1e-8)


def test_scaled_capsules_stay_drawable_and_scaled_fills_are_checked(tmp_path):
    """A capsule (corner radius = width / 2) scaled by 1.3741 rounds its width to
    0.041223 mm: its radius is rounded down to 0.020611, not up over half the width, so
    its CSV reads back; a fill the largest scaled dot cannot reach is refused before any
    work, as for one size."""
    from optdot.geometry.shapes import KINDS, DotShape

    capsule = DotShape(KINDS["rounded_rectangle"], (0.12, 0.03, 0.015))
    feet = capsule.footprints(np.zeros(3), np.array([1.3741, 1.0, 0.6]))
    np.testing.assert_array_equal(feet.size[0], [0.164892, 0.041223, 0.020611])
    np.testing.assert_array_equal(feet.size[1], [0.12, 0.03, 0.015])
    p = type(generate(load_job(_job(tmp_path, PRISM))))(
        np.array([[0.5, 0.5], [1.0, 0.5], [1.5, 0.5]]), feet.diameter, (0, 0, 2, 1.5), dots=feet
    )
    save_pattern(p, tmp_path / "c.csv")
    np.testing.assert_array_equal(load_pattern(tmp_path / "c.csv").dots.size, feet.size)
    path = _job(tmp_path, {**ELLIPSE, "scale": "[0.8, 1.6]"}, grid=np.full((4, 4), 0.8))
    one_error(("check", path), 2, "fill 0.8", "128 × 63.99 µm ellipse", "at most")
