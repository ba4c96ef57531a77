import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from optdot.neighbors import (
    csr_to_pairs,
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
)
def test_cell_grid_matches_brute_force(n, seed, rmin, spread, skin):
    rng = np.random.default_rng(seed)
    xy = rng.random((n, 2)) * [2.0, 1.0]
    r = rng.uniform(rmin, rmin * spread, n)
    got = csr_to_pairs(*neighbor_pairs(xy, r, skin))
    want = pairs_brute_force(xy, r, skin)
    assert np.array_equal(got, want)


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
