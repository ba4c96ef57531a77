"""The MD baseline (Idé et al. 2003): force (1), step (2), and the method end to end."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from optdot.orchestration.pipeline import generate
from optdot.relax.md import MDForce, md_forces, md_relax
from optdot.relax.result import RelaxResult
from optdot.spatial.blocks import PairList
from optdot.spatial.cellgrid import neighbor_pairs, pairs_within

B = 0.046


def reference_forces(xy: np.ndarray, law: MDForce) -> np.ndarray:
    """Eq. (1) summed over all pairs by brute force, as we read it (see optdot.md)."""
    n = len(xy)
    f = np.zeros_like(xy)
    for i in range(n):
        for j in range(n):
            if i == j:
                continue
            diff = xy[i] - xy[j]
            d = np.hypot(*diff)
            L = law.decay * 0.5 * (law.spacing[i] + law.spacing[j])
            if d >= law.core + law.cutoff * L:
                continue
            g = 1.0 if d < law.core else np.exp(-(d - law.core) / L)
            f[i] += g * diff / d
    return f


def kernel_forces(xy: np.ndarray, law: MDForce) -> np.ndarray:
    pl = PairList.from_csr(*neighbor_pairs(xy, law.interaction_radius(), 0.0))
    return md_forces(np.ascontiguousarray(xy), law, pl)


def random_law(n: int, rng: np.random.Generator) -> MDForce:
    return MDForce(core=B, spacing=rng.uniform(0.06, 0.2, n), decay=0.25, cutoff=3.0)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_forces_match_reference_and_are_antisymmetric(seed):
    rng = np.random.default_rng(seed)
    xy = rng.random((300, 2)) * [1.2, 0.8]
    law = random_law(len(xy), rng)
    f = kernel_forces(xy, law)
    np.testing.assert_allclose(f, reference_forces(xy, law), rtol=1e-12, atol=1e-12)
    # f_ij = -f_ji: the forces of a closed system sum to zero
    assert np.abs(f.sum(axis=0)).max() < 1e-10


@pytest.mark.parametrize("d,expected", [(0.02, 1.0), (0.05, np.exp(-0.004 / 0.02)), (0.2, 0.0)])
def test_isolated_pair(d, expected):
    law = MDForce(core=B, spacing=np.array([0.08, 0.08]), decay=0.25, cutoff=3.0)  # L = 0.02
    xy = np.array([[0.5, 0.5], [0.5 + d, 0.5]])
    f = kernel_forces(xy, law)
    assert f[0] == pytest.approx([-expected, 0.0], abs=1e-12)
    assert f[1] == pytest.approx([expected, 0.0], abs=1e-12)
    res = md_relax(xy, law, (0.0, 0.0, 1.0, 1.0), 0.023, steps=5, step=0.02)
    # no net force on the pair: its centre of mass does not move
    assert res.xy.mean(axis=0) == pytest.approx(xy.mean(axis=0), abs=1e-15)
    if d < B:  # the core pushes the pair apart by exactly 2 * step * b per step
        assert res.xy[1, 0] - res.xy[0, 0] == pytest.approx(d + 5 * 2 * 0.02 * B)


def test_step_is_stable_and_resolves_a_cluster():
    rng = np.random.default_rng(4)
    xy = 0.5 + rng.normal(0, 0.03, (60, 2))  # a crowded blob with many collisions
    law = MDForce(core=B, spacing=np.full(60, 0.07))
    before = len(pairs_within(xy, B))
    res = md_relax(xy, law, (0.0, 0.0, 1.0, 1.0), 0.023, steps=300, step=0.02)
    assert before > 50
    # the one relaxation result OptDot returns too
    assert isinstance(res, RelaxResult) and res.nit == res.nfev == len(res.history) == 300
    info = res.run_info()
    assert info["md_step_mm"] == pytest.approx(0.02 * B) and "penalty" not in info
    assert len(pairs_within(res.xy, B)) == 0
    # bounded motion: the net force on a dot is at most its 59 partners' unit cores, so
    # one step moves a dot at most 59 * step * b; over the run, at most that per step
    assert max(res.history) <= 59
    one = md_relax(xy, law, (0.0, 0.0, 1.0, 1.0), 0.023, steps=1, step=0.02)
    assert np.hypot(*(one.xy - xy).T).max() <= one.history[0] * 0.02 * B + 1e-12
    moved = np.hypot(*(res.xy - xy).T)
    assert np.isfinite(res.xy).all() and moved.max() <= 300 * 59 * 0.02 * B
    assert ((res.xy >= 0.023) & (res.xy <= 1 - 0.023)).all()


def test_md_method_end_to_end(tiny_job):
    job = dataclasses.replace(
        tiny_job, optimize=dataclasses.replace(tiny_job.optimize, method="md", max_iter=80)
    )
    p = generate(job, keep_stages=True)
    assert p.meta["method"] == "md" and p.meta["iterations"] == 80
    assert len(pairs_within(p.xy, job.min_distance)) == 0
    assert not job.density.empty_mask(p.xy).any()
    # same start as OptDot: identical initial dots for the same seed
    p_opt = generate(tiny_job, keep_stages=True)
    assert np.array_equal(p.stats["initial_xy"], p_opt.stats["initial_xy"])
    before = len(pairs_within(p.stats["initial_xy"], job.min_distance))
    assert len(pairs_within(p.stats["relaxed_xy"], job.min_distance)) < before / 4
    assert np.array_equal(generate(job).xy, p.xy)
