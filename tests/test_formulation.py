"""Formulation options: radius rule, hard core (share, floor, cap), polydispersity, stages."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from optdot.pipeline import generate
from optdot.relax.circles import circle_radius, hex_radius
from optdot.relax.formulation import PRESETS, Formulation, formulation_of
from optdot.relax.optdot import RelaxSettings, relax_staged
from optdot.spatial.cellgrid import pairs_within
from optdot.stages import problem_of


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


def test_containers_are_sized_for_at_least_the_fill_floor(tmp_path):
    """Where a map falls to zero (a film's clear islands, read bilinearly) the fill near
    the rim reaches 1e-5 and the circle of §3.3 tens of millimetres: containers are
    sized for :data:`CONTAINER_FILL_FLOOR` at least, above it by the rule, and the
    phantoms' reach (twice the largest circle) is held with them."""
    from optdot.config.schema import load_job
    from optdot.relax.formulation import CONTAINER_FILL_FLOOR
    from optdot.stages.beyond_walls import phantom_reach

    form = Formulation()
    rho = np.array([1e-7, 1e-4, CONTAINER_FILL_FLOOR, 0.02, 0.3])
    got = form.radii(rho, 0.023, 1)
    want = circle_radius(np.maximum(rho, CONTAINER_FILL_FLOOR), 0.023) * form.radius_factor
    assert np.allclose(got, want) and got[0] == got[1] == got[2] > got[3] > got[4]
    assert got[3] == pytest.approx(circle_radius(np.array([0.02]), 0.023)[0] * form.radius_factor)
    grid = np.full((8, 8), 0.3)
    grid[3:5, 3:5] = 0.0  # a clear island; bilinear reads 1e-6 by its rim
    grid[2, 3] = 1e-6
    np.savetxt(tmp_path / "m.csv", grid, delimiter=",")
    (tmp_path / "job.toml").write_text(
        '[domain]\nwidth = 4.0\nheight = 4.0\n[density]\ngrid = "m.csv"\n'
        'interpolation = "linear"\n[dots]\ndiameter = 0.046\n'
    )
    job = load_job(tmp_path / "job.toml")
    top = 2 * form.radii(np.array([CONTAINER_FILL_FLOOR]), 0.023, 0)[0]
    assert phantom_reach(job, form) == pytest.approx(top * (1 + form.polydispersity))


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
