"""A dot's 3-D profile: what a moulded, embossed or laser-dotted guide's dot is beyond its
footprint. ``ink`` (the default) is a printed layer, flat. ``bump`` is a cap of the
guide's material standing ``height`` mm out of the face, ``dimple`` a cap of air cut
``depth`` mm into it: a spherical cap on a circle's footprint, on an ellipse's the same
cap stretched along the long axis (a spheroid's: its section across the long axis is the
circle's cap on the short axis). ``prism`` is a micro-prism on a rectangle's (or rounded
rectangle's) footprint: a facet rising from each end of its length at ``facets`` degrees
to the face until the two meet at the ridge, its sides vertical, standing out of the face
or cut into it (``cut``). The tracer meets the surfaces exactly
(:mod:`optdot.optics.faces.dot_profile`), each dot turned as its footprint is.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

#: The profiles a job may name.
PROFILES = ("ink", "bump", "dimple", "prism")
#: The ``[dots]`` key of each cap's height.
HEIGHT_KEY = {"bump": "height", "dimple": "depth"}
#: How each profile's height reads in words ("bumps 10 µm high").
HEIGHT_WORD = {"bump": "high", "dimple": "deep"}
#: The tracer's codes (a face table's ``F_PROFILE``): a prism cut into the face has its own.
INK, BUMP, DIMPLE, PRISM, PRISM_CUT = 0, 1, 2, 3, 4


@dataclass(frozen=True)
class DotProfile:
    """A dot's profile.

    Attributes:
        kind: one of :data:`PROFILES`.
        height: how far a bump or a prism's ridge stands out of the face, or a dimple or
            a cut prism goes into it, mm (0 for ink).
        facets: a prism's facet angles to the face at the start and the end of its
            length, degrees (``(0, 0)`` for the others).
        cut: a prism cut into the face (air in it), not standing out of it (only a
            prism's).
        sized: the dots vary in size: a prism's :attr:`height` is the largest one's (its
            facets keep their angles; a cap's height is every cap's).
    """

    kind: str = "ink"
    height: float = 0.0
    facets: tuple[float, float] = (0.0, 0.0)
    cut: bool = False
    sized: bool = False

    @property
    def code(self) -> int:
        """The profile's code in the tracer's face table."""
        return PRISM_CUT if self.cut else PROFILES.index(self.kind)

    @property
    def keeps_height(self) -> bool:
        """Every dot's cap stands (or sinks) the job's height whatever its size: a bump
        or a dimple (a prism's grows with its length; ink has none)."""
        return self.code in (BUMP, DIMPLE)

    def aspect(self, radius: float) -> float:
        """A cap's height over the footprint's (short) half axis ``radius`` (mm): 1 a
        hemisphere."""
        return self.height / radius

    def words(self) -> str:
        """The dots in words: ``bumps 10 µm high``, ``prisms cut 12 µm deep, facets 45° /
        30°``."""
        um = f"{'up to ' if self.sized else ''}{self.height * 1e3:.3g} µm"
        if self.code >= PRISM:
            a, b = (f"{f:g}°" for f in self.facets)
            how = f"cut {um} deep" if self.cut else f"{um} high"
            return f"prisms {how}, facets {a} / {b}"
        return f"{self.kind}s {um} {HEIGHT_WORD[self.kind]}"

    def summary(self) -> dict:
        """The profile for a simulation's summary (JSON)."""
        out = {"kind": self.kind, "height_mm": self.height}
        if self.code >= PRISM:
            out.update(facets_deg=list(self.facets), cut=self.cut)
            if self.sized:
                out["height_of"] = "the largest dot"
        return out


def prism_height(length: float, facets: tuple[float, float]) -> float:
    """The height of a prism ``length`` mm long whose facets rise at ``facets`` degrees
    from its two ends to their ridge, mm: ``length t1 t2 / (t1 + t2)``."""
    t1, t2 = (math.tan(math.radians(f)) for f in facets)
    return round(length * t1 * t2 / (t1 + t2), 12)  # to 1e-12 mm: 45° makes 0.0599...
