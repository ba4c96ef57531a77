import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from optdot.geometry.morton import spatial_order
from optdot.spatial.cellgrid import (
    csr_to_pairs,
    neighbor_grid,
    neighbor_list,
    neighbor_pairs,
    pairs_within,
)
from optdot.testing import pairs_brute_force


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


@settings(max_examples=30, deadline=None)
@given(
    n=st.integers(0, 200),
    h=st.integers(0, 120),
    seed=st.integers(0, 2**31),
    skin=st.floats(0.0, 0.4),
    per_dot=st.integers(1, 12),
)
def test_pure_search_with_a_frozen_halo_matches_brute_force(n, h, seed, skin, per_dot):
    """Live pairs once each, live-halo pairs apart, no halo-halo pairs: as brute force on
    the union says."""
    rng = np.random.default_rng(seed)
    xy = rng.random((n, 2)) * [1.0, 1.0]
    halo = rng.random((h, 2)) * [1.4, 1.4] - 0.2  # around and over the live square
    r = rng.uniform(0.01, 0.05, n)
    hr = rng.uniform(0.01, 0.05, h)
    nl = neighbor_list(xy, r, skin, halo, hr, per_dot=per_dot)
    ref = pairs_brute_force(np.concatenate([xy, halo]), np.concatenate([r, hr]), skin)
    live = ref[(ref[:, 0] < n) & (ref[:, 1] < n)]
    cross = ref[(ref[:, 0] < n) & (ref[:, 1] >= n)]  # i < j, so a live i comes first
    assert np.array_equal(nl.pairs(), live)
    got = np.stack([nl.halo_i, nl.halo_j + n], axis=1).astype(np.int64)
    assert np.array_equal(got, cross)
    assert len(nl.ptr) == n + 1


def test_pure_search_reports_overflow_of_its_capacity_guess():
    rng = np.random.default_rng(5)
    xy = rng.random((3000, 2)) * 0.5
    small = neighbor_list(xy, 0.02, per_dot=1)
    big = neighbor_list(xy, 0.02, per_dot=64)
    assert small.overflow and not big.overflow
    assert np.array_equal(small.pairs(), big.pairs())
    assert np.array_equal(small.pairs(), pairs_brute_force(xy, 0.02))


def test_pure_search_does_not_modify_its_inputs():
    xy = np.random.default_rng(2).random((500, 2))
    r = np.full(500, 0.03)
    before = xy.copy(), r.copy()
    neighbor_list(xy, r, 0.2, xy[:50] + 0.5, r[:50])
    assert np.array_equal(xy, before[0]) and np.array_equal(r, before[1])


def test_verlet_update_never_changes_a_list_it_handed_out():
    from optdot.spatial.verlet import VerletList

    rng = np.random.default_rng(4)
    xy = rng.random((2000, 2))
    reff = np.full(2000, 0.01)
    v = VerletList(reff, 0.3)
    first = v.update(xy)
    snapshot = {k: getattr(first, k).copy() for k in ("ptr", "nbr", "skip", "ei", "ej")}
    moved = xy.copy()
    moved[:5] += 0.05  # five movers: patched, not rebuilt
    second = v.update(moved)
    assert v.n_movers == 5 and second is not first
    assert second.skip.sum() == 5 and len(second.ei) > 0
    for k, arr in snapshot.items():
        assert np.array_equal(getattr(first, k), arr), k
    # the patched list holds every pair now closer than re_i + re_j
    found = {tuple(sorted(p)) for p in csr_to_pairs(second.ptr, second.nbr).tolist()}
    found = {p for p in found if not (second.skip[p[0]] or second.skip[p[1]])}
    found |= {tuple(sorted(p)) for p in zip(second.ei.tolist(), second.ej.tolist(), strict=True)}
    want = {tuple(p) for p in pairs_brute_force(moved, reff).tolist()}
    assert want <= found


@pytest.mark.slow  # over 1.5 s
def test_counting_sort_in_parallel_ranges_is_the_stable_sort():
    """The cell sort split over index ranges gives what one serial stable sort gives:
    every cell's dots in index order, whatever the number of ranges."""
    from optdot.spatial.cellgrid import Workspace, bin_points

    rng = np.random.default_rng(5)
    n = 4 * 65536 + 17  # enough dots for four ranges
    xy = rng.random((n, 2)) * [30.0, 20.0]
    xy[:100] = xy[100:200]  # shared cells across ranges
    reff = 0.01 + 0.02 * rng.random(n)
    nx, ny, cell = 300, 200, 0.1
    cid = np.minimum((xy[:, 1] / cell).astype(int), ny - 1) * nx + np.minimum(
        (xy[:, 0] / cell).astype(int), nx - 1
    )
    want = np.argsort(cid, kind="stable")
    ws = Workspace()  # kept arrays, written over by each sort: nothing of the last may stay
    for parts in (1, 2, 3, 4, 2):
        start, order, bx, by, br, cellmax = bin_points(xy, reff, 0.0, 0.0, cell, nx, ny, parts, ws)
        np.testing.assert_array_equal(order, want)
        np.testing.assert_array_equal(start, np.searchsorted(cid[want], np.arange(nx * ny + 1)))
        np.testing.assert_array_equal(bx, xy[want, 0])
        np.testing.assert_array_equal(br, reff[want])
        top = np.zeros(nx * ny)
        np.maximum.at(top, cid, reff)
        np.testing.assert_array_equal(cellmax, top)


@settings(max_examples=30, deadline=None)
@given(
    n=st.integers(2, 400),
    seed=st.integers(0, 2**31),
    spread=st.floats(1.0, 6.0),
    skin=st.floats(0.0, 0.5),
    clump=st.booleans(),
)
@pytest.mark.slow
def test_few_dots_far_apart_give_the_dense_grids_pairs_in_its_order(n, seed, spread, skin, clump):
    """A Verlet list's movers: a few dots over a panel of ~10^6 cells. The bisected
    search gives the dense grid's CSR list exactly (the same pairs, the same order)."""
    from optdot.spatial import cellgrid

    rng = np.random.default_rng(seed)
    xy = rng.random((n, 2)) * [200.0, 120.0]
    if clump:  # clusters that touch across cell borders, and coincident centres
        xy[: n // 2] = xy[0] + rng.normal(0.0, 0.05, (n // 2, 2))
        xy[n // 2 : n // 2 + 3] = xy[0]
    r = 0.02 * rng.uniform(1.0, spread, n)
    x0, y0, cell, nx, ny = cellgrid._grid_shape(xy, cellgrid.cell_side(r, skin))
    assume(nx * ny > cellgrid.SPARSE_CELLS * n)  # the bisected path is the one taken
    ptr, nbr = neighbor_pairs(xy, r, skin)
    # the dense search on the same grid (a dense search of its own takes larger cells
    # over so many a dot: test_points_of_tiny_reach_over_a_wide_box...)
    dense_ptr, dense_nbr, _, _, _, _ = cellgrid._search(xy, r, skin, None, 8, crowd=False)
    np.testing.assert_array_equal(ptr, dense_ptr)
    np.testing.assert_array_equal(nbr, dense_nbr)
    np.testing.assert_array_equal(csr_to_pairs(ptr, nbr), pairs_brute_force(xy, r, skin))


def test_the_search_compiles_once_for_one_radius_and_for_radii_per_dot():
    """One radius (a copy) and radii per dot (a read-only view) reach the compiled search
    with the same types, so a first run compiles it once, not twice (7 s each)."""
    from optdot.spatial.cellgrid import _pairs_csr, neighbor_grid

    rng = np.random.default_rng(3)
    xy = rng.random((500, 2))
    neighbor_grid(xy, 0.02)
    neighbor_grid(xy, np.full(500, 0.02))
    neighbor_grid(xy, np.full(500, 0.02)[::1].copy())
    radii = {sig[1] for sig in _pairs_csr.signatures}
    assert radii and all(not t.mutable for t in radii), radii


def test_the_search_compiles_once_for_moving_and_frozen_centres():
    """Centres being moved (writable) and a pattern's frozen centres (read-only) reach the
    compiled search and binning with the same types (a second compile took 7-15 s), and
    the caller's array stays writable."""
    from optdot.spatial.cellgrid import _bin_points, _pairs_csr, neighbor_grid

    xy = np.random.default_rng(4).random((500, 2))
    frozen = xy.copy()
    frozen.flags.writeable = False
    neighbor_grid(xy, 0.02)
    neighbor_grid(frozen, 0.02)
    assert xy.flags.writeable
    for kernel in (_pairs_csr, _bin_points):
        centres = {sig[0] for sig in kernel.signatures}
        assert len(centres) == 1 and not next(iter(centres)).mutable, centres


@settings(max_examples=20, deadline=None)
@given(
    sizes=st.lists(st.integers(1, 12000), min_size=2, max_size=3),
    seed=st.integers(0, 2**31),
    per_dot=st.integers(1, 12),
    skin=st.floats(0.0, 0.5),
)
def test_a_verlet_rebuild_lays_out_the_rows_as_the_block_split_does(sizes, seed, per_dot, skin):
    """The search that splits rows into blocks while copying them (a Verlet list's
    rebuild, into the memory of the last one) gives :meth:`PairList.from_csr`'s list of
    the plain search exactly: the same pointers, rows, block ends and cross rows, also
    when chunks overflow (a small ``per_dot``) and when the kept arrays held a larger or
    smaller list before."""
    from optdot.spatial.blocks import PairList
    from optdot.spatial.cellgrid import Workspace, block_pairs, cell_side

    rng = np.random.default_rng(seed)
    ws = Workspace()
    for n in sizes:
        side = np.sqrt(n) * 0.05
        xy = rng.random((n, 2)) * [side, side]
        r = 0.02 * rng.uniform(0.8, 1.6, n)
        cell = cell_side(r, skin)
        got, grid = block_pairs(xy, r, skin, cell, per_dot, ws)
        ptr, nbr, want_grid = neighbor_grid(xy, r, skin, cell, per_dot)
        want = PairList.from_csr(ptr, nbr)
        for name in ("ptr", "nbr", "mid", "cross", "skip", "ei", "ej"):
            np.testing.assert_array_equal(getattr(got, name), getattr(want, name), err_msg=name)
        np.testing.assert_array_equal(grid.order, want_grid.order)
        np.testing.assert_array_equal(grid.start, want_grid.start)
        np.testing.assert_array_equal(grid.cellmax, want_grid.cellmax)


@settings(max_examples=40, deadline=None)
@given(
    n=st.integers(1, 3000),
    seed=st.integers(0, 2**31),
    scale=st.floats(1e-3, 1e3),
    strided=st.booleans(),
)
def test_the_compiled_bounding_box_is_numpys(n, seed, scale, strided):
    """:func:`optdot.spatial.window.bounds` (compiled: numpy's axis-0 min and max of an
    ``[n, 2]`` array are ~80x slower) gives numpy's box exactly, for any layout."""
    import pytest

    from optdot.spatial.window import bounds

    rng = np.random.default_rng(seed)
    xy = (rng.random((n, 4 if strided else 2)) - 0.3) * scale
    if strided:
        xy = xy[:, ::2]  # a view with a stride, as a column slice of a wider array
    want = (*xy.min(axis=0), *xy.max(axis=0))
    assert bounds(xy) == want
    with pytest.raises(ValueError):
        bounds(np.zeros((0, 2)))


def test_points_of_tiny_reach_over_a_wide_box_get_a_grid_of_few_cells_a_point(monkeypatch):
    """A hard-core pass of a sized film's relaxation: 80 % of its points phantoms whose
    soft circles shrank a thousandfold (reach ~0.05 µm) over a box 3x the panel, the
    rest dots of 23-54 µm. The grid's side came from the median reach: 59 million cells
    for 354k points (1.4 GB, 0.4 s a rebuild). Now at most 32 cells a point, and the
    pairs are still every pair brute force finds."""
    import optdot.spatial.cellgrid as cg

    rng = np.random.default_rng(3)
    n = 3000
    xy = rng.uniform(-20.0, 40.0, (n, 2))
    r = np.where(rng.random(n) < 0.8, 5e-5, rng.uniform(0.023, 0.054, n))
    xy[:40] = xy[40:80] + rng.uniform(-0.05, 0.05, (40, 2))  # some pairs within reach
    r[:80] = 0.03
    seen = []
    real = cg.bin_points

    def spy(xy_, reff, x0, y0, cell, nx, ny, parts, ws=None):
        seen.append(nx * ny / len(xy_))
        return real(xy_, reff, x0, y0, cell, nx, ny, parts, ws)

    monkeypatch.setattr(cg, "bin_points", spy)
    ptr, nbr, grid = neighbor_grid(xy, r, 0.3)  # the dense search a Verlet rebuild makes
    assert seen and max(seen) <= cg.CELLS_PER_POINT + 1 and grid.nx * grid.ny <= 32 * n + 1e4
    got = np.array(
        [(i, j) if i < j else (j, i) for i in range(n) for j in nbr[ptr[i] : ptr[i + 1]]],
        np.int64,
    ).reshape(-1, 2)
    got = got[np.lexsort(got.T[::-1])]
    want = pairs_brute_force(xy, r, 0.3)
    assert len(want) >= 40
    np.testing.assert_array_equal(got, want)
