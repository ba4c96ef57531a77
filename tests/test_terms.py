"""Each penalty term on its own: value and gradient against finite differences, and the
composed kernel against the sum of its terms."""

import numpy as np
import pytest
from scipy.optimize import approx_fprime

from optdot.geometry.domain import Domain
from optdot.geometry.edges import EdgeIndex, edge_args
from optdot.relax.terms import (
    box_penalty,
    container_penalty,
    edge_penalty,
    empty_penalty,
    pair_penalty,
)
from optdot.testing import pairs_brute_force, penalty_reference
from tests.test_penalty import fast, make_terms

EPS = 1e-7


def check_fd(fn, xy, rtol=1e-4, atol=1e-8):
    """``fn(xy) -> (f, grad)``: the gradient equals central finite differences."""
    f, g = fn(xy)
    assert f > 0, "the test point must activate the term"
    num = approx_fprime(xy.ravel(), lambda x: fn(x.reshape(-1, 2))[0], EPS)
    np.testing.assert_allclose(g.ravel(), num, rtol=rtol, atol=atol)


def test_pair_term_gradient():
    rng = np.random.default_rng(0)
    xy = rng.random((40, 2)) * 0.3
    r = rng.uniform(0.02, 0.04, 40)
    core = np.full(40, 0.03)
    pairs = pairs_brute_force(xy, np.full(40, 1.0))
    check_fd(lambda p: pair_penalty(p, r, core, 12.0, pairs), xy, atol=1e-6)


def test_pair_term_value_by_hand():
    xy = np.array([[0.0, 0.0], [0.03, 0.04]])  # d = 0.05
    f, g = pair_penalty(xy, np.array([0.03, 0.03]), np.array([0.03, 0.03]), 2.0, [[0, 1]])
    assert f == pytest.approx(0.01**2 + 2.0 * 0.01**2)
    # the gradient pushes the dots apart along their axis
    assert g[0] @ np.array([0.03, 0.04]) > 0 and np.allclose(g[0], -g[1])


@pytest.mark.parametrize("weight,margin", [(1.0, 0.0), (15.0, 0.01)])
def test_box_term_gradient(weight, margin):
    rng = np.random.default_rng(1)
    xy = np.concatenate([rng.random((30, 2)) * [1.0, 0.8], [[0.01, 0.4], [0.99, 0.79]]])
    rad = rng.uniform(0.02, 0.05, len(xy))
    check_fd(lambda p: box_penalty(p, rad, (0.0, 0.0, 1.0, 0.8), margin, weight), xy)
    f, _ = box_penalty(np.array([[0.01, 0.4]]), [0.03], (0.0, 0.0, 1.0, 0.8), margin, weight)
    assert f == pytest.approx(weight * (0.03 + margin - 0.01) ** 2)


def test_container_term_gradient():
    rng = np.random.default_rng(2)
    center = rng.random((30, 2))
    xy = center + rng.normal(0, 0.05, center.shape)
    r = rng.uniform(0.02, 0.04, 30)
    half = np.full(30, 0.05)
    check_fd(lambda p: container_penalty(p, r, center, half), xy)
    f, _ = container_penalty(np.array([[0.1, 0.0]]), [0.03], np.zeros((1, 2)), [0.1])
    assert f == pytest.approx(0.03**2)


def test_edge_term_gradient_on_an_outline():
    dom = Domain(
        Domain.rect(0, 0, 2, 2).geometry.difference(Domain.rect(0.8, 0.8, 1.2, 1.2).geometry)
    )
    rng = np.random.default_rng(3)
    # dots near the outer edges and around the hole, never on a vertex's bisector
    xy = np.concatenate([rng.uniform(0.02, 0.08, (10, 2)), 1.0 + rng.uniform(-0.27, 0.27, (20, 2))])
    xy = xy[np.abs(np.abs(xy[:, 0] - 1) - np.abs(xy[:, 1] - 1)) > 1e-3]
    ed = edge_args(EdgeIndex.build(dom, 0.1))
    rad = np.full(len(xy), 0.06)
    check_fd(lambda p: edge_penalty(p, rad, ed, 0.005, 3.0), xy)


def test_empty_term_gradient():
    mask = np.zeros((4, 5), np.uint8)
    mask[1, 2] = 1
    rng = np.random.default_rng(4)
    xy = np.array([0.5, 0.3]) + rng.uniform(-0.15, 0.15, (40, 2))  # around and inside cell (1, 2)
    rp = np.full(len(xy), 0.05)
    check_fd(lambda p: empty_penalty(p, rp, mask, (0.0, 0.0, 0.2, 0.2)), xy, atol=1e-6)


def test_kernel_is_the_sum_of_its_terms():
    xy, terms = make_terms(w_hard=10.0, empty=True)
    f, g = fast(xy, terms)
    pairs = pairs_brute_force(xy, np.full(len(xy), 1.0))
    parts = [
        pair_penalty(xy, terms.radius, terms.core_radius, terms.w_hard, pairs),
        box_penalty(xy, terms.panel_radius, terms.box, terms.margin, 1.0),
        box_penalty(xy, np.full(len(xy), terms.dot_radius), terms.box, terms.margin, 10.0),
        container_penalty(xy, terms.radius, terms.center, terms.half_side),
        empty_penalty(xy, terms.panel_radius, terms.empty, terms.grid_box),
    ]
    assert all(fp > 0 for fp, _ in parts)
    assert f == pytest.approx(sum(fp for fp, _ in parts), rel=1e-12)
    np.testing.assert_allclose(g, sum(gp for _, gp in parts), rtol=1e-9, atol=1e-12)
    f_ref, _ = penalty_reference(xy, terms, pairs)
    assert f == pytest.approx(f_ref, rel=1e-12)
