"""``[process]``: masks drawn for the print. Each kind's parallel body against shapely's
``buffer``, Steiner's sum against shapely's areas, a mask read back as the print it makes
(GDSII, OASIS, DXF; KLayout and ezdxf reading the compensated footprints), the guarantee
on the print after the grid, and refusals."""

from __future__ import annotations

import math

import numpy as np
import pytest
import shapely
from hypothesis import given, settings
from hypothesis import strategies as st

from optdot.config.schema import load_job
from optdot.exporters.options import ExportOptions
from optdot.exporters.readback import read_any
from optdot.geometry.kinds import KINDS, turned
from optdot.orchestration.pipeline import generate
from optdot.printing.mask import mask_ring
from optdot.printing.process import Process

from .conftest import cli, one_error, write_job

CIRCLE, ELLIPSE, RECT = KINDS["circle"], KINDS["ellipse"], KINDS["rounded_rectangle"]
#: Sizes (mm) of each kind with a gain each must take exactly (under its curvature).
CASES = [
    (CIRCLE, [0.046], 0.010),
    (ELLIPSE, [0.080, 0.040], 0.008),
    (RECT, [0.120, 0.030, 0.005], 0.005),
]


def _exact(kind, size, tol=1e-7):
    return shapely.Polygon(kind.outline(np.asarray(size, float), 0.0, tol))


@pytest.mark.parametrize(("kind", "size", "g"), CASES)
@pytest.mark.parametrize("sign", [1.0, -1.0])
def test_mask_grown_by_the_gain_is_the_footprint(kind, size, g, sign):
    """The mask's polygon (the parallel body at -g) grown by g with shapely's buffer
    (exact arcs to its segment count) is the footprint: within the export tolerance
    everywhere (Hausdorff) and in area; a negative gain (an etch) the other way."""
    g *= sign
    tol = 1e-5
    ring = kind.parallel_outline(np.asarray(size, float), -g, tol)
    mask = shapely.Polygon(ring)
    assert mask.is_valid and mask.exterior.is_ccw
    printed = mask.buffer(g, quad_segs=256, join_style="round")
    want = _exact(kind, size)
    assert printed.hausdorff_distance(want) < 2 * tol
    assert abs(printed.area - want.area) <= want.length * tol  # chords inside by <= tol
    # the mask itself: the footprint's inner (outer) parallel body, by shapely
    assert mask.hausdorff_distance(want.buffer(-g, quad_segs=256)) < 2 * tol


@pytest.mark.parametrize(("kind", "size", "g"), CASES)
def test_steiner_sum_against_shapely(kind, size, g):
    """``A + P g + π g²`` against shapely's area of the footprint buffered by ±g (shrunk:
    exact while g is within the curvature), and the perimeters against shapely's."""
    proc = Process(dot_gain=g)
    s = np.asarray(size, float)[None, :]
    poly = _exact(kind, size, 1e-9)
    assert kind.perimeter(s)[0] == pytest.approx(poly.length, rel=1e-6)
    for h in (g, -g, 0.5 * g):
        want = poly.buffer(h, quad_segs=512).area
        # shapely's inward buffer of a polygon errs by ~1e-5 of the area
        assert proc.steiner_area(kind, s, h)[0] == pytest.approx(want, rel=2e-6 if h > 0 else 2e-5)


@settings(max_examples=40, deadline=None)
@given(
    st.floats(0.03, 0.2),
    st.floats(0.2, 1.0),
    st.floats(0.0, 0.5),
    st.floats(-0.9, 0.9),
    st.floats(-math.pi, math.pi),
)
def test_fit_grown_reads_the_print_off_any_mask(length, aspect, corner, gain, angle):
    """Whatever the kind's size, gain (within its curvature) and angle: the mask's
    polygon on a 1 nm grid is read back as the printed footprint, to 3 nm."""
    width = length * aspect
    for kind, size in (
        (CIRCLE, [width]),
        (ELLIPSE, [length, width]),
        (RECT, [length, width, corner * 0.5 * width]),
    ):
        s = np.asarray(size, float)
        floor = float(kind.curvature_floor(s[None])[0])
        g = gain * (floor if gain > 0 else 0.02)
        if kind is RECT and g > 0 and s[2] < g:
            continue  # a corner under the gain prints rounder: refused by the job
        ring = np.round((turned(kind.parallel_outline(s, -g, 1e-6), angle) + 0.3) * 1e6) / 1e6
        fit = kind.fit_grown(ring, g, 2e-6, 1e-3)
        assert fit.ok, (kind.name, size, g)
        assert np.abs(fit.size - s).max() < 3e-6, (kind.name, fit.size, s, g)
        np.testing.assert_allclose(fit.centre, 0.3, atol=2e-6)


def test_mask_ring_scaled_snapped_and_mirrored_by_coordinates():
    p = Process(dot_gain=0.008, grid=1e-4, shrink=(0.005, 0.005), mirror="x")
    ring = mask_ring(p, CIRCLE, np.array([0.046]), 1e-5)
    r = np.hypot(*ring.T)
    assert np.all(np.abs(np.round(ring / 1e-4) * 1e-4 - ring) < 1e-12)  # on the grid
    assert np.abs(r - (0.023 - 0.008) / 0.995).max() <= 1e-4 / math.sqrt(2) + 1e-12
    box = (0.0, 0.0, 3.0, 2.0)
    xy = np.array([[0.5, 0.25], [2.9, 1.9]])
    placed = p.place(xy, box)
    np.testing.assert_allclose(
        placed, np.round(np.column_stack([3.0 - xy[:, 0], xy[:, 1]]) / 0.995 / 1e-4) * 1e-4
    )
    np.testing.assert_allclose(p.unplace(placed, box), xy, atol=1e-4)
    assert p.turn(np.array([0.3]))[0] == -0.3
    assert Process(mirror="y").place(xy, box)[0, 1] == pytest.approx(1.75)


# --- jobs -------------------------------------------------------------------------------

PROCESS = {"dot_gain": 0.008, "min_space": 0.005, "grid": 0.0001, "shrink": 0.005, "mirror": '"x"'}


def _job(tmp_path, process=PROCESS, dots=None, **more):
    grid = np.tile(np.linspace(0.1, 0.3, 6), (4, 1))
    sections = {"domain": {"width": 1.6, "height": 1.2}, "process": process, **more}
    if dots:
        sections["dots"] = dots
    return write_job(tmp_path, grid, **sections)


@pytest.fixture(scope="module")
def circles(tmp_path_factory):
    """A circle job with a process, its pattern (the print) and its masks."""
    tmp = tmp_path_factory.mktemp("process")
    path = _job(tmp)
    job = load_job(path)
    rc, err, _ = cli(
        "export", path, "--gds", tmp / "m.gds", "--oas", tmp / "m.oas", "--dxf", tmp / "m.dxf",
        "--csv", tmp / "p.csv", "-q",
    )  # fmt: skip
    assert rc == 0, err
    return tmp, path, job, read_any(tmp / "p.csv")


def test_the_relaxation_keeps_the_printed_gap_with_the_grid_on_top(circles):
    _, _, job, p = circles
    margin = 2 * math.sqrt(2) * 1e-4
    assert job.optimize.gap == pytest.approx(0.005 + margin)
    assert job.collision_distance == pytest.approx(0.046 + 0.005)
    d = np.hypot(*(p.xy[:, None] - p.xy[None]).transpose(2, 0, 1))
    np.fill_diagonal(d, 1)
    assert d.min() >= 0.046 + 0.005 + margin - 1e-9


@pytest.mark.parametrize("fmt", ["gds", "oas", "dxf"])
def test_a_mask_reads_back_as_the_print(circles, fmt):
    """The mask's dots are the print's shrunk by the gain, scaled and mirrored; read with
    the job's process they are the pattern's again (places to the grid, sizes to nm)."""
    from scipy.spatial import cKDTree

    tmp, _, job, p = circles
    drawn = read_any(tmp / f"m.{fmt}", ExportOptions(process=Process(grid=1e-4)))  # as drawn
    k = 1 / 0.995
    np.testing.assert_allclose(drawn.diameter, k * (0.046 - 0.016), atol=2e-5)
    assert drawn.box[2] == pytest.approx(1.6 * k, abs=1e-4)
    want = np.column_stack([1.6 - p.xy[:, 0], p.xy[:, 1]]) * k  # mirrored in x, scaled
    d, i = cKDTree(want).query(drawn.xy)
    assert d.max() < 1e-4 and len(set(i.tolist())) == p.n
    q = read_any(tmp / f"m.{fmt}", ExportOptions(process=job.process))
    d, i = cKDTree(p.xy).query(q.xy)
    assert d.max() < 1e-4 and len(set(i.tolist())) == p.n
    np.testing.assert_allclose(q.diameter, 0.046, atol=2e-5)


def test_klayout_reads_the_compensated_footprints(circles):
    kdb = pytest.importorskip("klayout.db")
    tmp, _, _, p = circles
    ly = kdb.Layout()
    ly.read(str(tmp / "m.gds"))
    it = ly.top_cell().begin_shapes_rec(ly.layer(1, 0))
    areas, xs = [], []
    while not it.at_end():
        poly = it.shape().polygon.transformed(it.trans())
        areas.append(poly.area() * ly.dbu**2 * 1e-6)
        xs.append([pt.x * ly.dbu * 1e-3 for pt in poly.each_point_hull()])
        it.next()
    assert len(areas) == p.n
    want = math.pi * (0.5 * (0.046 - 0.016) / 0.995) ** 2
    np.testing.assert_allclose(areas, want, rtol=5e-3)
    on_grid = np.concatenate(xs) / 1e-4
    assert np.abs(on_grid - np.round(on_grid)).max() < 1e-6  # every vertex on the grid


def test_qa_judges_the_print(circles, tmp_path):
    """An uncompensated mask of the same dots passes as drawn and fails under the process
    (its print: 62 µm dots that overlap, in the wrong place); the compensated one passes."""
    tmp, path, _, _ = circles
    rc, err, _ = cli("qa", tmp / "m.gds", "--job", path, "-q")
    assert rc == 0, err
    plain = tmp_path / "plain.toml"
    plain.write_text(
        path.read_text()
        .split("[process]")[0]
        .replace('grid = "density.csv"', f'grid = "{tmp / "density.csv"}"')
    )
    rc, err, _ = cli("export", tmp / "p.csv", "--job", plain, "--gds", tmp_path / "u.gds", "-q")
    assert rc == 0, err
    rc, _, out = cli("qa", tmp_path / "u.gds", "--job", plain)
    assert rc == 0
    rc, _, out = cli("qa", tmp_path / "u.gds", "--job", path)
    assert rc == 1
    fails = [line for line in out.splitlines() if line.startswith("FAIL")]
    assert any("(collisions)" in f for f in fails), out
    # drawn 46 µm, unscaled by the shrink and grown by twice the gain
    assert any("not the job's circle 46 µm (the first: circle 61.77 µm" in f for f in fails), out


@pytest.mark.slow  # over 2 s on 2 cores
def test_shaped_dots_print_exactly_after_the_grid(tmp_path):
    """Turned ellipses on a coarse grid (each a polygon of its own, every vertex on the
    grid): every near pair's printed gap, by shapely on the mask's own polygons unscaled
    and grown by the gain, is at least min_space; read back they are the pattern's."""
    proc = {"dot_gain": 0.006, "min_space": 0.004, "grid": 0.0005, "shrink": 0.004, "mirror": '"y"'}
    dots = {"shape": '"ellipse"', "length": 0.08, "width": 0.04, "diameter": None}
    path = _job(tmp_path, proc, dots, orientation={"random": "true"})
    job = load_job(path)
    p = generate(job)
    rc, err, _ = cli("export", path, "--gds", tmp_path / "m.gds", "--dxf", tmp_path / "m.dxf", "-q")
    assert rc == 0, err
    import gdstk

    lib = gdstk.read_gds(str(tmp_path / "m.gds"))
    top = lib.top_level()[0]
    polys = [q.points * 1e-3 for q in top.polygons if q.layer == 1]
    assert len(polys) == p.n
    pts = np.concatenate(polys) / 5e-4
    assert np.abs(pts - np.round(pts)).max() < 1e-6
    shapes = [shapely.Polygon(q / (1 / 0.996)) for q in polys]
    centres = np.array([s.centroid.coords[0] for s in shapes])
    tree = shapely.STRtree(shapes)
    i, j = tree.query(shapes, predicate="dwithin", distance=0.05)
    keep = i < j
    gaps = shapely.distance(np.array(shapes)[i[keep]], np.array(shapes)[j[keep]]) - 2 * 0.006
    assert keep.sum() > 0.5 * p.n and gaps.min() >= 0.004 - 1e-9, (keep.sum(), gaps.min())
    assert len(centres) == p.n
    from scipy.spatial import cKDTree

    from optdot.geometry.orientation import axis

    drawn = read_any(tmp_path / "m.dxf", ExportOptions(process=Process(grid=5e-4)))
    want = np.column_stack([p.xy[:, 0], 1.2 - p.xy[:, 1]]) / 0.996  # mirrored in y, scaled
    d, i = cKDTree(want).query(drawn.xy)
    assert d.max() < 1e-3
    off = np.degrees(axis(drawn.dots.angles + p.dots.angles[i]))  # turned the other way
    assert np.abs(off).max() < 0.5
    for fmt in ("gds", "dxf"):
        q = read_any(tmp_path / f"m.{fmt}", ExportOptions(process=job.process))
        np.testing.assert_allclose(np.sort(q.xy[:, 1]), np.sort(p.xy[:, 1]), atol=1e-3)
        np.testing.assert_allclose(q.dots.size, np.tile([0.08, 0.04], (p.n, 1)), atol=2.5e-4)
        rc, err, _ = cli("qa", tmp_path / f"m.{fmt}", "--job", path, "-q")
        assert rc == 0, (fmt, err)


ELLIPSE_DOTS = {"shape": '"ellipse"', "length": 0.08, "width": 0.04, "diameter": None}


@pytest.mark.parametrize(
    ("process", "dots", "words"),
    [
        ({"dot_gain": 0.012}, ELLIPSE_DOTS,
         ("ellipse's smallest radius of curvature (10 µm)", "largest gain it allows is 9 µm")),
        ({"dot_gain": 0.006}, {"shape": '"rounded_rectangle"', "length": 0.12, "width": 0.03,
                               "corner_radius": 0.005, "diameter": None},
         ("corners of 6 µm", "9.442 µm²", "at least 6 µm")),
        ({"dot_gain": 0.012, "min_feature": 0.03}, None,
         ("22 µm wide on the mask", "min_feature = 30 µm", "over 54 µm wide")),
        ({"shrink": 0.12}, None, ("process.shrink = 0.12", "0 <= s < 0.1")),
        ({"shrink": "[0.004]"}, None, ("process.shrink", "[x, y]")),
        ({"mirror": '"z"'}, None, ("process.mirror = 'z'", "none, x, y")),
        ({"dot_gain": -0.004, "min_space": 0.005}, None, ("closes the mask's gap", "over 8 µm")),
        ({"dot_gain": 0.005, "gain_tolerance": 0.003, "min_space": 0.005}, None,
         ("gain_tolerance = ±3 µm", "raise min_space")),
        ({"grid": 0.006, "min_space": 0.005}, None,
         ("process.grid = 6 µm", "coarser than the 5 µm gap")),
        ({"dot_gain": 1.5}, None, ("process.dot_gain = 1.5", "per edge")),
        ({"grid": 1e-9}, None, ("process.grid = 1e-09", "finer than the masks' 1 nm")),
        ({"min_feature": 0.05}, None, ("process.min_feature:", "46 µm wide")),
    ],
)  # fmt: skip
def test_a_job_that_cannot_print_is_refused(tmp_path, process, dots, words):
    path = _job(tmp_path, process, dots)
    one_error(["generate", path, "-o", tmp_path / "p.csv"], 2, str(path), *words)
    assert not (tmp_path / "p.csv").exists()


def test_anisotropic_shrink_in_gds_not_dxf(tmp_path):
    """A scale per axis: GDSII draws round dots as their scaled polygons (read back as the
    print); DXF, whose circles cannot be scaled so, refuses in one line."""
    path = _job(tmp_path, {"dot_gain": 0.005, "shrink": "[0.006, 0.002]"})
    job = load_job(path)
    p = generate(job)
    rc, err, _ = cli("export", path, "--gds", tmp_path / "m.gds", "-q")
    assert rc == 0, err
    q = read_any(tmp_path / "m.gds", ExportOptions(process=job.process))
    np.testing.assert_allclose(np.sort(q.xy[:, 0]), np.sort(p.xy[:, 0]), atol=1e-6)
    np.testing.assert_allclose(q.diameter, 0.046, atol=2e-6)
    one_error(["export", path, "--dxf", tmp_path / "m.dxf"], 2, "scales x and y apart", "GDSII")


def test_the_tolerance_band_is_steiner_on_every_dot(circles, tmp_path):
    """The band's printed coverage at gain ± tolerance: each dot's disc grown by the
    offset, summed, over the map's coverage (shapely's buffer on a sample of dots agrees
    with Steiner's sum); the nominal print is the map's within 0.2 %."""
    tmp, path, job, p = circles
    text = path.read_text().replace("[process]", "[process]\ngain_tolerance = 0.002")
    banded = tmp_path / "job.toml"
    banded.write_text(text.replace('grid = "density.csv"', f'grid = "{tmp / "density.csv"}"'))
    rc, err, out = cli("qa", tmp / "m.gds", "--job", banded, "--json", tmp_path / "q.json")
    assert rc == 0, err  # advisory: a warning, not a failure
    assert "WARN  coverage error RMS across the gain's tolerance (6–10 µm per edge" in out
    import json

    band = json.loads((tmp_path / "q.json").read_text())["metrics"]["tolerance_band"]
    assert band["gain_mm"] == pytest.approx([0.006, 0.008, 0.010])
    wanted = float(job.density.grid.mean()) * 1.6 * 1.2
    q = read_any(tmp / "m.gds", ExportOptions(process=job.process))  # the print read back
    for got, delta in zip(band["coverage_ratio"], (-0.002, 0.0, 0.002), strict=True):
        want = float(np.sum(np.pi * (0.5 * q.diameter + delta) ** 2)) / wanted
        assert got == pytest.approx(want, rel=2e-4)
        sample = [
            shapely.Point(x, y).buffer(0.023, quad_segs=512).buffer(delta, quad_segs=512)
            for x, y in p.xy[:20]
        ]
        assert sum(s.area for s in sample) == pytest.approx(
            20 * np.pi * (0.023 + delta) ** 2, rel=1e-5
        )
    assert band["coverage_ratio"][1] == pytest.approx(1.0, abs=2e-3)
    assert band["coverage_rel_rms_smoothed"][0] > 3 * band["coverage_rel_rms_smoothed"][1]


@pytest.mark.slow  # over 10 s
@pytest.mark.parametrize("ink", [None, [1.0, 1.0, 0.8, 0.5, 0.3, 0.0, 0.2, 0.9]])
def test_caps_print_as_the_job_s_caps(tmp_path, ink):
    """Caps over LEDs are printed too: a solid cap's disc and a graded cap's rings shrink
    by the gain on the mask (each ring's edges move in) and read back as the job's."""
    from .test_backlight import _toml, direct_job

    leds = {"pitch": [5.0, 5.0], "size": 0.2, "cap": 0.8, **({"cap_ink": ink} if ink else {})}
    path = direct_job(tmp_path, 10.0, 10.0, 0.3, leds=leds)
    proc = {"process": {"dot_gain": 0.005, "grid": 0.0001, "shrink": 0.004, "mirror": "x"}}
    path.write_text(path.read_text() + _toml(proc))
    job = load_job(path)
    rc, err, _ = cli("export", path, "--gds", tmp_path / "m.gds", "--dxf", tmp_path / "m.dxf", "-q")
    assert rc == 0, err
    for fmt in ("gds", "dxf"):
        drawn = read_any(tmp_path / f"m.{fmt}", ExportOptions(process=Process(grid=1e-4)))
        q = read_any(tmp_path / f"m.{fmt}", ExportOptions(process=job.process))
        if ink is None:
            np.testing.assert_allclose(drawn.outline.caps[:, 2], (0.8 - 0.01) / 0.996, atol=2e-4)
        else:
            rings = job.domain.cap_rings
            inner = np.where(rings[:, 0] > 0, rings[:, 0] + 0.005, 0.0)
            want = np.column_stack([inner, rings[:, 1] - 0.005]) / 0.996
            np.testing.assert_allclose(drawn.outline.cap_rings, want, atol=2e-4)
            np.testing.assert_allclose(q.outline.cap_rings, rings, atol=2e-4)
        np.testing.assert_allclose(
            np.sort(q.outline.caps[:, 0]), np.sort(job.domain.caps[:, 0]), atol=2e-4
        )
        np.testing.assert_allclose(q.outline.caps[:, 2], 0.8, atol=2e-4)
        rc, err, _ = cli("qa", tmp_path / f"m.{fmt}", "--job", path, "-q")
        assert rc == 0, (fmt, err)


@pytest.mark.slow
def test_the_luminance_band_traces_the_real_dots_grown(tmp_path):
    """``simulate`` with a pattern under a process with a tolerance traces the real dots
    grown to each end of the gain: the upper end is exactly the trace of a pattern whose
    dots are 2 tol wider (same rays, same seed) under no process; more ink extracts more;
    ``qa --simulation`` reports the band."""
    import json

    from optdot.io.patterns import save_pattern

    guide = {"thickness": 0.4, "reflector": 0.95, "edge_reflectance": 0.9}
    grid = np.tile(np.linspace(0.05, 0.3, 8)[:, None], (1, 8))
    plain = write_job(tmp_path, grid, domain={"width": 8.0, "height": 8.0}, light_guide=guide)
    plain.write_text(
        plain.read_text()
        + '[[light_guide.leds]]\nedge = "bottom"\npositions = [4.0]\nwidth = 1.0\n'
    )
    banded = tmp_path / "banded.toml"
    banded.write_text(plain.read_text() + "[process]\ndot_gain = 0.004\ngain_tolerance = 0.003\n")
    p = generate(load_job(banded))
    save_pattern(p, tmp_path / "p.npz")
    rc, err, out = cli(
        "simulate", banded, tmp_path / "p.npz", "--rays", 60000, "--json", tmp_path / "s.json"
    )
    assert rc == 0, err
    band = json.loads((tmp_path / "s.json").read_text())["tolerance_band"]
    assert band["gain_mm"] == pytest.approx([0.001, 0.004, 0.007])
    assert band["efficiency"][0] < band["efficiency"][1] < band["efficiency"][2]
    assert "at a gain of 7 µm: efficiency" in out
    wide = type(p)(p.xy, p.diameter + 0.006, p.box, meta=p.meta, outline=p.outline)
    save_pattern(wide, tmp_path / "wide.npz")
    wider = tmp_path / "wider.toml"  # the same guide, its dots 52 µm
    wider.write_text(plain.read_text().replace("diameter = 0.046", "diameter = 0.052"))
    rc, err, _ = cli(
        "simulate", wider, tmp_path / "wide.npz", "--rays", 60000, "--json", tmp_path / "w.json"
    )
    assert rc == 0, err
    w = json.loads((tmp_path / "w.json").read_text())
    assert w["efficiency"] == band["efficiency"][2]
    assert w["uniformity_9point"] == band["uniformity_9point"][2]
    rc, err, _ = cli("qa", tmp_path / "p.npz", "--job", banded, "--simulation", tmp_path / "s.json",
                     "--html", tmp_path / "r.html", "-q")  # fmt: skip
    assert rc in (0,), err
    assert "Across the process's gain tolerance" in (tmp_path / "r.html").read_text()


def test_grown_footprints_for_the_tracer():
    """The tracer's grown dots: circles and rounded rectangles exactly their parallel
    bodies; an ellipse one of the same area as its parallel body (shapely's buffer)."""
    from optdot.printing.process import grown_sizes

    for kind, size in ((CIRCLE, [0.046]), (RECT, [0.12, 0.03, 0.005]), (ELLIPSE, [0.08, 0.04])):
        s = np.array([size])
        for delta in (0.003, -0.003):
            got = grown_sizes(kind, s, delta)
            want = _exact(kind, size, 1e-8).buffer(delta, quad_segs=256).area
            change = want - kind.area(s)[0]
            tol = 1e-5 * want  # shapely's inward buffer errs by ~1e-6
            assert abs(change) > 100 * tol
            assert abs(kind.area(got)[0] - want) <= tol, (kind.name, delta)


def test_oasis_and_gds_agree_without_a_grid(tmp_path):
    """A shrink without a grid: the scaled centres are put on the files' 1 nm, so an
    OASIS repetition's offsets add up to the GDSII's places exactly."""
    path = _job(tmp_path, {"dot_gain": 0.005, "shrink": 0.005})
    rc, err, _ = cli("export", path, "--gds", tmp_path / "m.gds", "--oas", tmp_path / "m.oas", "-q")
    assert rc == 0, err
    job = load_job(path)
    a, b = (
        read_any(tmp_path / f"m.{f}", ExportOptions(process=job.process)) for f in ("gds", "oas")
    )
    ia, ib = np.lexsort(a.xy.T), np.lexsort(b.xy.T)
    np.testing.assert_allclose(a.xy[ia], b.xy[ib], atol=1.01e-6)
    rc, err, _ = cli("qa", tmp_path / "m.oas", "--job", path, "-q")
    assert rc == 0, err


@pytest.mark.slow
@pytest.mark.parametrize(
    ("dots", "orientation", "grid"),
    [
        ({"diameter": 0.046}, None, 0.001),  # circles of 26 µm on a 1 µm grid: a staircase
        ({"shape": '"rounded_rectangle"', "length": 0.12, "width": 0.03, "corner_radius": 0.005,
          "diameter": None}, {"random": "true"}, 0.0001),
        (ELLIPSE_DOTS, {"random": "true"}, 0.001),
    ],
)  # fmt: skip
def test_masks_on_a_coarse_grid_pass_their_own_qa(tmp_path, dots, orientation, grid):
    """Whatever the grid the job accepts, the masks it writes pass ``qa`` with the job:
    read as the print within the grid's slack (sizes 3 steps, angles their share)."""
    gain = 0.01 if "shape" not in dots else 0.004
    proc = {"dot_gain": gain, "min_space": 0.006, "grid": grid, "min_feature": 0.01}
    more = {"orientation": orientation} if orientation else {}
    path = _job(tmp_path, proc, dots, **more)
    outs = [tmp_path / f"m.{f}" for f in ("gds", "dxf")]
    rc, err, _ = cli("export", path, "--gds", outs[0], "--dxf", outs[1], "-q")
    assert rc == 0, err
    for mask in outs:
        rc, err, out = cli("qa", mask, "--job", path)
        assert rc == 0, (mask.name, err, [x for x in out.splitlines() if x.startswith("FAIL")])
    import gdstk

    top = gdstk.read_gds(str(outs[0])).top_level()[0].copy("FLAT", deep_copy=True)
    top.flatten()
    rings = [q.points for q in top.polygons if q.layer == 1]
    assert len(rings) > 100
    for ring in rings:  # snapped vertices neither repeat nor cross: a writer takes them
        assert np.all(np.any(ring != np.roll(ring, 1, axis=0), axis=1))
        assert shapely.Polygon(ring).is_valid


def test_caps_that_cannot_print_are_refused(tmp_path):
    from .test_backlight import _toml, direct_job

    ink = [1.0, 1.0, 0.8, 0.5, 0.3, 0.0, 0.2, 0.9]
    leds = {"pitch": [5.0, 5.0], "size": 0.2, "cap": 0.8, "cap_ink": ink}
    path = direct_job(tmp_path, 10.0, 10.0, 0.3, leds=leds)
    base = path.read_text()
    path.write_text(base + _toml({"process": {"dot_gain": 0.02}}))
    one_error(["generate", path, "-o", tmp_path / "p.csv"], 2, "caps' ring", "wide on the mask")
    path.write_text(base + _toml({"process": {"shrink": [0.002, 0.006]}}))
    one_error(["generate", path, "-o", tmp_path / "p.csv"], 2, "scales x and y apart", "ellipses")
