"""The block layout of the parallel pair kernels (penalty, MD forces).

Dots are split into fixed blocks of :data:`BLOCK` (in the Morton order the pipeline
sorts them into); each block's in-block pairs are summed in parallel, the pairs that
cross blocks serially in a fixed order, so sums come out bit-identical on any thread
count. :class:`PairList` is a CSR half list rearranged for that, plus the extra pairs of
dots handled outside the list.
"""

from __future__ import annotations

from dataclasses import dataclass

import numba as nb
import numpy as np

#: Dots per block of the parallel pair kernels (penalty, MD forces). Fixed, not the
#: thread count, so sums are added in the same order on every machine: bit-identical.
BLOCK = 4096


@nb.njit(cache=True, inline="always")
def put_row(i, src, lo, m, nbr, at, split, mid, has_cross):  # pragma: no cover - compiled
    """Row i's ``m`` partners ``src[lo:lo + m]`` written to ``nbr`` from ``at``; with
    ``split``, its partners in i's block of :data:`BLOCK` first, then the others (each in
    their order), the end of the first kept in ``mid[i]``, ``has_cross[i]`` set."""
    if not split:
        nbr[at : at + m] = src[lo : lo + m]
        return
    b = i // BLOCK
    k = at
    for q in range(lo, lo + m):
        if src[q] // BLOCK == b:
            nbr[k] = src[q]
            k += 1
    mid[i] = k
    for q in range(lo, lo + m):
        if src[q] // BLOCK != b:
            nbr[k] = src[q]
            k += 1
    has_cross[i] = k > mid[i]


@nb.njit(parallel=True, cache=True)
def _split_blocks(ptr, nbr):  # pragma: no cover - compiled
    """Reorder each dot's partners: same BLOCK first; returns (nbr', mid, cross)."""
    n = ptr.shape[0] - 1
    out = np.empty_like(nbr)
    mid = np.empty(n, np.int64)
    has_cross = np.zeros(n, np.bool_)
    for i in nb.prange(n):
        put_row(i, nbr, ptr[i], ptr[i + 1] - ptr[i], out, ptr[i], True, mid, has_cross)
    return out, mid, np.flatnonzero(has_cross)


@dataclass
class PairList:
    """A CSR half list prepared for the block-parallel pair kernels, plus movers' pairs.

    Attributes:
        ptr: ``[n + 1]`` int64; partners of i are ``nbr[ptr[i]:ptr[i + 1]]``.
        nbr: ``[K]`` int32, each row with same-block partners first.
        mid: ``[n]`` int64, end of row i's same-block partners.
        skip: ``[n]`` bool, dots whose pairs come only from the extra list.
        cross: ``[C]`` int64 ascending, the rows with partners in other blocks.
        ei, ej: ``[P]`` int32 extra pairs (each once).
    """

    ptr: np.ndarray
    nbr: np.ndarray
    mid: np.ndarray
    skip: np.ndarray
    cross: np.ndarray
    ei: np.ndarray
    ej: np.ndarray

    @classmethod
    def from_csr(cls, ptr: np.ndarray, nbr: np.ndarray) -> PairList:
        """Wrap a CSR half list from :func:`optdot.spatial.cellgrid.neighbor_pairs`."""
        return cls.from_split(ptr, *_split_blocks(ptr, nbr))

    @classmethod
    def from_split(
        cls, ptr: np.ndarray, nbr: np.ndarray, mid: np.ndarray, cross: np.ndarray
    ) -> PairList:
        """A list whose rows are already laid out for the blocks (``nbr``, ``mid``,
        ``cross`` as above), with no dot skipped and no extra pair."""
        none = np.zeros(0, np.int32)
        return cls(ptr, nbr, mid, np.zeros(len(ptr) - 1, np.bool_), cross, none, none)
