"""The registry of dot kinds: each kind one module (:mod:`.circle`, :mod:`.ellipse`,
:mod:`.rounded_rectangle`, :mod:`.polygon`), a :class:`~.base.Kind` with its size
parameters, numerics,
drawing and reading, and two compiled kernels (``inside``: whether a point lies on a
packed footprint; ``support_bound``: its support or a bound from above). A new kind is one
module and one line in :data:`KINDS` and in each dispatch below (its code is its place).

numba's cache keys a compiled function by its own file only: after editing a kind's
kernels, a command run from the checkout keeps the old code inlined in the dispatch
below until the cached kernels are cleared (``find optdot -name '*.nb[ic]' -delete``);
the tests compile into a cache named by the kernels' sources (``tests/conftest.py``).
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

from . import circle, ellipse, polygon, rounded_rectangle
from .base import (
    DISC_SLACK,
    MIN_VERTICES,
    REGISTRY,
    Curve,
    Fit,
    Kind,
    axis_angle,
    kind_named,
    polygon_vertices,
    rotate,
    turned,
)
from .circle import Circle
from .ellipse import GAP_NEWTON, GAP_SAMPLES, Ellipse, gap_samples
from .polygon import MAX_POLYGON_VERTICES, Polygon
from .rounded_rectangle import RoundedRect

#: Every kind, by name; a kind's code is its place here.
KINDS: dict[str, Kind] = REGISTRY
for _code, _kind in enumerate((Circle(), Ellipse(), RoundedRect(), Polygon())):
    assert _kind.code == _code, f"{_kind.name}: code {_kind.code} is not its place {_code}"
    KINDS[_kind.name] = _kind
#: The circle, the kind of every pattern that does not name one.
CIRCLE = KINDS["circle"]


def shaped_names() -> str:
    """The kinds other than the circle, quoted, for messages (``"ellipse" or ...``)."""
    names = [f'"{k.name}"' for k in KINDS.values() if k is not CIRCLE]
    return ", ".join(names[:-1]) + " or " + names[-1] if len(names) > 1 else names[0]


def kinds_text(kinds=None) -> str:
    """Every kind (of ``kinds``, default the registry's) with its article and spaces,
    for messages (``a circle, an ellipse or a rounded rectangle``)."""
    words = [k.name.replace("_", " ") for k in (KINDS.values() if kinds is None else kinds)]
    named = [("an " if w[0] in "aeiou" else "a ") + w for w in words]
    return ", ".join(named[:-1]) + " or " + named[-1]


def kind_of(name: str, spec: dict | None = None) -> Kind:
    """The kind a file names by ``name`` and ``spec`` (:meth:`Kind.spec`): the
    registry's, or for a kind made per job (:attr:`Kind.derived`), the one the spec
    gives.

    Raises:
        ValueError: an unknown name, or a spec that does not make the kind.
    """
    if name not in KINDS:
        raise ValueError(f"shape {name[:40]!r} is not one of {', '.join(KINDS)}")
    kind = KINDS[name]
    return kind.from_spec(spec or {}) if kind.derived else kind


def drawn_as(form: str) -> Kind:
    """The kind whose :meth:`~.base.Kind.curve` is of ``form`` in general
    (:attr:`~.base.Kind.curve_form`: an ELLIPSE entity read from a CAD file is that
    kind's footprint)."""
    return next(k for k in KINDS.values() if k.curve_form == form)


def packed(kind: Kind, size: np.ndarray, angle: np.ndarray | None) -> np.ndarray:
    """``[n, 6 + e]`` footprints as the compiled kernels take them: kind code, the kind's
    three :meth:`Kind.shape_params`, the cosine and sine of the angle, then the kind's
    :meth:`Kind.packed_extra` (none: ``e = 0``)."""
    n = len(size)
    a = np.zeros(n) if angle is None else np.broadcast_to(angle, (n,))
    extra = kind.packed_extra(size)
    out = np.empty((n, 6 + (0 if extra is None else extra.shape[1])))
    out[:, 0] = kind.code
    out[:, 1:4] = kind.shape_params(size)
    out[:, 4], out[:, 5] = np.cos(a), np.sin(a)
    if extra is not None:
        out[:, 6:] = extra
    return out


@nb.njit(cache=True, inline="always")
def on_packed(f, k, dx, dy):  # pragma: no cover - compiled
    """Whether the point ``(dx, dy)`` (mm, from the centre) lies on packed footprint
    ``f[k]`` (:func:`packed`; closed: the edge counts): its kind's ``inside``."""
    code = f[k, 0]
    if code == 0.0:
        return circle.inside(f, k, dx, dy)
    if code == 1.0:
        return ellipse.inside(f, k, dx, dy)
    if code == 2.0:
        return rounded_rectangle.inside(f, k, dx, dy)
    return polygon.inside(f, k, dx, dy)


@nb.njit(cache=True)
def contains_packed(f, p):  # pragma: no cover - compiled
    """``[m]`` whether each point ``p[k]`` (mm, from its dot's centre) lies on packed
    footprint ``f[k]``."""
    out = np.empty(p.shape[0], np.bool_)
    for k in range(p.shape[0]):
        out[k] = on_packed(f, k, p[k, 0], p[k, 1])
    return out


@nb.njit(cache=True, inline="always")
def half_width_packed(f, k):  # pragma: no cover - compiled
    """Packed footprint ``f[k]``'s half width across its long axis, mm (the frame a 3-D
    profile stands on, :meth:`Kind.profile_frame`'s second; NaN for a kind that takes
    only ink)."""
    code = f[k, 0]
    if code == 0.0:
        return circle.half_width(f, k)
    if code == 1.0:
        return ellipse.half_width(f, k)
    if code == 2.0:
        return rounded_rectangle.half_width(f, k)
    return math.nan


@nb.njit(cache=True, inline="always")
def support_bound(code, c, s, a, b, cp, sp):  # pragma: no cover - compiled
    """The support of a footprint of kind ``code`` (:meth:`Kind.bound_params` ``a``,
    ``b``; the angle's cosine ``cp`` and sine ``sp``) in the direction ``(c, s)``, or a
    bound of it from above: its kind's ``support_bound``."""
    if code == 0:
        return circle.support_bound(c, s, a, b, cp, sp)
    if code == 1:
        return ellipse.support_bound(c, s, a, b, cp, sp)
    if code == 2:
        return rounded_rectangle.support_bound(c, s, a, b, cp, sp)
    return polygon.support_bound(c, s, a, b, cp, sp)


__all__ = [
    "CIRCLE",
    "DISC_SLACK",
    "GAP_NEWTON",
    "GAP_SAMPLES",
    "KINDS",
    "MAX_POLYGON_VERTICES",
    "MIN_VERTICES",
    "Circle",
    "Curve",
    "Ellipse",
    "Fit",
    "Kind",
    "Polygon",
    "RoundedRect",
    "axis_angle",
    "contains_packed",
    "drawn_as",
    "gap_samples",
    "kind_named",
    "kind_of",
    "kinds_text",
    "on_packed",
    "packed",
    "polygon_vertices",
    "rotate",
    "shaped_names",
    "support_bound",
    "turned",
]
