"""What the faces and walls of a traced stack do to a ray: each kind of face one module
(:mod:`.reflector`, :mod:`.interface`, :mod:`.diffuser_sheet`, :mod:`.prism_sheet`; the
walls :mod:`.slab_walls`; the 3-D dots of the bottom face :mod:`.dot_profile`), each
with its compiled ``meet_*`` kernel, and :func:`meet_face` dispatching on the face's
kind (:data:`optdot.optics.tables.BOTTOM_FACE`, ...). A kernel returns ``(state, act,
dx, dy, dz)``: a fate (``>= 0``) that ends the ray, or what it goes on with
(:data:`~optdot.optics.tables.SAME_LEG`, ``NEW_LEG``, ``CROSS``). A new kind of face is
one module, one code in the tables and one line here.

numba's cache keys a compiled function by its own file: after editing a face's kernel,
a command run from the checkout keeps the old code inlined in the tracer until the cached
kernels are cleared (``find optdot -name '*.nb[ic]' -delete``); the tests compile into a
cache named by the kernels' sources (``tests/conftest.py``).
"""

from __future__ import annotations

import numba as nb

from ..tables import BOTTOM_FACE, F_KIND, F_PROFILE, PRISM_FACE, SHEET_FACE
from .diffuser_sheet import meet_sheet
from .dot_profile import meet_profile
from .interface import meet_interface
from .prism_sheet import meet_prism
from .reflector import meet_reflector
from .slab_walls import meet_wall, wall_distance


@nb.njit(cache=True, inline="always")
def meet_face(state, f, up, n, n_to, is_top, ink, at, dxn, dyn, dz):  # pragma: no cover
    """A ray meeting a face (its row ``f``, :func:`~optdot.optics.tables.face_row`), going
    up (``up``) or down from index ``n`` toward ``n_to`` (``is_top``: the top face), on
    the print's ink (``ink``) or not, where on its dot for a 3-D one (``at``,
    :func:`~optdot.optics.marks.dot_frame`'s): its kind's ``meet_*``. The print test is
    the stepping's, and a kernel takes the face's numbers as a tuple: arrays handed to a
    kernel at every event cost the tracer a third of its speed."""
    kind = int(f[F_KIND])
    if kind == SHEET_FACE:
        return meet_sheet(state, f, up, dxn, dyn, dz)
    if kind == PRISM_FACE:
        return meet_prism(state, f, up, dxn, dyn, dz)
    if kind == BOTTOM_FACE:
        if ink and f[F_PROFILE] > 0.5:  # a 3-D dot, not ink
            return meet_profile(state, f, n, at, dxn, dyn, dz)
        return meet_reflector(state, f, n, ink, dxn, dyn, dz)
    return meet_interface(state, f, up, n, n_to, is_top, ink, dxn, dyn, dz)


__all__ = ["meet_face", "meet_wall", "wall_distance"]
