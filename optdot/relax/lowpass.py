"""Long-wavelength correction: the coverage error the local penalty cannot see, removed by
one global displacement field.

Why. The penalty (3) is local: each circle meets its six or so neighbours. A region a
few millimetres wide with 0.3 % too many dots raises the pressure so little that L-BFGS
stops (its ``ftol`` plateau, ~60 iterations) long before such a mode relaxes, since the
relaxation time of a density mode grows with the square of its wavelength. So the
pattern keeps the long-wavelength grain of its initial throw (scrambled Sobol: 0.28 %
RMS through a 0.5 mm Gaussian on a uniform 0.20 map; issue 24). The displacement that
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
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.fft import dctn, idctn, next_fast_len
from scipy.ndimage import gaussian_filter, map_coordinates

from ..geometry.density import DensityMap
from ..geometry.domain import Domain

#: Grid cells at most (memory: a few float64 arrays of this size).
MAX_CELLS = 1 << 25
#: Largest displacement, in dot spacings.
MAX_SHIFT = 0.1


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
    it (a neighbour tile's, around a tile's window) gives only the share that falls in."""
    ny, nx = shape
    gx = (xy[:, 0] - x0) / h[0] - 0.5
    gy = (xy[:, 1] - y0) / h[1] - 0.5
    ix = np.floor(gx).astype(np.int64)
    iy = np.floor(gy).astype(np.int64)
    fx, fy = gx - ix, gy - iy
    inside = (gx >= -0.5) & (gx < nx - 0.5) & (gy >= -0.5) & (gy < ny - 0.5)
    out = np.zeros(ny * nx)
    for dx, wx in ((0, 1.0 - fx), (1, fx)):
        for dy, wy in ((0, 1.0 - fy), (1, fy)):
            cx, cy = ix + dx, iy + dy
            keep = inside | ((cx >= 0) & (cx < nx) & (cy >= 0) & (cy < ny))
            cx = np.clip(cx[keep], 0, nx - 1)
            cy = np.clip(cy[keep], 0, ny - 1)
            w = (weight * wx * wy)[keep]
            out += np.bincount(cy * nx + cx, w, minlength=ny * nx)
    return out.reshape(ny, nx)


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
    gt = gaussian_filter(target, s, mode="constant")
    gg = gaussian_filter(got, s, mode="constant")
    live = (target > 0) & (gt > 0)
    del got, target
    e = np.where(live, (gg - gt) / np.where(live, gt, 1.0), 0.0)
    del gt, gg
    if live.any():
        e[live] -= e[live].mean()
    return e


def neumann_potential(e: np.ndarray, hx: float, hy: float) -> np.ndarray:
    """``φ`` with ``∇²φ = e`` (discrete 5-point Laplacian, zero normal gradient at the
    grid's border, zero mean), ``[ny, nx]``."""
    ny, nx = e.shape
    lx = (2.0 * np.cos(np.pi * np.arange(nx) / nx) - 2.0) / (hx * hx)
    ly = (2.0 * np.cos(np.pi * np.arange(ny) / ny) - 2.0) / (hy * hy)
    lam = ly[:, None] + lx[None, :]
    lam[0, 0] = 1.0
    c = dctn(e, type=2, norm="ortho")
    c /= lam
    c[0, 0] = 0.0
    return idctn(c, type=2, norm="ortho")


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
    uy, ux = np.gradient(phi, hy, hx)
    row = (xy[:, 1] - box[1]) / hy - 0.5
    col = (xy[:, 0] - box[0]) / hx - 0.5
    u = np.empty_like(xy)
    u[:, 0] = map_coordinates(ux, [row, col], order=1, mode="nearest")
    u[:, 1] = map_coordinates(uy, [row, col], order=1, mode="nearest")
    size = np.hypot(u[:, 0], u[:, 1])
    cap = MAX_SHIFT * spacing
    return u * np.minimum(1.0, cap / np.maximum(size, 1e-300))[:, None]


class RegionError:
    """The blurred relative coverage error over a region of a lattice shared by every tile
    (origin the map's corner, step ``h``), for the windows a tile blends
    (:func:`optdot.tiling.tasks.correct_tile`): deposited, resampled and blurred once for
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
        gt = gaussian_filter(target, s, mode="constant")
        gg = gaussian_filter(got, s, mode="constant")
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
        e = np.pad(e, pads)
        phi = neumann_potential(e, h, h)
        uy, ux = np.gradient(phi, h, h)
        ox = self.x0 + (self.i0 + a - pads[1][0]) * h
        oy = self.y0 + (self.j0 + b - pads[0][0]) * h
        row = (at[:, 1] - oy) / h - 0.5
        col = (at[:, 0] - ox) / h - 0.5
        u = np.empty((len(at), 2))
        u[:, 0] = map_coordinates(ux, [row, col], order=1, mode="nearest")
        u[:, 1] = map_coordinates(uy, [row, col], order=1, mode="nearest")
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
    """Cloud-in-cell deposit of ``weight`` (``[n]``) at ``xy`` (``[n, 2]`` mm, inside the
    lattice's box) on the cells around the dots' bounds: the parts of disjoint sets of
    dots added in a fixed order equal (to rounding) one deposit of all of them, and each
    part is only as large as its dots' box."""
    g = lattice
    if not len(xy):
        return LatticePart(0, 0, np.zeros((0, 0)))
    lo, hi = xy.min(axis=0), xy.max(axis=0)
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
    (:func:`coarse_field`): ``e`` ``[ny, nx]`` the blurred relative coverage error at the
    cells' centres; ``ux`` ``[ny, nx + 1]`` and ``uy`` ``[ny + 1, nx]`` the displacement
    that removes it (mm) on the cells' vertical and horizontal faces (0 on the walls), all
    float32 on ``lattice``; ``cap`` the largest displacement, mm."""

    lattice: Lattice
    e: np.ndarray
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
        return {"box": box, "shape": np.array([g.nx, g.ny], np.int64), "e": self.e,
                "ux": self.ux, "uy": self.uy}  # fmt: skip

    @classmethod
    def from_arrays(cls, a: dict[str, np.ndarray]) -> CoarseField:
        """The field :meth:`to_arrays` wrote."""
        x0, y0, hx, hy, cap = (float(v) for v in a["box"])
        nx, ny = (int(v) for v in a["shape"])
        return cls(Lattice(x0, y0, hx, hy, nx, ny), a["e"], a["ux"], a["uy"], cap)

    def displacement(self, at: np.ndarray) -> np.ndarray:
        """``[m, 2]`` displacement (mm, capped at ``cap``) of the dots at ``at``."""
        row, col = self._coords(at[:, 0], at[:, 1])
        u = np.empty((len(at), 2))
        u[:, 0] = map_coordinates(self.ux, [row, col + 0.5], np.float64, order=1, mode="nearest")
        u[:, 1] = map_coordinates(self.uy, [row + 0.5, col], np.float64, order=1, mode="nearest")
        size = np.hypot(u[:, 0], u[:, 1])
        return u * np.minimum(1.0, self.cap / np.maximum(size, 1e-300))[:, None]


def coarse_field(
    parts: list[LatticePart], lattice: Lattice, density: DensityMap, sigma: float, cap: float,
    domain: Domain | None = None,
) -> CoarseField:  # fmt: skip
    """The panel's coverage error blurred by ``sigma`` mm from the deposits ``parts`` (added
    in the order given) of all its dots, and the Neumann field that removes it.

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
    e = _relative_error(got, target, (sigma / g.hy, sigma / g.hx))
    del got, target
    phi = neumann_potential(e, g.hx, g.hy)
    # the gradient on the cells' faces, 0 on the walls' (nothing flows across them): a
    # lattice cell is a few spacings, and a gradient at the border cells' centres, taken
    # as it is out to the wall, slid the whole first strip of dots into the wall
    ux = np.zeros((g.ny, g.nx + 1), np.float32)
    uy = np.zeros((g.ny + 1, g.nx), np.float32)
    ux[:, 1:-1] = np.diff(phi, axis=1) / g.hx
    uy[1:-1, :] = np.diff(phi, axis=0) / g.hy
    return CoarseField(g, e.astype(np.float32), ux, uy, cap)
