import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from optdot.neighbors import (
    csr_to_pairs,
    neighbor_grid,
    neighbor_pairs,
    pairs_brute_force,
    pairs_within,
    spatial_order,
)


@settings(max_examples=40, deadline=None)
@given(
    n=st.integers(0, 300),
    seed=st.integers(0, 2**31),
    rmin=st.floats(0.005, 0.05),
    spread=st.floats(1.0, 6.0),
    skin=st.floats(0.0, 0.5),
    per_dot=st.integers(1, 24),
)
def test_cell_grid_matches_brute_force(n, seed, rmin, spread, skin, per_dot):
    """Any guess of partners per dot (too small: chunks overflow and are scanned again)."""
    rng = np.random.default_rng(seed)
    xy = rng.random((n, 2)) * [2.0, 1.0]
    r = rng.uniform(rmin, rmin * spread, n)
    ptr, nbr, _ = neighbor_grid(xy, r, skin, per_dot=per_dot)
    want = pairs_brute_force(xy, r, skin)
    assert np.array_equal(csr_to_pairs(ptr, nbr), want)
    assert np.array_equal(csr_to_pairs(*neighbor_pairs(xy, r, skin)), want)


def test_one_circle_with_more_partners_than_a_row_holds():
    """A big circle over 600 small ones: its row overflows the scan's 256-slot buffer."""
    rng = np.random.default_rng(3)
    xy = np.concatenate([[[0.5, 0.5]], rng.random((600, 2))])
    r = np.concatenate([[1.0], np.full(600, 1e-4)])
    ptr, nbr, _ = neighbor_grid(xy, r, 0.0, per_dot=2)
    assert ptr[1] - ptr[0] == 600
    assert np.array_equal(csr_to_pairs(ptr, nbr), pairs_brute_force(xy, r, 0.0))


def test_clustered_and_coincident_points():
    rng = np.random.default_rng(1)
    xy = np.concatenate(
        [rng.normal(0.5, 0.01, (200, 2)), [[0.5, 0.5], [0.5, 0.5]], rng.random((100, 2)) * 30]
    )
    r = rng.uniform(0.01, 0.05, len(xy))
    assert np.array_equal(csr_to_pairs(*neighbor_pairs(xy, r, 0.1)), pairs_brute_force(xy, r, 0.1))


def test_pairs_within_is_strict():
    xy = np.array([[0.0, 0.0], [0.046, 0.0], [0.0, 0.0459]])
    p = pairs_within(xy, 0.046)
    assert p.tolist() == [[0, 2]]


def test_spatial_order_is_permutation():
    xy = np.random.default_rng(2).random((1000, 2))
    o = spatial_order(xy)
    assert np.array_equal(np.sort(o), np.arange(1000))
