"""QA's order and spectrum measures on inputs whose answer is known:
a hexagonal lattice (ψ6 = 1, grains everywhere, a Bragg peak at its reciprocal spacing)
and a Poisson pattern (|ψ6| near the random-phasor mean, no coherence, a flat spectrum)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from optdot.quality.metrics import patch_coherence, psi6, radial_spectrum


def hex_lattice(a: float, size: float, angle: float = 0.0) -> np.ndarray:
    """``[n, 2]`` points of a hexagonal lattice of spacing ``a`` filling a square of
    side ``size`` (mm), rotated by ``angle`` (rad)."""
    n = int(2 * size / a) + 4
    i, j = np.meshgrid(np.arange(-n, n), np.arange(-n, n), indexing="ij")
    x = a * (i + 0.5 * j)
    y = a * (math.sqrt(3) / 2) * j
    c, s = math.cos(angle), math.sin(angle)
    xy = np.column_stack([c * x.ravel() - s * y.ravel(), s * x.ravel() + c * y.ravel()])
    keep = (xy >= 0).all(1) & (xy < size).all(1)
    return xy[keep]


def poisson(n: int, size: float, seed: int = 0) -> np.ndarray:
    return np.random.default_rng(seed).uniform(0, size, (n, 2))


@pytest.mark.parametrize("angle", [0.0, 0.37, 1.1])
def test_hexagonal_lattice_has_psi6_one_and_full_coherence(angle):
    xy = hex_lattice(0.1, 6.0, angle)
    psi = psi6(xy)
    interior = ((xy > 0.3) & (xy < 5.7)).all(1)
    np.testing.assert_allclose(np.abs(psi[interior]), 1.0, atol=1e-9)
    # one grain: the phase is the same everywhere, so every 2 mm patch is coherent
    assert patch_coherence(xy[interior], psi[interior], 2.0) > 0.999


def test_poisson_pattern_psi6_matches_random_phasors():
    """Six neighbours at independent angles give E|ψ6| = E|sum of 6 unit phasors| / 6,
    0.3594 by simulation (0.36 from the Rayleigh approximation)."""
    xy = poisson(40_000, 20.0)
    psi = psi6(xy)
    rng = np.random.default_rng(1)
    expected = np.abs(np.exp(1j * rng.uniform(0, 2 * np.pi, (200_000, 6))).mean(1)).mean()
    assert abs(np.abs(psi).mean() - expected) < 0.02, (np.abs(psi).mean(), expected)


def test_poisson_pattern_coherence_is_the_noise_floor():
    """Patch means of N independent phasors: E|mean| = sqrt(pi/4 * E|psi|^2 / N)."""
    size, patch = 20.0, 2.0
    xy = poisson(40_000, size)
    psi = psi6(xy)
    n_patch = len(xy) / (size / patch) ** 2
    floor = math.sqrt(math.pi / 4 * np.mean(np.abs(psi) ** 2) / n_patch)
    got = patch_coherence(xy, psi, patch)
    assert 0.6 * floor < got < 1.6 * floor, (got, floor)
    assert got < 0.1  # the gate's default limit passes a Poisson pattern


def test_poisson_spectrum_is_flat_and_lattice_spectrum_peaks_at_its_spacing():
    size, px = 10.0, 0.02
    xy = poisson(20_000, size, seed=3)
    f, p = radial_spectrum(xy, (0, 0, size, size), px)
    mid = (f > 2) & (f < 20)
    assert 0.8 < p[mid].mean() < 1.2, p[mid].mean()
    a = 0.1
    lat = hex_lattice(a, size, 0.2)
    f, p = radial_spectrum(lat, (0, 0, size, size), px)
    peak = f[np.argmax(p)]
    bragg = 2 / (math.sqrt(3) * a)  # first reciprocal-lattice vector, 1/mm
    assert abs(peak - bragg) <= 2 * (f[1] - f[0]), (peak, bragg)
    assert p.max() > 50 * np.median(p)
