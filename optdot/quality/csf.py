"""The eye's contrast sensitivity: Barten's (1999) model, and the SEMU threshold.

Contrast sensitivity S is the inverse of the modulation threshold of a sinusoidal
luminance grating (50 % detection, two eyes): a grating of modulation ``m`` at spatial
frequency ``u`` is ``m * S(u)`` JND, 1 = just visible. Barten's model (P. G. J. Barten,
*Contrast Sensitivity of the Human Eye and Its Effects on Image Quality*, SPIE 1999,
eq. 3.26; the same in Barten, "Formula for the contrast sensitivity of the human eye",
Proc. SPIE 5294, 2004) builds S from the eye's optics, photon noise, neural noise and
lateral inhibition::

    S(u) = M_opt(u) / k / sqrt( 2/T (1/X0² + 1/Xmax² + u²/Nmax²)
                                  (1/(η p E) + Φ0 / (1 - exp(-(u/u0)²))) )    (1)

    M_opt(u) = exp(-2 π² σ² u²),   σ = sqrt(σ0² + (C_ab d)²)
    d = 5 - 3 tanh(0.4 log10(L X0² / 40²))                 pupil, mm
    E = π d² / 4 · L · (1 - (d/9.7)² + (d/12.4)⁴)           retinal illuminance, Td

with u in cycles/degree, L the adapting luminance (cd/m²) and X0 the object's angular
size (degrees). The constants are Barten's for a standard observer of 20–30 years
(:data:`BARTEN`): k = 3, T = 0.1 s, Xmax = 12°, Nmax = 15 cycles, η = 0.03,
Φ0 = 3·10⁻⁸ s·deg², u0 = 7 cycles/deg, σ0 = 0.5 arcmin, C_ab = 0.08 arcmin/mm, and
p = 1.2274·10⁶ photons/(s·deg²·Td) for a display white (ITU-R BT.2246-4, fig. 31).
The pupil formula takes the base-10 logarithm as Barten does (colour-science's
``pupil_diameter_Barten1999`` takes the natural one; its CSF takes d as an input).

Why Barten and not the Spatial Standard Observer's CSF: Barten's model is physical in
the two quantities a viewing preset changes, the luminance (through the pupil and
photon noise) and the object's angular size, and it is the model display standards
quote (ITU-R BT.2246, DICOM PS3.14's grayscale function is built on it).

Frequencies on the panel convert to the eye's as ``u = f · D · π / 180`` (f cycles/mm,
D the viewing distance in mm; a small-angle form, exact to 0.1 % for objects under 5°).

:func:`semu_threshold` is the SEMI D31 just-noticeable contrast of a mura of area S
(mm²), ``C_jnd = 1.97 / S^0.33 + 0.72`` %: the commonly cited form (SEMI D31-1102, after
Mori et al.), independent of the viewing distance (the standard fixes it).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class BartenConstants:
    """Barten's (1999) observer constants (see the module docstring for units)."""

    k: float = 3.0
    T: float = 0.1
    X_max: float = 12.0
    N_max: float = 15.0
    eta: float = 0.03
    p: float = 1.2274e6
    phi_0: float = 3e-8
    u_0: float = 7.0
    sigma_0: float = 0.5 / 60
    C_ab: float = 0.08 / 60


BARTEN = BartenConstants()


def cycles_per_degree(f_per_mm, distance_mm: float):
    """Spatial frequency at the eye, cycles/degree, of ``f_per_mm`` cycles/mm on a panel
    seen from ``distance_mm``: ``f · D · π / 180`` (one degree spans D·π/180 mm)."""
    return np.asarray(f_per_mm) * distance_mm * math.pi / 180.0


def pupil_diameter(luminance: float, field_deg: float) -> float:
    """Pupil diameter, mm, at ``luminance`` cd/m² for a field of ``field_deg`` degrees
    (Barten 1999, eq. 3.9, base-10 logarithm)."""
    return 5.0 - 3.0 * math.tanh(0.4 * math.log10(luminance * field_deg**2 / 40.0**2))


def retinal_illuminance(luminance: float, pupil_mm: float) -> float:
    """Retinal illuminance, troland, with the Stiles–Crawford correction (Barten 1999)."""
    d = pupil_mm
    return math.pi * d * d / 4.0 * luminance * (1 - (d / 9.7) ** 2 + (d / 12.4) ** 4)


def barten_csf(
    u,
    luminance: float,
    field_deg: float,
    pupil_mm: float | None = None,
    illuminance_td: float | None = None,
    c: BartenConstants = BARTEN,
):
    """Contrast sensitivity S(u) of eq. (1), ``u`` in cycles/degree (array or scalar).

    Args:
        u: spatial frequency, cycles/degree (``>= 0``; S(0) = 0).
        luminance: adapting luminance, cd/m².
        field_deg: angular size of the object X0 = Y0, degrees.
        pupil_mm, illuminance_td: override the pupil diameter (mm) and the retinal
            illuminance (Td) that are otherwise derived from ``luminance`` and ``field_deg``.

    Returns:
        S, same shape as ``u`` (dimensionless; 1/S is the modulation threshold).
    """
    u = np.asarray(u, dtype=float)
    d = pupil_diameter(luminance, field_deg) if pupil_mm is None else pupil_mm
    E = retinal_illuminance(luminance, d) if illuminance_td is None else illuminance_td
    sigma = math.hypot(c.sigma_0, c.C_ab * d)
    m_opt = np.exp(-2 * math.pi**2 * sigma**2 * u**2)
    size = 1 / field_deg**2 + 1 / c.X_max**2 + u**2 / c.N_max**2
    with np.errstate(divide="ignore"):
        inhibition = c.phi_0 / -np.expm1(-((u / c.u_0) ** 2))
    noise = 1 / (c.eta * c.p * E) + inhibition
    # Barten's 1/(X Y) with X = Y = size^-1/2 (X0 = Y0)
    s = m_opt / c.k / np.sqrt(2 / c.T * size * noise)
    return np.where(u > 0, s, 0.0)


def semu_threshold(area_mm2):
    """SEMI D31 just-noticeable contrast of a mura of ``area_mm2``, in % (the commonly
    cited form ``1.97 / S^0.33 + 0.72``)."""
    return 1.97 / np.asarray(area_mm2, dtype=float) ** 0.33 + 0.72
