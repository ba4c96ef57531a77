"""A thin diffuser sheet between two air layers: ``F_SHEET_T`` of the light transmitted
to the other side (Lambertian, or tilted by a Gaussian angle), ``F_SHEET_R`` reflected
Lambertian (recycled), the rest absorbed (compiled)."""

from __future__ import annotations

import numba as nb

from ..rays import lambert, scatter_through, uniform
from ..tables import CROSS, F_SHEET_R, F_SHEET_T, F_SPREAD, F_SPREAD_SIG, NEW_LEG, SHEET


@nb.njit(cache=True, inline="always")
def meet_sheet(state, f, up, dxn, dyn, dz):  # pragma: no cover - compiled
    """A ray meeting the sheet (its face row ``f``) going up (``up``) or
    down: ``(state, act, dx, dy, dz)`` (``CROSS``, ``NEW_LEG`` or the fate ``SHEET``)."""
    state, u = uniform(state)
    if u < f[F_SHEET_T]:
        spread = 1 + int(f[F_SPREAD])
        state, dxn, dyn, dz = scatter_through(state, dxn, dyn, dz, spread, f[F_SPREAD_SIG], 1.0)
        return state, CROSS, dxn, dyn, dz
    if u < f[F_SHEET_T] + f[F_SHEET_R]:
        state, dxn, dyn, dz = lambert(state, not up)
        return state, NEW_LEG, dxn, dyn, dz
    return state, SHEET, dxn, dyn, dz
