"""Graded caps: caps printed as concentric rings whose ink the design sizes.
The ring table against the bands' ink and the printable widths, the exact disc-cell
areas and ring shares against shapely, the tracer's ring test against brute force, the
job's key and its errors, the design's band step, and every file that carries the rings
(NPZ, GDSII, OASIS, DXF) read back by optdot and by KLayout / ezdxf."""

from __future__ import annotations

import math

import numpy as np
import pytest
import shapely
from hypothesis import given, settings
from hypothesis import strategies as st

from optdot.config.schema import load_job
from optdot.geometry.caps import (
    RING_LINE,
    design_bands,
    disc_rect_area,
    ring_shares,
    ring_table,
)
from optdot.optics.marks import on_cap as _on_cap
from optdot.optics.scene import cap_grid

from .conftest import cli, one_error
from .test_backlight import direct_job

#: Four LEDs on a 5 mm grid under a 10 x 10 mm film, caps of 0.8 mm graded in 8 bands.
INK = [1.0, 1.0, 0.8, 0.5, 0.3, 0.0, 0.2, 0.9]
GRADED = {"pitch": [5.0, 5.0], "size": 0.2, "cap": 0.8, "cap_ink": INK}


def _graded(tmp, fill=0.3, **leds):
    path = direct_job(tmp, 10.0, 10.0, fill, leds={**GRADED, **leds})
    return load_job(path, need_map=fill is not None)


@settings(max_examples=60, deadline=None)
@given(
    st.floats(0.2, 4.0),
    st.lists(st.floats(0.0, 1.0), min_size=1, max_size=40),
)
def test_the_ring_table_prints_the_bands_ink_in_widths_a_mask_can_hold(diameter, ink):
    rings = ring_table(diameter, ink)
    big_r = 0.5 * diameter
    n = len(ink)
    p = big_r / n
    line = min(RING_LINE, 0.5 * p)
    if len(rings):
        assert rings[0, 0] >= 0 and rings[-1, 1] <= big_r + 1e-9
        assert np.all(rings[:, 1] > rings[:, 0])
        assert np.all(rings[1:, 0] - rings[:-1, 1] >= line - 2e-6)  # clear space
        assert np.all(rings[:, 1] - rings[:, 0] >= line - 2e-6)  # no ring too narrow
    # the running ink follows the bands' within what one band's quantum can hold back
    edges = np.arange(n + 1) * p
    for i in range(1, n + 1):
        want = sum(ink[k] * math.pi * (edges[k + 1] ** 2 - edges[k] ** 2) for k in range(i))
        inside = np.clip(rings, 0, edges[i])
        got = math.pi * float((inside[:, 1] ** 2 - inside[:, 0] ** 2).sum())
        quantum = 2 * math.pi * edges[i] * line + 1e-9
        assert abs(got - want) <= quantum


@pytest.mark.parametrize("share", [0.05, 0.3, 0.85, 0.97])
def test_a_share_no_single_ring_can_print_is_kept_over_the_bands(share):
    """Error diffusion: 0.05 of a 50 µm band is a 2.5 µm ring (none can print) and 0.85
    one of 42.5 µm (it leaves less than 10 µm clear); over 30 bands the ink still comes
    out right."""
    rings = ring_table(3.0, [share] * 30)
    printed = math.pi * float((rings[:, 1] ** 2 - rings[:, 0] ** 2).sum())
    rim = math.pi * (1.5**2 - (1.5 - RING_LINE) ** 2)  # the last ring the carry may miss
    assert printed == pytest.approx(share * math.pi * 1.5**2, abs=rim)


def test_a_solid_cap_is_one_disc_and_full_bands_merge():
    assert np.array_equal(ring_table(0.8, None), [[0.0, 0.4]])
    assert np.allclose(ring_table(0.8, [1.0] * 8), [[0.0, 0.4]])
    assert len(ring_table(0.8, [0.0] * 8)) == 0


# coordinates on a 1 nm grid: GEOS, the reference, loses 2e-4 of the area when a corner
# sits near the smallest doubles (shapely gives 0.95642 at 2e-313 and at 2.2e-308, the
# smallest normal one; 0.95661 at 0 and at 1e-300); nothing of a panel is finer than 1 nm
NM = st.floats(-1, 1).map(lambda v: round(v, 6))


@settings(max_examples=80, deadline=None)
@given(
    NM,
    NM,
    st.floats(0.01, 1.5),
    st.floats(-2, 1).map(lambda v: round(v, 6)),
    st.floats(-2, 1).map(lambda v: round(v, 6)),
    st.floats(0.01, 2),
    st.floats(0.01, 2),
)
def test_the_disc_rectangle_area_is_exact(cx, cy, r, x0, y0, w, h):
    want = (
        shapely.Point(cx, cy)
        .buffer(r, quad_segs=1024)
        .intersection(shapely.box(x0, y0, x0 + w, y0 + h))
        .area
    )
    got = float(disc_rect_area(cx, cy, r, x0, y0, x0 + w, y0 + h))
    assert got == pytest.approx(want, abs=2e-6 * math.pi * r * r + 1e-12)


def test_ring_shares_match_shapely_annuli_on_cells():
    """Caps inside the grid, across its edges and corner, at different offsets to the
    cells: the rings' share of every cell against shapely's annuli."""
    caps = np.array([[1.3, 1.1, 1.6], [3.7, 2.2, 1.6], [0.2, 3.45, 1.6], [4.95, -0.1, 1.6]])
    rings = ring_table(1.6, [1.0, 0.6, 0.0, 0.4, 0.8, 0.2, 1.0, 0.5])
    got = ring_shares(caps, rings, 0.0, 0.0, 0.35, 0.3, 14, 12)
    polys = [
        shapely.Point(x, y)
        .buffer(b, quad_segs=1024)
        .difference(shapely.Point(x, y).buffer(a, quad_segs=1024))
        for x, y, _ in caps
        for a, b in rings
    ]
    ink = shapely.union_all(polys)
    want = np.array(
        [
            [
                ink.intersection(shapely.box(i * 0.35, j * 0.3, (i + 1) * 0.35, (j + 1) * 0.3)).area
                for i in range(14)
            ]
            for j in range(12)
        ]
    ) / (0.35 * 0.3)
    assert np.abs(got - want).max() < 1e-4
    assert got.sum() > 1.0  # not a grid of zeros


@settings(max_examples=30, deadline=None)
@given(st.lists(st.floats(0.0, 1.0), min_size=2, max_size=12), st.integers(0, 2**32 - 1))
def test_the_tracer_s_ring_test_agrees_with_brute_force(ink, seed):
    caps = np.array([[2.0, 2.0, 1.2], [5.0, 2.5, 1.2], [3.0, 5.0, 1.2]])
    rings = ring_table(1.2, ink)
    start, cap, grid = cap_grid(caps, (0.0, 0.0, 8.0, 8.0))
    pts = np.random.default_rng(seed).uniform((0.5, 0.5), (7.0, 7.0), (600, 2))
    d = np.hypot(*(pts[:, None, :] - caps[None, :, :2]).transpose(2, 0, 1)).min(axis=1)
    want = ((d[:, None] >= rings[None, :, 0]) & (d[:, None] <= rings[None, :, 1])).any(axis=1)
    table = np.ascontiguousarray(rings**2) if len(rings) else np.zeros((0, 2))
    got = np.array([_on_cap(x, y, start, cap, grid, table) for x, y in pts])
    assert np.array_equal(got >= 0, d <= 0.6)  # within a cap: ink or clear, never a dot
    edge = np.abs(d[:, None] - rings.ravel()[None, :]).min(axis=1) < 1e-9 if len(rings) else 0
    assert np.array_equal((got == 1) | edge, want | edge)


def test_the_job_s_cap_ink_becomes_the_domain_s_rings(tmp_path):
    job = _graded(tmp_path)
    assert np.array_equal(job.domain.cap_rings, ring_table(0.8, INK))
    design = load_job(direct_job(tmp_path, 10.0, 10.0, 0.3, leds={**GRADED, "cap_ink": "design"}))
    assert design.domain.cap_rings.shape == (0, 2)  # the design starts bare
    assert design_bands(0.8) == 8


@pytest.mark.parametrize(
    "leds, fragment",
    [
        ({"cap": 0.0}, "backlight.leds.cap is 0"),
        ({"cap_ink": "later"}, 'must be "design"'),
        ({"cap_ink": [0.5, 1.2]}, "ink shares in [0, 1]"),
        ({"cap_ink": []}, "ink shares in [0, 1]"),
        ({"cap_ink": [0.5, "x"]}, "ink shares in [0, 1]"),
    ],
)
def test_bad_cap_ink_gets_one_line(tmp_path, leds, fragment):
    path = direct_job(tmp_path, 10.0, 10.0, 0.3, leds={**GRADED, **leds})
    one_error(("simulate", path, "--rays", "1000"), 2, str(path), "cap_ink", fragment)


def test_generate_refuses_caps_the_design_has_not_sized(tmp_path):
    path = direct_job(tmp_path, 10.0, 10.0, 0.3, leds={**GRADED, "cap_ink": "design"})
    one_error(("generate", path, "-o", tmp_path / "p.npz", "-q"), 2, "cap_ink", "optdot design")
    assert not (tmp_path / "p.npz").exists()


def test_a_band_under_too_much_light_takes_more_ink(tmp_path):
    from optdot.optics.design import Grades, design_grid

    job = _graded(tmp_path)
    nx, ny, dx, dy = design_grid(job.bench)
    g = Grades(job, nx, ny, dx, dy)
    before = g.ink.copy()
    too_bright = np.full((ny, nx), -0.2)  # every cell brighter than wanted
    g.update(too_bright, np.ones((ny, nx), bool), 0.9, 1.0)
    grow = g.ink - before
    assert np.all(grow[before < 1] > 0) and np.all(g.ink <= 1)
    assert g.capped.sum() > 0 and g.rings.shape[1] == 2
    g.update(np.full((ny, nx), 0.3), np.ones((ny, nx), bool), 0.9, 1.0)  # too dark
    assert np.all(g.ink <= grow + before + 1e-12) and np.any(g.ink < grow + before)


def test_the_design_sizes_graded_caps_and_writes_them_into_its_job(tmp_path):
    path = direct_job(tmp_path, 10.0, 10.0, None, leds={**GRADED, "cap_ink": "design"})
    text = path.read_text() + "\n[design]\niterations = 3\nrays = 200000\n"
    path.write_text(text)
    rc, err, _ = cli("design", path, "-o", tmp_path / "map.csv", "-q")
    assert rc == 0, err
    job = load_job(tmp_path / "map.toml")
    ink = job.backlight.leds.cap_ink
    assert isinstance(ink, tuple) and len(ink) == 8 and max(ink) > 0
    assert all(0 <= f <= 1 for f in ink)
    assert np.array_equal(job.domain.cap_rings, ring_table(0.8, np.array(ink)))


def _pattern(tmp_path):
    from optdot.orchestration.pipeline import generate

    job = _graded(tmp_path)
    return job, generate(job)


@pytest.mark.slow
def test_graded_caps_survive_every_mask_and_klayout_reads_their_ink(tmp_path):
    import dataclasses

    from optdot.errors import ExportError
    from optdot.exporters.dxf import write_dxf
    from optdot.exporters.gds import write_gds, write_oas
    from optdot.exporters.options import ExportOptions
    from optdot.exporters.readback import read_any
    from optdot.io.patterns import load_pattern, save_pattern

    job, p = _pattern(tmp_path)
    want = job.domain.cap_rings
    save_pattern(p, tmp_path / "p.npz")
    assert np.array_equal(load_pattern(tmp_path / "p.npz").outline.cap_rings, want)
    opts = ExportOptions()
    for name, write in (("p.gds", write_gds), ("p.oas", write_oas), ("p.dxf", write_dxf)):
        write(p, tmp_path / name, opts)
        back = read_any(tmp_path / name)
        assert back.n == p.n
        assert np.allclose(back.outline.caps, job.domain.caps, atol=1e-6)
        assert back.outline.cap_rings.shape == want.shape
        assert np.abs(back.outline.cap_rings - want).max() <= 2e-6, name
    with pytest.raises(ExportError, match="R12"):
        write_dxf(p, tmp_path / "r12.dxf", dataclasses.replace(opts, dxf_version="R12"))
    from optdot.exporters.speos import write_speos

    with pytest.raises(ExportError, match="graded caps"):
        write_speos(p, tmp_path / "p.OPT3DMapping", opts)
    assert not (tmp_path / "p.OPT3DMapping").exists() and not (tmp_path / "r12.dxf").exists()

    import klayout.db as kdb

    layout = kdb.Layout()
    layout.read(str(tmp_path / "p.gds"))
    cell = layout.cell("CAP_800000")
    region = kdb.Region(cell.begin_shapes_rec(layout.layer(opts.layer, opts.datatype)))
    area = region.merged().area() * layout.dbu**2 * 1e-6  # µm^2 -> mm^2
    ink = math.pi * float((want[:, 1] ** 2 - want[:, 0] ** 2).sum())
    assert area == pytest.approx(ink, rel=2e-3)

    import ezdxf

    doc = ezdxf.readfile(tmp_path / "p.dxf")
    assert not doc.audit().has_errors
    hatches = doc.modelspace().query("HATCH")
    assert len(hatches) == len(want) * len(job.domain.caps)


def test_qa_fails_a_pattern_whose_rings_differ_from_the_job_s():
    from optdot.quality.gate import caps_check

    caps = np.array([[2.5, 2.5, 0.8], [7.5, 2.5, 0.8]])
    rings = ring_table(0.8, INK)
    assert caps_check(caps, caps, rings, rings).passed
    other = rings.copy()
    other[1, 1] += 0.005
    assert caps_check(caps, caps, other, rings).value == 2
    assert caps_check(caps, caps, None, rings).value == 2  # solid where graded is wanted
    assert caps_check(caps, caps, None, None).passed


@pytest.mark.slow
def test_the_tracer_s_rings_pass_the_light_their_coverage_does(tmp_path):
    """Real rings against coverage mode: the film with graded caps (no dots) passes the
    light a film without caps passes through a coverage raster of the rings' share of
    each 0.1 mm cell; solid caps and no caps bracket it."""
    from dataclasses import replace

    from optdot.optics.scene import Coverage
    from optdot.optics.simulate import simulate

    ink = [1.0] * 6 + [0.5] * 12 + [0.2] * 12
    job = _graded(tmp_path, fill=None, cap=3.0, cap_ink=ink)
    empty = Coverage(np.zeros((1, 1)), 0.0, 0.0, 10.0, 10.0)
    rays = 400_000
    rings = simulate(job.bench, rays, seed=3, coverage=empty).efficiency
    shares = ring_shares(job.domain.caps, job.domain.cap_rings, 0.0, 0.0, 0.1, 0.1, 100, 100)
    bare_path = direct_job(tmp_path, 10.0, 10.0, None, leds={"pitch": [5.0, 5.0]})
    bare = load_job(bare_path, need_map=False)
    raster = simulate(bare.bench, rays, seed=3, coverage=Coverage(shares, 0.0, 0.0, 0.1, 0.1))
    none = simulate(bare.bench, rays, seed=3, coverage=empty).efficiency
    solid = replace(job, domain=replace(job.domain, cap_rings=None))
    full = simulate(solid.bench, rays, seed=3, coverage=empty).efficiency
    assert full < rings < none
    noise = 3 * math.sqrt(rings * (1 - rings) / rays) * math.sqrt(2)
    assert abs(rings - raster.efficiency) <= noise + 0.002


@pytest.mark.slow
def test_rings_survive_datasets_and_damaged_rings_are_refused(tmp_path):
    import io
    import zipfile

    from optdot.io.dataset import load_dataset
    from optdot.io.patterns import save_pattern

    job, p = _pattern(tmp_path)
    save_pattern(p, tmp_path / "p.parquet")
    ds = load_dataset(tmp_path / "p.parquet")
    assert np.array_equal(ds.outline.cap_rings, job.domain.cap_rings)
    save_pattern(p, tmp_path / "p.npz")
    with zipfile.ZipFile(tmp_path / "p.npz") as z, zipfile.ZipFile(tmp_path / "bad.npz", "w") as w:
        for item in z.infolist():
            data = z.read(item)
            if item.filename == "cap_rings.npy":
                buf = io.BytesIO()
                np.lib.format.write_array(buf, np.array([[0.1, 0.3], [0.2, 0.35]]))
                data = buf.getvalue()
            w.writestr(item, data)
    one_error(("qa", tmp_path / "bad.npz"), 2, "bad.npz", "cap_rings", "overlap")


def test_no_dot_of_the_coverage_lands_between_a_cap_s_rings(tmp_path):
    """Coverage mode on a coarse raster: a cap's clear bands stay clear (the coverage
    holds the dots' share outside the caps), as on a fine raster of the same dots that
    leaves the caps out."""
    from optdot.geometry.caps import cap_shares
    from optdot.optics.scene import Coverage
    from optdot.optics.simulate import simulate

    job = _graded(tmp_path, fill=None, cap=3.0, cap_ink=[0.0] * 30)
    inside = job.domain.cell_fractions(0.0, 0.0, 1.0, 1.0, 10, 10)
    rays = 400_000
    coarse = simulate(job.bench, rays, seed=5, coverage=Coverage(0.5 * inside, 0.0, 0.0, 1.0, 1.0))
    bare_path = direct_job(tmp_path, 10.0, 10.0, None, leds={"pitch": [5.0, 5.0]})
    bare = load_job(bare_path, need_map=False)
    free = 1.0 - cap_shares(job.domain.caps, 0.0, 0.0, 0.05, 0.05, 200, 200)
    fine = simulate(bare.bench, rays, seed=5, coverage=Coverage(0.5 * free, 0.0, 0.0, 0.05, 0.05))
    noise = 3 * math.sqrt(2 * fine.efficiency * (1 - fine.efficiency) / rays)
    assert abs(coarse.efficiency - fine.efficiency) <= noise + 0.002


@pytest.mark.slow
def test_a_mask_whose_caps_print_different_rings_is_refused(tmp_path):
    import ezdxf

    from optdot.errors import PatternFileError
    from optdot.exporters.dxf import write_dxf
    from optdot.exporters.options import ExportOptions
    from optdot.exporters.readback import read_any

    _, p = _pattern(tmp_path)
    write_dxf(p, tmp_path / "p.dxf", ExportOptions())
    doc = ezdxf.readfile(tmp_path / "p.dxf")
    msp = doc.modelspace()
    msp.delete_entity(msp.query("HATCH")[0])  # one cap loses a ring
    doc.saveas(tmp_path / "odd.dxf")
    with pytest.raises(PatternFileError, match="same rings"):
        read_any(tmp_path / "odd.dxf")


@pytest.mark.slow  # over 1.5 s
def test_a_graded_cap_drawn_as_triangles_is_refused(tmp_path):
    """A GDSII whose graded cap cell holds triangles reaching the rings' radii: the
    reader took each polygon's nearest and farthest vertex for a ring and QA passed."""
    import gdstk

    from optdot.errors import PatternFileError
    from optdot.exporters.gds import write_gds
    from optdot.exporters.options import ExportOptions
    from optdot.exporters.readback import read_any

    _, p = _pattern(tmp_path)
    write_gds(p, tmp_path / "p.gds", ExportOptions())
    assert read_any(tmp_path / "p.gds").n == p.n
    lib = gdstk.read_gds(str(tmp_path / "p.gds"))
    cell = next(c for c in lib.cells if c.name.startswith("CAP_"))
    swapped = 0
    for poly in [q for q in cell.polygons if (q.layer, q.datatype) == (1, 0)]:
        r = np.hypot(*poly.points.T)
        lo, hi = float(r.min()), float(r.max())
        cell.remove(poly)
        cell.add(gdstk.Polygon([(lo, 0), (hi, 0), (0, hi)], layer=1))  # a spoke, not a ring
        swapped += 1
    assert swapped
    lib.write_gds(str(tmp_path / "forged.gds"))
    with pytest.raises(PatternFileError, match="not a ring about the cap's centre"):
        read_any(tmp_path / "forged.gds")
