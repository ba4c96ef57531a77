"""A dot's 3-D profile: what a moulded, embossed or laser-dotted guide's dot is beyond its
footprint. ``ink`` (the default) is a printed layer, flat; ``bump`` is a spherical cap of
the guide's material standing ``height`` mm out of the face on the circle's footprint;
``dimple`` a spherical cap of air cut ``depth`` mm into it. The tracer meets the cap
exactly (:mod:`optdot.optics.faces.dot_profile`)."""

from __future__ import annotations

from dataclasses import dataclass

#: Profiles by code (a face table's ``F_PROFILE``), and the ``[dots]`` key of each one's
#: height (none for ink).
PROFILES = ("ink", "bump", "dimple")
HEIGHT_KEY = {"bump": "height", "dimple": "depth"}
#: How each profile's height reads in words ("bumps 10 µm high").
HEIGHT_WORD = {"bump": "high", "dimple": "deep"}


@dataclass(frozen=True)
class DotProfile:
    """A dot's profile.

    Attributes:
        kind: one of :data:`PROFILES`.
        height: how far a bump stands out of the face, or a dimple is cut into it, mm
            (0 for ink).
    """

    kind: str = "ink"
    height: float = 0.0

    @property
    def code(self) -> int:
        """The profile's code in the tracer's face table."""
        return PROFILES.index(self.kind)

    def aspect(self, radius: float) -> float:
        """The cap's height over the footprint's ``radius`` (mm): 1 a hemisphere."""
        return self.height / radius
