"""Formulation options: radius rule, hard core (share, floor, cap), polydispersity, stages."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from optdot.orchestration.job_settings import problem_of
from optdot.orchestration.pipeline import generate
from optdot.relax.circles import circle_radius, hex_radius
from optdot.relax.formulation import PRESETS, Formulation, formulation_of
from optdot.relax.optdot import RelaxSettings, relax_staged
from optdot.spatial.cellgrid import pairs_within


def test_core_share_floor_and_cap(tiny_job):
    rho = np.array([0.05, 0.3, 0.45, 0.55])
    xy = np.tile([[1.0, 1.0]], (4, 1))
    form = Formulation(w_hard=15.0, core_share=0.93, core_floor=0.059, core_cap=0.064)
    core = form.terms(problem_of(tiny_job), xy, rho).core_radius
    want = 0.93 * hex_radius(rho, 0.023)
    # sparse: capped at 64 µm; mid: 0.93 of the spacing; densest: below the floor -> dmin/2
    assert core[0] == pytest.approx(0.032)
    assert core[2] == pytest.approx(want[2])
    assert 2 * want[3] < 0.059 and core[3] == pytest.approx(0.023)
    assert (core >= 0.023).all()


def test_default_core_clears_the_close_distance(tiny_job):
    """Default: 0.93 a clamped to 61..64 µm where a >= 61 / 0.98 µm, else the diameter;
    never a core in (46, 61) µm, which would pin pairs just under 60 µm."""
    rho = np.linspace(0.02, 0.6, 300)
    xy = np.tile([[1.0, 1.0]], (len(rho), 1))
    a = 2 * hex_radius(rho, 0.023)
    dist = 2 * PRESETS["optdot"].terms(problem_of(tiny_job), xy, rho).core_radius
    wide = a * 0.98 >= 0.061
    assert np.allclose(dist[wide], np.clip(0.93 * a[wide], 0.061, 0.064))
    assert np.allclose(dist[~wide], 0.046)
    assert wide.any() and (~wide).any()


def test_core_lengths_scale_with_the_close_distance(tiny_job):
    """A job that calls 80 µm close gets floor, cap and gap scaled by 80 / 60."""
    rho = np.linspace(0.02, 0.6, 300)
    xy = np.tile([[1.0, 1.0]], (len(rho), 1))
    job = dataclasses.replace(tiny_job, qa=dataclasses.replace(tiny_job.qa, close_distance=0.080))
    a = 2 * hex_radius(rho, 0.023)
    dist = 2 * PRESETS["optdot"].terms(problem_of(job), xy, rho).core_radius
    k = 0.080 / 0.060
    wide = a * 0.98 >= k * 0.061
    assert np.allclose(dist[wide], np.clip(0.93 * a[wide], k * 0.061, k * 0.064))
    assert np.allclose(dist[~wide], 0.046)


def test_radius_rule_and_polydispersity(tiny_job):
    rho = np.full(2000, 0.3)
    base = circle_radius(rho, 0.023)
    assert np.allclose(Formulation(radius_factor=1.05).radii(rho, 0.023, 1), 1.05 * base)
    ramp = Formulation(dense_factor=0.8).radii(np.array([0.2, 0.375, 0.6]), 0.023, 1)
    ref = circle_radius(np.array([0.2, 0.375, 0.6]), 0.023)
    assert np.allclose(ramp / ref, [1.0, 0.9, 0.8])
    poly = Formulation(polydispersity=0.1).radii(rho, 0.023, 7)
    assert set(np.round(poly / base * np.sqrt(1.01), 9)) == {0.9, 1.1}
    assert np.mean(poly**2) == pytest.approx(np.mean(base**2), rel=0.02)  # mean area kept
    assert np.array_equal(poly, Formulation(polydispersity=0.1).radii(rho, 0.023, 7))


def test_a_dip_s_containers_take_their_neighbourhood_s_fill_and_a_sparse_map_keeps_its_own(
    tmp_path,
):
    """Where a map dips towards zero (a designed cell of 1e-6 among cells of 0.3, read
    bilinearly) §3.3's circle would reach tens of millimetres: the containers there are
    sized for the neighbourhood's mean, at most :data:`CONTAINER_FILL_FLOOR`, and the
    phantoms' reach (twice the largest circle) with them: under 2 mm. A map sparse over a wide
    region keeps its own fill, to the bit (a uniform 0.5 % map sized for 1 % orders:
    psi6 0.11), and so does the sparse half of a map beside a dense half, away from it."""
    from optdot.config.schema import load_job
    from optdot.orchestration.job_settings import containers, stage_settings
    from optdot.relax.formulation import CONTAINER_FILL_FLOOR as FLOOR
    from optdot.stages.beyond_walls import phantom_reach

    def job_of(grid, name):
        np.savetxt(tmp_path / f"{name}.csv", grid, delimiter=",")
        (tmp_path / f"{name}.toml").write_text(
            f'[domain]\nwidth = 8.0\nheight = 8.0\n[density]\ngrid = "{name}.csv"\n'
            'interpolation = "linear"\n[dots]\ndiameter = 0.046\n'
        )
        return load_job(tmp_path / f"{name}.toml")

    form = Formulation()
    dip = np.full((16, 16), 0.3)
    dip[6:9, 6:9] = 1e-6  # 1.5 mm across: the centre reads 1e-6, its circle 32 mm
    job = job_of(dip, "dip")
    at = np.array([[3.75, 3.75], [1.0, 1.0]])  # the dip's centre, the open map
    own = job.density.at(at)
    got = stage_settings(job).container_fill(at)
    assert own[0] == pytest.approx(1e-6) and 1e3 * own[0] < got[0] <= FLOOR
    assert got[1] == own[1] == pytest.approx(0.3)
    low = containers(job).lowest()
    assert 1e-3 < low <= FLOOR
    reach = 2 * form.radii(np.array([low]), 0.023, 0)[0] * (1 + form.polydispersity)
    assert phantom_reach(stage_settings(job, form)) == pytest.approx(reach) and reach < 2.0
    from optdot.orchestration.tiling.plan import max_spacing
    from optdot.relax.circles import hex_radius

    # a tiled run's seams are sized by the same fills (1e-6 asked for seams of 40 mm)
    assert max_spacing(job) == pytest.approx(2 * hex_radius(np.array([low]), 0.023)[0])
    sparse = job_of(np.full((16, 16), 0.005), "sparse")
    xy = np.random.default_rng(2).uniform(0, 8, (500, 2))
    assert np.array_equal(stage_settings(sparse).container_fill(xy), sparse.density.at(xy))
    assert max_spacing(sparse) == 2 * hex_radius(np.array([0.005]), 0.023)[0]
    half = np.full((16, 32), 0.3)
    half[:, :16] = 0.004  # 4 mm of 0.4 % beside 0.3
    split = job_of(half, "half")
    far = np.array([[0.5, 4.0], [1.5, 2.0]])  # over 2 mm from the dense half
    assert np.array_equal(stage_settings(split).container_fill(far), split.density.at(far))


@pytest.mark.slow
def test_stages_split_the_iterations(tiny_job):
    job = dataclasses.replace(
        tiny_job, optimize=dataclasses.replace(tiny_job.optimize, max_iter=30, ftol=0.0)
    )
    form = Formulation(stages=((0.5, 1.15), (0.5, 0.9)))
    p = generate(job, formulation=form)
    assert p.meta["iterations"] == 30 and len(p.stats["history"]) == 30
    assert len(pairs_within(p.xy, job.min_distance)) == 0
    xy0 = np.array([[1.0, 1.0], [1.01, 1.0]])
    calls = []
    settings = RelaxSettings(max_iter=30)
    res = relax_staged(
        problem_of(job), form, xy0, np.array([0.3, 0.3]), settings, lambda i, f: calls.append(i)
    )
    assert calls == sorted(calls) and calls[-1] <= 30
    # one result over both stages: counts summed, history of every iteration
    assert res.nit == len(res.history) == len(calls) and res.nfev >= res.nit
    assert res.run_info()["iterations"] == res.nit and "penalty" in res.run_info()


def test_job_overrides_reach_the_formulation(tiny_job):
    job = dataclasses.replace(
        tiny_job,
        optimize=dataclasses.replace(tiny_job.optimize, radius_factor=0.8, container_factor=5.0),
    )
    opt = job.optimize
    form = formulation_of(opt.formulation, opt.radius_factor, opt.container_factor)
    assert form.radius_factor == 0.8 and form.container_factor == 5.0
    assert formulation_of(tiny_job.optimize.formulation) == PRESETS["optdot"]
    # and the pipeline uses them: a smaller radius factor gives smaller circles
    rho = np.array([0.3])
    xy = np.array([[1.0, 1.0]])
    assert (
        form.terms(problem_of(job), xy, rho).radius[0]
        < PRESETS["optdot"].terms(problem_of(tiny_job), xy, rho).radius[0]
    )
