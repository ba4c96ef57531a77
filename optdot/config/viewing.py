"""How the finished panel is seen: viewing distance, screen luminance and the optical blur
of the backlight stack, named by product class (``[qa] view = "notebook"``).

The presets are the usual design points of each class; any field can be overridden
(``[qa] view_distance``, ``view_luminance``, ``psf``; ``optdot qa --view tv --distance
2000``). Where a class spans a range (notebooks are seen from 0.5–0.65 m at 300–500 cd/m²)
the preset takes the near end and the middle luminance: a defect of a few mm, the size
that matters for a dot pattern, is seen best from nearer.

``psf`` is the Gaussian sigma (mm) of the point-spread function from the dot layer to the
viewer: the light guide spreads each dot's light over ~0.3–0.5 × its thickness, and the
diffuser and prism films above add their own blur (their sigmas add in quadrature). To
calibrate it, photograph a test plate (a dot-free line or a single-dot row printed on the
guide, lit in the finished stack) with a camera whose pixel is well under the blur; fit
a Gaussian to the line's profile across it: its sigma is ``psf``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from ..errors import JobError

#: name: (distance mm, luminance cd/m²)
VIEW_PRESETS: dict[str, tuple[float, float]] = {
    "phone": (400.0, 500.0),
    "notebook": (500.0, 400.0),
    "monitor": (600.0, 200.0),
    "tv": (2600.0, 270.0),
}
DEFAULT_VIEW = "notebook"
#: Default Gaussian sigma of the stack's point-spread function, mm: a 0.4–0.8 mm guide
#: (0.1–0.4 mm) under a diffuser and two prism films (together ~1 mm). A guide seen
#: through a single thin diffuser is nearer 0.3 mm.
DEFAULT_PSF = 1.0
#: Width (FWHM) of the region the eye adapts to around each point, degrees.
ADAPTATION_DEG = 2.0


@dataclass(frozen=True)
class Viewing:
    """One viewing condition.

    Attributes:
        name: the preset it came from (or ``"custom"``).
        distance: viewing distance, mm.
        luminance: screen luminance, cd/m².
        psf: Gaussian sigma of the stack's point-spread function at the panel, mm.
        adaptation: FWHM of the adaptation field, degrees.
    """

    name: str
    distance: float
    luminance: float
    psf: float = DEFAULT_PSF
    adaptation: float = ADAPTATION_DEG

    def __post_init__(self) -> None:
        for key, v, lo, hi in (
            ("view_distance", self.distance, 50.0, 1e5),
            ("view_luminance", self.luminance, 1.0, 1e5),
            ("psf", self.psf, 0.001, 100.0),
        ):
            if not (math.isfinite(v) and lo <= v <= hi):
                raise JobError(f"qa.{key} = {v} must be within {lo:g}..{hi:g}")

    @property
    def mm_per_degree(self) -> float:
        """Panel length that subtends one degree at the viewing distance, mm."""
        return self.distance * math.pi / 180.0

    def describe(self) -> str:
        """One line: ``notebook: 500 mm, 400 cd/m², PSF sigma 0.3 mm``."""
        return (
            f"{self.name}: {self.distance:g} mm, {self.luminance:g} cd/m², "
            f"PSF sigma {self.psf:g} mm"
        )


def viewing(
    name: str = DEFAULT_VIEW,
    distance: float | None = None,
    luminance: float | None = None,
    psf: float | None = None,
) -> Viewing:
    """The preset ``name`` with any of its fields overridden.

    Raises:
        JobError: unknown preset name, or a value out of range.
    """
    if name not in VIEW_PRESETS:
        raise JobError(f"qa.view = {name!r} must be one of {', '.join(VIEW_PRESETS)}")
    d, lum = VIEW_PRESETS[name]
    return Viewing(
        name,
        float(d if distance is None else distance),
        float(lum if luminance is None else luminance),
        float(DEFAULT_PSF if psf is None else psf),
    )
