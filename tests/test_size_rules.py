"""Dot-size modulation: the size rules, the count, generation with per-dot diameters, the
size fit, QA's edge-gap rule, the job options and the whole chain through every format."""

from __future__ import annotations

import math
import subprocess
import sys

import numpy as np
import pytest
from scipy.ndimage import gaussian_filter
from scipy.spatial.distance import pdist, squareform

from optdot import Pattern, generate, load_job, qa
from optdot.config.job import QAParams
from optdot.errors import JobError
from optdot.geometry.density import DensityMap
from optdot.geometry.domain import Domain
from optdot.geometry.sizes import CLAIM_TARGET, DotSizes
from optdot.relax.resize import fit_sizes

from .conftest import write_job

RANGE = {"diameter": "[0.030, 0.120]"}


def _gradient() -> np.ndarray:
    """8 x 12 cells from fill 0.05 (left) to 0.55 (right), an empty first column."""
    g = np.tile(np.linspace(0.05, 0.55, 12), (8, 1))
    g[:, 0] = 0.0
    return g


@pytest.fixture(scope="module")
def sized(tmp_path_factory):
    """A generated 30-120 µm pattern on a 150 µm pitch, with its job."""
    tmp = tmp_path_factory.mktemp("sized")
    path = write_job(
        tmp,
        _gradient(),
        domain={"width": 3.0, "height": 2.0},
        dots={**RANGE, "spacing": 0.150},
        optimize={"max_iter": 80, "seed": 5},
    )
    job = load_job(path)
    return job, generate(job), path


# --- the rules --------------------------------------------------------------------------


def test_spacing_rule_puts_dots_on_the_pitch():
    s = DotSizes(0.001, 1.0, spacing=0.15)
    rho = np.array([0.05, 0.2, 0.5, 0.8])
    d = s.raw(rho)
    n = rho / (math.pi * d * d / 4)  # dots per mm²
    pitch = np.sqrt(2.0 / (math.sqrt(3.0) * n))  # hexagonal lattice of that density
    np.testing.assert_allclose(pitch, 0.15, rtol=1e-12)


def test_claim_rule_keeps_the_claim_at_its_target():
    s = DotSizes(0.001, 1.0, gap=0.014)
    rho = np.array([0.1, 0.3, 0.5])
    d = s.raw(rho)
    np.testing.assert_allclose(rho * (1 + 0.014 / d) ** 2, CLAIM_TARGET, rtol=1e-12)
    assert np.isinf(s.raw(np.array([0.7]))[0])  # no size is enough: the range clips it


def test_cell_diameters_are_quantised_and_in_range():
    s = DotSizes(0.030, 0.120, step=0.0005, spacing=0.15)
    m = DensityMap(_gradient(), 3.0, 2.0)
    d = s.cell_diameters(m)
    assert d.min() >= 0.030 and d.max() <= 0.120
    np.testing.assert_allclose(d / 0.0005, np.round(d / 0.0005), atol=1e-9)
    assert d[0, -1] == pytest.approx(0.117)  # 0.15 sqrt(2 sqrt3 0.55 / pi) = 0.11682
    assert d[0, 1] == pytest.approx(0.0485)  # 0.15 sqrt(2 sqrt3 0.0955 / pi) = 0.04865
    assert d[0, 0] == 0.030  # an empty cell holds no dots; it gets the low end


@pytest.mark.slow
def test_count_is_each_cells_fill_over_its_own_dot_area(sized):
    job, pattern, _ = sized
    d = job.cell_diameters
    g = job.density.grid
    cell = job.density.cell_size[0] * job.density.cell_size[1]
    want = sum(
        g[i, j] * cell / (math.pi * d[i, j] ** 2 / 4)
        for i in range(g.shape[0])
        for j in range(g.shape[1])
    )
    assert job.n_dots == round(want) == pattern.n


# --- generation ---------------------------------------------------------------------------


def test_generated_sizes_keep_every_guarantee(sized):
    job, p, _ = sized
    assert p.uniform_diameter is None
    d, xy = p.diameter, p.xy
    assert d.min() >= 0.030 - 1e-12 and d.max() <= 0.120 + 1e-12
    np.testing.assert_allclose(d / 0.0005, np.round(d / 0.0005), atol=1e-6)
    dist = squareform(pdist(xy))
    np.fill_diagonal(dist, np.inf)
    need = 0.5 * (d[:, None] + d[None, :])  # brute force: edges may touch, never overlap
    assert (dist >= need).all()
    r = 0.5 * d
    assert (xy[:, 0] >= r).all() and (xy[:, 0] <= 3.0 - r).all()
    assert (xy[:, 1] >= r).all() and (xy[:, 1] <= 2.0 - r).all()
    assert (xy[:, 0] > 0.25).all()  # the empty first column
    want = float(job.density.grid.sum()) * job.density.cell_size[0] * job.density.cell_size[1]
    assert p.areas.sum() == pytest.approx(want, rel=5e-3)
    m = qa(p, job).metrics
    assert m["pairs_below_collision"] == 0 and m["protruding"] == 0 and m["in_empty_cells"] == 0


def test_sizes_follow_the_fill(sized):
    job, p, _ = sized
    left, right = p.diameter[p.xy[:, 0] < 1.0], p.diameter[p.xy[:, 0] > 2.5]
    assert np.median(right) > 1.8 * np.median(left)
    # each dot within the fit's freedom (15 %) of its start cell's rule diameter, give or
    # take one step and a cell of drift
    rule = job.cell_diameters.ravel()[job.density.cell_index(p.xy)]
    assert np.median(np.abs(p.diameter / rule - 1)) < 0.1


def test_same_job_same_sizes(sized):
    job, p, _ = sized
    again = generate(job)
    assert np.array_equal(again.xy, p.xy) and np.array_equal(again.diameter, p.diameter)


def test_explicit_diameter_grid(tmp_path):
    dg = np.full((2, 3), 0.040)
    dg[:, 2] = 0.080
    np.savetxt(tmp_path / "d.csv", dg, delimiter=",")
    path = write_job(
        tmp_path,
        np.full((4, 6), 0.3),
        domain={"width": 3.0, "height": 2.0},
        dots={**RANGE, "diameter_grid": '"d.csv"'},
    )
    job = load_job(path)
    p = generate(job)
    right = p.xy[:, 0] > 2.0 + 0.2  # well inside the last third (dots may drift a little)
    left = p.xy[:, 0] < 2.0 - 0.2
    assert set(np.round(p.diameter[right], 6)) <= {0.08, 0.04}
    assert np.median(p.diameter[right]) == 0.08 and set(np.round(p.diameter[left], 6)) == {0.04}


# --- the size fit -------------------------------------------------------------------------


def _blur_error(xy, d, rho, box=10.0, sigma=0.5, px=0.05):
    n = int(box / px)
    c, _, _ = np.histogram2d(
        xy[:, 1], xy[:, 0], bins=(n, n), range=((0, box), (0, box)), weights=math.pi / 4 * d * d
    )
    c = gaussian_filter(c / (px * px), sigma / px, mode="constant")
    t = gaussian_filter(np.full((n, n), rho), sigma / px, mode="constant")
    k = int(2 * sigma / px)
    return float(np.sqrt(np.mean((c / t - 1)[k:-k, k:-k] ** 2)))


def test_fit_flattens_the_blurred_coverage_and_keeps_the_total():
    rng = np.random.default_rng(1)
    xy = rng.uniform(0, 10, (4000, 2))  # Poisson: a harsh case, 8 % blurred error
    d0 = np.full(4000, 0.1)
    rho = 4000 * math.pi / 4 * 0.01 / 100
    sizes = DotSizes(0.05, 0.2, step=1e-6)
    d1 = fit_sizes(
        xy, d0, sizes, DensityMap(np.full((10, 10), rho), 10, 10), Domain.rect(0, 0, 10, 10), 0.5
    )
    before, after = _blur_error(xy, d0, rho), _blur_error(xy, d1, rho)
    assert after < 0.5 * before
    assert np.sum(d1**2) == pytest.approx(np.sum(d0**2), rel=1e-4)
    # within the fit's band (give or take the total's rescaling) and the range
    assert d1.min() >= 0.1 / 1.15 * 0.995 and d1.max() <= 0.1 * 1.15 * 1.005


def test_fit_leaves_dots_at_an_end_of_the_range():
    rng = np.random.default_rng(2)
    xy = rng.uniform(0, 4, (600, 2))
    d0 = np.where(xy[:, 0] < 2, 0.05, 0.08)  # left half at the range's low end
    m = DensityMap(np.full((4, 4), 0.2), 4, 4)
    d1 = fit_sizes(xy, d0, DotSizes(0.05, 0.2, step=1e-6), m, Domain.rect(0, 0, 4, 4), 0.5)
    assert np.array_equal(d1[xy[:, 0] < 2], d0[xy[:, 0] < 2])
    assert not np.array_equal(d1[xy[:, 0] >= 2], d0[xy[:, 0] >= 2])


# --- QA by edge gaps ----------------------------------------------------------------------


def test_qa_counts_pairs_by_edge_gap_like_brute_force():
    rng = np.random.default_rng(3)
    xy = np.round(rng.uniform(0.2, 2.8, (700, 2)), 6)
    d = rng.choice([0.030, 0.060, 0.110], 700)
    p = Pattern(xy, d, (0.0, 0.0, 3.0, 3.0))
    dist = squareform(pdist(xy))
    mean = 0.5 * (d[:, None] + d[None, :])
    iu = np.triu_indices(700, 1)
    for gap in (0.0, 0.014, 0.05):
        m = qa(p, close_gap=gap).metrics
        assert m["pairs_below_close"] == int((dist < mean + gap)[iu].sum())
        assert m["close_gap_mm"] == gap
    assert qa(p).metrics["pairs_below_collision"] == int((dist < mean)[iu].sum())


def test_centre_distances_are_refused_for_varying_sizes(sized):
    _, p, _ = sized
    with pytest.raises(JobError, match="edge gaps"):
        qa(p, close=0.06)


def test_close_gap_on_one_size_is_the_centre_rule(tiny_pattern):
    a = qa(tiny_pattern).metrics
    from optdot.quality.gate import run_qa

    b = run_qa(tiny_pattern, None, QAParams(close_gap=0.014), 0.046).metrics
    assert a["close_distance_mm"] == 0.060 and b["close_distance_mm"] == pytest.approx(0.060)
    assert a["pairs_below_close"] == b["pairs_below_close"]


# --- job options ----------------------------------------------------------------------


@pytest.mark.parametrize(
    "dots, other, message",
    [
        ({"spacing": 0.15}, {}, "needs a diameter range"),
        ({**RANGE, "spacing": 0.01}, {}, "dots.spacing"),
        ({"diameter": "[0.12, 0.03]"}, {}, "low < high"),
        ({"diameter": "[0.03, 0.12, 0.2]"}, {}, "number or"),
        ({**RANGE, "diameter_step": 0.5}, {}, "diameter_step"),
        ({**RANGE, "spacing": 0.15, "diameter_grid": '"d.csv"'}, {}, "not both"),
        ({**RANGE}, {"qa": {"close_distance": 0.06}}, "qa.close_gap"),
        ({**RANGE}, {"optimize": {"method": '"md"'}}, "one dot size"),
        ({"diameter": "[0.03, 20.0]"}, {}, "0.001 <= low < high <= 10"),
    ],
)
def test_bad_size_options_are_one_line(tmp_path, dots, other, message):
    path = write_job(
        tmp_path, _gradient(), domain={"width": 3.0, "height": 2.0}, dots=dots, **other
    )
    with pytest.raises(JobError, match=message):
        load_job(path)


def test_diameter_grid_out_of_range_names_the_cell(tmp_path):
    np.savetxt(tmp_path / "d.csv", [[0.04, 0.2]], delimiter=",")
    path = write_job(
        tmp_path,
        _gradient(),
        domain={"width": 3.0, "height": 2.0},
        dots={**RANGE, "diameter_grid": '"d.csv"'},
    )
    with pytest.raises(JobError, match=r"d.csv: dots.diameter_grid: row 1, column 2"):
        load_job(path)


def _mixed_pairs_too_close(xy, d, gap):
    """Pairs whose centres are closer than their mean diameter + gap (brute force)."""
    dist = squareform(pdist(xy))
    limit = 0.5 * (d[:, None] + d[None, :]) + gap
    np.fill_diagonal(dist, np.inf)
    return int((dist < limit - 1e-9).sum() // 2)


def test_tiled_run_with_varying_sizes_calls_the_same_stages(tmp_path):
    """Size-modulated jobs tile (they were refused): the tiles hold exactly the job's dot
    count, no pair is closer than its mixed-pair limit (brute force), the sizes are
    fitted (not the rule's cell sizes) within the range, and the coverage is as good as
    one process's."""
    from optdot.orchestration.pipeline import generate_tiled, use_tiles
    from optdot.orchestration.tiling.plan import plan_tiles
    from optdot.orchestration.tiling.run import InProcess

    path = write_job(
        tmp_path,
        np.tile(_gradient(), (1, 3)),
        domain={"width": 9.0, "height": 2.6},
        dots={**RANGE, "spacing": 0.150},
        optimize={"max_iter": 60, "seed": 3},
    )
    job = load_job(path)
    assert use_tiles(job, "on")
    plan = plan_tiles(job, side=3.0)
    assert plan.count == 3
    p = generate_tiled(job, plan=plan, executor=InProcess())
    assert p.n == job.n_dots and p.uniform_diameter is None
    assert _mixed_pairs_too_close(p.xy, p.diameter, job.optimize.gap) == 0
    assert p.diameter.min() >= 0.030 and p.diameter.max() <= 0.120
    rule = job.diameters_at(job.density.cell_index(p.xy))
    assert np.mean(p.diameter != rule) > 0.3  # fitted, also in the tiles
    one = generate(job)
    r_tiled, r_one = qa(p, job), qa(one, job)
    assert r_tiled.passed, r_tiled.failures
    tiled, single = (r.metrics["coverage_rel_rms_smoothed"] for r in (r_tiled, r_one))
    assert tiled < 1.5 * single, (tiled, single)


# --- the whole chain --------------------------------------------------------------------


@pytest.mark.slow
def test_cli_exports_every_format_and_qa_agrees_on_each(sized, tmp_path):
    from optdot.exporters.readback import read_any

    _, p, job_path = sized
    out = {f: tmp_path / f"s.{f}" for f in ("gds", "oas", "dxf", "csv")}
    cmd = [
        sys.executable,
        "-P",
        "-m",
        "optdot",
        "generate",
        str(job_path),
        "-o",
        str(tmp_path / "s.npz"),
    ]
    assert subprocess.run(cmd, capture_output=True).returncode == 0
    args = [x for f, path in out.items() for x in (f"--{f}", str(path))]
    run = subprocess.run(
        [
            sys.executable,
            "-P",
            "-m",
            "optdot",
            "export",
            str(tmp_path / "s.npz"),
            "--job",
            str(job_path),
            *args,
        ],
        capture_output=True,
        text=True,
    )
    assert run.returncode == 0, run.stderr
    ref = qa(read_any(tmp_path / "s.npz"), load_job(job_path)).metrics
    o = np.lexsort(p.xy.T[::-1])
    for fmt, path in out.items():
        back = read_any(path)
        b = np.lexsort(back.xy.T[::-1])
        np.testing.assert_allclose(back.xy[b], p.xy[o], atol=1e-9)
        np.testing.assert_allclose(back.diameter[b], p.diameter[o], atol=1e-6)  # 1 nm dbu
        js = tmp_path / f"{fmt}.json"
        run = subprocess.run(
            [
                sys.executable,
                "-P",
                "-m",
                "optdot",
                "qa",
                str(path),
                "--job",
                str(job_path),
                "--json",
                str(js),
                "-q",
            ],
            capture_output=True,
            text=True,
        )
        assert run.returncode == 0, run.stderr
        import json

        m = json.loads(js.read_text())["metrics"]
        for key in (
            "pairs_below_collision",
            "pairs_below_close",
            "protruding",
            "in_empty_cells",
            "dots",
        ):
            assert m[key] == ref[key], (fmt, key)
        assert m["coverage_rel_rms_smoothed"] == pytest.approx(
            ref["coverage_rel_rms_smoothed"], rel=1e-6
        )


def test_core_targets_keep_the_edge_gap_whatever_the_sizes():
    from optdot.relax.formulation import PRESETS, Problem

    m = DensityMap(np.full((2, 2), 0.3), 2.0, 2.0)
    prob = Problem(Domain.rect(0, 0, 2, 2), m, 0.015, 0.030, close_target=0.044)
    xy = np.array([[0.5, 0.5], [1.5, 1.5], [0.5, 1.5]])
    rho = np.full(3, 0.3)
    d = np.array([0.030, 0.075, 0.120])
    t = PRESETS["optdot"].terms(prob, xy, rho, diameters=d)
    same = PRESETS["optdot"].terms(prob, xy, rho, diameters=np.full(3, 0.030))
    # every size's core is its own radius plus the same half gap as the smallest dot's
    # (where the hexagonal spacing allows that gap at all, as it does at fill 0.3 here)
    gap = 2 * same.core_radius[0] - 0.030
    np.testing.assert_allclose(t.core_radius - d / 2, gap / 2, atol=1e-12)
    # circles: r = r0_i sqrt(pi / (sqrt3 rho)) x 1.05, each with its own r0
    np.testing.assert_allclose(t.radius / same.radius, d / 0.030, rtol=1e-12)


def test_guarantee_pass_pushes_a_mixed_pair_to_its_own_distance():
    from optdot.relax.legalize import MARGIN, check_guarantee, legalize

    m = DensityMap(np.full((1, 1), 0.3), 1.0, 1.0)
    dom = Domain.rect(0, 0, 1, 1)
    xy = np.array([[0.50, 0.5], [0.55, 0.5], [0.2, 0.2]])
    d = np.array([0.030, 0.120, 0.030])
    home = m.cell_index(xy)
    before = check_guarantee(xy, m, dom, d / 2, d)
    assert before.collisions == 1
    leg = legalize(xy, m, home, dom, d / 2, d)
    dist = np.hypot(*(leg.xy[0] - leg.xy[1]))
    assert 0.075 <= dist <= 0.075 + 2 * MARGIN  # (30 + 120) / 2 µm, not more
    assert check_guarantee(leg.xy, m, dom, d / 2, d).ok
    np.testing.assert_array_equal(leg.xy[2], xy[2])  # a dot with room is left alone


@pytest.mark.parametrize("fmt", ["gds", "oas"])
def test_klayout_reads_every_generated_diameter(sized, tmp_path, fmt):
    kdb = pytest.importorskip("klayout.db")
    from optdot import exporters

    _, p, _ = sized
    path = tmp_path / f"s.{fmt}"
    exporters.write(p, fmt, path)
    layout = kdb.Layout()
    layout.read(str(path))
    got = []
    for inst in layout.top_cell().each_inst():
        name = layout.cell(inst.cell_index).name
        assert name.startswith("DOT_")
        width = layout.cell(inst.cell_index).bbox().width()  # dbu = 1 nm
        # the polygon lies within the 10 nm export tolerance inside its circle
        assert 0 <= int(name[4:]) - width <= 20
        for t in inst.cell_inst.each_trans():
            got.append((t.disp.x, t.disp.y, int(name[4:])))
    got = np.array(sorted(got))
    want = np.array(
        sorted(
            zip(
                *np.round(p.xy.T * 1e6).astype(np.int64),
                np.round(p.diameter * 1e6).astype(int),
                strict=True,
            )
        )
    )
    np.testing.assert_array_equal(got, want)  # every dot, position and diameter to 1 nm
