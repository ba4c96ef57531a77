"""The gate holds a file's dots to the job's: a mask whose footprints are not the ones the
job asks for fails, whatever their spacing, and collisions are measured on the file's own
footprints (circles overlapping by 6.6 µm under an ellipse job used to pass)."""

from __future__ import annotations

import pickle

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from optdot.config.schema import load_job
from optdot.geometry.kinds.polygon import Polygon, canonical
from optdot.geometry.shapes import CIRCLE, KINDS, DotShape, Footprints
from optdot.geometry.sizes import DotSizes
from optdot.io.patterns import load_pattern, save_pattern
from optdot.orchestration.pipeline import generate, qa
from optdot.pattern import Pattern
from optdot.quality.conformance import TOLERANCE, DotRule

from .conftest import cli, write_job
from .test_shaped_dots import ELLIPSE, PRISM

GRID = np.tile(np.linspace(0.05, 0.25, 8), (6, 1))


def _job(folder, dots, **more):
    folder.mkdir(exist_ok=True)
    sections = {"dots": dots, "optimize": {"max_iter": 60, "seed": 3, "gap": 0.005}}
    if "shape" in dots:
        sections["orientation"] = {"random": "true"}
    return write_job(folder, GRID, **sections, **more)


@pytest.fixture(scope="module")
def made(tmp_path_factory):
    """``{name: (job path, job, pattern)}`` for a circle, an ellipse and a prism job on
    one 2 x 1.5 mm panel."""
    root = tmp_path_factory.mktemp("footprints")
    out = {}
    for name, dots in (
        ("circle", {"diameter": 0.0566}),
        ("ellipse", ELLIPSE),
        ("prism", PRISM),
    ):
        path = _job(root / name, dots)
        job = load_job(path)
        out[name] = (path, job, generate(job))
    return out


def _circles_of(p: Pattern, d: float) -> Pattern:
    return Pattern(p.xy, d, p.box, meta={"source": "forged.csv"})


def test_circles_under_an_ellipse_job_fail_on_their_kind_and_their_own_overlap(made):
    """56.6 µm circles (the ellipse's area) where the ellipses stood, one pair 50 µm
    apart: the pair overlaps by 6.6 µm and collides on the file's own diameter (not at the
    job's width + gap, 45 µm, where it passed), and every dot is not the job's."""
    _, job, p = made["ellipse"]
    xy = p.xy.copy()
    xy[1] = xy[0] + [0.050, 0.0]
    bad = Pattern(xy, 0.0566, p.box)
    r = qa(bad, job)
    assert not r.passed
    assert r.metrics["collision_distance_mm"] == pytest.approx(0.0566 + 0.005)
    assert r.metrics["pairs_below_collision"] >= 1
    assert r.metrics["footprints"]["not_the_jobs"] == p.n
    line = next(c for c in r.checks if "footprint" in c.name)
    assert not line.passed and "ellipse 80 × 40 µm" in line.name and "circle 56.6" in line.name


def test_the_job_s_own_pattern_passes_the_footprint_line(made):
    for name in made:
        _, job, p = made[name]
        r = qa(p, job)
        assert r.passed, (name, r.failures())
        assert r.metrics["footprints"]["not_the_jobs"] == 0


@pytest.mark.parametrize(
    "file_of, job_of, why",
    [
        ("ellipse", "circle", "ellipses under a circle job of the same area"),
        ("prism", "ellipse", "rounded rectangles under an ellipse job"),
    ],
)
def test_another_kind_fails(made, file_of, job_of, why):
    _, job, _ = made[job_of]
    _, _, p = made[file_of]
    far = p.xy  # the same panel
    r = qa(Pattern(far, p.diameter, p.box, dots=p.dots), job)
    assert not r.passed, why
    assert r.metrics["footprints"]["not_the_jobs"] == p.n


def test_one_dot_of_another_size_fails(made):
    """One 90 x 45 ellipse among 80 x 40, one 60 µm circle among 56.6 µm: one dot, and
    where it is."""
    _, job, p = made["ellipse"]
    size = p.dots.size.copy()
    size[7] = [0.09, 0.045]
    q = Pattern(p.xy, 0, p.box, dots=Footprints(p.dots.kind, size, p.dots.angle))
    r = qa(q, job)
    assert r.metrics["footprints"]["not_the_jobs"] == 1
    line = next(c for c in r.checks if "footprint" in c.name)
    assert not line.passed and line.where == [list(map(float, p.xy[7]))]
    assert "90 × 45 µm" in line.name
    _, job, p = made["circle"]
    d = np.full(p.n, 0.0566)
    d[3] = 0.060
    r = qa(Pattern(p.xy, d, p.box), job)
    assert r.metrics["footprints"]["not_the_jobs"] == 1 and not r.passed


def test_prisms_with_other_corners_fail_as_csv_and_as_a_dataset(made, tmp_path):
    path, job, p = made["prism"]
    size = p.dots.size.copy()
    size[:, 2] = 0.015
    q = Pattern(p.xy, 0, p.box, dots=Footprints(p.dots.kind, size, p.dots.angle))
    for name in ("corners.csv", "corners.parquet"):
        save_pattern(q, tmp_path / name)
        rc, err, out = cli("qa", tmp_path / name, "--job", path)
        assert rc == 1, err
        assert "corner_radius 15 µm" in out and "verdict: FAIL" in out
        rc, err, _ = cli("export", tmp_path / name, "--job", path, "--gds", tmp_path / "m.gds")
        assert rc == 1 and not (tmp_path / "m.gds").exists(), err


def test_an_ellipse_mask_with_its_dot_cell_redrawn_as_a_circle_fails(made, tmp_path):
    """The ellipse job's GDS with its dot cell's polygon swapped (gdstk) for a 56.6 µm
    circle of the same area: read back as circles, it fails on its kind."""
    import gdstk

    from optdot.exporters.readback import read_any

    path, job, p = made["ellipse"]
    save_pattern(p, tmp_path / "p.npz")
    rc, err, _ = cli("export", tmp_path / "p.npz", "--job", path, "--gds", tmp_path / "m.gds")
    assert rc == 0, err
    rc, err, out = cli("qa", tmp_path / "m.gds", "--job", path)
    assert rc == 0, out
    lib = gdstk.read_gds(str(tmp_path / "m.gds"))
    swapped = 0
    for cell in lib.cells:
        polys = [q for q in cell.polygons if (q.layer, q.datatype) == (1, 0)]
        if len(polys) == 1 and cell.references == [] and cell.name != lib.top_level()[0].name:
            cell.remove(polys[0])
            radius = 0.0283e-3 / lib.unit  # 28.3 µm in the library's unit
            cell.add(gdstk.ellipse((0, 0), radius, tolerance=1e-3 * radius, layer=1))
            swapped += 1
    assert swapped >= 1
    lib.write_gds(str(tmp_path / "swapped.gds"))
    back = read_any(tmp_path / "swapped.gds")
    assert back.kind is CIRCLE and back.diameter[0] == pytest.approx(0.0566, abs=2e-6)
    rc, err, out = cli("qa", tmp_path / "swapped.gds", "--job", path)
    assert rc == 1 and "not the job's ellipse 80 × 40 µm" in out, out


def test_sizes_off_the_rule_s_steps_or_range_fail():
    """A job of sizes 30–120 µm on 0.5 µm steps: dots on the steps pass; 45.7 µm (off a
    step), 125 µm (out of the range) do not; the same for ellipses scaled from 80 x 40."""
    sizes = DotSizes(0.030, 0.120, 0.0005)
    rule = DotRule(DotShape(CIRCLE, (0.030,)), sizes)
    d = np.array([0.030, 0.0455, 0.046, 0.120, 0.0457, 0.125, 0.0295])
    np.testing.assert_array_equal(
        rule.stray(Footprints.circles(d)), [False, False, False, False, True, True, True]
    )
    ellipse = DotShape(KINDS["ellipse"], (0.08, 0.04))
    rule = DotRule(ellipse, DotSizes(0.0566, 0.113, 0.0005))
    scale = ellipse.scale_of(np.array([0.0566, 0.080, 0.0805]))
    good = ellipse.footprints(np.zeros(3), scale)
    assert not rule.stray(good).any()
    aspect = Footprints(good.kind, good.size * [1.0, 1.02], good.angle)  # another aspect
    assert rule.stray(aspect).all()


@settings(max_examples=60, deadline=None)
@given(
    st.sampled_from(["circle", "ellipse", "rounded_rectangle"]),
    st.lists(st.integers(0, 180), min_size=1, max_size=20),
    st.integers(0, 19),
    st.sampled_from([-1, 1]),
    st.floats(1.5 * TOLERANCE, 5e-3),
)
def test_the_rule_takes_every_size_it_makes_and_no_other(name, steps, which, sign, off):
    """Every footprint the size rule makes (a step of the range, the job's footprint
    scaled to it) passes; any one size parameter of one dot moved by more than the
    tolerance (and off the rule's steps) does not."""
    kind = KINDS[name]
    base = {"circle": (0.046,), "ellipse": (0.08, 0.04), "rounded_rectangle": (0.12, 0.03, 0.005)}
    shape = DotShape(kind, base[name])
    low = shape.equivalent_diameter
    sizes = DotSizes(low, low + 0.0005 * 180, 0.0005)
    rule = DotRule(shape, sizes)
    d = sizes.quantise(low + 0.0005 * np.array(steps, float))
    if kind is CIRCLE:
        dots = Footprints.circles(d)
    else:
        dots = shape.footprints(np.zeros(len(d)), shape.scale_of(d))
    assert not rule.stray(dots).any()
    k = which % dots.n
    size = dots.size.copy()
    size[k, (which // dots.n) % size.shape[1]] += sign * off
    if kind is CIRCLE:  # a circle moved onto another step is one the rule makes
        assume(abs(size[k, 0] / 0.0005 - round(size[k, 0] / 0.0005)) * 0.0005 > 1.5 * TOLERANCE)
    moved = Footprints(kind, size, dots.angle)
    stray = rule.stray(moved)
    assert stray[k] and stray.sum() == 1


def test_a_kind_pickles_to_the_registry_s_own():
    """A shaped pattern read back in a child process (masks are) keeps the registry's
    kind, so it is compared by identity with the job's; a polygon made for a job comes
    back with its vertices, equal to the job's and to no other."""
    for kind in KINDS.values():
        assert pickle.loads(pickle.dumps(kind)) is kind
    hexagon = Polygon(canonical([[0.03, 0], [0.015, 0.026], [-0.015, 0.026], [-0.03, 0],
                                 [-0.015, -0.026], [0.015, -0.026]]))  # fmt: skip
    back = pickle.loads(pickle.dumps(hexagon))
    assert back == hexagon and back is not hexagon and hash(back) == hash(hexagon)
    assert back != Polygon(hexagon.base * 1.001) and back != KINDS["polygon"]


def test_the_file_s_own_collision_distance_without_a_job(tmp_path):
    """Without a job the collision distance is the file's own diameter."""
    xy = np.array([[0.5, 0.5], [0.55, 0.5], [1.0, 1.0]])
    r = qa(Pattern(xy, 0.0566, (0, 0, 2, 2)))
    assert r.metrics["collision_distance_mm"] == pytest.approx(0.0566)
    assert r.metrics["pairs_below_collision"] == 1


def test_the_csv_circles_under_the_ellipse_job_on_the_command_line(made, tmp_path):
    path, _, p = made["ellipse"]
    xy = p.xy.copy()
    xy[1] = xy[0] + [0.050, 0.0]
    save_pattern(Pattern(xy, 0.0566, p.box), tmp_path / "circles.csv")
    rc, err, out = cli("qa", tmp_path / "circles.csv", "--job", path)
    assert rc == 1, out
    assert "FAIL  pairs closer than 61.6 µm (collisions)" in out
    assert load_pattern(tmp_path / "circles.csv").n == p.n


def test_simulate_refuses_a_pattern_that_is_not_the_job_s(made, tmp_path):
    """An ellipse pattern under a prism job, and a CSV of a smaller panel (a CSV keeps no
    box to compare) on a bigger guide, are refused with one line each before any ray is
    traced; the job's own pattern is traced."""
    led_row = '\n[[light_guide.leds]]\nedge = "bottom"\npositions = [0.5, 1.5]\nwidth = 0.2\n'
    _, _, ellipses = made["ellipse"]
    save_pattern(ellipses, tmp_path / "ellipses.csv")
    prism = _job(tmp_path / "prism", PRISM, light_guide={"thickness": 0.4})
    prism.write_text(prism.read_text() + led_row)
    rc, err, _ = cli("simulate", prism, tmp_path / "ellipses.csv", "--rays", 1000)
    assert rc == 2 and len(err) == 1, err
    assert "are not this job's rounded_rectangle 120 × 30 µm" in err[0]
    assert "(the first: ellipse 80 × 40 µm)" in err[0]
    big = tmp_path / "big"
    big.mkdir()
    path = write_job(big, np.full((8, 12), 0.2), domain={"width": 6.0, "height": 4.0},
                     light_guide={"thickness": 0.4})  # fmt: skip
    path.write_text(path.read_text() + led_row)
    _, _, small = made["circle"]  # 2 x 1.5 mm of 56.6 µm dots
    big_job = load_job(path)
    save_pattern(Pattern(small.xy, 0.046, small.box), tmp_path / "small.csv")
    rc, err, _ = cli("simulate", path, tmp_path / "small.csv", "--rays", 1000)
    assert rc == 2 and len(err) == 1, err
    assert "mm empty along the right of this job's map" in err[0]
    own = generate(big_job)
    save_pattern(own, tmp_path / "own.csv")
    rc, err, out = cli("simulate", path, tmp_path / "own.csv", "--rays", 1000)
    assert rc == 0, err


def test_a_kept_mask_is_refused_before_the_gate(made, tmp_path):
    """``export`` onto a kept mask ran the whole gate (12 s on a large pattern) before
    refusing; a GDSII or DXF without this run's provenance digest is refused first: a
    pattern whose gate would fail gets the kept-mask line, not the gate's."""
    import optdot
    from optdot.errors import ExportError

    path, job, p = made["circle"]
    for fmt in ("gds", "dxf"):
        out = tmp_path / f"m.{fmt}"
        optdot.export(p, {fmt: out}, job)
        before = out.read_bytes()
        optdot.export(p, {fmt: out}, job, overwrite=False)  # the same bytes again: allowed
        xy = p.xy.copy()
        xy[1] = xy[0] + [0.01, 0.0]  # a collision: this gate would fail
        bad = Pattern(xy, p.diameter, p.box, meta={"seed": 99})
        with pytest.raises(ExportError, match="is kept"):
            optdot.export(bad, {fmt: out}, job, overwrite=False)
        assert out.read_bytes() == before


def test_a_nudged_dot_does_not_dodge_the_job_s_centre_distances(tmp_path):
    """A one-size job with ``qa.collision_distance = 0.070``: its own dots fail it; the
    same dots with one 0.05 µm larger (within the footprint tolerance) were judged by edge
    gaps at ``optimize.gap`` instead, and passed."""
    path = write_job(tmp_path, GRID, optimize={"max_iter": 60, "seed": 3, "gap": 0.005},
                     qa={"collision_distance": 0.070})  # fmt: skip
    job = load_job(path)
    p = generate(job)
    own = qa(p, job)
    assert not own.passed and own.metrics["pairs_below_collision"] > 0
    d = p.diameter.copy()
    d[0] += 0.00005
    nudged = qa(Pattern(p.xy, d, p.box), job)
    assert nudged.metrics["footprints"]["not_the_jobs"] == 0
    assert nudged.metrics["pairs_below_collision"] == own.metrics["pairs_below_collision"]
    assert not nudged.passed


def test_a_size_the_rule_does_not_give_that_place_fails(tmp_path):
    """Sizes 30–120 µm on a pitch rule: 30 µm dots everywhere (each a size of the range,
    on its step) passed where the rule asks for 34–96 µm."""
    grid = np.tile(np.linspace(0.1, 0.35, 8), (6, 1))
    dots = {"diameter": "[0.030, 0.120]", "spacing": 0.15}
    job = load_job(write_job(tmp_path, grid, dots=dots, domain={"width": 4.0, "height": 3.0}))
    p = generate(job)
    assert qa(p, job).metrics["footprints"]["not_the_jobs"] == 0
    small = Pattern(p.xy, np.full(p.n, 0.030), p.box)
    got = qa(small, job).metrics["footprints"]["not_the_jobs"]
    assert got > 0.8 * p.n, got


def test_export_with_force_still_needs_a_job(made, tmp_path):
    """``--force`` writes through a failed gate; it did the same through a missing job
    (exit 0, no word). The job, or ``--no-job``, is still asked for."""
    _, _, p = made["circle"]
    save_pattern(p, tmp_path / "p.npz")
    rc, err, _ = cli("export", tmp_path / "p.npz", "--gds", tmp_path / "m.gds", "--force")
    assert rc == 5 and not (tmp_path / "m.gds").exists(), err
    rc, err, _ = cli("export", tmp_path / "p.npz", "--gds", tmp_path / "m.gds", "--no-job")
    assert rc == 0, err


@pytest.mark.parametrize("version", ["R2000", "R12", "R2018"])
def test_the_same_dxf_again_is_written_whatever_its_release(made, tmp_path, version):
    """A DXF R2000 holds no custom properties, so no provenance digest: the early refusal
    of kept masks refused the very same run again."""
    path, _, p = made["circle"]
    save_pattern(p, tmp_path / "p.npz")
    args = ("export", tmp_path / "p.npz", "--job", path, "--dxf", tmp_path / "k.dxf",
            "--dxf-version", version, "-q")  # fmt: skip
    assert cli(*args)[0] == 0
    rc, err, _ = cli(*args)
    assert rc == 0, err


def test_circles_on_a_lowercase_dots_layer_are_read(made, tmp_path):
    """DXF layer names are case-insensitive: 50 overlapping circles on layer ``dots``
    were left out of QA (0 collisions, PASS)."""
    import ezdxf

    from optdot.exporters.readback import read_any

    path, job, p = made["circle"]
    save_pattern(p, tmp_path / "p.npz")
    assert cli("export", tmp_path / "p.npz", "--job", path, "--dxf", tmp_path / "m.dxf",
               "-q")[0] == 0  # fmt: skip
    doc = ezdxf.readfile(tmp_path / "m.dxf")
    msp = doc.modelspace()
    for k in range(50):
        msp.add_circle((0.5 + 0.02 * k, 0.7), 0.0283, dxfattribs={"layer": "dots"})
    doc.saveas(tmp_path / "extra.dxf")
    assert read_any(tmp_path / "extra.dxf").n == p.n + 50
    r = qa(read_any(tmp_path / "extra.dxf"), job)
    assert r.metrics["pairs_below_collision"] >= 49 and not r.passed
