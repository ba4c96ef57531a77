"""The tables a traced scene is made of, and the codes the tracer's kernels read them by:
the rays' fates, the emitters', layers' and faces' columns, the face kinds, and the
records (:class:`Scene`: :class:`Sources`, :class:`Stack`, :class:`Print`) that
:mod:`optdot.optics.scene` builds from a job and :func:`optdot.optics.trace.trace` reads.
"""

from __future__ import annotations

from typing import NamedTuple

import numba as nb
import numpy as np

#: Fates of a ray (``trace`` output).
EXTRACTED, BULK, DOT, EDGE, BOTTOM, UNCOUPLED, UNFINISHED, SHEET = range(8)
FATES = (
    "extracted",
    "absorbed_bulk",
    "absorbed_dots",
    "lost_edges",
    "lost_bottom",
    "not_coupled",
    "unfinished",
    "absorbed_sheets",
)
#: Events (reflections, scatterings) after which a ray is given up (``unfinished``;
#: reported, never silently dropped).
MAX_EVENTS = 1 << 16

# -- the scene's tables: column indices ------------------------------------------------
#: Emitter ``[e, 17]``: centre (3), axis (3, unit), tangent (3), second tangent (3), width
#: along the tangent, span and start along the second tangent (a point is centre +
#: tangent (u - 1/2) width + second (v span + start)), profile index, layer.
E_C, E_A, E_T, E_B, E_W, E_SPAN, E_START, E_PROF, E_LAYER = 0, 3, 6, 9, 12, 13, 14, 15, 16
E_COLS = 17
#: Layer ``[L, 7]``: z0, z1 (mm), index, absorption (1/mm), wall cover's reflectance, its
#: finish (0 diffuse, 1 specular, 2 absorbing), the walls' critical cosine (0 when none).
L_Z0, L_Z1, L_N, L_ABS, L_WALL_R, L_WALL_MODE, L_WALL_COS = range(7)
L_COLS = 7
#: Face ``[L + 1, F_COLS]``: kind, printed (0 no, 1 the job's print, 2 the second map), dot
#: R, dot T, reflector (BOTTOM), dot extract (0/1), haze (0 none, 1 Lambertian, 2
#: Gaussian), haze sigma (rad), sheet T, sheet R, sheet spread (0 Lambertian, 1 Gaussian),
#: its sigma (rad), critical cosine going up, going down (0 when there is none), the
#: reflector's finish (BOTTOM: 0 diffuse, 1 specular), whether a ray meeting the face
#: draws the print test's number (1: a printed face, and the reflector face even bare,
#: so that a stack's rays draw their numbers in the order they always have), the dots'
#: 3-D profile (:data:`~optdot.geometry.profile.INK`, ``BUMP``, ...) and a cap's height
#: over the footprint's half width, the footprint's half length, half width and corner
#: radius (mm, along its own axes), a prism's facets' tangents (its start's, its end's),
#: and how far the tallest raised dot stands out of the face (mm: where the reflector
#: sheet lies under raised dots; 0 for the others).
(F_KIND, F_PRINT, F_DOT_R, F_DOT_T, F_REFL, F_EXTRACT, F_HAZE, F_HAZE_SIG, F_SHEET_T) = range(9)
F_SHEET_R, F_SPREAD, F_SPREAD_SIG, F_COS_UP, F_COS_DOWN, F_REFL_FINISH, F_TEST = range(9, 16)
F_PROFILE, F_PROF_K, F_PROF_U, F_PROF_V, F_PROF_C, F_PROF_T1, F_PROF_T2 = range(16, 23)
F_PROF_H = 23
F_COLS = 24


# numba types a constant handed to a kernel as a literal (``True``, ``-1``) and compiles
# the kernel again for each: the tracer's kernels are handed these instead, and compile once.
@nb.njit(cache=True, inline="always")
def var_bool(value):  # pragma: no cover - compiled
    """``value`` as a bool typed at run time, not as the literal constant it may be."""
    return bool(value)


@nb.njit(cache=True, inline="always")
def var_int(value):  # pragma: no cover - compiled
    """``value`` as an int typed at run time, not as the literal constant it may be."""
    return int(value)


@nb.njit(cache=True, inline="always")
def face_row(face, fi):  # pragma: no cover - compiled
    """Face ``fi`` of the table ``face`` as a tuple of its ``F_COLS`` numbers, read by the
    ``F_*`` columns: what a face's kernel is handed (a tuple is passed by value; the
    table itself, handed to a kernel at every event, costs the tracer's speed)."""
    return (
        face[fi, 0], face[fi, 1], face[fi, 2], face[fi, 3], face[fi, 4], face[fi, 5],
        face[fi, 6], face[fi, 7], face[fi, 8], face[fi, 9], face[fi, 10], face[fi, 11],
        face[fi, 12], face[fi, 13], face[fi, 14], face[fi, 15], face[fi, 16], face[fi, 17],
        face[fi, 18], face[fi, 19], face[fi, 20], face[fi, 21], face[fi, 22], face[fi, 23],
    )  # fmt: skip


assert F_COLS == 24, "face_row reads every column"
#: Face kinds (:mod:`optdot.optics.faces`: what each does to a ray).
BOTTOM_FACE, INTERFACE, SHEET_FACE, PRISM_FACE = 0, 1, 2, 3
#: What a face or a wall did to a ray that goes on (a fate, ``>= 0``, ends it): turned it
#: back without changing its horizontal course, sent it on a new course in the same layer,
#: let it through into the layer on the other side, or (cut dots) brought it, inside their
#: layer, onto the panel's wall where it now stands (the tracer turns it off the wall).
SAME_LEG, NEW_LEG, CROSS, AT_WALL = -1, -2, -3, -4


class Sources(NamedTuple):
    """The emitters and their angular profiles.

    Attributes:
        emit: ``[e, E_COLS]`` emitters (see ``E_*``), mm.
        start: ``[e + 1]`` int64 first global ray of each emitter (the last = the total).
        theta: ``[K]`` angles in air, rad, of the profiles' CDFs.
        cdf: ``[p, K]`` the CDF of ``I(theta) sin(theta)`` per profile.
        mode: ``[p, 2]`` (0 table / 1 collimated, the collimated tilt in rad).
    """

    emit: np.ndarray
    start: np.ndarray
    theta: np.ndarray
    cdf: np.ndarray
    mode: np.ndarray


class Stack(NamedTuple):
    """Layers, faces and walls (see ``L_*``, ``F_*``).

    Attributes:
        layer: ``[L, L_COLS]``. face: ``[L + 1, F_COLS]``.
        walls: ``[m, 4]`` wall segments (ax, ay, bx, by), mm. normals: ``[m, 2]`` inward.
        max_events: events after which a ray is given up (``unfinished``).
    """

    layer: np.ndarray
    face: np.ndarray
    walls: np.ndarray
    normals: np.ndarray
    max_events: int


class Print(NamedTuple):
    """What is printed: on faces marked 1 the job's map (its coverage) or its real dots; on
    faces marked 2 a second coverage map (the other printed face of a stack).

    Attributes:
        explicit: trace real dots (True) or the coverage map ``phi``.
        phi: ``[ny, nx]`` coverage; g: ``[4]`` its x0, y0, dx, dy, mm.
        start: ``[cells + 1]`` CSR of dots by cell; x, y: ``[n]`` centres, mm; foot:
            ``[n, 6]`` their footprints (:func:`optdot.geometry.shapes.packed`); cg:
            ``[7]`` cell grid x0, y0, dx, dy, nx, ny and the largest dot extent (cells
            at least that wide).
        phi2, g2: the second coverage map and its grid (as ``phi``, ``g``).
        cap_start, cap: the caps of print 1 (solid ink discs, tested before the dots or
            the coverage, so ``phi`` is the coverage where no cap is): ``[cells + 1]``
            CSR by cell and ``[m, 3]`` rows ``(x, y, r^2)``, mm; cap_g: ``[7]`` their
            cell grid (as ``cg``).
        cap_ring: ``[k, 2]`` the rings each cap prints, ``(r_in^2, r_out^2)`` mm^2 about
            its centre (a solid cap: ``[[0, inf]]``; graded caps:
            :func:`optdot.geometry.caps.ring_table`).
        turn: ``[ny f nx f, 3]`` the cosine and sine of the dots' angle and their half
            width, mm, in each cell of ``phi`` split ``f`` × ``f`` (row ``iy nx f + ix``
            over the finer cells; a coverage trace of turned 3-D dots, or of dots of
            several sizes; NaN where each dot draws its angle, or all have the job's one
            size), or ``[1, 3]`` NaN (the same everywhere; real dots carry their own
            angles and sizes).
    """

    explicit: bool
    phi: np.ndarray
    g: np.ndarray
    start: np.ndarray
    x: np.ndarray
    y: np.ndarray
    foot: np.ndarray
    cg: np.ndarray
    phi2: np.ndarray
    g2: np.ndarray
    cap_start: np.ndarray
    cap: np.ndarray
    cap_g: np.ndarray
    cap_ring: np.ndarray
    turn: np.ndarray


class Scene(NamedTuple):
    """Everything :func:`trace` reads."""

    sources: Sources
    stack: Stack
    print: Print
