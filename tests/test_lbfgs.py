import numpy as np
import pytest
from scipy.optimize import minimize, rosen, rosen_der

from optdot.relax.lbfgs import minimize_lbfgs


def test_quadratic_converges_to_exact_minimum():
    rng = np.random.default_rng(0)
    a = rng.uniform(0.5, 20, 50)
    b = rng.normal(size=50)

    def fun(x, g):
        g[:] = a * (x - b)
        return 0.5 * float((a * (x - b) ** 2).sum())

    res = minimize_lbfgs(fun, np.zeros(50), memory=6, max_iter=200)
    np.testing.assert_allclose(res.x, b, atol=1e-6)


def test_rosenbrock_matches_scipy():
    x0 = np.array([-1.2, 1.0, -0.5, 0.8])

    def fun(x, g):
        g[:] = rosen_der(x)
        return float(rosen(x))

    ours = minimize_lbfgs(fun, x0, memory=6, max_iter=500)
    ref = minimize(rosen, x0, jac=rosen_der, method="L-BFGS-B", options={"maxcor": 6})
    assert ours.fun == pytest.approx(ref.fun, abs=1e-8)
    np.testing.assert_allclose(ours.x, np.ones(4), atol=1e-4)


def test_history_is_monotone_and_callback_called():
    seen = []

    def fun(x, g):
        g[:] = 2 * x
        return float((x * x).sum())

    res = minimize_lbfgs(fun, np.ones(10), max_iter=5, callback=lambda i, f: seen.append((i, f)))
    assert all(b <= a for a, b in zip(res.history, res.history[1:], strict=False))
    assert [i for i, _ in seen] == list(range(1, len(seen) + 1))


def _bowl(x, g):
    g[:] = 2 * (x - 1.0)
    return float(((x - 1.0) ** 2).sum()) + 1.0


def test_status_codes_and_messages():
    from optdot.relax.lbfgs import CONVERGED, HALTED, MAX_ITER

    res = minimize_lbfgs(_bowl, np.zeros(8), max_iter=2)
    assert res.status == MAX_ITER and res.success and "max_iter" in res.message
    res = minimize_lbfgs(_bowl, np.zeros(8), max_iter=500, gtol=1e-6)
    assert res.status == CONVERGED and res.nit < 500 and "gtol" in res.message
    g = np.empty(8)
    _bowl(res.x, g)
    assert np.abs(g).max() <= 1e-6
    res = minimize_lbfgs(_bowl, np.zeros(8), max_iter=50, callback=lambda i, f: i >= 3)
    assert res.status == HALTED and res.nit == 3 and not res.success
    assert len(res.history) == 3


def test_a_rejected_pair_never_overwrites_the_history_in_use(monkeypatch):
    """With the history full, a pair failing the curvature test was written over
    the oldest pair, which the next two-loop still used."""
    from optdot.relax import lbfgs

    real_store, real_two_loop = lbfgs._store, lbfgs._two_loop
    calls = {"store": 0}
    seen = []

    def store(s_out, y_out, *args):
        calls["store"] += 1
        sy, yy = real_store(s_out, y_out, *args)
        return (-1.0, yy) if calls["store"] == 6 else (sy, yy)  # reject the 6th pair

    def two_loop(g, S, Y, rho, slots, gamma, d):
        seen.append(sorted((S[i].tobytes(), Y[i].tobytes(), rho[i]) for i in slots))
        return real_two_loop(g, S, Y, rho, slots, gamma, d)

    monkeypatch.setattr(lbfgs, "_store", store)
    monkeypatch.setattr(lbfgs, "_two_loop", two_loop)
    a = np.linspace(1.0, 30.0, 40)
    res = lbfgs.minimize_lbfgs(
        lambda x, g: (g.__setitem__(slice(None), a * x), float(0.5 * (a * x * x).sum()))[1],
        np.ones(40),
        memory=3,
        max_iter=8,
    )
    assert res.nit == 8
    # the 6th iteration's pair was rejected: the next direction uses exactly the 3 pairs
    # the 6th used, untouched
    assert len(seen[5]) == 3 and seen[6] == seen[5]


@pytest.mark.parametrize("first_move", [0.0, 1e-3, 0.1])
def test_first_move_bounds_the_steepest_descent_step(first_move):
    """The first trial moves no coordinate farther than ``first_move`` (when the fixed
    guess ``gamma0`` would move it farther), and exactly that far along the gradient."""
    rng = np.random.default_rng(4)
    a = rng.uniform(0.5, 20, 40)
    x0 = rng.normal(size=40)
    tried = []

    def fun(x, g):
        tried.append(x.copy())
        g[:] = a * x
        return 0.5 * float((a * x * x).sum())

    res = minimize_lbfgs(fun, x0, max_iter=50, gamma0=0.25, first_move=first_move)
    g0 = a * x0
    step = 0.25 if first_move == 0.0 else min(0.25, first_move / np.abs(g0).max())
    np.testing.assert_allclose(tried[1] - x0, -step * g0, rtol=1e-12, atol=1e-15)
    assert res.fun < 1e-6 * fun(x0, np.empty(40))
