"""What every kind of footprint answers: :class:`Kind`, the base each kind's module
(:mod:`.circle`, :mod:`.ellipse`, :mod:`.rounded_rectangle`) fills in, and the pieces they
share (a footprint read from a polygon, :class:`Fit`; how it is drawn in a CAD file,
:class:`Curve`; turning points and rings).

A kind's methods take ``size [n, k]`` (mm, :attr:`Kind.params` in order) and ``angle [n]``
(rad, the long axis from +x, counter-clockwise) arrays; the registry
(:mod:`optdot.geometry.kinds`) numbers the kinds for the compiled kernels.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numba as nb
import numpy as np

#: Sizes of a footprint within this of each other make a disc (:meth:`Kind.disc`), mm:
#: files hold sizes to 1 nm, masks read back to 1-2 nm.
DISC_SLACK = 2e-6
#: Circles per footprint in the multi-sphere penalty (:meth:`Kind.spheres`): at most this
#: many along the long axis.
MAX_SPHERES = 9


class Kind:
    """One kind of footprint: how its size parameters make a shape. Methods take
    ``size [n, k]`` (mm, :attr:`params` in order) and ``angle [n]`` (rad) arrays."""

    #: The kind's name, as a job's ``[dots] shape`` and a file's ``shape`` field say it.
    name: str = ""
    #: Its size parameters, in the order of ``size``'s columns.
    params: tuple[str, ...] = ()
    #: Whether the footprint is the same at every angle (then ``angle`` is ignored).
    round: bool = False
    #: The kind's number in a packed footprint (the registry's ``packed``, the compiled
    #: kernels: the registry's order).
    code: int = -1
    #: Size parameters that may be 0 (the others are lengths of at least the smallest dot).
    zero_params: tuple[str, ...] = ()
    #: The penalty term the relaxation holds this kind's gaps with (a name the
    #: relaxation's own registry of terms knows: ``"exact_gap"``, ``"spheres"``).
    relaxation: str = "exact_gap"
    #: The form of :meth:`curve` in general (a CAD file's ELLIPSE is the kind drawn so).
    curve_form: str = "bulged"
    #: The size parameter (index) a CAD file's arcs give exactly (a corner radius drawn
    #: as bulges), or None.
    arc_param: int | None = None
    #: ``[dots]`` keys the kind reads besides its size parameters (name: types).
    keys: dict[str, tuple[type, ...]] = {}
    #: Whether the size parameters come from those keys (:meth:`from_job`), not the job.
    derived: bool = False
    #: The least turn that maps a footprint onto itself, rad (its angles are equal
    #: modulo it).
    period: float = math.pi
    #: Words for a footprint of this kind made per job from other keys than the job's
    #: (:attr:`derived`: a polygon "of other vertices").
    made_otherwise: str = ""
    #: The 3-D profiles (:mod:`optdot.geometry.profile`) its footprint takes: a cap on a
    #: circle or an ellipse, a micro-prism on a rectangle; ink on any.
    profiles: tuple[str, ...] = ("ink",)

    def __reduce__(self):
        """Pickled by name, so a kind sent to a worker or read in a child process comes
        back as the registry's own (kinds are compared by identity)."""
        return (kind_named, (self.name,))

    def from_job(self, dots: dict, where: str) -> tuple[Kind, tuple[float, ...]]:
        """The job's kind and size when :attr:`derived` (the kind's own keys of
        ``dots``, a job's ``[dots]``).

        Raises:
            ValueError: the keys do not make a footprint (the message names the key).
        """
        raise NotImplementedError

    def from_spec(self, spec: dict) -> Kind:
        """The kind a file's :meth:`spec` gives, when :attr:`derived`.

        Raises:
            ValueError: the spec does not make the kind (the message names the field).
        """
        raise NotImplementedError

    def unlike(self, other: Kind) -> str:
        """Words for how this kind differs from ``other`` beyond its name and size (a
        kind made per job from other keys: :attr:`made_otherwise`), or ``""``."""
        return self.made_otherwise if other != self and other.name == self.name else ""

    def spec(self) -> dict:
        """What a file holds to name this kind besides its name (a JSON object; empty
        for the registry's kinds, which the name alone gives)."""
        return {}

    def packed_extra(self, size: np.ndarray) -> np.ndarray | None:
        """``[n, e]`` numbers the compiled ``inside`` reads after the packed row's six
        (:func:`~optdot.geometry.kinds.packed`), or None."""
        return None

    def profile_frame(self, size: tuple[float, ...]) -> tuple[float, float, float]:
        """``(half length, half width, corner radius)`` of a footprint of ``size`` (mm,
        :attr:`params` in order) along its own axes, mm: the frame a 3-D profile's body
        stands on (a kind that takes only ink has none)."""
        raise NotImplementedError(f"a {self.name} takes no 3-D profile")

    def inradius(self, size: np.ndarray) -> np.ndarray:
        """``[n]`` the radius of the largest disc about the centre inside each footprint
        (half the width), mm: two footprints whose centres are nearer than twice it
        (plus the gap) are too close at any angles."""
        return 0.5 * size[:, 1]

    def aspect(self, size: np.ndarray) -> np.ndarray:
        """``[n]`` how elongated each footprint is: length over width."""
        return size[:, 0] / size[:, 1]

    def narrowest(self, size: np.ndarray) -> np.ndarray:
        """``[n]`` each footprint's least width, mm (its width)."""
        return size[:, 1].astype(np.float64, copy=True)

    def fill_share(self, size: np.ndarray) -> np.ndarray:
        """``[n]`` the share of the fill limit of dots of its aspect that footprints of
        ``size`` are dealt at (1: their curved or blunt corners do not lower it)."""
        return np.ones(len(size))

    def angle_lever(self, size: np.ndarray) -> float:
        """How far a footprint of ``size`` (``[k]`` mm) reaches to show its angle, mm: a
        size off by ``e`` reads as an angle off by about ``e`` over it (the length less
        the width; 0: its angle cannot be read)."""
        return float(size[0] - size[1]) if len(size) > 1 else 0.0

    def shape_params(self, size: np.ndarray) -> np.ndarray:
        """``[n, 3]`` the numbers the kind's compiled ``inside`` tests a point against, mm
        (or mm²)."""
        raise NotImplementedError

    def bound_params(self, size: np.ndarray) -> np.ndarray:
        """``[n, 2]`` the numbers the kind's compiled ``support_bound`` takes, mm: its
        support, or a bound of it from above, cheap enough for a pair prefilter."""
        raise NotImplementedError

    def problem(self, size: tuple[float, ...]) -> str | None:
        """Why a job's footprint of ``size`` (mm, :attr:`params` in order) cannot be drawn,
        beyond the sizes every kind checks (None: it can)."""
        return None

    def spheres(self, size: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(t [k] mm, r [k] mm)``: the circles standing for one footprint of ``size``
        (``[k]`` mm) in the multi-sphere penalty, centred along its long axis at ``t``."""
        raise NotImplementedError

    def curve(self, size: np.ndarray) -> Curve:
        """How a CAD file draws one footprint of ``size`` (``[k]`` mm) at angle 0 about
        the origin with its own curves (a disc, an ellipse, arcs and lines)."""
        raise NotImplementedError

    def disc(self, size: np.ndarray) -> np.ndarray:
        """``[n]`` the diameter of the disc each footprint of ``size`` (``[n, k]`` mm) is,
        mm, NaN where it is not a disc (its sizes equal within :data:`DISC_SLACK`): how a
        circle a mask reader recognises matches a kind that draws a disc."""
        return np.full(len(size), np.nan)

    def undrawable(self, size: np.ndarray) -> np.ndarray:
        """``[n]`` bool: sizes (``[n, k]`` mm) no footprint of this kind has (a width
        not > 0, a length under the width; NaN)."""
        return ~(size[:, 1] > 0) | ~(size[:, 0] >= size[:, 1])

    def drawable(self, size: np.ndarray) -> np.ndarray:
        """``size`` (``[n, k]`` mm, rounded to 1 nm) kept drawable after the rounding
        (a capsule's corner radius not over half its rounded width)."""
        return size

    def support(self, theta: np.ndarray, size: np.ndarray, angle: np.ndarray) -> np.ndarray:
        """The support function ``h(θ) = max over the footprint of ⟨p, u(θ)⟩`` (mm, about
        the centre) in the directions ``theta`` (rad): what :meth:`separation` maximises
        ``⟨d, u⟩ - h_i - h_j`` over."""
        raise NotImplementedError

    def area(self, size: np.ndarray) -> np.ndarray:
        """``[n]`` areas, mm²."""
        raise NotImplementedError

    def extent(self, size: np.ndarray) -> np.ndarray:
        """``[n]`` bounding radii about the centre, mm."""
        raise NotImplementedError

    def equivalent_diameter(self, size: np.ndarray) -> np.ndarray:
        """``[n]`` diameters of the discs of the same areas, mm: what sets a dot's
        spacing, its count and the coverage it is counted at."""
        return 2.0 * np.sqrt(self.area(size) / np.pi)

    def gap(
        self,
        d: np.ndarray,
        size_i: np.ndarray,
        angle_i: np.ndarray,
        size_j: np.ndarray,
        angle_j: np.ndarray,
    ) -> np.ndarray:
        """``[m]`` edge-to-edge distances of pairs whose centres differ by ``d`` (``[m,
        2]`` mm, j minus i), mm; negative: the footprints overlap."""
        return self.separation(d, size_i, angle_i, size_j, angle_j)[0]

    def separation(
        self,
        d: np.ndarray,
        size_i: np.ndarray,
        angle_i: np.ndarray,
        size_j: np.ndarray,
        angle_j: np.ndarray,
    ) -> tuple[np.ndarray, np.ndarray]:
        """``(gap [m] mm, u [m, 2])``: :meth:`gap` and the unit direction it is measured
        along (from i toward j): moving j along ``u`` widens the gap at rate 1, the
        gap's gradient in ``d``."""
        raise NotImplementedError

    def outline(self, size: np.ndarray, angle: float, tolerance: float) -> np.ndarray:
        """``[v, 2]`` vertices (counter-clockwise, mm, about the centre) of a polygon
        within ``tolerance`` mm of one footprint of ``size`` (``[k]``) at ``angle``."""
        raise NotImplementedError

    def fit(self, points: np.ndarray, slack: float, share: float = 0.0) -> Fit:
        """The footprint a polygon's vertices (``[v, 2]``, any unit) draw: what a mask
        reader recognises a dot by. A vertex may stray from the fitted outline by
        ``slack`` (same unit: the file's grid) plus ``share`` of the footprint's size."""
        raise NotImplementedError

    # the parallel bodies a printing process makes of a footprint (optdot.printing):
    # grown by a signed distance g (a print's dot gain; negative: shrunk, an etch's bias)

    def perimeter(self, size: np.ndarray) -> np.ndarray:
        """``[n]`` perimeters, mm (Steiner's formula: a convex footprint grown by ``g``
        covers ``area + perimeter g + π g²``)."""
        raise NotImplementedError

    def curvature_floor(self, size: np.ndarray) -> np.ndarray:
        """``[n]`` the smallest radius of curvature of the outline, mm (0 at a sharp
        corner): the largest distance it can be shrunk by and grown back exactly."""
        raise NotImplementedError

    def parallel(self, size: np.ndarray, g: float) -> np.ndarray | None:
        """``[n, k]`` the sizes of the footprints (``size [n, k]`` mm) grown by ``g`` mm
        (shrunk when negative: the inner parallel body) when that is a footprint of this
        kind, else None (an ellipse's parallel curve is not an ellipse)."""
        return None

    def parallel_outline(self, size: np.ndarray, g: float, tolerance: float) -> np.ndarray:
        """``[v, 2]`` vertices (counter-clockwise, mm, about the centre, angle 0) of a
        polygon inscribed within ``tolerance`` mm in one footprint of ``size`` (``[k]``)
        grown by ``g`` mm (shrunk when negative)."""
        grown = self.parallel(np.asarray(size, float)[None, :], g)
        return self.outline(grown[0], 0.0, tolerance)

    def fit_grown(self, points: np.ndarray, g: float, slack: float, share: float = 0.0) -> Fit:
        """The footprint that a polygon (``[v, 2]``, any unit) draws shrunk by ``g``
        (same unit; grown when negative): :meth:`fit` of the polygon, grown back by
        ``g``. What a mask reader recognises a compensated dot's print by."""
        f = self.fit(points, slack, share)
        grown = self.parallel(f.size[None, :], g) if f.ok else None
        if grown is None:
            return f
        return Fit(f.ok, f.centre, grown[0], f.angle, (f.radii[0] + g, f.radii[1] + g))


@nb.njit(cache=True, inline="always")
def unit_toward(wx, wy):  # pragma: no cover - compiled
    """``(ux, uy)``: the unit vector along ``(wx, wy)``, or ``(1, 0)`` for the zero vector
    (the direction from a point of a Minkowski sum to a centres' difference that is it)."""
    n = math.sqrt(wx * wx + wy * wy)
    if n == 0.0:
        return 1.0, 0.0
    return wx / n, wy / n


def rotate(p: np.ndarray, angle: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(x, y)`` of points ``p`` (``[m, 2]``) in frames turned by ``angle`` (``[m]`` rad):
    the coordinates along and across each dot's long axis."""
    c, s = np.cos(angle), np.sin(angle)
    return c * p[:, 0] + s * p[:, 1], -s * p[:, 0] + c * p[:, 1]


def turned(ring: np.ndarray, angle: float) -> np.ndarray:
    """``ring`` (``[v, 2]``) turned counter-clockwise by ``angle`` rad about the origin."""
    if angle == 0.0:
        return ring
    c, s = math.cos(angle), math.sin(angle)
    return ring @ np.array([[c, s], [-s, c]])


def axis_angle(v: np.ndarray) -> float:
    """The angle of the axis along ``v`` (``[2]``), rad, in ``(-π/2, π/2]``."""
    a = math.atan2(float(v[1]), float(v[0]))
    if a <= -0.5 * math.pi:
        a += math.pi
    elif a > 0.5 * math.pi:
        a -= math.pi
    return a


@dataclass(frozen=True)
class Curve:
    """One footprint as a CAD file's curves, about the origin, mm.

    Attributes:
        form: ``"disc"`` (radius ``a``), ``"ellipse"`` (half axes ``a`` along x and ``b``)
            or ``"bulged"`` (a closed polyline, ``ring [v, 3]``: x, y and the bulge of the
            segment each vertex starts: 0 for a line, ``tan(θ/4)`` for an arc of θ).
        a, b: the half axes. ring: the bulged ring.
    """

    form: str
    a: float = 0.0
    b: float = 0.0
    ring: tuple[tuple[float, float, float], ...] = ()


@dataclass(frozen=True)
class Fit:
    """A footprint recognised from a polygon (:meth:`Kind.fit`).

    Attributes:
        ok: whether the polygon is this kind. centre: ``[2]`` its centre. size: ``[k]``
        its size parameters. angle: its orientation, rad. radii: the smallest and
        largest distance of a vertex from the centre (for messages). All in the
        polygon's unit.
    """

    ok: bool
    centre: np.ndarray
    size: np.ndarray
    angle: float
    radii: tuple[float, float]


#: Fewest vertices a polygon needs to be read as a round dot (an octagon).
MIN_VERTICES = 8


def polygon_vertices(radius: float, tolerance: float) -> int:
    """Vertices of a regular polygon inscribed in a circle of ``radius`` that stays within
    ``tolerance`` of it (same unit), at least 8."""
    t = min(tolerance, radius)
    return max(MIN_VERTICES, math.ceil(math.pi / math.acos(1.0 - t / radius)))


#: Every kind, by name, in the order of their codes (filled by the registry,
#: :mod:`optdot.geometry.kinds`).
REGISTRY: dict[str, Kind] = {}


def kind_named(name: str) -> Kind:
    """The registry's kind of ``name`` (what a pickled kind comes back as)."""
    return REGISTRY[name]
