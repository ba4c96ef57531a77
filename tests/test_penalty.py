import numpy as np
import pytest
from scipy.optimize import approx_fprime

from optdot.relax.circles import circle_radius, container_half_sides
from optdot.relax.penalty import PenaltyTerms, penalty_fast
from optdot.spatial.blocks import PairList
from optdot.spatial.cellgrid import neighbor_pairs
from optdot.testing import pairs_brute_force, penalty_reference


def make_terms(n=120, seed=0, w_hard=10.0, empty=True):
    rng = np.random.default_rng(seed)
    xy = rng.random((n, 2)) * [1.0, 0.8]
    rho = rng.uniform(0.1, 0.6, n)
    r = circle_radius(rho, 0.023)
    mask = np.zeros((4, 5), np.uint8)
    if empty:
        mask[0, :2] = 1
        mask[2, 3] = 1
    terms = PenaltyTerms(
        radius=r,
        panel_radius=0.7 * r,
        center=xy + rng.normal(0, 0.05, xy.shape),
        half_side=container_half_sides(r, 4.0) * 0.5,
        box=(0.0, 0.0, 1.0, 0.8),
        dmin=0.046,
        dot_radius=0.023,
        w_hard=w_hard,
        empty=mask,
        grid_box=(0.0, 0.0, 0.2, 0.2),
    )
    return xy, terms


def fast(xy, terms):
    reff = np.maximum(terms.radius, terms.dmin / 2)
    ptr, nbr = neighbor_pairs(xy, reff, 0.0)
    g = np.empty_like(xy)
    return penalty_fast(np.ascontiguousarray(xy), terms, PairList.from_csr(ptr, nbr), g), g


@pytest.mark.parametrize("w_hard,empty", [(0.0, False), (10.0, True), (10.0, False)])
def test_fast_matches_reference(w_hard, empty):
    xy, terms = make_terms(w_hard=w_hard, empty=empty)
    f1, g1 = fast(xy, terms)
    f2, g2 = penalty_reference(xy, terms, pairs_brute_force(xy, np.full(len(xy), 1.0)))
    assert f1 > 0
    assert f1 == pytest.approx(f2, rel=1e-12)
    np.testing.assert_allclose(g1, g2, rtol=1e-9, atol=1e-12)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_gradient_matches_finite_differences(seed):
    xy, terms = make_terms(n=60, seed=seed)

    def f(x):
        return fast(x.reshape(-1, 2), terms)[0]

    x = xy.ravel()
    g = fast(xy, terms)[1].ravel()
    num = approx_fprime(x, f, 1e-8)
    # piecewise quadratic: away from kinks the finite difference is exact to O(eps)
    assert np.abs(g - num).max() < 1e-5 * max(1.0, np.abs(g).max())


def test_penalty_zero_when_feasible():
    xy = np.array([[0.3, 0.3], [0.6, 0.3]])
    r = np.array([0.1, 0.1])
    terms = PenaltyTerms(r, r, xy.copy(), r * 2, (0, 0, 1, 1), 0.046, 0.023, 10.0)
    assert fast(xy, terms)[0] == 0.0


def test_each_term_pushes_the_right_way():
    r = np.array([0.1, 0.1])
    # overlapping pair: gradient pushes them apart
    xy = np.array([[0.4, 0.5], [0.5, 0.5]])
    terms = PenaltyTerms(r, r, xy.copy(), r * 2, (0, 0, 1, 1), 0.046, 0.023, 0.0)
    f, g = fast(xy, terms)
    assert f == pytest.approx(0.1**2)
    assert g[0, 0] > 0 and g[1, 0] < 0  # descent moves 0 left, 1 right
    # protruding from the panel at x = 0.05 < r
    xy = np.array([[0.05, 0.5], [0.7, 0.5]])
    terms = PenaltyTerms(r, r, xy.copy(), r * 2, (0, 0, 1, 1), 0.046, 0.023, 0.0)
    f, g = fast(xy, terms)
    assert f == pytest.approx(0.05**2) and g[0, 0] < 0
    # outside its container (centre moved 0.15 > h - r = 0.1)
    terms = PenaltyTerms(
        r, r, np.array([[0.5, 0.5], [0.7, 0.5]]), r * 2, (0, 0, 1, 1), 0.046, 0.023, 0.0
    )
    xy = np.array([[0.35, 0.5], [0.7, 0.5]])
    f, g = fast(xy, terms)
    assert f == pytest.approx(0.05**2) and g[0, 0] < 0


def with_phantoms(xy, terms, seed=5, outline=None):
    """``terms`` with 40 phantoms added: beyond the panel's edges, in and around the zero
    cells, and some that strayed into the allowed region (their term acts)."""
    rng = np.random.default_rng(seed)
    x0, y0, x1, y1 = terms.box
    beyond = np.column_stack([rng.uniform(x0 - 0.05, x0 + 0.04, 14), rng.uniform(y0, y1, 14)])
    below = np.column_stack([rng.uniform(x0, x1, 14), rng.uniform(y0 - 0.05, y0 + 0.04, 14)])
    zero = np.column_stack([rng.uniform(0.55, 0.85, 12), rng.uniform(0.35, 0.65, 12)])
    p = np.concatenate([beyond, below, zero])
    n, m = len(xy), len(p)
    r = np.concatenate([terms.radius, rng.uniform(0.03, 0.05, m)])
    ph = np.zeros(n + m, bool)
    ph[n:] = True
    t = PenaltyTerms(
        radius=r,
        panel_radius=np.concatenate([terms.panel_radius, r[n:]]),
        center=np.concatenate([terms.center, p + rng.normal(0, 0.02, p.shape)]),
        half_side=container_half_sides(r, 4.0) * 0.5,
        box=terms.box,
        dmin=terms.dmin,
        dot_radius=terms.dot_radius,
        w_hard=terms.w_hard,
        empty=terms.empty,
        grid_box=terms.grid_box,
        margin=0.004,
        edges=terms.edges,
        phantom=ph,
    )
    return np.concatenate([xy, p]), t


@pytest.mark.parametrize("empty", [True, False])
def test_phantoms_fast_matches_reference(empty):
    xy, terms = with_phantoms(*make_terms(w_hard=10.0, empty=empty))
    f1, g1 = fast(xy, terms)
    f2, g2 = penalty_reference(xy, terms, pairs_brute_force(xy, np.full(len(xy), 1.0)))
    assert f1 == pytest.approx(f2, rel=1e-12)
    np.testing.assert_allclose(g1, g2, rtol=1e-9, atol=1e-12)
    # the phantoms' own term acts: some strayed inside, and they have no hard core
    ph = terms.phantom
    assert np.abs(g1[ph]).max() > 0
    assert (terms.core_radius[ph] < 0).all()


def test_phantom_gradient_matches_finite_differences():
    xy, terms = with_phantoms(*make_terms(n=60, seed=1))

    def f(x):
        return fast(x.reshape(-1, 2), terms)[0]

    g = fast(xy, terms)[1].ravel()
    num = approx_fprime(xy.ravel(), f, 1e-8)
    assert np.abs(g - num).max() < 1e-5 * max(1.0, np.abs(g).max())
