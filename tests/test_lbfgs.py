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
