"""Shaped dots in tiles and datasets: the tiled run keeps the exact guarantee
across its seams (checked by shapely), turns every dot by the field where it ends (a
held neighbour keeps the angle it was written with), gives the same bytes on one and
two workers, resumes to the bytes of an uninterrupted run, and its dataset holds the
footprints (sizes, angles) that exporters and QA read back."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
import shapely

from optdot.config.schema import load_job
from optdot.errors import PatternFileError
from optdot.geometry.orientation import axis
from optdot.io.dataset import MANIFEST, load_dataset, open_dataset
from optdot.io.dataset_write import save_dataset
from optdot.io.patterns import load_pattern, save_pattern
from optdot.orchestration.pipeline import generate, generate_tiled, qa
from optdot.orchestration.tiling.plan import plan_tiles
from optdot.orchestration.tiling.run import InProcess
from optdot.runtime.stop import stop_note

from .conftest import optdot
from .test_shaped_dots import ELLIPSE, PRISM, _check_guarantee_with_shapely, _job
from .test_tiles import _Counting

#: 7.5 x 5 mm, fill 0.2-0.4: ~4,500 ellipses of 80 x 40 µm in 3 x 2 tiles of 2.5 mm.
SIDE = 2.5
LEDS = '\n[light_guide]\nthickness = 0.6\n[[light_guide.leds]]\nedge = "bottom"\n'
LEDS += "positions = [1.25, 3.75, 6.25]\nwidth = 0.3\n"


def _tiled_job(tmp_path, dots=ELLIPSE, orientation=None, leds=False):
    grid = np.tile(np.linspace(0.2, 0.4, 8), (6, 1))
    path = _job(tmp_path, dots, orientation or {"random": "true"}, grid=grid,
                domain={"width": 7.5, "height": 5.0})  # fmt: skip
    if leds:
        path.write_text(path.read_text() + LEDS)
    return path


def _resumed(job, tmp_path, stop_after: int) -> int:
    """Run ``job`` in tiles of :data:`SIDE` uninterrupted (``full.parquet``), then again
    stopped after ``stop_after`` finished tiles and resumed (``resumed.parquet``): the
    two must hold the same bytes. Returns the guarantee passes the resumed run made."""
    plan = plan_tiles(job, side=SIDE)
    full, out = tmp_path / "full.parquet", tmp_path / "resumed.parquet"
    generate_tiled(job, full, plan=plan, executor=InProcess())
    with pytest.raises(KeyboardInterrupt):
        generate_tiled(job, out, plan=plan, executor=_Counting(stop_after=stop_after))
    # what the interrupt's line adds: the tiles kept, and that the same command resumes
    note = stop_note()
    assert "finished tiles are kept in" in note and "resumes from them" in note, note
    again = _Counting()
    generate_tiled(job, out, plan=plan, executor=again)
    names = sorted(p.name for p in full.iterdir())
    assert names == sorted(p.name for p in out.iterdir())
    for name in names:
        assert (full / name).read_bytes() == (out / name).read_bytes(), name
    return again.kinds["legal"]


def _field_error(p, job) -> float:
    """Largest angle of a dot off the job's field where it stands, degrees (fields that
    follow the position only)."""
    want = job.orientation.at(p.xy, p.xy)
    return float(np.degrees(np.abs(axis(p.dots.angles - want))).max())


@pytest.mark.slow
@pytest.mark.parametrize(
    "dots,orientation",
    [(ELLIPSE, {"random": "true"}), (PRISM, {"toward": '"leds"'})],
    ids=["ellipse-random", "prism-leds"],
)
def test_tiled_shaped_dots_keep_the_gap_across_seams_and_follow_the_field(
    tmp_path, dots, orientation
):
    """In process, 3 x 2 tiles: the exact count, no pair under the gap edge to edge by
    shapely (every seam included), every dot inside the panel; prisms turned toward
    their LED where they end; QA passes with its seam measures."""
    job = load_job(_tiled_job(tmp_path, dots, orientation, leds="toward" in orientation))
    plan = plan_tiles(job, side=SIDE)
    assert (plan.nx, plan.ny) == (3, 2)
    p = generate_tiled(job, plan=plan, executor=InProcess())
    assert p.n == job.n_dots and p.kind is job.shape.kind
    assert p.meta["shape"] == job.shape.kind.name
    _check_guarantee_with_shapely(p, job.optimize.gap, job.box)
    if job.orientation.follows_position:
        assert _field_error(p, job) < 1e-5  # angles are stored to 1e-6°
    r = qa(p, job)
    assert r.passed, r.failures()
    assert r.metrics["seams"]["tiles"] == [3, 2]
    assert r.metrics["shape"]["shapely_disagreements"] == 0


def test_a_held_neighbour_keeps_the_angle_it_was_written_with():
    """The guarantee pass turns only the dots it moves: a held dot's footprint is the one
    it was written with, not the field's at its position (a random field hashes where a
    dot was thrown, which a neighbour's tile does not know), and the mobile dot is made
    legal against that footprint."""
    from optdot.geometry.density import DensityMap
    from optdot.geometry.domain import Domain
    from optdot.geometry.orientation import Orientation
    from optdot.geometry.shapes import KINDS, DotShape
    from optdot.relax.shaped import make_legal_shapes

    shape = DotShape(KINDS["ellipse"], (0.08, 0.04))
    density = DensityMap(np.full((1, 1), 0.3), 1.0, 1.0)
    field = Orientation("constant", angle=0.0)
    box = Domain.rect(0.0, 0.0, 1.0, 1.0)
    xy = np.array([[0.5, 0.5], [0.55, 0.5]])  # 50 µm apart along x: too close either way
    frozen = np.array([False, True])
    gap = 0.005

    def legal(held_angle: float):
        leg, dots = make_legal_shapes(
            xy, xy, density, np.zeros(2, np.int64), box, shape, field, gap, "test", frozen,
            np.array([held_angle]),
        )  # fmt: skip
        np.testing.assert_array_equal(leg.xy[1], xy[1])
        assert dots.angles[1] == held_angle and dots.angles[0] == 0.0
        return leg.xy[0]

    def edge_gap(p, held_angle: float) -> float:
        a = shapely.Polygon(shape.footprints(np.zeros(1)).outline(0, 1e-5) + p)
        held = shape.footprints(np.array([held_angle])).outline(0, 1e-5) + xy[1]
        return a.distance(shapely.Polygon(held))

    upright = legal(math.pi / 2)  # legal against the upright footprint ...
    assert edge_gap(upright, math.pi / 2) >= gap - 4e-5
    assert edge_gap(upright, 0.0) < gap - 1e-3  # ... which the field's would not be
    lying = legal(0.0)
    assert edge_gap(lying, 0.0) >= gap - 4e-5


@pytest.fixture(scope="module")
def tiled_shapes(tmp_path_factory):
    """Ellipses turned toward 3 LEDs, 3 x 2 tiles, on a 2-worker and a 1-worker cluster."""
    d = tmp_path_factory.mktemp("tiled_shapes")
    path = _tiled_job(d, ELLIPSE, {"toward": '"leds"'}, leds=True)
    common = ["generate", path, "--tiles", "on", "--tile-size", SIDE]
    r2 = optdot(*common, "--workers", "2", "-o", d / "two.parquet", check=True)
    optdot(*common, "--workers", "1", "-o", d / "one.parquet", "-q", check=True)
    return d, load_job(path), r2


@pytest.mark.slow
def test_shaped_tiles_give_the_same_bytes_on_two_workers_and_one(tiled_shapes):
    d, job, r2 = tiled_shapes
    two, one = d / "two.parquet", d / "one.parquet"
    names = sorted(p.name for p in two.iterdir())
    assert names == sorted(p.name for p in one.iterdir()) and len(names) == 7
    for name in names:
        assert (two / name).read_bytes() == (one / name).read_bytes(), name
    assert "6 tiles (3 x 2)" in r2.stderr
    manifest = json.loads((two / MANIFEST).read_text())
    assert manifest["shape"] == "ellipse" and manifest["uniform_diameter_mm"] is None
    p = load_dataset(two)
    assert p.n == job.n_dots and p.kind.name == "ellipse"
    np.testing.assert_allclose(p.dots.size, [[0.08, 0.04]] * p.n)
    _check_guarantee_with_shapely(p, job.optimize.gap, job.box)
    assert _field_error(p, job) < 1e-5


@pytest.mark.slow
def test_a_shaped_dataset_is_exported_and_checked_part_by_part(tiled_shapes, tmp_path):
    """QA reads the dataset tile by tile (exact gaps, shapely, the field) and agrees with
    QA of the same dots in memory; a GDSII made from it holds the same footprints."""
    from optdot.exporters.readback import read_any

    d, job, _ = tiled_shapes
    ds = open_dataset(d / "two.parquet")
    r = qa(ds, job)
    mem = qa(load_dataset(d / "two.parquet"), job)
    assert r.passed, r.failures()
    for key in ("pairs_below_collision", "pairs_below_close"):
        assert r.metrics[key] == mem.metrics[key]
    assert r.metrics["shape"]["shapely_disagreements"] == 0
    assert r.metrics["orientation"]["field_error_max_deg"] < 1e-5
    rc = optdot("export", d / "two.parquet", "--gds", tmp_path / "m.gds", "-q", "--no-job")
    assert rc.returncode == 0, rc.stderr
    q, p = read_any(tmp_path / "m.gds"), load_dataset(d / "two.parquet")
    a, b = np.lexsort(q.xy.T), np.lexsort(p.xy.T)
    np.testing.assert_allclose(q.xy[a], p.xy[b], atol=1e-9)
    off = np.degrees(axis(q.dots.angles[a] - p.dots.angles[b]))
    assert np.abs(off).max() < 2e-6


@pytest.mark.slow
def test_an_interrupted_shaped_tiled_run_resumes_with_the_bytes_of_an_uninterrupted_one(
    tmp_path,
):
    """Stopped after 2 of 6 tiles, the same run again makes only the other 4 guarantee
    passes, holding the kept tiles' footprints as written, and writes the bytes of a run
    that was never interrupted."""
    job = load_job(_tiled_job(tmp_path, PRISM, {"random": "true"}))
    assert _resumed(job, tmp_path, stop_after=2) == 4


@pytest.mark.slow
def test_scaled_shapes_resume_with_the_bytes_of_an_uninterrupted_run(tmp_path):
    """Sizes that vary: a kept tile's dots are held at the sizes they were made at (their
    area-equivalent diameters recovered from the footprints on the rule's steps), so the
    resumed run is the uninterrupted one byte for byte."""
    grid = np.tile(np.linspace(0.15, 0.4, 8), (6, 1))
    dots = {**ELLIPSE, "scale": "[0.8, 1.6]", "spacing": 0.15}
    path = _job(tmp_path, dots, {"random": "true"}, grid=grid,
                domain={"width": 7.5, "height": 5.0})  # fmt: skip
    job = load_job(path)
    assert _resumed(job, tmp_path, stop_after=3) == 3
    p = load_dataset(tmp_path / "full.parquet")
    assert len(np.unique(p.dots.size[:, 0])) >= 10
    _check_guarantee_with_shapely(p, job.optimize.gap, job.box)


def test_a_shaped_dataset_holds_the_patterns_footprints(tmp_path):
    """One process to a dataset: the columns of the CSV, read back exactly as the NPZ;
    a manifest naming an unknown shape, or a part with a NaN angle, is refused in one
    line."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    path = _job(tmp_path, PRISM, {"random": "true"})
    p = generate(load_job(path))
    save_dataset(p, tmp_path / "p.parquet")
    save_pattern(p, tmp_path / "p.npz")
    a, b = load_pattern(tmp_path / "p.parquet"), load_pattern(tmp_path / "p.npz")
    np.testing.assert_array_equal(a.xy, b.xy)
    np.testing.assert_array_equal(a.dots.size, b.dots.size)
    np.testing.assert_allclose(a.dots.angles, b.dots.angles, atol=1e-15)
    part = tmp_path / "p.parquet" / "part-00000.parquet"
    cols = pq.read_table(part).column_names
    assert cols == ["x_mm", "y_mm", "length_mm", "width_mm", "corner_radius_mm", "angle_deg"]
    manifest = tmp_path / "p.parquet" / MANIFEST
    doc = json.loads(manifest.read_text())
    manifest.write_text(json.dumps({**doc, "shape": "triangle"}))
    with pytest.raises(PatternFileError, match="shape must be one of"):
        open_dataset(tmp_path / "p.parquet")
    manifest.write_text(json.dumps(doc))
    table = pq.read_table(part)
    angle = table.column("angle_deg").to_numpy().copy()
    angle[3] = np.nan
    table = table.set_column(5, "angle_deg", pa.array(angle))
    pq.write_table(table, part)
    with pytest.raises(PatternFileError, match="NaN or infinite rounded_rectangle"):
        open_dataset(tmp_path / "p.parquet").read_part(0)


@pytest.mark.slow
def test_a_dot_wedged_against_a_wall_by_held_dots_is_moved_where_it_fits(tmp_path):
    """Scaled capsules on an outlined panel with a zero cell, tiled (the hostile tester's
    job): a dot of the last tile stood between the panel's edge (its bounding disc) and
    two final dots of a neighbour, and the disc pass and the exact pushes sent it back
    and forth until the pass gave up; before that, a held dot in the zero cell crashed
    the hard core (an infinite circle). Now the wedged dot is moved to a place it fits
    and the run meets the guarantee (shapely) and passes QA."""
    (tmp_path / "panel.wkt").write_text("POLYGON ((0 0, 8 0, 8 8, 0 8, 0 0))")
    grid = np.array([[0.1, 0.2, 0.3, 0.4], [0.15, 0.25, 0.35, 0.45],
                     [0.0, 0.2, 0.3, 0.4], [0.1, 0.2, 0.3, 0.4]])  # fmt: skip
    dots = {**PRISM, "corner_radius": 0.015, "scale": "[0.6, 1.4]"}
    path = _job(tmp_path, dots, {"random": "true"}, grid=grid,
                domain={"width": None, "height": None, "outline": '"panel.wkt"'},
                optimize={"max_iter": 40, "seed": 1, "gap": 0.005})  # fmt: skip
    job = load_job(path)
    p = generate_tiled(job, plan=plan_tiles(job, side=4.0), executor=InProcess())
    assert p.n == job.n_dots
    _check_guarantee_with_shapely(p, job.optimize.gap, job.box)
    assert (p.dots.size[:, 2] <= 0.5 * p.dots.size[:, 1]).all()  # capsules stay drawable
    r = qa(p, job)
    assert r.passed, r.failures()


def test_a_tampered_shaped_dataset_is_refused_in_one_line(tmp_path):
    """A part whose columns are not its kind's (a rounded rectangle relabelled an
    ellipse), a width under zero, an angle of 1e300, angles stored as text: each refused
    by the dataset reader, naming the part and the problem, as the CSV reader does."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    from optdot.files import sha256_file

    p = generate(load_job(_job(tmp_path, PRISM, {"random": "true"})))
    base = tmp_path / "p.parquet"
    save_dataset(p, base)
    doc = json.loads((base / MANIFEST).read_text())
    part = base / "part-00000.parquet"
    table = pq.read_table(part)

    def tampered(name, table=table, **manifest):
        d = tmp_path / f"{name}.parquet"
        d.mkdir()
        pq.write_table(table, d / part.name)
        parts = [{**doc["parts"][0], "sha256": sha256_file(d / part.name)}]
        (d / MANIFEST).write_text(json.dumps({**doc, **manifest, "parts": parts}))
        return d

    def refused(d, words):
        with pytest.raises(PatternFileError, match=words):
            ds = open_dataset(d)
            ds.verify()
            ds.read_part(0)

    refused(tampered("relabelled", shape="ellipse"), "ellipse dots are x_mm, y_mm, length_mm")
    width = table.column("width_mm").to_numpy().copy()
    width[4] = -0.04
    refused(tampered("negative", table.set_column(3, "width_mm", pa.array(width))),
            "dot 5: rounded_rectangle .* cannot be drawn")  # fmt: skip
    angle = table.column("angle_deg").to_numpy().copy()
    angle[2] = 1e300
    refused(tampered("turned", table.set_column(5, "angle_deg", pa.array(angle))),
            "dot 3: angle_deg = 1e[+]300 is not an angle")  # fmt: skip
    text = pa.array([str(v) for v in table.column("angle_deg").to_pylist()])
    refused(tampered("text", table.set_column(5, "angle_deg", text)), "angle_deg holds string")
