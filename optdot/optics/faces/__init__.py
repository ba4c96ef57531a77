"""What the faces and walls of a traced stack do to a ray: each kind of face one module
(:mod:`.reflector`, :mod:`.interface`, :mod:`.diffuser_sheet`, :mod:`.prism_sheet`; the
walls :mod:`.slab_walls`; the 3-D dots of the bottom face :mod:`.dot_profile`, met
through :func:`meet_dots`), each with its compiled ``meet_*`` kernel, and
:func:`meet_face` dispatching on the face's kind
(:data:`optdot.optics.tables.BOTTOM_FACE`, ...). A kernel returns ``(state, act, dx, dy,
dz)``: a fate (``>= 0``) that ends the ray, or what it goes on with
(:data:`~optdot.optics.tables.SAME_LEG`, ``NEW_LEG``, ``CROSS``). A new kind of face is
one module, one code in the tables and one line here.

numba's cache keys a compiled function by its own file: after editing a face's kernel,
a command run from the checkout keeps the old code inlined in the tracer until the cached
kernels are cleared (``find optdot -name '*.nb[ic]' -delete``); the tests compile into a
cache named by the kernels' sources (``tests/conftest.py``).
"""

from __future__ import annotations

import numba as nb

from ..marks import BARE, dot_frame
from ..tables import (
    BOTTOM_FACE,
    F_COS_DOWN,
    F_KIND,
    F_PROFILE,
    PRISM_FACE,
    SAME_LEG,
    SHEET_FACE,
    var_int,
)
from .cavities import meet_cut
from .diffuser_sheet import meet_sheet
from .dot_profile import BUMP, DIMPLE, PRISM, PRISM_CUT, leave_between, meet_profile
from .interface import meet_interface
from .prism_sheet import meet_prism
from .reflector import meet_reflector
from .slab_walls import meet_wall, wall_distance


@nb.njit(cache=True, inline="always")
def meet_face(state, f, up, n, n_to, is_top, ink, dxn, dyn, dz):  # pragma: no cover
    """A ray meeting a face (its row ``f``, :func:`~optdot.optics.tables.face_row`), going
    up (``up``) or down from index ``n`` toward ``n_to`` (``is_top``: the top face), on
    the print's ink (``ink``) or not: its kind's ``meet_*`` (a face of 3-D dots:
    :func:`meet_dots`). The print test is the stepping's, and a kernel takes the face's
    numbers as a tuple: arrays handed to a kernel at every event cost the tracer a third
    of its speed."""
    kind = int(f[F_KIND])
    if kind == SHEET_FACE:
        return meet_sheet(state, f, up, dxn, dyn, dz)
    if kind == PRISM_FACE:
        return meet_prism(state, f, up, dxn, dyn, dz)
    if kind == BOTTOM_FACE:
        return meet_reflector(state, f, n, ink, dxn, dyn, dz)
    return meet_interface(state, f, up, n, n_to, is_top, ink, dxn, dyn, dz)


# The 3-D dots' kernels (this one, dot_profile's, cavities') are inlined by LLVM
# (``forceinline``), not by numba (``inline="always"``): numba copies and retypes an
# inlined function's code at every place it is called, which took the tracer's compile
# from 81 s to 116 s (this machine, one process) for no speed.
@nb.njit(cache=True, forceinline=True)
def meet_dots(state, f, n, on, x, y, pr, walls, run, dxn, dyn, dz):  # pragma: no cover
    """A ray going down onto the bottom face of 3-D dots (its row ``f``) from the guide of
    index ``n`` at ``(x, y)`` (mm), on a dot or not (``on``: what
    :func:`~optdot.optics.marks.printed` found there), with the print's
    :func:`~optdot.optics.marks.dot_tables` ``pr`` and the panel's ``walls`` (``run``: how
    far, mm, its course has come over the face since it last turned): a dot's
    ``meet_profile``, the face between raised dots (``leave_between``), or the cut dots'
    cavities its path passes (``meet_cut``): ``(state, act, x, y, z, dx, dy, dz)``, and
    where the ray goes on from (a dot moves it; ``z`` mm over the face). Kept apart from
    :func:`meet_face`: the print's arrays handed to every face's kernel at every event cost
    the tracer half its speed. Among cut dots ``act`` may be ``AT_WALL``: their walk
    brought the ray onto the panel's wall, at ``(x, y)``, ``z`` over the face."""
    profile = f[F_PROFILE]
    x2, y2, z2 = x, y, 0.0
    if profile == DIMPLE or profile == PRISM_CUT:  # among the cavities its path passes
        state, act, x2, y2, z2, dxn, dyn, dz = meet_cut(
            state, f, n, on, x, y, 0.0, pr, walls, dxn, dyn, dz, run
        )
    elif on != BARE:  # on a dot: where on it (a real one), or the coverage cell's angle and size
        at = dot_frame(x, y, on, pr)
        state, act, x2, y2, dxn, dyn, dz = meet_profile(
            state, f, n, at, x, y, pr, walls, dxn, dyn, dz
        )
    elif (profile == BUMP or profile == PRISM) and -dz > f[F_COS_DOWN]:  # out between them
        state, act, x2, y2, dxn, dyn, dz = leave_between(state, f, n, x, y, pr, walls, dxn, dyn, dz)
    else:  # total internal reflection between raised dots, kept inline
        act, dz = SAME_LEG, -dz
    return state, act, x2, y2, z2, dxn, dyn, dz


# called, not inlined: rare (a birth, a wall), and inlined it compiled meet_cut again at
# each of the three places the tracer reaches it (a third of the tracer's compile)
@nb.njit(cache=True)
def born_among_dots(state, f, n, x, y, z, pr, walls, run, dxn, dyn, dz):  # pragma: no cover
    """A ray in the guide at ``(x, y)``, ``z`` mm over its bottom face of 3-D dots (row
    ``f``; index ``n``; ``pr``, ``walls`` and ``run`` as :func:`meet_dots`'), off the face:
    born there or sent back off the panel's wall going up, the cut dots' cavities it passes
    before it leaves their layer; coming down onto the wall there (``z > 0``), the one its
    path passes through before the wall, if any (``meet_cut``, the twins of a coverage
    about a point off them). ``(state, act, x, y, z, dx, dy, dz)``; a ray that meets no
    cavity as it came (``SAME_LEG``)."""
    profile = f[F_PROFILE]
    if (profile == DIMPLE or profile == PRISM_CUT) and (dz > 0 or (dz < 0 and z > 0)):
        return meet_cut(state, f, n, var_int(BARE), x, y, z, pr, walls, dxn, dyn, dz, run)
    return state, SAME_LEG, x, y, z, dxn, dyn, dz


__all__ = ["born_among_dots", "meet_dots", "meet_face", "meet_wall", "wall_distance"]
