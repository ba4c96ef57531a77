"""The convex polygon kind: a job's own vertices, placed with exact gaps, written to every
file and mask, read back as the job's dots (and as no other), traced."""

from __future__ import annotations

import math

import numpy as np
import pytest
import shapely

from optdot.config.schema import load_job
from optdot.errors import JobError
from optdot.geometry.kinds import KINDS, contains_packed, packed, turned
from optdot.geometry.kinds.polygon import Polygon, canonical
from optdot.geometry.orientation import axis
from optdot.io.patterns import load_pattern, save_pattern
from optdot.orchestration.pipeline import generate

from .conftest import cli, write_job

TRIANGLE_MM = [[-0.02, -0.03], [0.04, 0.0], [-0.01, 0.03]]  # scalene: no mirror of it is it
HEXAGON_MM = [[0.03 * math.cos(a), 0.03 * math.sin(a)] for a in np.arange(6) * math.pi / 3]
TRIANGLE = Polygon(canonical(TRIANGLE_MM))
HEXAGON = Polygon(canonical(HEXAGON_MM))


def _vertices(v) -> str:
    return "[" + ", ".join(f"[{x!r}, {y!r}]" for x, y in v) + "]"


def _job(tmp_path, vertices=TRIANGLE_MM, orientation=None, **more):
    sections = {
        "dots": {"diameter": None, "shape": '"polygon"', "vertices": _vertices(vertices)},
        "optimize": {"seed": 3, "gap": 0.005},
        **more,
    }
    if orientation:
        sections["orientation"] = orientation
    return write_job(tmp_path, np.full((3, 4), 0.3), **sections)


def _mask(pattern, job, folder, fmt: str, name: str = "p"):
    """The path of ``pattern``'s mask of ``fmt`` that ``optdot export`` writes with
    ``job`` into ``folder`` (the pattern saved there as ``name.npz`` first)."""
    save_pattern(pattern, folder / f"{name}.npz")
    mask = folder / f"{name}.{fmt}"
    rc, err, _ = cli("export", folder / f"{name}.npz", "--job", job, f"--{fmt}", mask)
    assert rc == 0, err
    return mask


def test_vertices_are_the_dot_about_its_centroid(tmp_path):
    """Clockwise vertices anywhere: counter-clockwise about their area centroid, rounded to
    1 nm; length and width their extents; the same polygon however it was given."""
    shifted = [[x + 1.0, y - 2.0] for x, y in TRIANGLE_MM[::-1]]
    job = load_job(_job(tmp_path, shifted))
    kind = job.shape.kind
    assert kind == TRIANGLE and kind is not KINDS["polygon"]
    np.testing.assert_allclose(kind.base.mean(axis=0), 0.0, atol=1e-6)  # a triangle's centroid
    assert job.shape.size == pytest.approx((0.06, 0.06))
    assert kind.area(np.array([job.shape.size]))[0] == pytest.approx(
        shapely.Polygon(TRIANGLE_MM).area
    )
    assert HEXAGON.period == pytest.approx(math.pi / 3) and TRIANGLE.period == 2 * math.pi


@pytest.mark.parametrize(
    "dots, words",
    [
        ({"vertices": "[[0, 0], [0.05, 0], [0.01, 0.01], [0, 0.05]]"}, "convex"),
        ({"vertices": "[[0, 0], [0.05, 0.05], [0.05, 0], [0, 0.05]]"}, "convex"),
        ({"vertices": "[[0, 0], [0.05, 0]]"}, "3 to 12"),
        ({"vertices": _vertices(HEXAGON_MM * 3)}, "3 to 12"),
        ({"vertices": "[[0, 0], [0.05, 0], [0.05, 0], [0, 0.05]]"}, "repeats a vertex"),
        ({"vertices": "[[0, 0], [0.03, 0], [0.06, 0], [0, 0.05]]"}, "straight"),
        ({"vertices": '[[0, 0], [0.05, "a"], [0, 0.05]]'}, "[x, y] pairs"),
        ({"vertices": "[[0, 0], [20.0, 0], [0, 20.0]]"}, "must be"),
        ({"vertices": "[[0, 0], [0.001, 0], [0, 0.001]]"}, "must be"),
        ({"vertices": "[[0, 0], [3.0, 0], [3.0, 0.05], [0, 0.05]]"}, "longer than"),
        (
            {"vertices": "[[0, 0], [0.07, 0.07], [0.0695, 0.0705], [-0.0005, 0.0005]]"},
            "wide at its narrowest",
        ),  # 0.7 µm thin, turned: its box is 70 µm
        (
            {"vertices": "[[0.0, 0.0], [0.03, 0.0], [0.0300004, 0.0000002], [0.0, 0.03]]"},
            "under 0.1 µm apart",
        ),
        (
            {
                "vertices": "[[0.0117684, 0.0155245], [0.0, 0.0], [0.0300004, 0.0000006], "
                "[0.0300008, 0.0000001]]"
            },
            "vertices",
        ),
        ({"length": 0.06}, "come from dots.vertices"),
        ({"diameter": 0.06}, "takes dots.vertices"),
        ({"vertices": None}, "needs dots.vertices"),
    ],
)
def test_bad_vertices_are_refused_in_one_line(tmp_path, dots, words):
    path = _job(tmp_path)
    text = path.read_text()
    for key, value in dots.items():
        if value is None:
            text = "\n".join(ln for ln in text.splitlines() if not ln.startswith(key)) + "\n"
        elif key + " =" in text:
            text = "\n".join(
                f"{key} = {value}" if ln.startswith(key + " =") else ln for ln in text.splitlines()
            )
        else:
            text = text.replace('shape = "polygon"', f'shape = "polygon"\n{key} = {value}')
    path.write_text(text)
    with pytest.raises(JobError, match="dots") as e:
        load_job(path)
    assert words in str(e.value) and "\n" not in str(e.value)


def test_vertices_rounded_to_1_nm_are_checked_again(tmp_path):
    """A polygon whose 1 nm rounding brings two vertices together or straightens a
    corner is refused before any work, so no file is written that its own reader
    refuses."""
    v = [[0.011768396, 0.015524524], [0.009149581, 0.017418295], [-0.012279743, 0.016098479],
         [-0.017719849, 0.009307777], [-0.010386175, -0.015059665],
         [-0.009866908, -0.015361471], [-0.007658416, -0.016417454],
         [-0.000610357, -0.01777899], [-0.000609268, -0.017778368]]  # fmt: skip
    with pytest.raises(JobError, match="dots.vertices") as e:
        load_job(_job(tmp_path, v))
    assert "\n" not in str(e.value)


def test_the_same_polygon_however_written_is_one_kind():
    """Another start vertex, the other way round, moved: the same kind (a file's
    vertices written from another corner are the job's)."""
    rolled = TRIANGLE_MM[1:] + TRIANGLE_MM[:1]
    assert Polygon(canonical(rolled)) == TRIANGLE
    assert Polygon(canonical([[x + 5, y] for x, y in rolled[::-1]])) == TRIANGLE
    spec = {"vertices_mm": np.roll(TRIANGLE.base, 1, axis=0).tolist()}
    assert KINDS["polygon"].from_spec(spec) == TRIANGLE


def test_vertices_on_another_kind_are_refused(tmp_path):
    path = write_job(
        tmp_path,
        np.full((3, 4), 0.3),
        dots={"diameter": None, "shape": '"ellipse"', "length": 0.08, "width": 0.04,
              "vertices": _vertices(TRIANGLE_MM)},
    )  # fmt: skip
    with pytest.raises(JobError, match="dots.vertices does not apply to an ellipse"):
        load_job(path)


def _pairs(rng, kind, m):
    d = rng.uniform(-0.09, 0.09, (m, 2))
    base = np.array([kind.l0, kind.w0])
    si = base * rng.uniform(0.6, 1.5, (m, 1))
    sj = base * rng.uniform(0.6, 1.5, (m, 1))
    return d, si, rng.uniform(-7, 7, m), sj, rng.uniform(-7, 7, m)


@pytest.mark.parametrize("kind", [TRIANGLE, HEXAGON], ids=["triangle", "hexagon"])
def test_the_gap_is_shapely_s_distance_and_its_direction_frees_the_pair(kind):
    """Apart: the exact gap is shapely's distance between the two polygons (1e-12 mm).
    Overlapping: minus the depth of the shallowest escape, so moving j along ``u`` by
    it just frees the pair, and by less does not (the triangle is symmetric about no
    point: j's reach toward i is its reach the other way)."""
    rng = np.random.default_rng(7)
    d, si, ai, sj, aj = _pairs(rng, kind, 600)
    gap, u = kind.separation(d, si, ai, sj, aj)
    apart = overlap = 0
    for m in range(len(d)):
        p = shapely.Polygon(kind.outline(si[m], ai[m], 0.0))
        q = kind.outline(sj[m], aj[m], 0.0) + d[m]
        if gap[m] > 0:
            assert shapely.Polygon(q).distance(p) == pytest.approx(gap[m], abs=1e-12)
            apart += 1
        else:
            freed = shapely.Polygon(q - u[m] * (gap[m] - 1e-9))
            short = shapely.Polygon(q - u[m] * (0.95 * gap[m]))
            assert freed.distance(p) > 0 and short.intersection(p).area > 0
            overlap += 1
    assert apart > 100 and overlap > 100


def test_the_gap_s_direction_is_its_gradient():
    """``u`` is the gap's gradient in the centres' difference (central differences)."""
    rng = np.random.default_rng(8)
    d, si, ai, sj, aj = _pairs(rng, TRIANGLE, 200)
    gap, u = TRIANGLE.separation(d, si, ai, sj, aj)
    h = 1e-7
    for axis_ in (0, 1):
        step = np.zeros(2)
        step[axis_] = h
        up = TRIANGLE.separation(d + step, si, ai, sj, aj)[0]
        down = TRIANGLE.separation(d - step, si, ai, sj, aj)[0]
        fd = (up - down) / (2 * h)
        smooth = np.abs(fd - u[:, axis_]) < 1e-4
        assert smooth.mean() > 0.97  # all but the few pairs at a kink of the gap


def test_the_tracer_s_test_is_shapely_s():
    """The compiled point test the tracer and the coverage rasters use: on the footprint
    exactly where shapely says a point is (closed)."""
    rng = np.random.default_rng(9)
    m = 4000
    size = np.array([TRIANGLE.l0, TRIANGLE.w0]) * rng.uniform(0.7, 1.4, (m, 1))
    angle = rng.uniform(-4, 4, m)
    pts = rng.uniform(-0.05, 0.05, (m, 2))
    got = contains_packed(packed(TRIANGLE, size, angle), pts)
    want = [
        shapely.Polygon(TRIANGLE.outline(size[k], angle[k], 0.0)).covers(shapely.Point(pts[k]))
        for k in range(m)
    ]
    np.testing.assert_array_equal(got, want)
    assert 0.1 < got.mean() < 0.6


def test_a_fit_finds_the_job_s_polygon_and_no_other():
    """Centre, size and angle back from a turned, moved outline; a mirrored triangle, a
    hexagon, a stretched triangle and one with a corner cut off are not the triangle."""
    size, angle, at = np.array([0.066, 0.066]), 2.5, np.array([3.0, -1.0])
    ring = TRIANGLE.outline(size, angle, 0.0) + at
    f = TRIANGLE.fit(ring, 1e-9)
    assert f.ok and f.centre == pytest.approx(at, abs=1e-12)
    assert f.size == pytest.approx(size, abs=1e-12) and f.angle == pytest.approx(angle)
    assert not TRIANGLE.fit(ring * [1.0, -1.0], 1e-6).ok
    assert not TRIANGLE.fit(HEXAGON.outline([0.06, 0.052], 0.0, 0.0), 1e-6).ok
    assert not TRIANGLE.fit(TRIANGLE.outline(size, 0.0, 0.0) * [1.1, 1.0], 1e-6).ok
    cut = np.insert(ring, 1, [0.9, 0.1] @ ring[:2], axis=0)  # every point on its outline,
    cut[0] = [0.9, 0.1] @ ring[[0, 2]]  # but a corner cut off
    assert not TRIANGLE.fit(cut, 1e-6).ok
    assert not KINDS["polygon"].fit(ring, 1e-6).ok  # the registry's knows no vertices


@pytest.fixture(scope="module")
def triangles(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("triangles")
    path = _job(tmp, orientation={"random": "true"})
    return path, generate(load_job(path))


def test_no_two_triangles_are_nearer_than_the_gap(triangles):
    """shapely's distance over every pair within reach: at least ``optimize.gap``."""
    path, p = triangles
    assert p.n > 200
    polys = [shapely.Polygon(p.dots.outline(k, 0.0) + p.xy[k]) for k in range(p.n)]
    tree = shapely.STRtree(polys)
    i, j = tree.query(polys, predicate="dwithin", distance=0.005)
    keep = i < j
    gaps = shapely.distance(np.array(polys)[i[keep]], np.array(polys)[j[keep]])
    assert gaps.min(initial=1.0) >= 0.005 - 1e-9


def test_files_keep_the_polygon(triangles, tmp_path):
    """CSV and NPZ give back the same kind, sizes and angles; the same job gives the same
    bytes; a CSV whose first line names other vertices is another kind."""
    path, p = triangles
    for suffix in ("csv", "npz"):
        save_pattern(p, tmp_path / f"p.{suffix}")
        q = load_pattern(tmp_path / f"p.{suffix}")
        assert q.dots.kind == p.dots.kind
        np.testing.assert_array_equal(q.xy, p.xy)
        np.testing.assert_array_equal(q.dots.size, p.dots.size)
        np.testing.assert_allclose(q.dots.angles, p.dots.angles, atol=1e-8)
    text = (tmp_path / "p.csv").read_text()
    assert text.startswith('# {"shape": "polygon", "vertices_mm": ')
    rc, err, _ = cli("generate", path, "-o", tmp_path / "again.csv")
    assert rc == 0, err
    assert (tmp_path / "again.csv").read_text() == text
    other = text.replace(text.splitlines()[0], '# {"shape": "polygon", "vertices_mm": '
                         + repr(HEXAGON.base.tolist()) + "}", 1)  # fmt: skip
    (tmp_path / "other.csv").write_text(other)
    assert load_pattern(tmp_path / "other.csv").dots.kind == HEXAGON
    rc, err, out = cli("qa", tmp_path / "other.csv", "--job", path)
    assert rc == 1 and "FAIL  dots whose footprint is not the job's polygon" in out


@pytest.mark.slow
@pytest.mark.parametrize("fmt", ["gds", "oas", "dxf"])
def test_masks_read_back_as_the_job_s_polygons(triangles, tmp_path, fmt):
    """A mask passes QA with its job (hexagons turned 45° too); without the job it is
    refused in one line naming the polygon; a hexagon mask under the triangle job
    fails."""
    path, p = triangles
    mask = _mask(p, path, tmp_path, fmt)
    rc, err, out = cli("qa", mask, "--job", path)
    assert rc == 0, err + [out]
    rc, err, _ = cli("qa", mask, "--no-job")
    assert rc == 2 and len(err) == 1 and "nor a job's polygon" in err[0]
    hexes = tmp_path / "hex"
    hexes.mkdir()
    hex_job = _job(hexes, HEXAGON_MM, orientation={"angle": 45})
    _mask(generate(load_job(hex_job)), hex_job, hexes, fmt, "h")
    # read back at -15°, a hexagon at 45° is on its field (modulo its 60° symmetry)
    rc, err, out = cli("qa", hexes / f"h.{fmt}", "--job", hex_job)
    assert rc == 0, err + [out]
    rc, err, out = cli("qa", hexes / f"h.{fmt}", "--job", path)
    assert rc == 2 and "nor" not in err[0] and "polygon" in err[0]


def test_klayout_reads_the_polygon_and_its_turns(triangles, tmp_path):
    """KLayout on its own: one dot cell of the triangle's 3 vertices, each reference at a
    dot's centre turned by its angle (the mask draws what the pattern holds)."""
    kdb = pytest.importorskip("klayout.db")
    path, p = triangles
    _mask(p, path, tmp_path, "gds")
    ly = kdb.Layout()
    ly.read(str(tmp_path / "p.gds"))
    it = ly.top_cell().begin_shapes_rec(ly.layer(1, 0))
    centres, angles, areas = [], [], []
    while not it.at_end():
        poly = it.shape().polygon
        assert poly.num_points() == 3
        areas.append(poly.area() * ly.dbu**2 * 1e-6)
        t = it.dtrans()
        centres.append((t.disp.x * 1e-3, t.disp.y * 1e-3))
        angles.append(t.angle)
        it.next()
    assert len(centres) == p.n
    np.testing.assert_allclose(areas, p.dots.area(), rtol=1e-4)
    order, back = np.lexsort(p.xy.T), np.lexsort(np.array(centres).T)
    np.testing.assert_allclose(np.array(centres)[back], p.xy[order], atol=1e-6)
    off = np.array(angles)[back] - np.degrees(p.dots.angles[order])
    assert np.abs((off + 180) % 360 - 180).max() < 0.01


@pytest.mark.slow
def test_a_positive_gain_is_refused_and_an_etch_prints_the_polygon(tmp_path):
    """Sharp corners print exactly only without gain: ``dot_gain > 0`` is refused in one
    line; an etch's bias (``< 0``) draws each side moved out on the mask, which QA reads
    as the job's polygon printed."""
    path = _job(tmp_path, process={"dot_gain": 0.002})
    with pytest.raises(JobError, match="rounds every corner of the polygon"):
        load_job(path)
    path = _job(tmp_path, process={"dot_gain": -0.002, "min_space": 0.006})
    p = generate(load_job(path))
    _mask(p, path, tmp_path, "gds")
    import gdstk

    lib = gdstk.read_gds(str(tmp_path / "p.gds"))
    cell = next(c for c in lib.cells if c.name != "TOP" and c.polygons)
    drawn = cell.polygons[0].area() * 1e-6  # µm² -> mm²
    size = p.dots.size[0][None]
    grown = TRIANGLE.area(size)[0] + TRIANGLE.perimeter(size)[0] * 0.002 + math.pi * 0.002**2
    assert drawn == pytest.approx(grown, rel=1e-3)
    rc, err, out = cli("qa", tmp_path / "p.gds", "--job", path)
    assert rc == 0, err + [out]


def test_sharp_corners_lower_the_fill_that_runs(tmp_path):
    """A triangle's corners lower the fill the preflight deals at (it failed at an
    effective fill of 0.62 where hexagons hold at 0.66): refused in one line naming the
    largest fill, which a hexagon of the same map is not."""
    path = write_job(
        tmp_path,
        np.full((3, 3), 0.48),
        dots={"diameter": None, "shape": '"polygon"', "vertices": _vertices(TRIANGLE_MM)},
        optimize={"seed": 3, "gap": 0.005},
    )
    rc, err, _ = cli("check", path)
    assert rc == 2 and len(err) == 1 and "reach at most 0.58" in err[0], err
    assert "the fill can be at most 0.44" in err[0]
    path.write_text(path.read_text().replace(_vertices(TRIANGLE_MM), _vertices(HEXAGON_MM)))
    rc, err, _ = cli("check", path)
    assert rc == 0, err


def _snapped(ring: np.ndarray) -> np.ndarray:
    """``ring`` (mm) on a mask's 1 nm grid."""
    return np.round(ring * 1e6) / 1e6


def test_an_etch_mask_of_a_needle_reads_back_its_print():
    """A needle's mask (a 7.6° tip, sides moved out 2 µm, corners arcs) on the 1 nm grid:
    its print read back to 0.1 nm, where the sides' meeting would place the tip ~15 times
    less well."""
    needle = Polygon(canonical([[0.0, -0.004], [0.06, 0.0], [0.0, 0.004]]))
    size = np.array([needle.l0, needle.w0])
    mask = _snapped(turned(needle.parallel_outline(size, 0.002, 1e-5), 0.4) + [2.0, 1.0])
    f = needle.fit_grown(mask, -0.002, 2e-6)
    assert f.ok and f.centre == pytest.approx([2.0, 1.0], abs=1e-7)
    assert f.size == pytest.approx(size, abs=2e-7) and f.angle == pytest.approx(0.4, abs=1e-6)


def test_a_mirrored_reference_is_read_as_its_mirror_image(triangles, tmp_path):
    """GDSII references mirrored (x_reflection) draw the triangle's mirror image, not the
    job's dots: refused in one line. A hexagon mirrored is a hexagon, read at the angle
    the mirror turns it to."""
    import gdstk

    path, p = triangles
    _mask(p, path, tmp_path, "gds")
    lib = gdstk.read_gds(str(tmp_path / "p.gds"))
    for ref in next(c for c in lib.cells if c.name == "TOP").references:
        ref.x_reflection = True
    lib.write_gds(str(tmp_path / "m.gds"))
    rc, err, _ = cli("qa", tmp_path / "m.gds", "--job", path)
    assert rc == 2 and len(err) == 1 and "placed mirrored" in err[0], err
    from optdot.exporters.options import ExportOptions
    from optdot.exporters.readback import read_any

    hexes = tmp_path / "hex"
    hexes.mkdir()  # a hexagon turned 10°: its mirror axes are at 10° + k 30°
    turned10 = [
        [0.03 * math.cos(a), 0.03 * math.sin(a)] for a in np.radians(10 + 60 * np.arange(6))
    ]
    hex_job = _job(hexes, turned10, orientation={"random": "true"})
    h = generate(load_job(hex_job))
    _mask(h, hex_job, hexes, "gds", "h")
    lib = gdstk.read_gds(str(hexes / "h.gds"))
    for ref in next(c for c in lib.cells if c.name == "TOP").references:
        ref.x_reflection = True
        ref.origin = (ref.origin[0], -ref.origin[1])
    lib.write_gds(str(hexes / "m.gds"))
    back = read_any(hexes / "m.gds", ExportOptions(kind=h.dots.kind))
    order, got = np.lexsort((h.xy * [1, -1]).T), np.lexsort(back.xy.T)
    np.testing.assert_allclose(back.xy[got], h.xy[order] * [1, -1], atol=1e-9)
    # placed at a turn of a after a mirror about x, the hexagon at 0 is the one at -20°
    want = h.dots.angles[order] - math.radians(20)
    off = np.degrees(axis(back.dots.angles[got] - want, math.pi / 3))
    assert np.abs(off).max() < 1e-3  # its vertices rounded to 1 nm: 2.5e-4° off that turn


def test_a_regular_12_gon_is_the_job_s_not_a_circle(tmp_path):
    """Twelve vertices on a circle are a round enough polygon for the circle's fit; a
    mask of the job's 12-gon still reads back as the job's dots."""
    twelve = [[0.03 * math.cos(a), 0.03 * math.sin(a)] for a in np.arange(12) * math.pi / 6]
    path = _job(tmp_path, twelve)
    _mask(generate(load_job(path)), path, tmp_path, "gds")
    rc, err, out = cli("qa", tmp_path / "p.gds", "--job", path)
    assert rc == 0, err + [out]


def test_a_huge_number_in_a_csv_s_first_line_is_one_line(tmp_path):
    bad = tmp_path / "p.csv"
    bad.write_text('# {"shape": "polygon", "vertices_mm": [[0, 0], [' + "9" * 400
                   + ', 0], [0, 0.05]]}\nx_mm,y_mm,length_mm,width_mm,angle_deg\n'
                   "1.0,1.0,0.05,0.05,0.0\n")  # fmt: skip
    rc, err, _ = cli("qa", bad, "--no-job")
    assert rc == 2 and len(err) == 1 and "not finite" in err[0], err
