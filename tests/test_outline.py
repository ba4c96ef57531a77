"""Real outlines: loading and validation, the edge penalty, generation, mask round trip."""

from __future__ import annotations

import dataclasses
import math

import ezdxf
import numpy as np
import pytest
import shapely
from click.testing import CliRunner
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.optimize import approx_fprime
from shapely.geometry import Polygon

from optdot.cli import main
from optdot.config.schema import load_job
from optdot.geometry.domain import Domain, validate_polygon
from optdot.geometry.edges import EdgeIndex, signed_distances
from optdot.orchestration.job_settings import problem_of
from optdot.orchestration.pipeline import generate
from optdot.relax.formulation import PRESETS
from optdot.relax.penalty import penalty_fast
from optdot.spatial.blocks import PairList
from optdot.spatial.cellgrid import neighbor_pairs, pairs_within
from optdot.testing import pairs_brute_force, penalty_reference
from tests.conftest import SAMPLES, cli, write_job

NOTCHED = [(0, 0), (4, 0), (4, 1.2), (3.2, 1.2), (3.2, 1.8), (4, 1.8), (4, 3), (0.6, 3), (0, 2.4)]


def notched_domain(margin: float = 0.0) -> Domain:
    hole = shapely.Point(1.2, 1.2).buffer(0.35, 24).exterior.coords
    return Domain(validate_polygon(Polygon(NOTCHED, [hole]), "test"), margin)


def write_outline_dxf(path, *, hole_at=(1.2, 1.2), closed=True):
    doc = ezdxf.new("R2010", units=4)
    msp = doc.modelspace()
    bulge = math.tan(math.radians(90) / 4)
    pts = [(0, 0, 0), (4, 0, 0), (4, 3, 0), (1, 3, bulge), (0, 2, 0)]  # rounded corner
    msp.add_lwpolyline(pts, format="xyb", close=closed)
    msp.add_circle(hole_at, 0.35)
    doc.saveas(path)


def outline_job(tmp_path, grid=None, **domain):
    write_outline_dxf(tmp_path / "outline.dxf")
    grid = np.full((12, 16), 0.3) if grid is None else grid
    dom = {"outline": '"outline.dxf"', "width": None, "height": None, **domain}
    return write_job(tmp_path, grid, domain=dom)


def test_signed_distance_matches_shapely():
    dom = notched_domain()
    idx = EdgeIndex.build(dom, 0.3)
    xy = np.random.default_rng(0).uniform(-0.5, 4.5, (20000, 2))
    d, _ = signed_distances(idx, xy)
    ref = dom.edge_distance(xy) * np.where(dom.contains(xy), 1.0, -1.0)
    exact = np.isfinite(d)
    assert np.abs(d[exact] - ref[exact]).max() < 1e-12
    assert (ref[~exact] >= 0.3).all()  # only points deep inside are left unmeasured
    assert exact[ref < 0.3].all()


@pytest.mark.parametrize("margin,phantoms", [(0.0, False), (0.05, False), (0.05, True)])
@pytest.mark.slow
def test_outline_penalty_matches_reference_and_gradient(margin, phantoms):
    from optdot.relax.circles import circle_radius, container_half_sides

    dom = notched_domain(margin)
    rng = np.random.default_rng(1)
    xy = rng.uniform(-0.1, 4.1, (400, 2))
    r = circle_radius(rng.uniform(0.1, 0.5, len(xy)), 0.023)
    from optdot.relax.penalty import PenaltyTerms

    terms = PenaltyTerms(
        radius=r,
        panel_radius=0.8 * r,
        center=xy.copy(),
        half_side=container_half_sides(r),
        box=dom.box,
        dmin=0.046,
        dot_radius=0.023,
        w_hard=10.0,
        margin=margin,
        edges=EdgeIndex.build(dom, 2 * float(r.max()) + margin),
        # phantoms: every third dot within 0.15 mm of an edge (inside it, their term acts)
        phantom=((np.arange(len(xy)) % 3 == 0) & (dom.edge_distance(xy) < 0.15))
        if phantoms
        else None,
    )

    def fast(x):
        x = np.ascontiguousarray(x.reshape(-1, 2))
        g = np.empty_like(x)
        pl = PairList.from_csr(*neighbor_pairs(x, terms.reach, 0.0))
        return penalty_fast(x, terms, pl, g), g

    f, g = fast(xy)
    f_ref, g_ref = penalty_reference(xy, terms, pairs_brute_force(xy, 10.0), dom.geometry)
    assert f > 0 and f == pytest.approx(f_ref, rel=1e-10)
    np.testing.assert_allclose(g, g_ref, rtol=1e-8, atol=1e-10)
    num = approx_fprime(xy.ravel(), lambda x: fast(x)[0], 1e-8)
    assert np.abs(g.ravel() - num).max() < 1e-5 * max(1.0, np.abs(g).max())


def test_outline_job_generates_inside_with_coverage_to_the_edges(tmp_path):
    job = load_job(outline_job(tmp_path, edge_margin=0.01))
    job = dataclasses.replace(job, optimize=dataclasses.replace(job.optimize, max_iter=120))
    dom = job.domain
    assert not dom.rectangle and len(dom.rings()) == 2
    p = generate(job)
    # count from the map integrated over the domain only
    area = dom.geometry.area
    assert p.n == round(0.3 * area / job.dot_area)
    assert len(pairs_within(p.xy, job.min_distance)) == 0
    assert dom.contains(p.xy).all()
    assert dom.edge_distance(p.xy).min() >= 0.023 + 0.01 - 1e-9
    from optdot.quality.gate import run_qa

    m = run_qa(p, job.density, job.qa, job.collision_distance).metrics
    assert m["protruding"] == 0 and m["outside_outline_or_in_holes"] == 0
    for name, ratio in m["edge_band_coverage_ratio"].items():
        assert ratio == pytest.approx(1.0, abs=0.05), name
    assert m["coverage_rel_rms_smoothed"] < 0.03


@pytest.mark.slow
def test_outline_exports_read_back_by_klayout_and_ezdxf(tmp_path):
    import klayout.db as kdb

    job_path = outline_job(tmp_path)
    gds, dxf = tmp_path / "o.gds", tmp_path / "o.dxf"
    res = CliRunner().invoke(
        main,
        ["export", str(job_path), "--gds", str(gds), "--dxf", str(dxf), "-q", "--max-iter", "40"],
    )
    assert res.exit_code == 0, res.output
    dom = load_job(job_path).domain
    layout = kdb.Layout()
    layout.read(str(gds))
    top = layout.top_cell()
    region = kdb.Region(top.begin_shapes_rec(layout.layer(2, 0)))
    polys = [p for p in region.each()]
    # klayout merges the outline and its hole into one polygon with a hole
    area_um2 = sum(p.area() for p in region.merged().each()) * layout.dbu**2
    assert len(polys) >= 1
    assert area_um2 * 1e-6 == pytest.approx(dom.geometry.area, rel=1e-6)
    doc = ezdxf.readfile(str(dxf))
    rings = [
        np.array([p[:2] for p in e.get_points()])
        for e in doc.modelspace().query('LWPOLYLINE[layer=="OUTLINE"]')
    ]
    assert len(rings) == 2
    areas = sorted(abs(Polygon(r).area) for r in rings)
    assert areas[1] - areas[0] == pytest.approx(dom.geometry.area, rel=1e-9)
    # QA of the mask alone rebuilds the outline from the OUTLINE layer
    res = CliRunner().invoke(
        main, ["qa", str(gds), "-q", "--no-job", "--json", str(tmp_path / "q.json")]
    )
    assert res.exit_code == 0, res.output


BAD = {
    "self-intersection": (
        "outline.wkt",
        "POLYGON ((0 0, 4 3, 4 0, 0 3, 0 0))",
        "self-intersection at",
    ),
    "zero area": ("outline.wkt", "POLYGON ((0 0, 4 0, 8 0, 0 0))", "zero area"),
    "not a polygon": ("outline.wkt", "LINESTRING (0 0, 4 0, 4 3)", "open loop"),
    "malformed": ("outline.wkt", "POLYGON ((0 0, 4 0", "malformed WKT"),
    "units": (
        "outline.wkt",
        "POLYGON ((0 0, 40000 0, 40000 30000, 0 30000, 0 0))",
        "optdot expects 0.5 .. 5000 mm",
    ),
    "geojson": ("outline.geojson", '{"type": "Point", "coordinates": [1, 2]}', "no polygon"),
}


@pytest.mark.parametrize("case", sorted(BAD))
def test_invalid_outlines_are_refused(tmp_path, case):
    name, text, message = BAD[case]
    (tmp_path / name).write_text(text)
    dom = {"outline": f'"{name}"', "width": None, "height": None}
    job = write_job(tmp_path, np.full((4, 4), 0.2), domain=dom)
    res = CliRunner().invoke(main, ["generate", str(job), "-o", str(tmp_path / "p.csv")])
    assert res.exit_code == 2, res.output
    assert message in res.output and name in res.output
    assert "Traceback" not in res.output
    assert not (tmp_path / "p.csv").exists()


@pytest.mark.parametrize(
    "kind,message",
    [
        ("open", "open loop"),
        ("hole outside", "lies outside the outer loop"),
        ("keep-out", "outside the panel"),
    ],
)
def test_invalid_dxf_outlines_are_refused(tmp_path, kind, message):
    if kind == "open":
        write_outline_dxf(tmp_path / "outline.dxf", closed=False)
        dom = {"outline": '"outline.dxf"'}
    elif kind == "hole outside":
        write_outline_dxf(tmp_path / "outline.dxf", hole_at=(6.0, 1.0))
        dom = {"outline": '"outline.dxf"'}
    else:
        write_outline_dxf(tmp_path / "outline.dxf")
        dom = {"outline": '"outline.dxf"', "keep_out": '["POLYGON ((9 9, 10 9, 10 10, 9 9))"]'}
    dom.update(width=None, height=None)
    job = write_job(tmp_path, np.full((4, 4), 0.2), domain=dom)
    res = CliRunner().invoke(main, ["generate", str(job), "-o", str(tmp_path / "p.csv")])
    assert res.exit_code == 2, res.output
    assert message in res.output and "Traceback" not in res.output


def test_width_must_match_outline(tmp_path):
    job = outline_job(tmp_path, width=5.0, height=3.0)
    res = CliRunner().invoke(main, ["generate", str(job), "-o", str(tmp_path / "p.csv")])
    assert res.exit_code == 2 and "differs from the outline's bounding box" in res.output


def test_keep_out_and_margin_are_respected(tmp_path):
    keep = "POLYGON ((2 0.5, 3 0.5, 3 1.5, 2 1.5, 2 0.5))"
    job = load_job(outline_job(tmp_path, keep_out=f'["{keep}"]', edge_margin=0.03))
    job = dataclasses.replace(job, optimize=dataclasses.replace(job.optimize, max_iter=60))
    p = generate(job)
    ko = shapely.from_wkt(keep)
    d = shapely.distance(ko, shapely.points(p.xy))
    assert d.min() >= 0.023 + 0.03 - 1e-9
    assert p.outline is not None and len(p.outline.rings()) == 3


def test_sample_outline_is_valid():
    job = load_job(__import__("pathlib").Path(__file__).parents[1] / "samples/outline/job.toml")
    assert not job.domain.rectangle
    assert len(job.domain.rings()) >= 3  # outline + two screw holes
    terms = PRESETS["optdot"].terms(problem_of(job), np.array([[5.0, 5.0]]), np.array([0.3]))
    assert terms.edges is not None


@settings(max_examples=30, deadline=None)
@given(
    seed=st.integers(0, 2**31),
    k=st.integers(3, 40),
    jag=st.floats(0.0, 0.6),
    reach=st.floats(0.05, 1.0),
)
def test_signed_distance_on_random_star_polygons(seed, k, jag, reach):
    """Random star-shaped outlines (convex and reflex vertices) with a hole."""
    rng = np.random.default_rng(seed)
    ang = np.sort(rng.uniform(0, 2 * np.pi, k))
    if np.unique(ang).size < 3:
        return
    rad = 3.0 * (1.0 - jag * rng.random(k))
    shell = np.stack([5 + rad * np.cos(ang), 5 + rad * np.sin(ang)], axis=1)
    poly = Polygon(shell, [shapely.Point(5, 5).buffer(0.4, 8).exterior.coords])
    if not poly.is_valid or poly.area <= 0:
        return
    dom = Domain(validate_polygon(poly, "random"))
    idx = EdgeIndex.build(dom, reach)
    xy = rng.uniform(1.5, 8.5, (2000, 2))
    d, u = signed_distances(idx, xy)
    ref = dom.edge_distance(xy) * np.where(dom.contains(xy), 1.0, -1.0)
    exact = np.isfinite(d)
    assert np.abs(d[exact] - ref[exact]).max() < 1e-9
    assert (ref[~exact] >= reach - 1e-12).all()
    assert np.allclose(np.hypot(u[exact, 0], u[exact, 1])[np.abs(d[exact]) > 1e-9], 1.0)


def test_rectangle_edge_margin(tmp_path):
    job = load_job(write_job(tmp_path, np.full((6, 8), 0.3), domain={"edge_margin": 0.05}))
    p = generate(job)
    x0, y0, x1, y1 = job.box
    need = 0.023 + 0.05
    assert job.domain.rectangle and job.domain.edge_margin == 0.05
    assert (p.xy[:, 0] - x0 >= need).all() and (x1 - p.xy[:, 0] >= need).all()
    assert (p.xy[:, 1] - y0 >= need).all() and (y1 - p.xy[:, 1] >= need).all()


def test_npz_keeps_the_outline(tmp_path):
    from optdot.io.patterns import load_pattern, save_pattern

    job = load_job(outline_job(tmp_path, edge_margin=0.01))
    job = dataclasses.replace(job, optimize=dataclasses.replace(job.optimize, max_iter=10))
    p = generate(job)
    save_pattern(p, tmp_path / "p.npz")
    q = load_pattern(tmp_path / "p.npz")
    assert q.outline is not None and q.outline.edge_margin == 0.01
    assert q.outline.geometry.equals(p.outline.geometry)
    assert np.array_equal(q.xy, p.xy)


@pytest.mark.parametrize(
    "domain,message",
    [
        ({"edge_margin": -1.0}, "domain.edge_margin"),
        ({"keep_out": '["POLYGON ((0 0, 1 0, 1 1, 0 0))"]'}, "needs domain.outline"),
        ({"outline": '"missing.dxf"', "width": None, "height": None}, "outline file not found"),
        ({"outline": '"o.svg"', "width": None, "height": None}, "must be .dxf, .wkt or .geojson"),
    ],
)
def test_bad_domain_keys(tmp_path, domain, message):
    (tmp_path / "o.svg").write_text("<svg/>")
    job = write_job(tmp_path, np.full((4, 4), 0.2), domain=domain)
    res = CliRunner().invoke(main, ["generate", str(job), "-o", str(tmp_path / "p.csv")])
    assert res.exit_code == 2, res.output
    assert message in res.output and "Traceback" not in res.output
    assert not (tmp_path / "p.csv").exists()


def _cloud_deposit(domain, weight, cw, ch, nx, ny, per_cell=32):
    """A dense cloud of points inside ``domain`` carrying ``weight``'s fill, deposited
    the way dots are (the visibility grid's cloud-in-cell): the reference."""
    from optdot.quality.visibility import LuminanceGrid

    k = 1.0 / per_cell
    xs = (np.arange(nx * per_cell) + 0.5) * k * cw
    ys = (np.arange(ny * per_cell) + 0.5) * k * ch
    xx, yy = np.meshgrid(xs, ys)
    xy = np.column_stack([xx.ravel(), yy.ravel()])
    w = np.ones(len(xy)) if weight is None else weight.at(xy)
    out = []
    for keep in (domain.contains(xy), np.ones(len(xy), bool)):
        g = LuminanceGrid(0.0, 0.0, cw, ch, nx, ny, False, np.zeros((ny, nx)))
        g.add(xy[keep], w[keep])
        out.append(g.sums)
    return np.where(out[1] > 0, out[0] / np.where(out[1] > 0, out[1], 1.0), 0.0)


@pytest.mark.parametrize("weighted", [False, True])
@pytest.mark.slow
def test_deposited_fractions_are_the_clouds_deposit_inside_the_outline(weighted):
    """The share of a cloud-in-cell deposit from inside the outline sample's outline (a
    notch, a cut-out, two holes, a keep-out), unweighted and weighed by its steep map,
    against a dense cloud deposited like dots; the cells' area shares, which the eye
    model and the correction's target used before, miss by a quarter at the edges."""
    job = load_job(SAMPLES / "outline" / "job.toml")
    weight = job.density if weighted else None
    cw = ch = 0.25
    nx, ny = 96, 64
    got = job.domain.deposited_fractions(0.0, 0.0, cw, ch, nx, ny, weight)
    ref = _cloud_deposit(job.domain, weight, cw, ch, nx, ny)
    assert np.abs(got - ref).max() < 0.02
    assert np.abs(job.domain.cell_fractions(0.0, 0.0, cw, ch, nx, ny) - ref).max() > 0.2
    if not weighted:  # a uniform fill keeps the domain's area
        assert got.sum() * cw * ch == pytest.approx(job.domain.geometry.area, rel=1e-12)
    rect = Domain.rect(0.0, 0.0, 24.0, 16.0)  # the panel: its cells' shares, as before
    assert np.array_equal(
        rect.deposited_fractions(0.0, 0.0, cw, ch, nx, ny, weight),
        rect.cell_fractions(0.0, 0.0, cw, ch, nx, ny),
    )


@pytest.mark.parametrize(
    "suffix, hole",
    [
        (".wkt", [(0, 0), (3, 1), (1, 3)]),  # at the outer ring's corner vertex
        (".wkt", [(5, 0), (6, 2), (4, 2)]),  # a hole vertex on an outer edge
        (".dxf", [(0, 0), (3, 1), (1, 3)]),
        (".dxf", [(10, 6), (7, 5), (9, 3)]),
        (".geojson", [(5, 0), (6, 2), (4, 2)]),
    ],
)
@pytest.mark.slow
def test_a_hole_touching_the_outer_ring_at_a_point_exports_and_reads_back(tmp_path, suffix, hole):
    """A hole that meets the outline in one point (valid OGC geometry) went through
    ``export`` and ``qa`` with exit 70 in a hostile round: every mask of it is written and
    read back, with the job and without."""
    import json

    ring = [(0, 0), (10, 0), (10, 6), (0, 6)]
    path = tmp_path / f"o{suffix}"
    if suffix == ".wkt":
        text = ", ".join(f"{x} {y}" for x, y in [*ring, ring[0]])
        inner = ", ".join(f"{x} {y}" for x, y in [*hole, hole[0]])
        path.write_text(f"POLYGON (({text}), ({inner}))\n")
    elif suffix == ".geojson":
        coords = [[list(p) for p in [*ring, ring[0]]], [list(p) for p in [*hole, hole[0]]]]
        path.write_text(json.dumps({"type": "Polygon", "coordinates": coords}))
    else:
        doc = ezdxf.new()
        doc.header["$INSUNITS"] = 4
        doc.modelspace().add_lwpolyline(ring, close=True)
        doc.modelspace().add_lwpolyline(hole, close=True)
        doc.saveas(path)
    (tmp_path / "d.csv").write_text("\n".join([",".join(["0.2"] * 10)] * 6) + "\n")
    job = tmp_path / "job.toml"
    job.write_text(
        f'name = "hole"\n[domain]\noutline = "{path.name}"\n[density]\ngrid = "d.csv"\n'
        "[dots]\ndiameter = 0.046\n"
    )
    masks = [tmp_path / n for n in ("m.gds", "m.oas", "m.dxf")]
    rc, err, _ = cli("export", job, *sum([[f"--{m.suffix[1:]}", m] for m in masks], []), "-q")
    assert rc == 0, err
    for mask in masks:
        for judged in (["--job", job], ["--no-job"]):
            rc, err, _ = cli("qa", mask, *judged, "-q")
            assert rc == 0, (mask.name, judged, err)


def test_a_domain_hands_out_each_grid_s_own_fractions_read_only_and_pickles_without_them():
    """The fractions a domain keeps are each grid's own (asked in turn and again, more
    grids than it keeps: every answer the direct computation's), read-only, and left out
    of a pickle (a worker computes its own)."""
    import pickle

    from optdot.geometry.domain import FRACTION_GRIDS, polygon_cell_fractions

    dom = Domain(
        shapely.Point(5.0, 5.0).buffer(3.0, quad_segs=16).difference(shapely.box(4, 4, 6, 6))
    )
    sizes = [(7, m) for m in range(7, 7 + FRACTION_GRIDS)] + [(9, 7), (11, 8)]
    grids = [(0.0, 0.0, 10.0 / nx, 10.0 / ny, nx, ny) for nx, ny in sizes]
    for g in grids + grids[::-1] + grids:
        got = dom.cell_fractions(*g)
        np.testing.assert_array_equal(got, polygon_cell_fractions(dom.geometry, *g))
        assert not got.flags.writeable
    assert len(dom._fractions) == FRACTION_GRIDS
    back = pickle.loads(pickle.dumps(dom))
    assert back._fractions == {} and back.geometry.equals(dom.geometry)
    np.testing.assert_array_equal(back.cell_fractions(*grids[0]), dom.cell_fractions(*grids[0]))
