"""A scrambled 3-D Sobol sequence (Sobol 1967; Joe & Kuo 2008 direction numbers).

The dart throwing of §2.1 needs three low-discrepancy coordinates per dot. scipy's
``qmc.Sobol`` would do, but importing ``scipy.stats`` costs ~0.5 s of every command's
start-up; three dimensions take forty lines. Scrambling is Matoušek's linear matrix
scramble plus a digital shift (what scipy calls ``scramble=True``), so every prefix of
2^m points keeps the (t, m, s)-net property: in each coordinate, one point per dyadic
interval of length 2^-m; in the first two, one point per elementary box of area 2^-m.
"""

from __future__ import annotations

import numba as nb
import numpy as np

#: Bits per coordinate (resolution 2^-32).
BITS = 32

# Joe & Kuo (new-joe-kuo-6.21201): degree s, coefficients a, initial m_1..m_s.
_POLYS = ((0, 0, ()), (1, 0, (1,)), (2, 1, (1, 3)))


def _direction_numbers() -> np.ndarray:
    """``[3, BITS]`` uint64 direction numbers v_k = m_k · 2^(BITS - k), k = 1..BITS."""
    v = np.zeros((3, BITS), np.uint64)
    for dim, (s, a, m_init) in enumerate(_POLYS):
        if s == 0:
            m = [1] * BITS
        else:
            m = list(m_init)
            for k in range(s, BITS):
                new = m[k - s] ^ (m[k - s] << s)
                for t in range(1, s):
                    if (a >> (s - 1 - t)) & 1:
                        new ^= m[k - t] << t
                m.append(new)
        for k in range(BITS):
            v[dim, k] = np.uint64(m[k] << (BITS - 1 - k))
    return v


def _scramble(v: np.ndarray, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """Linear matrix scramble of direction numbers ``v`` and a random digital shift.

    Bit b of a number is counted from the most significant (b = 0 has weight 2^-1); the
    lower-triangular matrix L with unit diagonal maps bit c to bits r >= c.
    """
    dims = v.shape[0]
    out = np.zeros_like(v)
    for dim in range(dims):
        L = np.tril(rng.integers(0, 2, (BITS, BITS), dtype=np.uint8), -1)
        L[np.arange(BITS), np.arange(BITS)] = 1
        bits = (v[dim][:, None] >> np.arange(BITS - 1, -1, -1, dtype=np.uint64)) & np.uint64(1)
        scrambled = (bits.astype(np.int64) @ L.T.astype(np.int64)) & 1  # [k, r]
        weights = np.uint64(1) << np.arange(BITS - 1, -1, -1, dtype=np.uint64)
        out[dim] = (scrambled.astype(np.uint64) * weights).sum(axis=1, dtype=np.uint64)
    shift = rng.integers(0, 2**BITS, dims, dtype=np.uint64)
    return out, shift


@nb.njit(cache=True)
def _gray_code_points(v, shift, n):  # pragma: no cover - compiled
    dims = v.shape[0]
    out = np.empty((n, dims))
    x = shift.copy()
    scale = 1.0 / 2.0**32
    for i in range(n):
        for d in range(dims):
            out[i, d] = (np.float64(x[d]) + 0.5) * scale
        # the next point flips the direction number of the lowest zero bit of i
        c = 0
        k = i
        while k & 1:
            k >>= 1
            c += 1
        if c < v.shape[1]:
            for d in range(dims):
                x[d] ^= v[d, c]
    return out


def sobol_points(n: int, seed: int) -> np.ndarray:
    """The first ``n`` points of a scrambled 3-D Sobol sequence, ``[n, 3]`` in (0, 1).

    Args:
        n: number of points (< 2^32).
        seed: scrambling seed; the same seed gives the same points.
    """
    if not 0 <= n < 2**BITS:
        raise ValueError(f"n = {n} outside 0 .. 2^{BITS} - 1")
    v, shift = _scramble(_direction_numbers(), np.random.default_rng(seed))
    return _gray_code_points(v, shift, n)
