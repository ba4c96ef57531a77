"""Where each dot's long axis points: the orientation field of a job's ``[orientation]``.

A field gives an angle (rad, counter-clockwise from +x, an axis: taken modulo π) at any
point of the panel, so a dot's orientation follows it wherever the dot ends up. A dot
that looks different turned half a turn (a micro-prism whose two facets differ) takes a
direction instead, modulo 2π (``period``): which end faces the LED, which way a random
one points.

- ``constant``: one angle everywhere;
- ``leds``: along (``parallel``) or across (``perpendicular``) the direction from the
  nearest LED, the way micro-prisms face their source;
- ``map``: an angle grid (degrees per cell over the panel box, row 0 = bottom),
  interpolated bilinearly between cell centres as axes (the doubled angle's unit vector
  is interpolated, so 179° and 1° blend to 0°, not 90°);
- ``random``: uniform, from a hash of where the dot was thrown (1 nm) and the seed, so
  the same dot keeps its angle as it moves, whatever order, tile or worker computes it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: The modes a field can have.
MODES = ("constant", "leds", "map", "random")


@dataclass(frozen=True, eq=False)
class Orientation:
    """An orientation field.

    Attributes:
        mode: one of :data:`MODES`.
        angle: the constant angle, rad; for ``leds`` and ``map`` an offset added to the
            field (``leds``: 0 along the direction from the LED, π/2 across it).
        leds: ``[k, 2]`` LED centres, mm (``leds``).
        grid: ``[ny, nx]`` angles, rad (``map``).
        box: ``(x0, y0, x1, y1)`` the grid covers, mm (``map``).
        seed: the hash's seed (``random``).
        period: the turn that maps a dot onto itself, rad: π for an axis (a footprint,
            a symmetric profile), 2π for a direction (a prism whose facets differ).
    """

    mode: str = "constant"
    angle: float = 0.0
    leds: np.ndarray | None = None
    grid: np.ndarray | None = None
    box: tuple[float, float, float, float] = (0.0, 0.0, 1.0, 1.0)
    seed: int = 0
    period: float = np.pi

    @property
    def follows_position(self) -> bool:
        """Whether the angle is a function of where a dot stands (not ``random``)."""
        return self.mode != "random"

    def at(self, xy: np.ndarray, thrown: np.ndarray | None = None) -> np.ndarray:
        """``[n]`` angles (rad, in ``(-period/2, period/2]``) of dots centred at ``xy``
        (``[n, 2]`` mm), thrown at ``thrown`` (``[n, 2]`` mm; ``random`` draws from it,
        default ``xy``)."""
        n, p = len(xy), self.period
        if self.mode == "constant":
            return axis(np.full(n, self.angle), p)
        if self.mode == "random":
            return axis(p * _unit_hash(xy if thrown is None else thrown, self.seed), p)
        if self.mode == "leds":
            return axis(self._from_leds(xy) + self.angle, p)
        return axis(self._from_map(xy) + self.angle, p)

    def _from_leds(self, xy: np.ndarray) -> np.ndarray:
        """Direction from the nearest LED, rad."""
        from scipy.spatial import cKDTree

        _, k = cKDTree(self.leds).query(xy)
        d = xy - self.leds[k]
        return np.arctan2(d[:, 1], d[:, 0])

    def _from_map(self, xy: np.ndarray) -> np.ndarray:
        """The grid's angle, interpolated between cell centres as an axis (a direction,
        for a ``period`` of 2π), rad."""
        from scipy.interpolate import RegularGridInterpolator

        g = self.grid
        ny, nx = g.shape
        x0, y0, x1, y1 = self.box
        xs = x0 + (np.arange(nx) + 0.5) * (x1 - x0) / nx
        ys = y0 + (np.arange(ny) + 0.5) * (y1 - y0) / ny
        p = np.column_stack([np.clip(xy[:, 1], ys[0], ys[-1]), np.clip(xy[:, 0], xs[0], xs[-1])])
        parts = []
        m = 2.0 * np.pi / self.period  # 2: the doubled angle's unit vector, for an axis
        for f in (np.cos, np.sin):
            v = f(m * g)
            if ny == 1 or nx == 1:  # one row or column: interpolate along the other
                axis_ = ys if nx == 1 else xs
                col = p[:, 0] if nx == 1 else p[:, 1]
                parts.append(np.interp(col, axis_, v.ravel()))
            else:
                parts.append(RegularGridInterpolator((ys, xs), v)(p))
        return np.arctan2(parts[1], parts[0]) / m


def axis(angle: np.ndarray, period: float = np.pi) -> np.ndarray:
    """Angles (rad) as axes: the same turn modulo ``period`` (π: an axis; a footprint's
    :attr:`~optdot.geometry.kinds.base.Kind.period`), in ``(-period/2, period/2]``."""
    a = np.mod(angle + 0.5 * period, period) - 0.5 * period
    return np.where(a <= -0.5 * period, a + period, a)


def _unit_hash(xy: np.ndarray, seed: int) -> np.ndarray:
    """``[n]`` numbers in ``[0, 1)`` from the positions at 1 nm and ``seed`` (splitmix64
    of both coordinates): the same point gives the same number in any order."""
    q = np.round(xy * 1e6).astype(np.int64).view(np.uint64)
    h = np.uint64(seed & 0xFFFFFFFFFFFFFFFF) ^ np.uint64(0x9E3779B97F4A7C15)
    with np.errstate(over="ignore"):
        for col in (q[:, 0], q[:, 1]):
            h = _mix(h + col)
    return (h >> np.uint64(11)).astype(np.float64) * (1.0 / (1 << 53))


def _mix(z: np.ndarray) -> np.ndarray:
    """splitmix64's finaliser."""
    z = (z ^ (z >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)
    z = (z ^ (z >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
    return z ^ (z >> np.uint64(31))


def led_centres(guide, box: tuple[float, float, float, float]) -> np.ndarray:
    """``[k, 2]`` the LED centres of a light guide's rows on the panel ``box``, mm."""
    x0, y0, x1, y1 = box
    out = []
    for row in guide.leds:
        for p in row.positions:
            out.append(
                {"bottom": (p, y0), "top": (p, y1), "left": (x0, p), "right": (x1, p)}[row.edge]
            )
    return np.asarray(out, dtype=np.float64).reshape(-1, 2)


def degrees(angle: np.ndarray) -> np.ndarray:
    """Angles in degrees, rounded to 1e-6° (what files store)."""
    return np.round(np.degrees(angle), 6)


__all__ = ["MODES", "Orientation", "axis", "degrees", "led_centres"]
