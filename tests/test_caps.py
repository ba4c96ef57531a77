"""Caps: discs of solid ink printed over a direct-lit backlight's LEDs. The job's
key, the keep-out the dots respect, the tracer's exact discs against brute force, the
design's shares, and every file that carries them (NPZ, dataset manifest, GDSII, OASIS,
DXF) read back by optdot and by KLayout / ezdxf."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from optdot.config.schema import load_job
from optdot.geometry.caps import CAP_APPID, CAP_CELL, cap_array, cap_shares, discs
from optdot.optics.marks import on_cap as _on_cap
from optdot.optics.scene import Coverage, cap_grid
from optdot.optics.simulate import simulate

from .conftest import cli, one_error
from .test_backlight import direct_job

#: Four LEDs on a 5 mm grid under a 10 x 10 mm film, with caps of 0.8 mm.
CAPPED = {"pitch": [5.0, 5.0], "size": 0.2, "cap": 0.8}


def _capped(tmp, fill=0.3, **leds):
    path = direct_job(tmp, 10.0, 10.0, fill, leds={**CAPPED, **leds})
    return load_job(path, need_map=fill is not None)


def test_a_cap_is_cut_out_of_the_dots_domain_with_qa_s_gap(tmp_path):
    job = _capped(tmp_path)
    dom = job.domain
    gap = job.qa.effective_close_gap
    assert dom.caps.shape == (4, 3) and np.all(dom.caps[:, 2] == 0.8)
    assert not dom.rectangle and dom.lit.area == pytest.approx(100.0)
    removed = 100.0 - dom.geometry.area
    # circumscribed polygons: at least the discs, within the keep-out tolerance
    assert 4 * math.pi * (0.4 + gap) ** 2 <= removed <= 4 * math.pi * (0.4 + gap + 2e-4) ** 2
    # no keep-out without caps
    bare = load_job(direct_job(tmp_path, 10.0, 10.0, 0.3))
    assert bare.domain.caps is None and bare.domain.rectangle


@pytest.mark.slow
def test_generated_dots_keep_out_of_every_cap_and_its_gap(tmp_path):
    from optdot.orchestration.pipeline import generate

    job = _capped(tmp_path, fill=0.5)
    pattern = generate(job)
    caps = job.domain.caps
    d = np.hypot(*(pattern.xy[:, None, :] - caps[None, :, :2]).transpose(2, 0, 1))
    edge_gap = d - pattern.radius[:, None] - 0.5 * caps[None, :, 2]
    assert edge_gap.min() >= job.qa.effective_close_gap - 1e-9
    assert pattern.outline is not None and np.array_equal(pattern.outline.caps, caps)


@settings(max_examples=40, deadline=None)
@given(
    st.lists(
        st.tuples(st.floats(0, 10), st.floats(0, 8), st.floats(0.05, 1.5)),
        min_size=1,
        max_size=12,
    ),
    st.integers(0, 2**32 - 1),
)
def test_the_tracer_s_cap_test_agrees_with_brute_force(rows, seed):
    caps = np.array(rows, np.float64)
    start, cap, grid = cap_grid(caps, (0.0, 0.0, 10.0, 8.0))
    pts = np.random.default_rng(seed).uniform((-1.0, -1.0), (11.0, 9.0), (400, 2))
    want = (
        np.hypot(*(pts[:, None, :] - caps[None, :, :2]).transpose(2, 0, 1))
        <= 0.5 * caps[None, :, 2]
    ).any(axis=1)
    solid = np.array([[0.0, np.inf]])
    got = np.array([_on_cap(x, y, start, cap, grid, solid) == 1 for x, y in pts])
    # a point within 1e-12 of a rim may go either way
    rim = np.abs(
        np.hypot(*(pts[:, None, :] - caps[None, :, :2]).transpose(2, 0, 1)) - 0.5 * caps[:, 2]
    ).min(axis=1)
    assert np.array_equal(got[rim > 1e-12], want[rim > 1e-12])


def test_a_cap_over_a_bare_film_is_ink_exactly_where_the_disc_is(tmp_path):
    """No dots, caps only: the ink's share of what reaches the film is the caps' share of
    the light, and it is zero without caps; a cap the size of a pitch cell takes most."""
    bare = Coverage(np.zeros((1, 1)), 0.0, 0.0, 10.0, 10.0)
    small = simulate(_capped(tmp_path, fill=None), 100_000, seed=3, coverage=bare)
    big = simulate(_capped(tmp_path, fill=None, cap=4.0), 100_000, seed=3, coverage=bare)
    plain = direct_job(tmp_path, 10.0, 10.0, None, leds={"pitch": [5.0, 5.0], "size": 0.2})
    none = simulate(load_job(plain, need_map=False), 100_000, seed=3, coverage=bare)
    ink = [s.fates["absorbed_dots"] for s in (none, small, big)]
    assert ink[0] == 0 < ink[1] < ink[2]
    assert big.efficiency < small.efficiency < none.efficiency


@pytest.mark.slow
def test_the_coverage_mode_with_caps_matches_real_dots_with_caps(tmp_path):
    from optdot.orchestration.pipeline import generate

    job = _capped(tmp_path, fill=0.3)
    pattern = generate(job)
    rays = 300_000
    cov = simulate(job.bench, rays, seed=6)
    real = simulate(job.bench, rays, seed=6, dots=pattern)
    for k in ("extracted", "absorbed_dots", "lost_bottom"):
        a, b = cov.fates[k] / rays, real.fates[k] / rays
        sigma = math.sqrt(2 * max(a, 1e-6) * (1 - a) / rays)
        assert abs(a - b) <= max(4 * sigma, 0.01 * a), (k, a, b)


def test_the_design_s_shares_add_up_and_cap_shares_match_the_discs(tmp_path):
    from optdot.optics.design import _shares, design_grid

    job = _capped(tmp_path)
    nx, ny, dx, dy = design_grid(job.bench)
    inside, panel, capped = _shares(job, nx, ny, dx, dy)
    ring = panel - inside - capped  # the gap around each cap: neither dots nor ink
    gap = job.qa.effective_close_gap
    assert ring.min() >= -1e-9
    assert ring.sum() * dx * dy == pytest.approx(4 * math.pi * ((0.4 + gap) ** 2 - 0.16), rel=0.02)
    assert capped.sum() * dx * dy == pytest.approx(4 * math.pi * 0.16, rel=1e-3)
    caps = cap_array([[1.0, 1.0]], 1.0)
    share = cap_shares(caps, 0.0, 0.0, 0.5, 0.5, 4, 4)
    assert share.sum() * 0.25 == pytest.approx(discs(caps).area)
    share[:] = 7.0  # the shares are kept for the next call on the grid: a copy is handed out
    again = cap_shares(caps.copy(), 0.0, 0.0, 0.5, 0.5, 4, 4)
    assert again.sum() * 0.25 == pytest.approx(discs(caps).area)
    assert cap_shares(caps, 0.0, 0.0, 0.5, 0.5, 4, 2).shape == (2, 4)  # another grid


@pytest.mark.slow
def test_designing_with_caps_evens_lambertian_leds_that_dots_alone_cannot(tmp_path):
    """Lambertian LEDs 1.5 mm under the film: the dots alone stop at their top fill over
    each LED; with caps the designed luminance's RMS (0.5 mm cells, noise 2.8 %) falls
    from ~10 % to ~6 %, and the fill under the dots stays within the range."""
    from optdot.optics.design import design

    leds = {"pitch": [5.0, 5.0], "size": 0.2, "profile": "lambertian"}
    plain = load_job(direct_job(tmp_path, 10.0, 10.0, None, leds=leds), need_map=False)
    capped = direct_job(tmp_path, 10.0, 10.0, None, leds={**leds, "cap": 0.8})
    capped = load_job(capped, need_map=False)
    a = design(plain.bench, seed=1, rays=600_000, iterations=6)
    b = design(capped.bench, seed=1, rays=600_000, iterations=6)
    rms_a, rms_b = a.history[-1]["luminance_rms"], b.history[-1]["luminance_rms"]
    assert rms_b < 0.8 * rms_a, (rms_a, rms_b)
    assert 0 <= b.fill.min() and b.fill.max() <= capped.design.fill_range[1]


@pytest.mark.parametrize(
    "leds, words",
    [
        ({"cap": 5.0}, ["backlight.leds.cap", "between the LEDs"]),
        ({"cap": -0.1}, ["backlight.leds.cap", "0 <= x"]),
        ({"offset": [0.3, 0.3], "cap": 0.8}, ["backlight.leds.cap", "past the panel"]),
        ({"cap": "big"}, ["backlight.leds.cap"]),
    ],
    ids=["too-big", "negative", "past-panel", "text"],
)
def test_bad_caps_get_one_line(tmp_path, leds, words):
    path = direct_job(tmp_path, 10.0, 10.0, 0.3, leds={**CAPPED, **leds})
    one_error(("simulate", path, "--rays", "1000"), 2, str(path), *words)


@pytest.mark.slow
def test_caps_survive_npz_and_datasets_and_bad_caps_are_refused(tmp_path):
    from optdot.io.dataset import load_dataset
    from optdot.io.patterns import load_pattern, save_pattern
    from optdot.orchestration.pipeline import generate

    job = _capped(tmp_path, fill=0.3)
    pattern = generate(job)
    save_pattern(pattern, tmp_path / "p.npz")
    back = load_pattern(tmp_path / "p.npz")
    assert np.array_equal(back.outline.caps, job.domain.caps)
    save_pattern(pattern, tmp_path / "p.parquet")
    ds = load_dataset(tmp_path / "p.parquet")
    assert np.array_equal(ds.outline.caps, job.domain.caps)
    # a damaged caps array: one line naming the file
    import zipfile

    with zipfile.ZipFile(tmp_path / "p.npz") as z, zipfile.ZipFile(tmp_path / "bad.npz", "w") as w:
        for item in z.infolist():
            data = z.read(item)
            if item.filename == "caps.npy":
                import io

                buf = io.BytesIO()
                np.lib.format.write_array(buf, np.array([[1.0, 2.0, -1.0]]))
                data = buf.getvalue()
            w.writestr(item, data)
    one_error(("qa", tmp_path / "bad.npz"), 2, "bad.npz", "caps", "> 0")


@pytest.mark.parametrize("fmt", ["gds", "oas", "dxf", "gds-flat"])
@pytest.mark.slow
def test_masks_carry_the_caps_and_read_them_back(tmp_path, fmt):
    job_path = direct_job(tmp_path, 10.0, 10.0, 0.3, leds=CAPPED)
    assert cli("generate", job_path, "-o", tmp_path / "p.npz", "-q")[0] == 0
    suffix = fmt.split("-")[0]
    out = tmp_path / f"m.{suffix}"
    extra = ["--flatten"] if fmt == "gds-flat" else []
    rc, err, _ = cli("export", tmp_path / "p.npz", f"--{suffix}", out, *extra, "--no-job")
    assert rc == 0, err
    from optdot.exporters.readback import read_any
    from optdot.io.patterns import load_pattern

    src = load_pattern(tmp_path / "p.npz")
    back = read_any(out)
    assert back.n == src.n  # the caps are not read as dots
    caps = np.asarray(back.outline.caps)
    order = np.lexsort((caps[:, 1], caps[:, 0]))
    want = src.outline.caps[np.lexsort((src.outline.caps[:, 1], src.outline.caps[:, 0]))]
    assert np.allclose(caps[order], want, atol=2e-6)
    if suffix == "dxf":
        import ezdxf

        doc = ezdxf.readfile(out)
        marked = [e for e in doc.modelspace().query("CIRCLE") if e.has_xdata(CAP_APPID)]
        assert len(marked) == 4 and all(e.dxf.layer == "DOTS" for e in marked)
        assert all(math.isclose(e.dxf.radius, 0.4) for e in marked)
    else:
        klayout = pytest.importorskip("klayout.db")
        layout = klayout.Layout()
        layout.read(str(out))
        cap = layout.cell(CAP_CELL)
        assert cap is not None
        top = layout.top_cell()
        placed = [i for i in top.each_inst() if i.cell_index == cap.cell_index()]
        assert sum(i.size() for i in placed) == 4
        box = cap.bbox().to_dtype(layout.dbu)
        assert box.width() == pytest.approx(800.0, abs=0.01)  # µm
    rc, err, _ = cli("qa", out, "--job", job_path)
    assert rc == 0, err


def test_edge_distances_on_a_capped_panel_match_shapely(tmp_path):
    """The edge index on a panel with caps (many small curved holes, finer buckets than
    the reach): a point deep in a cap's keep-out, near a rim or far inside measures the
    distance shapely gives, inside within the index's reach (beyond: inf)."""
    import shapely

    from optdot.geometry.edges import EdgeIndex, signed_distances

    job = _capped(tmp_path)
    pts = np.random.default_rng(4).uniform((-0.5, -0.5), (10.5, 10.5), (3000, 2))
    pts = np.vstack([pts, [[5.0, 5.0], [2.5, 2.5], [7.55, 2.4], [0.5, 9.5]]])
    want = shapely.distance(job.domain.geometry.boundary, shapely.points(pts))
    inside = shapely.contains_xy(job.domain.geometry, pts[:, 0], pts[:, 1])
    for reach in (0.05, 2.0, 20.0):
        index = EdgeIndex.build(job.domain, reach)
        assert index.cell < reach or reach == 0.05
        d, _ = signed_distances(index, pts)
        exact = ~inside | (want < reach)
        assert np.allclose(np.abs(d[exact]), want[exact], atol=1e-9)
        assert np.array_equal(d[exact] > 0, inside[exact])
        assert np.all(d[~exact] == np.inf)


@pytest.mark.slow
def test_qa_fails_a_pattern_whose_caps_differ_from_the_job_s(tmp_path):
    """QA with the job: every cap the job asks for is printed, at its place and size; a
    pattern without them (made for the uncapped job) fails, naming a missing cap."""
    from optdot.io.patterns import load_pattern, save_pattern
    from optdot.orchestration.pipeline import generate
    from optdot.quality.gate import caps_check

    capped_path = direct_job(tmp_path, 10.0, 10.0, 0.3, leds=CAPPED)
    job = load_job(capped_path)
    save_pattern(generate(job), tmp_path / "capped.npz")
    rc, err, out = cli("qa", tmp_path / "capped.npz", "--job", capped_path)
    assert rc == 0, err
    assert any("caps over LEDs" in ln and ln.startswith("PASS") for ln in out.splitlines())
    other = tmp_path / "plain"
    other.mkdir()
    plain = direct_job(other, 10.0, 10.0, 0.3, leds={"pitch": [5.0, 5.0], "size": 0.2})
    save_pattern(generate(load_job(plain)), tmp_path / "plain.npz")
    rc, err, out = cli("qa", tmp_path / "plain.npz", "--job", capped_path)
    assert rc == 1
    assert any("caps over LEDs" in ln and ln.startswith("FAIL") for ln in out.splitlines())
    wanted = job.domain.caps
    moved = wanted.copy()
    moved[0, 0] += 0.01
    assert caps_check(wanted, wanted).passed
    assert caps_check(moved, wanted).value == 2  # one missing, one extra
    bigger = wanted.copy()
    bigger[1, 2] += 0.01
    assert caps_check(bigger, wanted).value == 2
    assert load_pattern(tmp_path / "capped.npz").outline.caps.shape == (4, 3)


@pytest.mark.slow
def test_a_csv_refuses_caps_and_a_speos_mapping_carries_them(tmp_path):
    job_path = direct_job(tmp_path, 10.0, 10.0, 0.3, leds=CAPPED)
    assert cli("generate", job_path, "-o", tmp_path / "p.npz", "-q")[0] == 0
    one_error(
        ("export", tmp_path / "p.npz", "--csv", tmp_path / "p.csv", "--no-job"), 2, "caps", "CSV"
    )
    assert not (tmp_path / "p.csv").exists()
    rc, err, _ = cli(
        "export", tmp_path / "p.npz", "--speos", tmp_path / "p.OPT3DMapping", "--no-job"
    )
    assert rc == 0, err
    from optdot.io.patterns import load_pattern

    n = load_pattern(tmp_path / "p.npz").n
    lines = (tmp_path / "p.OPT3DMapping").read_text().splitlines()
    assert int(lines[0]) == n + 4 == len(lines) - 1
    last = np.array([[float(v) for v in row.split()] for row in lines[-4:]])
    nominal = load_pattern(tmp_path / "p.npz").nominal_diameter
    assert np.allclose(last[:, 9:], 0.8 / nominal, atol=1e-6)


def test_the_film_step_acts_on_each_cell_s_whole_ink_cap_included(tmp_path):
    """One step of the film rule (no smoothing, no grid symmetry): each cell's whole
    transmission ``1 - k (capped + fill inside) / panel`` is multiplied by ``q ** 0.8``
    times one level factor, ``q`` the target over its luminance: so ``(v' / v) lum **
    0.8`` is one number over the cells the range does not clip, cells under a cap
    included (a rule that ignored the cap would step their ink wrongly)."""
    from types import SimpleNamespace

    from optdot.optics.design import GAMMA, _film_step, _shares, design_grid

    leds = {"positions": [[2.5, 2.5], [7.5, 7.5]], "size": 0.2, "cap": 0.8}
    path = direct_job(tmp_path, 10.0, 10.0, None, leds=leds)
    path.write_text(path.read_text() + "[design]\nsmoothing = 0\n")
    job = load_job(path, need_map=False)
    nx, ny, dx, dy = design_grid(job.bench)
    inside, panel, capped = _shares(job, nx, ny, dx, dy)
    live = panel > 0.5
    step = _film_step(job, nx, ny, dx, dy, (inside, panel, capped), live, np.ones((ny, nx)), live)
    phi = np.full((ny, nx), 0.3)
    lum = np.where(capped > 0, 1.3, 1.0) * 100.0  # the capped cells too bright
    sim = SimpleNamespace(counts=panel * lum, measured=np.ones((ny, nx), bool))
    new = step(phi, sim)
    k = job.backlight.ink_contrast
    lo, hi = job.design.fill_range
    v = 1 - k * (capped + phi * inside) / panel
    v2 = 1 - k * (capped + new * inside) / panel
    free = live & (inside > 0.05) & (new < hi - 1e-9)  # the emptiest sit at lo exactly
    level = (v2 / v * lum**GAMMA)[free]
    assert np.allclose(level, level[0], rtol=1e-9)
    assert (free & (capped > 0.05)).sum() == 2 and (free & (capped == 0)).sum() > 50


def test_caps_keep_the_led_grid_s_symmetry_for_the_design(tmp_path):
    """Caps sit on the LED grid: the design still averages its corrections over the pitch
    cells (a keep-out elsewhere would break the symmetry and turn it off)."""
    from optdot.optics.design import design_grid
    from optdot.optics.periodic import period_classes

    job = _capped(tmp_path, fill=None)
    assert period_classes(job.bench, *design_grid(job.bench)) is not None
    other = direct_job(tmp_path, 10.0, 10.0, None, leds={"pitch": [5.0, 5.0], "size": 0.2})
    assert period_classes(load_job(other, need_map=False), *design_grid(job.bench)) is not None


@pytest.mark.slow
def test_the_print_names_the_real_dot_under_a_cap_s_ink_and_ink_elsewhere_on_the_cap():
    """``marks.printed`` on print 1 with caps (rows ``(x, y, diameter)``) over real dots:
    on a cap's ink over a dot, that dot's index (a 3-D dot's frame is read from it); on
    its ink off every dot, ``INK``; between a graded cap's rings, ``BARE`` whatever lies
    under it; off the caps, the dots alone."""
    from optdot.geometry.shapes import KINDS, Footprints
    from optdot.optics.marks import BARE, INK, printed
    from optdot.optics.scene import dot_grid
    from optdot.pattern import Pattern

    box = (0.0, 0.0, 4.0, 3.0)
    xy = np.array([[1.0, 1.0], [1.3, 1.0], [3.0, 2.0]])
    p = Pattern(xy, 0.0, box, dots=Footprints(KINDS["circle"], np.full((3, 3), 0.1), np.zeros(3)))
    start, x, y, foot, cg = dot_grid(p, box)
    caps = np.array([[1.0, 1.0, 1.0]])  # over the first two dots, 0.5 mm in radius
    c_start, cap, c_g = cap_grid(caps, box)

    def at(px, py, rings):
        pr = (True, np.zeros((1, 1)), np.ones(4), np.zeros((1, 1)), np.ones(4), start, x, y)
        pr += (foot, cg, c_start, cap, c_g, np.array(rings), np.full((1, 3), np.nan))
        return printed.py_func(px, py, 1, pr, 0.5)

    def centre(k):
        return (float(x[k]), float(y[k])) if k >= 0 else k

    solid = [[0.0, np.inf]]
    assert centre(at(1.02, 1.01, solid)) == (1.0, 1.0)
    assert centre(at(1.31, 0.99, solid)) == (1.3, 1.0)
    assert at(1.0, 1.3, solid) == INK
    assert centre(at(3.0, 2.03, solid)) == (3.0, 2.0)
    assert at(2.0, 2.0, solid) == BARE
    assert at(1.02, 1.01, [[0.04, 0.09]]) == BARE  # between the rings (0.2-0.3 mm out)
