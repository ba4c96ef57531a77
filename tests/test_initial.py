import math

import numpy as np
import pytest

from optdot.geometry.density import DensityMap
from optdot.relax.circles import circle_radius, container_half_sides, hex_radius
from optdot.sampling.initial import initial_dots
from optdot.sampling.sobol import sobol_points


def test_counts_per_cell_follow_the_map():
    rng = np.random.default_rng(0)
    g = rng.uniform(0.05, 0.6, (6, 9))
    g[2, 3] = 0.0
    dm = DensityMap(g, 9.0, 6.0)
    n = 20000
    xy = initial_dots(dm, n, seed=5)
    counts = np.bincount(dm.cell_index(xy), minlength=g.size)
    expected = n * g.ravel() / g.sum()
    assert counts[2 * 9 + 3] == 0
    # low discrepancy: far tighter than Poisson (sqrt(expected) ~ 20)
    assert np.abs(counts - expected).max() <= 5


def test_row_zero_is_bottom_and_deterministic():
    g = np.zeros((2, 2))
    g[0, 1] = 0.3  # bottom-right cell only
    dm = DensityMap(g, 2.0, 2.0)
    xy = initial_dots(dm, 500, seed=1)
    assert np.all(xy[:, 0] >= 1.0) and np.all(xy[:, 1] <= 1.0)
    assert np.array_equal(xy, initial_dots(dm, 500, seed=1))
    assert not np.array_equal(xy, initial_dots(dm, 500, seed=2))


def test_radius_rule():
    r0 = 0.023
    rho = np.array([0.1, 0.4, 0.9])
    r = circle_radius(rho, r0)
    np.testing.assert_allclose(r, r0 * np.sqrt(math.pi / (math.sqrt(3) * rho)))
    # sqrt(2) times the touching hexagonal radius, and hex circles at rho = pi/(2 sqrt3) touch dots
    np.testing.assert_allclose(r / hex_radius(rho, r0), math.sqrt(2))
    assert hex_radius(np.array([math.pi / (2 * math.sqrt(3))]), r0)[0] == pytest.approx(r0)
    np.testing.assert_allclose(container_half_sides(r, 4.0), 2 * r)


def test_dot_count_is_map_integral():
    dm = DensityMap(np.full((3, 4), 0.25), 4.0, 3.0)
    dot_area = math.pi * 0.023**2
    assert dm.dot_count(dot_area) == round(0.25 * 12 / dot_area)


@pytest.mark.parametrize("seed", [0, 7])
def test_sobol_prefixes_are_nets(seed):
    p = sobol_points(1 << 10, seed)
    assert np.all((p > 0) & (p < 1))
    for m in (3, 6, 10):
        q = p[: 1 << m]
        for d in range(3):  # one point per dyadic interval in every coordinate
            cells = (q[:, d] * (1 << m)).astype(int)
            assert np.array_equal(np.sort(cells), np.arange(1 << m))
        for a in range(m + 1):  # (0, m, 2)-net in the first two coordinates
            box = (q[:, 0] * (1 << a)).astype(int) * (1 << (m - a)) + (
                q[:, 1] * (1 << (m - a))
            ).astype(int)
            assert np.array_equal(np.sort(box), np.arange(1 << m))
    assert not np.array_equal(p, sobol_points(1 << 10, seed + 1))
    assert np.array_equal(p[:100], sobol_points(100, seed))


def test_sobol_matches_scipy_discrepancy():
    from scipy.stats import qmc

    ours = qmc.discrepancy(sobol_points(1024, 3))
    theirs = np.mean([qmc.discrepancy(qmc.Sobol(3, seed=s).random(1024)) for s in range(3)])
    rand = qmc.discrepancy(np.random.default_rng(0).random((1024, 3)))
    assert ours < 2 * theirs < rand / 20
