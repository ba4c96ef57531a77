"""The registry of dot kinds: each kind one module (:mod:`.circle`, :mod:`.ellipse`,
:mod:`.rounded_rectangle`), a :class:`~.base.Kind` with its size parameters, numerics,
drawing and reading, and two compiled kernels (``inside``: whether a point lies on a
packed footprint; ``support_bound``: its support or a bound from above). A new kind is one
module and one line in :data:`KINDS` and in each dispatch below (its code is its place).

numba's cache keys a compiled function by its own file only: after editing a kind's
kernels, a command run from the checkout keeps the old code inlined in the dispatch
below until the cached kernels are cleared (``find optdot -name '*.nb[ic]' -delete``);
the tests compile into a cache named by the kernels' sources (``tests/conftest.py``).
"""

from __future__ import annotations

import numba as nb
import numpy as np

from . import circle, ellipse, rounded_rectangle
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
from .rounded_rectangle import RoundedRect

#: Every kind, by name; a kind's code is its place here.
KINDS: dict[str, Kind] = REGISTRY
for _code, _kind in enumerate((Circle(), Ellipse(), RoundedRect())):
    assert _kind.code == _code, f"{_kind.name}: code {_kind.code} is not its place {_code}"
    KINDS[_kind.name] = _kind
#: The circle, the kind of every pattern that does not name one.
CIRCLE = KINDS["circle"]


def shaped_names() -> str:
    """The kinds other than the circle, quoted, for messages (``"ellipse" or ...``)."""
    names = [f'"{k.name}"' for k in KINDS.values() if k is not CIRCLE]
    return ", ".join(names[:-1]) + " or " + names[-1] if len(names) > 1 else names[0]


def kinds_text() -> str:
    """Every kind with its article and spaces, for messages (``a circle, an ellipse or
    a rounded rectangle``)."""
    words = [k.name.replace("_", " ") for k in KINDS.values()]
    named = [("an " if w[0] in "aeiou" else "a ") + w for w in words]
    return ", ".join(named[:-1]) + " or " + named[-1]


def drawn_as(form: str) -> Kind:
    """The kind whose :meth:`~.base.Kind.curve` is of ``form`` in general
    (:attr:`~.base.Kind.curve_form`: an ELLIPSE entity read from a CAD file is that
    kind's footprint)."""
    return next(k for k in KINDS.values() if k.curve_form == form)


def packed(kind: Kind, size: np.ndarray, angle: np.ndarray | None) -> np.ndarray:
    """``[n, 6]`` footprints as the compiled kernels take them: kind code, the kind's
    three :meth:`Kind.shape_params`, and the cosine and sine of the angle."""
    n = len(size)
    a = np.zeros(n) if angle is None else np.broadcast_to(angle, (n,))
    out = np.empty((n, 6))
    out[:, 0] = kind.code
    out[:, 1:4] = kind.shape_params(size)
    out[:, 4], out[:, 5] = np.cos(a), np.sin(a)
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
    return rounded_rectangle.inside(f, k, dx, dy)


@nb.njit(cache=True)
def contains_packed(f, p):  # pragma: no cover - compiled
    """``[m]`` whether each point ``p[k]`` (mm, from its dot's centre) lies on packed
    footprint ``f[k]``."""
    out = np.empty(p.shape[0], np.bool_)
    for k in range(p.shape[0]):
        out[k] = on_packed(f, k, p[k, 0], p[k, 1])
    return out


@nb.njit(cache=True, inline="always")
def support_bound(code, c, s, a, b, cp, sp):  # pragma: no cover - compiled
    """The support of a footprint of kind ``code`` (:meth:`Kind.bound_params` ``a``,
    ``b``; the angle's cosine ``cp`` and sine ``sp``) in the direction ``(c, s)``, or a
    bound of it from above: its kind's ``support_bound``."""
    if code == 0:
        return circle.support_bound(c, s, a, b, cp, sp)
    if code == 1:
        return ellipse.support_bound(c, s, a, b, cp, sp)
    return rounded_rectangle.support_bound(c, s, a, b, cp, sp)


__all__ = [
    "CIRCLE",
    "DISC_SLACK",
    "GAP_NEWTON",
    "GAP_SAMPLES",
    "KINDS",
    "MIN_VERTICES",
    "Circle",
    "Curve",
    "Ellipse",
    "Fit",
    "Kind",
    "RoundedRect",
    "axis_angle",
    "contains_packed",
    "drawn_as",
    "gap_samples",
    "kind_named",
    "kinds_text",
    "on_packed",
    "packed",
    "polygon_vertices",
    "rotate",
    "shaped_names",
    "support_bound",
    "turned",
]
