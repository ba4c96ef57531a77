"""Phantom dots beyond the walls (panel edges, holes, zero-fill borders): thrown once
per job, held still beside the real dots so the first row does not layer against a wall
(:mod:`optdot.sampling.phantoms`)."""

from __future__ import annotations

from functools import lru_cache

import numpy as np

from ..sampling.phantoms import phantom_dots
from ..spatial.window import bounds, grown, in_rect
from .settings import StageSettings


def with_phantoms(s: StageSettings, xy0, rho, start, frozen, diameters):
    """The phantom dots near the walls appended (frozen): ``(xy0, rho, start, frozen,
    diameters, phantom mask)``."""
    n = len(xy0)
    pxy, prho, pd = phantoms_near(s, xy0)
    xy0 = np.concatenate([xy0, pxy])
    rho = np.concatenate([rho, prho])
    start = None if start is None else np.concatenate([start, pxy])
    # phantoms stay where they were thrown: free, they would yield to the real dots'
    # hard core and let the first row settle against the wall again
    frozen = np.zeros(n, bool) if frozen is None else frozen
    frozen = np.concatenate([frozen, np.ones(len(pxy), bool)])
    if diameters is not None:
        diameters = np.concatenate([diameters, pd])
    phantom = np.zeros(len(xy0), bool)
    phantom[n:] = True
    return xy0, rho, start, frozen, diameters, phantom


def allowed_at(s: StageSettings):
    """``allowed(xy) -> [m] bool``: a real dot's centre may stand there (in the map's box,
    inside the outline, in a non-zero cell)."""
    dens, dom = s.density, s.domain

    def allowed(xy: np.ndarray) -> np.ndarray:
        ok = (
            (xy[:, 0] >= dens.x0)
            & (xy[:, 0] <= dens.x0 + dens.width)
            & (xy[:, 1] >= dens.y0)
            & (xy[:, 1] <= dens.y0 + dens.height)
        )
        ok[ok] = dens.at(xy[ok]) > 0
        if not dom.rectangle:
            ok[ok] = dom.contains(xy[ok])
        return ok

    return allowed


def phantom_reach(s: StageSettings) -> float:
    """How far beyond a wall phantoms reach the real dots: twice the largest circle
    (the lowest non-zero container fill, the largest dot), mm."""
    form = s.formulation
    rho_min = s.containers.lowest()
    r = float(form.radii(np.array([rho_min]), 0.5 * s.widest, 0)[0])
    return 2.0 * r * (1.0 + form.polydispersity)


@lru_cache(maxsize=4)
def job_phantoms(s: StageSettings, reach: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The job's phantom dots (:func:`~optdot.sampling.phantoms.phantom_dots`), thrown
    once per job and process: ``(xy [m, 2] mm, rho [m], diameter [m] mm)``. The cache
    holds the settings, so their identity stays unique while cached."""
    dens = s.density
    partial = None
    if not s.domain.rectangle:
        ny, nx = dens.shape
        cw, ch = dens.cell_size
        partial = s.domain.cell_fractions(dens.x0, dens.y0, cw, ch, nx, ny) < 1.0
    r0 = 0.5 * s.diameter
    xy, rho, weight = phantom_dots(
        dens, allowed_at(s), partial, reach, np.pi * r0 * r0, s.optimize.seed, s.dart_weights
    )
    return xy, s.containers.floored(rho, xy), s.diameter / np.sqrt(weight)


def phantoms_near(s: StageSettings, xy0: np.ndarray):
    """The job's phantom dots within reach of the box around ``xy0`` (``[n, 2]`` mm):
    ``(xy [m, 2] mm, rho [m], diameter [m] mm)``. A tile's phantoms are the panel's in
    its window, so they do not depend on the tiling."""
    reach = phantom_reach(s)
    xy, rho, d = job_phantoms(s, reach)
    m = in_rect(xy, grown(bounds(xy0), reach))
    return xy[m], rho[m], d[m]
