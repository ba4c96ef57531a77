"""Pair search in O(n log n + K): the pure cell-grid search, the block layout of the
parallel kernels, and the Verlet policy that reuses a list while dots move."""
