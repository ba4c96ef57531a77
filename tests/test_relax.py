import numpy as np
import pytest

from optdot.relax import VerletPenalty, relax
from optdot.relax.circles import container_half_sides
from optdot.relax.penalty import PenaltyTerms
from optdot.testing import pairs_brute_force, penalty_reference
from tests.test_penalty import make_terms


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_verlet_list_with_movers_matches_reference(seed):
    """Along a random walk where a few dots jump far (movers) and the rest drift, the
    patched Verlet list gives exactly the brute-force penalty and gradient."""
    xy, terms = make_terms(n=400, seed=seed)
    fun = VerletPenalty(terms, skin=0.2, rebuild_fraction=0.05)
    rng = np.random.default_rng(seed)
    all_pairs = pairs_brute_force(xy, np.full(len(xy), 10.0))
    saw_movers = False
    for _ in range(25):
        g = np.empty(xy.size)
        f = fun(np.ascontiguousarray(xy).ravel(), g)
        f_ref, g_ref = penalty_reference(xy, terms, all_pairs)
        assert f == pytest.approx(f_ref, rel=1e-12, abs=1e-15)
        np.testing.assert_allclose(g.reshape(-1, 2), g_ref, rtol=1e-9, atol=1e-12)
        saw_movers |= fun.n_movers > 0
        xy = xy + rng.normal(0, 0.002, xy.shape)
        jump = rng.choice(len(xy), 3, replace=False)
        xy[jump] += rng.normal(0, 0.05, (3, 2))
    assert saw_movers
    assert 1 < fun.rebuilds < 25


def test_relax_reaches_scipy_minimum():
    from scipy.optimize import minimize

    xy, terms = make_terms(n=200, seed=3, empty=False)
    pairs = pairs_brute_force(xy, np.full(len(xy), 10.0))

    def ref(x):
        f, g = penalty_reference(x.reshape(-1, 2), terms, pairs)
        return f, g.ravel()

    f0 = ref(xy.ravel())[0]
    best = minimize(ref, xy.ravel(), jac=True, method="L-BFGS-B", options={"maxiter": 2000}).fun
    res = relax(xy, terms, max_iter=300)
    assert res.history == sorted(res.history, reverse=True)  # Armijo: never increases
    assert res.penalty - best < 0.02 * (f0 - best)


def test_the_first_step_keeps_the_list_built_at_the_start():
    """A thrown pattern's first L-BFGS step is accepted at its first trial and needs no
    rebuild of the Verlet list: the step is bounded by the skin (``first_move``). Scaled
    by a fixed guess it moved dots by many radii, was rejected, and each trial rebuilt
    the list."""
    rng = np.random.default_rng(7)
    n = 3000
    xy = rng.random((n, 2)) * [3.0, 2.0]
    r = np.full(n, 0.05)  # fill ~0.2 at 23 µm dots: the led sample's crowding
    terms = PenaltyTerms(
        radius=r,
        panel_radius=r,
        center=xy.copy(),
        half_side=container_half_sides(r, 3.5),
        box=(0.0, 0.0, 3.0, 2.0),
        dmin=0.046,
        dot_radius=0.023,
        w_hard=15.0,
        empty=np.zeros((1, 1), np.uint8),
        grid_box=(0.0, 0.0, 3.0, 2.0),
        core=np.full(n, 0.0305),
    )
    res = relax(xy, terms, max_iter=1, skin=0.3)
    assert res.nit == 1
    assert res.nfev == 2
    assert res.rebuilds == 1
    assert res.penalty < 0.9 * relax(xy, terms, max_iter=0).penalty
