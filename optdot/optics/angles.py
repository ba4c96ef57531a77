"""The luminance's angles: what leaves the top, binned by direction in air.

A viewer off-axis and a prism sheet over the stack see the luminance's angular
distribution, not only its spatial one. Every extracted ray's direction in air (the top
face refracts it out and, if hazy, scatters it, :mod:`optdot.optics.faces.interface`) falls in
a bin of polar angle ``theta`` (from the normal, :data:`STEP_DEG` wide, 0 to 90°) and
azimuth ``phi`` (from +x towards +y, :data:`STEP_DEG` wide). The luminance of a bin is
its rays per unit projected solid angle, ``counts / (dOmega cos theta)``, relative to a
Lambertian emitter of the same flux (``1`` at every angle for a Lambertian top), so a
flux share ``c / N`` in a bin reads ``(c / N) / (dOmega cos theta / pi)``.

Figures (:meth:`Angles.figures`):

- ``on_axis``: the luminance within the first ring (``theta`` < :data:`STEP_DEG`),
  relative to a Lambertian's.
- ``half_luminance_deg``: horizontal (the x-z plane) and vertical (the y-z plane): the
  polar angle at which the luminance in that plane (the bins within
  :data:`PLANE_DEG` of it, both sides) falls to half its on-axis value, linear between
  ring centres; None when it stays above half to the last ring, and both None when
  fewer than :data:`~optdot.figures.MIN_ON_AXIS_RAYS` rays fall in the first ring
  (``on_axis_rays``; the figures say so in ``on_axis_judged``).

Each figure's Monte Carlo noise is Poisson in the rays counted (``on_axis_sigma``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numba as nb
import numpy as np

from ..figures import MIN_ON_AXIS_RAYS

#: Width of the polar and azimuth bins, degrees (the issue asks for 5 at most).
STEP_DEG = 5.0
#: Half-width of the sector about each viewing plane its profile is taken over, degrees.
PLANE_DEG = 15.0


@dataclass
class Angles:
    """Extracted rays counted by direction.

    Attributes:
        counts: ``[n_theta, n_phi]`` int64 rays per bin (row 0: ``theta`` in ``[0,
            STEP_DEG)``; column 0: ``phi`` in ``[0, STEP_DEG)``).
    """

    counts: np.ndarray

    @classmethod
    def empty(cls) -> Angles:
        """No ray yet."""
        nt, nphi = int(round(90 / STEP_DEG)), int(round(360 / STEP_DEG))
        return cls(np.zeros((nt, nphi), np.int64))

    def add(self, air: np.ndarray) -> None:
        """Count rays of directions ``air`` (``[m, 3]`` unit, in air; those not going up,
        ``z <= 0``, are left out), as float32, the tracer's (one compiled kernel)."""
        _count(np.ascontiguousarray(air, dtype=np.float32), self.counts)

    @property
    def total(self) -> int:
        """Rays counted."""
        return int(self.counts.sum())

    def _weights(self) -> tuple[np.ndarray, np.ndarray]:
        """``(theta centres [n_theta] rad, Lambertian share of each bin [n_theta])``:
        ``dOmega cos theta / pi`` of one bin of the ring = ``(sin² theta2 - sin² theta1)
        / 2 * dphi / pi``."""
        nt, nphi = self.counts.shape
        edges = np.radians(np.arange(nt + 1) * STEP_DEG)
        share = (np.sin(edges[1:]) ** 2 - np.sin(edges[:-1]) ** 2) / 2 * (2 * math.pi / nphi)
        return 0.5 * (edges[1:] + edges[:-1]), share / math.pi

    def luminance(self) -> np.ndarray:
        """``[n_theta, n_phi]`` each bin's luminance relative to a Lambertian emitter of
        the same flux (NaN with no ray)."""
        n = self.total
        _, lam = self._weights()
        if n == 0:
            return np.full(self.counts.shape, np.nan)
        return self.counts / n / lam[:, None]

    def profile(self, plane_deg: float) -> np.ndarray:
        """``[n_theta]`` the luminance in the plane at azimuth ``plane_deg`` (and ``+
        180``): :func:`plane_profile` of :meth:`luminance`."""
        return plane_profile(self.luminance(), plane_deg)

    def figures(self) -> dict:
        """On-axis luminance (relative to a Lambertian's) with its noise, the
        half-luminance angles in the horizontal and vertical planes and their profiles
        (ring by ring), the rays counted."""
        _, lam = self._weights()
        ring = self.counts[0].sum()
        n = self.total
        on_axis = ring / max(n, 1) / (lam[0] * self.counts.shape[1]) if n else math.nan
        sigma = on_axis / math.sqrt(ring) if ring > 0 else math.nan
        profiles = {name: self.profile(plane) for name, plane in PLANES}
        judged = int(ring) >= MIN_ON_AXIS_RAYS
        return {
            "rays": n,
            "on_axis_rays": int(ring),
            "on_axis_judged": judged,
            "on_axis": float(on_axis),
            "on_axis_sigma": float(sigma),
            "half_luminance_deg": {
                k: _half_angle(v) if judged else None for k, v in profiles.items()
            },
            "profiles": {k: [round(float(x), 4) for x in v] for k, v in profiles.items()},
        }

    def rows(self) -> list[list[float]]:
        """The luminance table for a JSON file: one row per polar ring, one column per
        azimuth bin, rounded to 4 decimals (NaN as None)."""
        lum = self.luminance()
        return [[None if not math.isfinite(v) else round(float(v), 4) for v in r] for r in lum]


#: Rays a parallel chunk of :func:`_count` bins.
COUNT_CHUNK = 1 << 16


@nb.njit(cache=True, parallel=True)
def _count(air, counts):  # pragma: no cover - compiled
    """Add each upward direction of ``air`` (``[m, 3]``) to its bin of ``counts``
    (``[n_theta, n_phi]``): chunks of :data:`COUNT_CHUNK` rays on all cores, each into its
    own histogram, summed after (integers: the same counts on any thread count)."""
    nt, nphi = counts.shape
    to_deg = 180.0 / math.pi
    chunks = (air.shape[0] + COUNT_CHUNK - 1) // COUNT_CHUNK
    part = np.zeros((chunks, nt, nphi), np.int64)
    for c in nb.prange(chunks):
        for k in range(c * COUNT_CHUNK, min(air.shape[0], (c + 1) * COUNT_CHUNK)):
            z = air[k, 2]
            if z <= 0:
                continue
            theta = math.acos(min(float(z), 1.0)) * to_deg
            phi = math.atan2(float(air[k, 1]), float(air[k, 0])) * to_deg
            if phi < 0:
                phi += 360.0
            part[c, min(int(theta / STEP_DEG), nt - 1), min(int(phi / STEP_DEG), nphi - 1)] += 1
    for c in range(chunks):
        counts += part[c]


def plane_profile(lum: np.ndarray, plane_deg: float) -> np.ndarray:
    """``[n_theta]`` the mean of ``lum`` (``[n_theta, n_phi]``, a luminance table) over
    the azimuth bins whose centres lie within :data:`PLANE_DEG` of the plane at
    ``plane_deg`` (either side of the normal): the bins of a ring share one solid angle,
    so their mean is the sector's luminance."""
    nphi = lum.shape[1]
    centres = (np.arange(nphi) + 0.5) * (360.0 / nphi)
    cols = np.abs((centres - plane_deg + 90.0) % 180.0 - 90.0) <= PLANE_DEG
    return np.nanmean(lum[:, cols], axis=1)


PLANES = (("horizontal", 0.0), ("vertical", 90.0))


def _half_angle(profile: np.ndarray) -> float | None:
    """The polar angle, degrees, at which ``profile`` (``[n_theta]``, ring centres)
    first falls to half its first ring's value, linear between ring centres; None when
    it does not (or has no light on axis)."""
    if not (len(profile) and math.isfinite(profile[0]) and profile[0] > 0):
        return None
    half = 0.5 * profile[0]
    centres = (np.arange(len(profile)) + 0.5) * STEP_DEG
    for k in range(1, len(profile)):
        if profile[k] <= half:
            a, b = profile[k - 1], profile[k]
            f = (a - half) / (a - b) if a != b else 0.0
            return float(centres[k - 1] + f * STEP_DEG)
    return None


__all__ = ["PLANES", "PLANE_DEG", "STEP_DEG", "Angles", "plane_profile"]
