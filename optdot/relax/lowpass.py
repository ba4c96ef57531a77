"""Long-wavelength correction: the coverage error the local penalty cannot see, removed by
one global displacement field.

Why. The penalty (3) is local: each circle meets its six or so neighbours. A region a
few millimetres wide with 0.3 % too many dots raises the pressure so little that L-BFGS
stops (its ``ftol`` plateau, ~60 iterations) long before such a mode relaxes, since the
relaxation time of a density mode grows with the square of its wavelength. So the
pattern keeps the long-wavelength grain of its initial throw (scrambled Sobol: 0.28 %
RMS through a 0.5 mm Gaussian on a uniform 0.20 map). The displacement that
removes such a mode is tiny (0.3 % at 3 mm wavelength: ~1.5 µm), far inside every
container; it only has to be computed globally.

How. The dots' area is deposited on a grid of ``h`` (cloud-in-cell), the map's fill on
the same grid, both blurred by a Gaussian of ``sigma`` (a few dot spacings: only what
the local relaxation cannot fix), and their relative difference ``e`` taken where the
map is not zero. The continuity equation, linearised, says moving every dot by ``u =
∇φ`` with ``∇²φ = e`` changes the coverage by ``-e``: dots leave the dense regions for
the sparse ones. ``φ`` is solved by a cosine transform (Neumann walls: nothing flows
across the panel's box) and ``u`` interpolated at the dots. The dots and their
containers move together; the local relaxation that follows tidies the short range.

Blurs mirror the grid at its border (:data:`BLUR_MODE`), the image the Neumann walls
imply: an error beside a wall is blurred over the panel's side alone, and the step
removes all of it. Blurred against zeros past the wall (and divided by the map blurred
alike, half the map's there) an excess in the first row along a wall is spread over a
kernel half outside, and a step removes ln 2 = 69 % of it.

The panel's pass (:func:`coarse_field`) goes further, because it is the last word on
what the eye sees (BENCHMARKS.md):

- It moves *coverage*, not relative error: the flux ``F = ∇ψ`` with ``∇²ψ`` the
  blurred coverage error (fill, not relative), each dot moved by ``F / c`` (``c`` the
  map's blurred fill). Moving dots by ``∇φ`` with ``∇²φ`` the relative error changes
  the coverage by ``-c e - ∇c·∇φ``: where the map is steep (an LED edge: fill 0.03 to
  0.17 within 1.25 mm of the wall) the second term is as large as the first and the
  step misses: the led sample's strongest blob 0.96 JND, p99 0.49, against 0.48 and 0.24.
- Its error is the cells' excess each divided by the share of the blur that falls on
  live cells around it (the lit cells inside the outline) before it is blurred: every
  cell's excess is then spread over live cells whole, as the mirror does at the box,
  at a hole's or a zero region's border too.
- Its potential lives on the live cells: nothing flows across a face to a cell with no
  map (a hole, a notch, a zero region), solved by conjugate gradients preconditioned by
  the box's cosine transform (:func:`live_potential`); the box's transform alone, when
  every cell is live. A flow through a notch the dots cannot follow left the outline
  sample 0.23 % short at the notch's convex corner (-1.41 JND); on the live cells,
  +0.41 JND there and nowhere over 0.5.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numba as nb
import numpy as np
from scipy.fft import dctn, idctn, next_fast_len
from scipy.ndimage import gaussian_filter, label, map_coordinates

from ..geometry.density import DensityMap
from ..geometry.domain import Domain
from ..spatial.window import bounds

#: Grid cells at most (memory: a few float64 arrays of this size).
MAX_CELLS = 1 << 25
#: Largest displacement, in dot spacings.
MAX_SHIFT = 0.1
#: How a blur extends the grid past its border: mirrored about it, the image the Neumann
#: walls imply (module docstring). A tile's region border that is not a wall lies 4
#: sigmas or more from the windows it is solved for, past the Gaussian's reach.
BLUR_MODE = "reflect"
#: Smallest share of a cell's blur on live cells its excess is divided by (a convex
#: corner's is a quarter): an isolated live cell's error is not amplified past 4 times.
MIN_SHARE = 0.25
#: The map's fill a face's flux is divided by, at least, as a share of its mean over the
#: live cells (a face in a zero region's penumbra, where few dots stand; the cap bounds
#: what they are moved by).
MIN_FILL = 0.05
#: Conjugate-gradient iterations of :func:`live_potential` at most, and its tolerance.
CG_ITER = 60
CG_RTOL = 1e-6


def grid_step(density: DensityMap, spacing: float) -> float:
    """Grid step for a pattern of median spacing ``spacing`` (mm): half a spacing, coarser
    where the grid would exceed :data:`MAX_CELLS`."""
    area = density.width * density.height
    return max(0.5 * spacing, math.sqrt(area / MAX_CELLS))


def _deposit(xy: np.ndarray, weight: np.ndarray, x0: float, y0: float, h, shape):
    """Cloud-in-cell deposit of ``weight`` (``[n]``) at ``xy`` on a ``shape`` grid of
    step ``h = (hx, hy)`` from ``(x0, y0)`` (cell centres at ``x0 + (i + 0.5) hx``),
    ``[ny, nx]``. A dot inside the grid's box keeps all its weight (what falls past a
    border cell's centre lands in that cell: at a wall, nothing is lost); a dot outside
    it (a neighbour tile's, around a tile's window) gives only the share that falls in.
    Compiled (:func:`_cic`); the same sums, in the same order, as four ``np.bincount``
    of the cloud's corners added in turn (tests/test_coarse_field.py holds it to them)."""
    ny, nx = shape
    xy = np.ascontiguousarray(xy, dtype=np.float64)
    weight = np.ascontiguousarray(np.broadcast_to(np.asarray(weight, np.float64), len(xy)))
    return _cic(xy, weight, float(x0), float(y0), float(h[0]), float(h[1]), nx, ny)


@nb.njit(cache=True)
def _cic(xy, weight, x0, y0, hx, hy, nx, ny):  # pragma: no cover - compiled
    """:func:`_deposit`'s sums: each corner of the clouds in turn, dots in index order,
    into a grid of its own that is then added to the total."""
    n = xy.shape[0]
    out = np.zeros((ny, nx))
    part = np.zeros((ny, nx))
    for corner in range(4):
        dx = corner // 2
        dy = corner % 2
        part[:] = 0.0
        for k in range(n):
            gx = (xy[k, 0] - x0) / hx - 0.5
            gy = (xy[k, 1] - y0) / hy - 0.5
            ix = int(np.floor(gx))
            iy = int(np.floor(gy))
            fx = gx - ix
            fy = gy - iy
            inside = (gx >= -0.5) & (gx < nx - 0.5) & (gy >= -0.5) & (gy < ny - 0.5)
            cx = ix + dx
            cy = iy + dy
            if not (inside or (cx >= 0 and cx < nx and cy >= 0 and cy < ny)):
                continue
            wx = fx if dx else 1.0 - fx
            wy = fy if dy else 1.0 - fy
            part[min(max(cy, 0), ny - 1), min(max(cx, 0), nx - 1)] += weight[k] * wx * wy
        out += part
    return out


Window = tuple[float, float, float, float]


def window_grid(window: Window, h: float) -> tuple[int, int, float, float]:
    """``(nx, ny, hx, hy)``: the grid of step about ``h`` (a little finer, so the cosine
    transform's lengths have small prime factors) over ``window``."""
    x0, y0, x1, y1 = window
    nx = next_fast_len(max(2, round((x1 - x0) / h)), real=True)
    ny = next_fast_len(max(2, round((y1 - y0) / h)), real=True)
    return nx, ny, (x1 - x0) / nx, (y1 - y0) / ny


def coverage_error(
    xy: np.ndarray, area: np.ndarray, density: DensityMap, h: float, sigma: float,
    window: Window, domain: Domain | None = None,
) -> np.ndarray:  # fmt: skip
    """``[ny, nx]`` relative coverage error on the grid of step ``h`` over ``window``,
    blurred by ``sigma`` mm: (dots - map) / map where the map is not zero, else 0.

    Args:
        xy: ``[n, 2]`` dot centres, mm. area: ``[n]`` dot areas, mm².
        window: ``(x0, y0, x1, y1)``, mm, inside the map's box: every dot in it given.
        domain: the panel; the map counts only inside it (each grid cell by its share).
    """
    nx, ny, hx, hy = window_grid(window, h)
    # the map's mean over each grid cell (sampling it at the centres would alias its cell
    # edges against the grid: a moiré the correction would then print)
    target = density.resampled(window[0], window[1], hx, hy, nx, ny)
    if domain is not None and not domain.rectangle:
        target = target * domain.cell_fractions(window[0], window[1], hx, hy, nx, ny)
    got = _deposit(xy, area, window[0], window[1], (hx, hy), (ny, nx)) / (hx * hy)
    return _relative_error(got, target, (sigma / hy, sigma / hx))


def _relative_error(got: np.ndarray, target: np.ndarray, s: tuple[float, float]) -> np.ndarray:
    """``[ny, nx]`` (dots - map) / map, both blurred by a Gaussian of ``s`` cells (rows,
    columns), where the map is not zero (else 0), less its mean there: the dots'
    coverage ``got`` and the map's ``target`` on one grid, fill per cell. ``got`` and
    ``target`` are not kept (on a panel's lattice a few such arrays are a worker's
    peak)."""
    gt = gaussian_filter(target, s, mode=BLUR_MODE)
    gg = gaussian_filter(got, s, mode=BLUR_MODE)
    live = (target > 0) & (gt > 0)
    del got, target
    e = np.where(live, (gg - gt) / np.where(live, gt, 1.0), 0.0)
    del gt, gg
    if live.any():
        e[live] -= e[live].mean()
    return e


def neumann_potential(e: np.ndarray, hx: float, hy: float) -> np.ndarray:
    """``φ`` with ``∇²φ = e`` (discrete 5-point Laplacian, zero normal gradient at the
    grid's border, zero mean), ``[ny, nx]``, in ``e``'s precision (float64 or float32)."""
    ny, nx = e.shape
    lx = (2.0 * np.cos(np.pi * np.arange(nx) / nx) - 2.0) / (hx * hx)
    ly = (2.0 * np.cos(np.pi * np.arange(ny) / ny) - 2.0) / (hy * hy)
    lam = ly[:, None] + lx[None, :]
    lam[0, 0] = 1.0
    c = dctn(e, type=2, norm="ortho")
    c /= lam
    c[0, 0] = 0.0
    return idctn(c, type=2, norm="ortho")


def gradient_at(
    phi: np.ndarray, hx: float, hy: float, row: np.ndarray, col: np.ndarray
) -> np.ndarray:
    """``∇φ`` at fractional cell indices ``(row, col)`` (``[m]`` each; cell centres at
    integers), ``[m, 2]`` (x, y components): ``np.gradient(phi, hy, hx)`` (central
    differences inside, one-sided at the border) interpolated bilinearly with indices
    clamped to the grid, as ``scipy.ndimage.map_coordinates(..., order=1,
    mode="nearest")`` does, but differenced only at the four cells around each point,
    not over the whole grid (the tiles' correction samples nine windows a tile, each at
    a quarter to all of the tile's dots: ``tests/test_coarse_field.py`` holds it to
    numpy's and scipy's). ``phi`` is ``[ny, nx]`` (float64, or float32: differenced in
    double precision) with ``nx, ny >= 2``."""
    return _gradient_at(
        np.ascontiguousarray(phi), float(hx), float(hy),
        np.ascontiguousarray(row, dtype=np.float64), np.ascontiguousarray(col, dtype=np.float64),
    )  # fmt: skip


@nb.njit(cache=True, inline="always")
def _diff(phi, j, i, axis, h):  # pragma: no cover - compiled
    """``np.gradient``'s derivative of ``phi`` along ``axis`` (0 rows, 1 columns) at
    cell ``(j, i)``: central inside, one-sided at the border."""
    n = phi.shape[axis]
    k = j if axis == 0 else i
    if k == 0:
        lo, hi, span = 0, 1, h
    elif k == n - 1:
        lo, hi, span = n - 2, n - 1, h
    else:
        lo, hi, span = k - 1, k + 1, 2.0 * h
    if axis == 0:
        return (np.float64(phi[hi, i]) - np.float64(phi[lo, i])) / span
    return (np.float64(phi[j, hi]) - np.float64(phi[j, lo])) / span


@nb.njit(cache=True)
def _gradient_at(phi, hx, hy, row, col):  # pragma: no cover - compiled
    ny, nx = phi.shape
    out = np.empty((row.shape[0], 2))
    for p in range(row.shape[0]):
        r0 = np.floor(row[p])
        c0 = np.floor(col[p])
        tr = row[p] - r0
        tc = col[p] - c0
        ux = 0.0
        uy = 0.0
        for dr in range(2):
            j = min(max(int(r0) + dr, 0), ny - 1)
            wr = tr if dr else 1.0 - tr
            for dc in range(2):
                i = min(max(int(c0) + dc, 0), nx - 1)
                w = wr * (tc if dc else 1.0 - tc)
                ux += w * _diff(phi, j, i, 1, hx)
                uy += w * _diff(phi, j, i, 0, hy)
        out[p, 0] = ux
        out[p, 1] = uy
    return out


def live_potential(a: np.ndarray, live: np.ndarray, hx: float, hy: float) -> np.ndarray:
    """``ψ`` with ``∇²ψ = a`` on the ``live`` cells (``[ny, nx]`` bool), no flow across a
    face to a dead cell or across the grid's border, ``[ny, nx]`` (0 on dead cells).

    ``a`` is taken less its mean over each connected piece of live cells (nothing flows
    between them). The box's cosine transform
    (:func:`neumann_potential`) when every cell is live; else conjugate gradients on the
    live cells' 5-point Laplacian, preconditioned by that transform (exact but for the
    faces to dead cells, so a few tens of iterations; at most :data:`CG_ITER`)."""
    from scipy.sparse.linalg import LinearOperator, cg  # loaded when a map has dead cells

    if live.all():
        return neumann_potential(a, hx, hy)
    ny, nx = a.shape
    wx = (live[:, 1:] & live[:, :-1]) / (hx * hx)
    wy = (live[1:, :] & live[:-1, :]) / (hy * hy)
    dead = ~live

    def minus_laplacian(v: np.ndarray) -> np.ndarray:
        p = v.reshape(ny, nx)
        out = np.zeros_like(p)
        d = (p[:, 1:] - p[:, :-1]) * wx
        out[:, :-1] -= d
        out[:, 1:] += d
        d = (p[1:, :] - p[:-1, :]) * wy
        out[:-1, :] -= d
        out[1:, :] += d
        out[dead] = p[dead]  # dead cells decoupled: identity, right-hand side 0
        return out.ravel()

    def box_inverse(v: np.ndarray) -> np.ndarray:
        r = v.reshape(ny, nx).copy()
        r[dead] = 0.0
        r[live] -= r[live].mean()
        z = -neumann_potential(r, hx, hy)
        z[dead] = 0.0
        return z.ravel()

    b = np.where(live, -a, 0.0)
    # each piece of live cells cut off from the others (an island in a zero region) keeps
    # its own coverage: its right-hand side has zero mean of its own
    pieces, count = label(live)
    if count > 1:
        means = np.bincount(pieces.ravel(), b.ravel()) / np.bincount(pieces.ravel())
        b = np.where(live, b - means[pieces], 0.0)
    n = nx * ny
    psi, _ = cg(
        LinearOperator((n, n), matvec=minus_laplacian, dtype=float), b.ravel(),
        rtol=CG_RTOL, maxiter=CG_ITER, M=LinearOperator((n, n), matvec=box_inverse, dtype=float),
    )  # fmt: skip
    return np.where(live, psi.reshape(ny, nx), 0.0)


def displacement(
    xy: np.ndarray,
    area: np.ndarray,
    density: DensityMap,
    spacing: float,
    sigma_share: float,
    window: Window | None = None,
    domain: Domain | None = None,
) -> np.ndarray:
    """``[n, 2]`` displacement (mm) of the dots at ``xy`` that removes their coverage
    error at wavelengths longer than about ``sigma_share`` spacings.

    Args:
        xy: ``[n, 2]`` dot centres, mm. area: ``[n]`` dot areas, mm².
        spacing: median dot spacing, mm.
        sigma_share: the error's blur, in spacings.
        window: the part of the map to correct (default the map's box); nothing flows
            across its border. Every dot in it must be given; dots given outside it count
            with the share of their cloud that falls in.
        domain: the panel (an outline: the map counts only inside it).

    The displacement is capped at :data:`MAX_SHIFT` spacings: the grain it removes needs
    micrometres, and a larger error (a map step sharper than the dots can follow) is the
    local relaxation's to settle, not a reason to move many dots far.
    """
    box = (density.x0, density.y0, density.x0 + density.width, density.y0 + density.height)
    if window is not None:
        box = (max(box[0], window[0]), max(box[1], window[1]),
               min(box[2], window[2]), min(box[3], window[3]))  # fmt: skip
    h = grid_step(density, spacing)
    e = coverage_error(xy, area, density, h, sigma_share * spacing, box, domain)
    ny, nx = e.shape
    hx, hy = (box[2] - box[0]) / nx, (box[3] - box[1]) / ny
    phi = neumann_potential(e, hx, hy)
    row = (xy[:, 1] - box[1]) / hy - 0.5
    col = (xy[:, 0] - box[0]) / hx - 0.5
    u = gradient_at(phi, hx, hy, row, col)
    size = np.hypot(u[:, 0], u[:, 1])
    cap = MAX_SHIFT * spacing
    return u * np.minimum(1.0, cap / np.maximum(size, 1e-300))[:, None]


class RegionError:
    """The blurred relative coverage error over a region of a lattice shared by every tile
    (origin the map's corner, step ``h``), for the windows a tile blends
    (:func:`optdot.orchestration.tiling.tasks.correct_tile`): deposited, resampled and blurred once
    for
    the region, then solved window by window (:meth:`field`). Two tiles that solve the same
    window snap it to the same lattice lines and see the same dots there, so they get the
    same field.

    Attributes:
        i0, j0: lattice index of the region's first column and row.
        h: lattice step, mm. x0, y0: the lattice's origin, mm.
        e: ``[ny, nx]`` relative error (0 where the map is 0), not mean-corrected.
        live: ``[ny, nx]`` bool, where the map is not zero.
    """

    def __init__(
        self, xy: np.ndarray, area: np.ndarray, density: DensityMap, h: float, sigma: float,
        region: Window, domain: Domain | None = None,
    ) -> None:  # fmt: skip
        self.h, self.x0, self.y0 = h, density.x0, density.y0
        self.mx = mx = int(math.ceil(density.width / h - 1e-9))
        self.my = my = int(math.ceil(density.height / h - 1e-9))
        self.i0 = max(0, int(math.floor((region[0] - self.x0) / h)))
        self.j0 = max(0, int(math.floor((region[1] - self.y0) / h)))
        i1 = min(mx, int(math.ceil((region[2] - self.x0) / h)))
        j1 = min(my, int(math.ceil((region[3] - self.y0) / h)))
        nx, ny = max(1, i1 - self.i0), max(1, j1 - self.j0)
        ox, oy = self.x0 + self.i0 * h, self.y0 + self.j0 * h
        target = density.resampled(ox, oy, h, h, nx, ny)
        if domain is not None and not domain.rectangle:
            target = target * domain.cell_fractions(ox, oy, h, h, nx, ny)
        got = _deposit(xy, area, ox, oy, (h, h), (ny, nx)) / (h * h)
        s = sigma / h
        gt = gaussian_filter(target, s, mode=BLUR_MODE)
        gg = gaussian_filter(got, s, mode=BLUR_MODE)
        self.live = (target > 0) & (gt > 0)
        self.e = np.where(self.live, (gg - gt) / np.where(self.live, gt, 1.0), 0.0)

    def field(self, window: Window, at: np.ndarray, cap: float) -> np.ndarray:
        """``[m, 2]`` displacement (mm, capped at ``cap``) at the points ``at`` from the
        Neumann solution over ``window`` snapped to the lattice (inside the region)."""
        h = self.h
        a = max(0, int(round((window[0] - self.x0) / h)) - self.i0)
        b = max(0, int(round((window[1] - self.y0) / h)) - self.j0)
        c = min(self.e.shape[1], int(round((window[2] - self.x0) / h)) - self.i0)
        d = min(self.e.shape[0], int(round((window[3] - self.y0) / h)) - self.j0)
        e = self.e[b:d, a:c].copy()
        live = self.live[b:d, a:c]
        if e.shape[0] < 2 or e.shape[1] < 2 or not live.any():
            return np.zeros((len(at), 2))
        e[live] -= e[live].mean()
        # zeros up to lengths the cosine transform is fast at, a few cells past a side
        # that is not a wall (a wall keeps its zero flux): the same for every tile
        pads = []
        for axis, (lo, hi, end) in enumerate(((b, d, self.my), (a, c, self.mx))):
            extra = next_fast_len(e.shape[axis], real=True) - e.shape[axis]
            first = self.j0 if axis == 0 else self.i0
            if first + hi < end:
                pads.append((0, extra))
            elif first + lo > 0:
                pads.append((extra, 0))
            else:
                pads.append((0, 0))
        # in single precision: the transforms take half the time, and the potential's
        # relative error (~1e-7) moves no dot by a nanometre (the shift is capped at
        # 0.1 spacing)
        e = np.pad(e.astype(np.float32), pads)
        phi = neumann_potential(e, h, h)
        ox = self.x0 + (self.i0 + a - pads[1][0]) * h
        oy = self.y0 + (self.j0 + b - pads[0][0]) * h
        row = (at[:, 1] - oy) / h - 0.5
        col = (at[:, 0] - ox) / h - 0.5
        u = gradient_at(phi, h, h, row, col)
        size = np.hypot(u[:, 0], u[:, 1])
        return u * np.minimum(1.0, cap / np.maximum(size, 1e-300))[:, None]


@dataclass(frozen=True)
class Lattice:
    """A regular grid over a box: cell ``(j, i)`` has its centre at
    ``(x0 + (i + 0.5) hx, y0 + (j + 0.5) hy)``, mm; ``[ny, nx]`` cells."""

    x0: float
    y0: float
    hx: float
    hy: float
    nx: int
    ny: int

    @classmethod
    def over(cls, box: Window, h: float, max_cells: int) -> Lattice:
        """The lattice of step about ``h`` mm (coarser when it would exceed ``max_cells``)
        that fits ``box`` exactly."""
        h = max(h, math.sqrt((box[2] - box[0]) * (box[3] - box[1]) / max_cells))
        nx, ny, hx, hy = window_grid(box, h)
        return cls(box[0], box[1], hx, hy, nx, ny)


@dataclass(frozen=True)
class LatticePart:
    """Dots' weights deposited on a part of a :class:`Lattice`: ``w`` ``[rows, cols]``
    covering cells ``j0..j0 + rows - 1`` and ``i0..i0 + cols - 1``."""

    i0: int
    j0: int
    w: np.ndarray


def deposit_part(xy: np.ndarray, weight: np.ndarray, lattice: Lattice) -> LatticePart:
    """Cloud-in-cell deposit of ``weight`` (``[n]``) at ``xy`` (``[n, 2]`` mm) on the
    cells around the dots' bounds: the parts of disjoint sets of dots added in a fixed
    order equal (to rounding) one deposit of all of them, and each part is only as large
    as its dots' box.

    The lattice is the panel's: a dot past its box (the relaxation's soft walls let a
    dot by a wall a few micrometres out, until the guarantee pass brings it back) is
    deposited at the box's edge with all its weight. Left out, the notebook panel's one
    dot 5 µm past its LED edge read as a dot missing to the wide pass, which pulled its
    neighbours in; the guarantee pass then put it back 0.2 mm inside, one dot too many
    there: 1.90 JND, the panel's strongest blob."""
    g = lattice
    if not len(xy):
        return LatticePart(0, 0, np.zeros((0, 0)))
    x1, y1 = g.x0 + g.nx * g.hx, g.y0 + g.ny * g.hy
    edge = 1e-9 * max(g.hx, g.hy)  # inside the last cell, not on its far face
    xy = np.column_stack([
        np.clip(xy[:, 0], g.x0, x1 - edge), np.clip(xy[:, 1], g.y0, y1 - edge),
    ])  # fmt: skip
    lo0, lo1, hi0, hi1 = bounds(xy)
    lo, hi = (lo0, lo1), (hi0, hi1)
    # one cell past the cells each dot's cloud reaches: no weight is clipped at a part's
    # side unless that side is the lattice's own (where a full deposit clips it too)
    i0 = max(0, int(math.floor((lo[0] - g.x0) / g.hx)) - 1)
    j0 = max(0, int(math.floor((lo[1] - g.y0) / g.hy)) - 1)
    i1 = min(g.nx, int(math.floor((hi[0] - g.x0) / g.hx)) + 2)
    j1 = min(g.ny, int(math.floor((hi[1] - g.y0) / g.hy)) + 2)
    ox, oy = g.x0 + i0 * g.hx, g.y0 + j0 * g.hy
    return LatticePart(i0, j0, _deposit(xy, weight, ox, oy, (g.hx, g.hy), (j1 - j0, i1 - i0)))


@dataclass(frozen=True)
class CoarseField:
    """The long-wavelength correction of a whole panel at once, solved on a coarse lattice
    (:func:`coarse_field`): ``ux`` ``[ny, nx + 1]`` and ``uy`` ``[ny + 1, nx]`` the
    displacement that removes the blurred coverage error (mm) on the cells' vertical and
    horizontal faces (0 on the walls), float32 on ``lattice``; ``cap`` the largest
    displacement, mm. Every worker that moves dots holds each field a tiled run makes (the
    wide pass's rounds), so it holds nothing more."""

    lattice: Lattice
    ux: np.ndarray
    uy: np.ndarray
    cap: float

    def _coords(self, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        g = self.lattice
        return (y - g.y0) / g.hy - 0.5, (x - g.x0) / g.hx - 0.5

    def to_arrays(self) -> dict[str, np.ndarray]:
        """The field as named arrays (:meth:`from_arrays` reads them back, bit for bit)."""
        g = self.lattice
        box = np.array([g.x0, g.y0, g.hx, g.hy, self.cap], np.float64)
        return {"box": box, "shape": np.array([g.nx, g.ny], np.int64),
                "ux": self.ux, "uy": self.uy}  # fmt: skip

    @classmethod
    def from_arrays(cls, a: dict[str, np.ndarray]) -> CoarseField:
        """The field :meth:`to_arrays` wrote."""
        x0, y0, hx, hy, cap = (float(v) for v in a["box"])
        nx, ny = (int(v) for v in a["shape"])
        return cls(Lattice(x0, y0, hx, hy, nx, ny), a["ux"], a["uy"], cap)

    def displacement(self, at: np.ndarray) -> np.ndarray:
        """``[m, 2]`` displacement (mm, capped at ``cap``) of the dots at ``at``."""
        row, col = self._coords(at[:, 0], at[:, 1])
        u = np.empty((len(at), 2))
        u[:, 0] = map_coordinates(self.ux, [row, col + 0.5], np.float64, order=1, mode="nearest")
        u[:, 1] = map_coordinates(self.uy, [row + 0.5, col], np.float64, order=1, mode="nearest")
        size = np.hypot(u[:, 0], u[:, 1])
        return u * np.minimum(1.0, self.cap / np.maximum(size, 1e-300))[:, None]


def steepness(density: DensityMap, lattice: Lattice, sigma: float) -> float:
    """The largest relative change of the map's fill (deposited on ``lattice`` and blurred
    by ``sigma`` mm, as :func:`coarse_field` sees it) between two neighbouring live cells:
    ``|c1 - c2| / min(c1, c2)``. Where it is large, the dots of one cell sit at fills far
    apart and move by one interpolated flux, and one linear step of the field misses."""
    g = lattice
    target = density.deposited(g.x0, g.y0, g.hx, g.hy, g.nx, g.ny)
    live = target > 0
    c = gaussian_filter(target, (sigma / g.hy, sigma / g.hx), mode=BLUR_MODE)
    del target
    worst = 0.0
    for a, b, la, lb in (
        (c[:, 1:], c[:, :-1], live[:, 1:], live[:, :-1]),
        (c[1:, :], c[:-1, :], live[1:, :], live[:-1, :]),
    ):
        both = la & lb
        if both.any():
            r = np.abs(a - b)[both] / np.maximum(np.minimum(a, b)[both], 1e-300)
            worst = max(worst, float(r.max()))
    return worst


def coarse_field(
    parts: list[LatticePart], lattice: Lattice, density: DensityMap, sigma: float, cap: float,
    domain: Domain | None = None,
) -> CoarseField:  # fmt: skip
    """The panel's coverage error blurred by ``sigma`` mm from the deposits ``parts`` (added
    in the order given) of all its dots, and the displacement that removes it: the flow
    of coverage over the live cells divided by the map's fill (module docstring).

    Like :func:`coverage_error` and :func:`displacement` over the panel's box, but from
    parts each deposited by one tile, so the panel's dots never meet in one process."""
    g = lattice
    got = np.zeros((g.ny, g.nx))
    for p in parts:
        rows, cols = p.w.shape
        got[p.j0 : p.j0 + rows, p.i0 : p.i0 + cols] += p.w
    got /= g.hx * g.hy
    # the map as the same cloud-in-cell deposit sees it: against its cell means, a
    # coarse lattice mistakes the deposit's own smoothing for an error where the map is
    # steep or meets a wall (led sample, 0.16 mm cells: 3 % at the LED corner)
    target = density.deposited(g.x0, g.y0, g.hx, g.hy, g.nx, g.ny)
    if domain is not None and not domain.rectangle:  # the outline deposited alike
        target = target * domain.deposited_fractions(g.x0, g.y0, g.hx, g.hy, g.nx, g.ny, density)
    s = (sigma / g.hy, sigma / g.hx)
    live = target > 0
    # each cell's excess divided by the share of its blur that lands on live cells, then
    # blurred (module docstring): spread whole over the live cells around it
    share = gaussian_filter(live.astype(np.float64), s, mode=BLUR_MODE)
    a = np.where(live, (got - target) / np.maximum(share, MIN_SHARE), 0.0)
    del got, share
    a = np.where(live, gaussian_filter(a, s, mode=BLUR_MODE), 0.0)
    if live.any():
        a[live] -= a[live].mean()
    cover = gaussian_filter(target, s, mode=BLUR_MODE)  # the map's fill at the blur
    del target
    psi = live_potential(a, live, g.hx, g.hy)
    del a
    # the flux on the cells' faces over the map's fill there, 0 on the walls' and on
    # faces to dead cells (nothing flows across them): a lattice cell is a few spacings,
    # and a gradient at the border cells' centres, taken as it is out to the wall, slid
    # the whole first strip of dots into the wall
    floor = MIN_FILL * float(cover[live].mean()) if live.any() else 1.0
    ux = np.zeros((g.ny, g.nx + 1), np.float32)
    uy = np.zeros((g.ny + 1, g.nx), np.float32)
    cx = np.maximum(0.5 * (cover[:, 1:] + cover[:, :-1]), floor)
    ux[:, 1:-1] = np.diff(psi, axis=1) / g.hx / cx * (live[:, 1:] & live[:, :-1])
    del cx
    cy = np.maximum(0.5 * (cover[1:, :] + cover[:-1, :]), floor)
    uy[1:-1, :] = np.diff(psi, axis=0) / g.hy / cy * (live[1:, :] & live[:-1, :])
    return CoarseField(g, ux, uy, cap)
