"""The physical sizes optdot accepts, shared by the job reader and the pattern readers.

Anything outside is refused up front, before memory or time is sized from it.
"""

from __future__ import annotations

#: Largest panel side, mm (a 100-inch panel is 2.2 m wide).
MAX_EXTENT_MM = 10_000.0
#: Dot diameters, mm (1 µm .. 10 mm).
DIAMETER_RANGE_MM = (0.001, 10.0)
