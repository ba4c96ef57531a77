"""What a mask draws for a printed pattern under a :class:`~.process.Process`, and the
print a mask read back stands for: the drawing side of the writers (GDSII, OASIS, DXF)
and the reading side of ``optdot qa``.

Print to mask: each footprint's parallel body at ``-g`` (``g`` the dot gain), at angle 0
about its centre, scaled by ``1 / (1 - shrink)``; centres mirrored and scaled; all on the
address grid. Mask to print: the inverse, each footprint fitted as the print it grows to
(:meth:`~optdot.geometry.kinds.base.Kind.fit_grown`).
"""

from __future__ import annotations

import numpy as np

from ..geometry.kinds import turned
from .process import Process


def mask_ring(process: Process, kind, size: np.ndarray, tolerance: float) -> np.ndarray:
    """``[v, 2]`` the mask's polygon (mm, counter-clockwise, about the centre, angle 0) of
    one printed footprint of ``size`` (``[k]`` mm): its parallel body at ``-g`` within
    ``tolerance`` mm, scaled, each vertex on the grid."""
    ring = kind.parallel_outline(np.asarray(size, float), -process.dot_gain, tolerance)
    return _on_grid(process, _thinned(ring * process.scale, process.grid))


def mask_polygons(
    process: Process, kind, size: np.ndarray, xy: np.ndarray, angle: np.ndarray, box, tolerance
) -> list[np.ndarray]:
    """The mask's polygons (mm, counter-clockwise, each vertex on the grid) of printed
    footprints of one ``size`` (``[k]`` mm) at ``xy`` (``[n, 2]`` mm) turned by ``angle``
    (``[n]`` rad), one each: what a writer draws when a reference cannot place the cell of
    :func:`mask_ring` exactly (a turned dot off the grid, a scale per axis)."""
    ring = kind.parallel_outline(np.asarray(size, float), -process.dot_gain, tolerance)
    ring = _thinned(ring, process.grid / float(np.min(process.scale)))
    out = []
    for (x, y), t in zip(np.asarray(xy, float).tolist(), np.asarray(angle).tolist(), strict=True):
        pts = process.place(turned(ring, float(t)) + (x, y), box)
        out.append(pts[::-1] if process.reflects else pts)
    return out


def placed_whole(process: Process, kind, angle: np.ndarray | None) -> bool:
    """Whether a reference to the cell of :func:`mask_ring` draws these dots exactly, on
    the grid: round dots or dots at angle 0 always; turned ones only when the mask is
    scaled alike along both axes and has no grid coarser than the file's."""
    if kind.round or angle is None or not np.any(angle):
        return True
    return process.isotropic and process.grid <= 0


def mask_rings(process: Process, rings: list[np.ndarray], box) -> list[np.ndarray]:
    """The panel's boundary loops (``[k, 2]`` mm each) on the mask, each running the way
    it ran (a mirror would turn exteriors clockwise)."""
    out = [process.place(r, box) for r in rings]
    return [r[::-1] for r in out] if process.reflects else out


def mask_cap_rings(process: Process, rings: np.ndarray) -> np.ndarray:
    """``[k, 2]`` graded caps' rings ``(r_in, r_out)`` mm on the mask: each edge moved in
    by the gain (a ring from the centre keeps its centre), scaled."""
    g = process.dot_gain
    inner = np.where(rings[:, 0] > 0, rings[:, 0] + g, 0.0)
    return np.column_stack([inner, rings[:, 1] - g]) * float(process.scale[0])


def printed_cap_rings(process: Process, rings: np.ndarray) -> np.ndarray:
    """:func:`mask_cap_rings`' inverse: the printed rings of rings read off a mask."""
    g = process.dot_gain
    r = rings / float(process.scale[0])
    return np.column_stack([np.where(r[:, 0] > 0, r[:, 0] - g, 0.0), r[:, 1] + g])


def unscaled(process: Process, pts: np.ndarray) -> np.ndarray:
    """Points of a mask (``[v, 2]``, any unit) at the print's scale, same unit: what a
    footprint is fitted on."""
    return pts / (process.scale if not process.isotropic else float(process.scale[0]))


def printed_box(process: Process, rings: list[np.ndarray]) -> tuple[float, float, float, float]:
    """The printed panel's box from its loops read off a mask (mm): the mirror keeps a
    box where it is, so the unscaled box is the print's."""
    pts = np.concatenate(rings) / process.scale
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    return (float(lo[0]), float(lo[1]), float(hi[0]), float(hi[1]))


#: Nearest two vertices of a ring may lie before it is put on a grid, in grid steps: each
#: moves by at most half a step's diagonal (0.71), so vertices further apart than √2 steps
#: keep their order and never fall on one grid point (no repeated vertex, no ring that
#: crosses itself).
GRID_SPACING = 1.5


def _thinned(ring: np.ndarray, grid: float) -> np.ndarray:
    """``ring`` (``[v, 2]``, a convex outline's inscribed polygon) keeping only vertices
    :data:`GRID_SPACING` grid steps or more from the last kept (and from the first): still
    inscribed, each chord a little longer. Unchanged without a grid."""
    if grid <= 0 or len(ring) < 4:
        return ring
    step = GRID_SPACING * grid
    keep = [0]
    for k in range(1, len(ring)):
        if np.hypot(*(ring[k] - ring[keep[-1]])) >= step:
            keep.append(k)
    while len(keep) > 3 and np.hypot(*(ring[keep[-1]] - ring[0])) < step:
        keep.pop()
    return ring[keep]


def _on_grid(process: Process, ring: np.ndarray) -> np.ndarray:
    """``ring`` (mm) on the grid, repeated vertices dropped (a grid as coarse as the
    tolerance merges neighbours); without a grid, as drawn (the writer rounds it)."""
    if process.grid <= 0:
        return ring
    ring = process.snap(ring)
    keep = np.any(ring != np.roll(ring, 1, axis=0), axis=1)
    return ring[keep]
