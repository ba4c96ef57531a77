"""Panel domains: the rectangle, or a polygon with holes and keep-outs.

A :class:`Domain` is a shapely (Multi)Polygon in mm plus an ``edge_margin``: every dot
keeps ``r0 + edge_margin`` between its centre and every edge (outline, holes, keep-outs).
Reading outlines from CAD files lives in :mod:`optdot.geometry.outline_io`; the compiled
edge index the optimizer measures distances with in :mod:`optdot.geometry.edges`.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np
import shapely
from shapely.geometry import MultiPolygon, Polygon
from shapely.geometry.polygon import orient

from ..errors import GeometryError

if TYPE_CHECKING:  # scipy.sparse costs ~0.15 s of a command's start: loaded when used
    import scipy.sparse

#: Default flattening tolerance of arcs and curves, mm (1 µm).
DEFAULT_TOLERANCE = 0.001


@dataclass(frozen=True, eq=False)
class Domain:
    """Where dots may go.

    Attributes:
        geometry: polygonal region, mm; exteriors counter-clockwise, holes clockwise.
        edge_margin: extra clearance of every dot from every edge, mm.
        rectangle: True for the plain ``[x0, x1] x [y0, y1]`` panel.
        source: where the outline came from (for messages).
        slab: the panel before its keep-outs were cut out (the light guide's slab: a
            keep-out is clear slab without dots), or None when it has none.
        caps: ``[m, 3]`` discs of solid ink ``(x, y, diameter)``, mm, printed with the
            dots (over a direct-lit backlight's LEDs: :mod:`optdot.geometry.caps`), cut
            out of ``geometry`` with a ring of QA's close gap; None when there are none.
        cap_rings: ``[k, 2]`` ``(r_in, r_out)`` mm of the rings every cap prints (graded
            caps: :func:`optdot.geometry.caps.ring_table`), or None for solid caps.
    """

    geometry: Polygon | MultiPolygon
    edge_margin: float = 0.0
    rectangle: bool = False
    source: str = "panel"
    slab: Polygon | MultiPolygon | None = None
    caps: np.ndarray | None = None
    cap_rings: np.ndarray | None = None
    #: :meth:`cell_fractions` of the grids asked for last (a polygon's cost grows with its
    #: edges; a run asks for the same grids again and again): not pickled, not compared.
    _fractions: dict = field(default_factory=dict, init=False, repr=False, compare=False)

    def __getstate__(self) -> dict:
        """Pickled without the fractions it has computed (a worker computes its own)."""
        return {k: v for k, v in self.__dict__.items() if k != "_fractions"}

    def __setstate__(self, state: dict) -> None:
        self.__dict__.update(state, _fractions={})

    @classmethod
    def rect(cls, x0: float, y0: float, x1: float, y1: float, edge_margin: float = 0.0) -> Domain:
        """The rectangular panel."""
        return cls(orient(shapely.box(x0, y0, x1, y1)), edge_margin, True)

    @property
    def box(self) -> tuple[float, float, float, float]:
        """Bounding box ``(xmin, ymin, xmax, ymax)``, mm."""
        return tuple(float(v) for v in self.geometry.bounds)  # type: ignore[return-value]

    @property
    def polygons(self) -> list[Polygon]:
        """The polygons of the domain (one, unless keep-outs cut it apart)."""
        g = self.geometry
        return list(g.geoms) if isinstance(g, MultiPolygon) else [g]

    @property
    def lit(self) -> Polygon | MultiPolygon:
        """Where the light is seen: the geometry with its caps and their rings filled
        back in (the panel a viewer looks at; dots keep out of caps, light does not)."""
        return self.geometry if self.caps is None or self.slab is None else self.slab

    def slab_polygons(self) -> list[Polygon]:
        """The polygons of the slab: the panel with its holes, keep-outs not cut out."""
        g = self.geometry if self.slab is None else self.slab
        return list(g.geoms) if isinstance(g, MultiPolygon) else [g]

    def rings(self) -> list[np.ndarray]:
        """Every boundary loop as ``[k, 2]`` vertices (not repeating the first), mm;
        exteriors counter-clockwise, holes clockwise (interior on the left)."""
        out = []
        for p in self.polygons:
            for ring in (p.exterior, *p.interiors):
                out.append(np.asarray(ring.coords, dtype=np.float64)[:-1, :2])
        return out

    def contains(self, xy: np.ndarray) -> np.ndarray:
        """``[n]`` bool: the centre lies inside the domain (not in a hole)."""
        return shapely.contains_xy(self.geometry, xy[:, 0], xy[:, 1])

    def edge_distance(self, xy: np.ndarray) -> np.ndarray:
        """``[n]`` distance of each centre to the nearest edge, mm (unsigned)."""
        return shapely.distance(self.geometry.boundary, shapely.points(xy))

    def protruding(
        self, xy: np.ndarray, dot_radius: float, margin: bool = True, tol: float = 1e-9
    ) -> np.ndarray:
        """``[n]`` bool: the dot (with the edge margin, if ``margin``) is not wholly
        inside the domain."""
        need = dot_radius + (self.edge_margin if margin else 0.0) - tol
        return ~self.contains(xy) | (self.edge_distance(xy) < need)

    def max_dots(self, dot_radius: float, min_distance: float) -> int:
        """An upper bound on how many dots fit: their centres lie in the domain shrunk by
        ``dot_radius + edge_margin``, and discs of radius ``min_distance / 2`` about them
        are disjoint inside that region grown by ``min_distance / 2`` (so the count is at
        most its area over one disc's; exact bound, no packing-density assumption)."""
        h = 0.5 * min_distance
        room = self.geometry.buffer(-(dot_radius + self.edge_margin), quad_segs=16)
        if room.is_empty:
            return 0
        return int(room.buffer(h, quad_segs=16).area / (np.pi * h * h)) + 1

    def map_weights(self, density) -> np.ndarray | None:
        """``[ny, nx]`` share of each cell of ``density`` (a
        :class:`~optdot.geometry.density.DensityMap`) inside the domain, or None for a
        rectangle (all of every cell)."""
        if self.rectangle:
            return None
        d = density
        return self.cell_fractions(d.x0, d.y0, *d.cell_size, d.shape[1], d.shape[0])

    def cell_fractions(
        self, x0: float, y0: float, cw: float, ch: float, nx: int, ny: int
    ) -> np.ndarray:
        """``[ny, nx]`` share of each grid cell's area inside the domain (read-only: the
        last :data:`FRACTION_GRIDS` grids' are kept and handed out again)."""
        if self.rectangle:
            return polygon_cell_fractions(self.geometry, x0, y0, cw, ch, nx, ny, True)
        key = (x0, y0, cw, ch, nx, ny)
        got = self._fractions.pop(key, None)
        if got is None:
            got = polygon_cell_fractions(self.geometry, x0, y0, cw, ch, nx, ny)
            got.setflags(write=False)
        while len(self._fractions) >= FRACTION_GRIDS:
            self._fractions.pop(next(iter(self._fractions)))  # the least recently used
        self._fractions[key] = got
        return got

    def deposited_fractions(
        self, x0: float, y0: float, cw: float, ch: float, nx: int, ny: int, weight=None
    ) -> np.ndarray:
        """``[ny, nx]``: the share of a cloud-in-cell deposit of the fill ``weight`` (a
        :class:`optdot.geometry.density.DensityMap`, or None: a uniform fill) that comes
        from inside the domain, in each cell of the grid (the rectangle: its
        :meth:`cell_fractions`). The map cut by the outline, as the dots' deposit sees
        it, is the map's deposit times this.

        The dots are deposited that way (bilinear weights to the four nearest cell
        centres, all of a dot's weight kept past the outermost centres), so a map cut by
        an outline must be too: against the cells' area shares a deposit of dots that
        fills the domain exactly reads a dipole along every edge inside the box, which a
        1 mm blur turns into 1.2 JND at the outline sample's notch (and where the map is
        steep by an edge, the share must weigh it: 1.0 JND unweighted). Computed on
        sub-cells a quarter of a cell a side (:data:`SUB_CELLS`), each a point mass at
        its centre: exact where the domain's edges are straight within a sub-cell and
        the map's cells are whole sub-cells."""
        if self.rectangle:
            return self.cell_fractions(x0, y0, cw, ch, nx, ny)
        k = SUB_CELLS
        wx = _deposit_weights(nx, k)  # [nx, nx k]
        inside = np.zeros((ny, nx))
        whole = np.zeros((ny, nx))
        step = max(1, (1 << 22) // max(1, nx * k * k))  # rows of cells a strip
        for r0 in range(0, ny, step):
            r1 = min(ny, r0 + step)
            args = (x0, y0 + r0 * ch, cw / k, ch / k, nx * k, (r1 - r0) * k)
            w = np.ones((args[5], args[4])) if weight is None else weight.resampled(*args)
            # the sub-rows' weights to the cell rows around them (clamped at the grid's)
            u = (r0 * k + np.arange((r1 - r0) * k) + 0.5) / k - 0.5
            i = np.floor(u).astype(np.int64)
            t = (u - i)[:, None]
            for out, sub in ((inside, self.cell_fractions(*args) * w), (whole, w)):
                rows = (wx @ sub.T).T  # [(r1 - r0) k, nx]
                np.add.at(out, np.clip(i, 0, ny - 1), (1.0 - t) * rows)
                np.add.at(out, np.clip(i + 1, 0, ny - 1), t * rows)
        return np.where(whole > 0, inside / np.where(whole > 0, whole, 1.0), 0.0)


#: Grids whose :meth:`Domain.cell_fractions` a domain keeps (a direct-lit film's run asks
#: for its 1280 x 864 sub-cells six times, 0.7 s each with 24 caps cut out).
FRACTION_GRIDS = 4
#: Sub-cells a side per cell in :meth:`Domain.deposited_fractions` (even: the bilinear
#: weights' kinks fall on sub-cell borders, so the sum over sub-cells is exact).
SUB_CELLS = 4


def _deposit_weights(n: int, k: int) -> scipy.sparse.csr_matrix:
    """``[n, n k]`` sparse: the cloud-in-cell weights of ``n k`` sub-cell centres (``k`` a
    cell) to the ``n`` cell centres of one axis, all weight kept past the outermost
    centres."""
    import scipy.sparse

    u = (np.arange(n * k) + 0.5) / k - 0.5
    i = np.floor(u).astype(np.int64)
    t = u - i
    cols = np.arange(n * k)
    rows = np.concatenate([np.clip(i, 0, n - 1), np.clip(i + 1, 0, n - 1)])
    w = np.concatenate([1.0 - t, t])
    return scipy.sparse.csr_matrix((w, (rows, np.concatenate([cols, cols]))), shape=(n, n * k))


def centres_in_box(x0: float, y0: float, cw: float, ch: float, nx: int, ny: int, box) -> np.ndarray:
    """``[ny, nx]`` bool: the cells of a grid (lower-left corner ``x0, y0``, cells
    ``cw x ch``, mm) whose centres lie in ``box`` (``(x0, y0, x1, y1)`` mm, edges in)."""
    xc = x0 + (np.arange(nx) + 0.5) * cw
    yc = y0 + (np.arange(ny) + 0.5) * ch
    inx = (xc >= box[0]) & (xc <= box[2])
    iny = (yc >= box[1]) & (yc <= box[3])
    return iny[:, None] & inx[None, :]


def polygon_cell_fractions(
    geom, x0: float, y0: float, cw: float, ch: float, nx: int, ny: int, rectangle: bool = False
) -> np.ndarray:
    """``[ny, nx]`` share of each cell of a grid inside the shapely polygon ``geom``."""
    if rectangle:
        bx0, by0, bx1, by1 = geom.bounds
        xs = x0 + np.arange(nx + 1) * cw
        ys = y0 + np.arange(ny + 1) * ch
        fx = np.clip(np.minimum(xs[1:], bx1) - np.maximum(xs[:-1], bx0), 0, None) / cw
        fy = np.clip(np.minimum(ys[1:], by1) - np.maximum(ys[:-1], by0), 0, None) / ch
        return fy[:, None] * fx[None, :]
    inside = _centres_inside(geom, x0, y0, cw, ch, nx, ny)
    frac = inside.astype(np.float64)
    iy, ix = np.nonzero(_crossed(geom, x0, y0, cw, ch, nx, ny))
    cells = shapely.box(x0 + ix * cw, y0 + iy * ch, x0 + (ix + 1) * cw, y0 + (iy + 1) * ch)
    shapely.prepare(geom)
    full = shapely.contains(geom, cells)
    part = ~full & shapely.intersects(geom, cells)
    share = np.zeros(len(cells))
    share[full] = 1.0
    share[part] = shapely.area(shapely.intersection(cells[part], geom)) / (cw * ch)
    frac[iy, ix] = share
    return frac


def _rings(geom) -> list[np.ndarray]:
    """Every boundary loop of a (multi)polygon, ``[k, 2]`` vertices."""
    polys = getattr(geom, "geoms", [geom])
    return [np.asarray(r.coords) for p in polys for r in (p.exterior, *p.interiors)]


def _centres_inside(geom, x0, y0, cw, ch, nx, ny) -> np.ndarray:
    """``[ny, nx]`` bool: the cell's centre lies inside ``geom`` (even-odd scanlines over
    every ring: O(rows x edges), no object per cell)."""
    seg = np.concatenate([np.stack([r[:-1], r[1:]], axis=1) for r in _rings(geom)])
    (ax, ay), (bx, by) = seg[:, 0].T, seg[:, 1].T
    xc = x0 + (np.arange(nx) + 0.5) * cw
    out = np.zeros((ny, nx), bool)
    for j in range(ny):
        yc = y0 + (j + 0.5) * ch
        hit = (ay <= yc) != (by <= yc)
        if not hit.any():
            continue
        xs = np.sort(ax[hit] + (yc - ay[hit]) * (bx[hit] - ax[hit]) / (by[hit] - ay[hit]))
        out[j] = np.searchsorted(xs, xc) % 2 == 1
    return out


def _crossed(geom, x0, y0, cw, ch, nx, ny) -> np.ndarray:
    """``[ny, nx]`` bool: cells the boundary may cross (a superset): the cells of points
    every <= one cell along each edge, grown by one cell (a cell an edge crosses lies
    within one cell of such a point)."""
    step = min(cw, ch)
    mask = np.zeros((ny, nx), bool)
    for r in _rings(geom):
        a, b = r[:-1], r[1:]
        k = np.maximum(1, np.ceil(np.hypot(*(b - a).T) / step).astype(np.int64))
        t = np.concatenate([np.arange(n + 1) / n for n in k])
        s = np.repeat(np.arange(len(a)), k + 1)
        pts = a[s] + (b[s] - a[s]) * t[:, None]
        ix = np.floor((pts[:, 0] - x0) / cw).astype(np.int64)
        iy = np.floor((pts[:, 1] - y0) / ch).astype(np.int64)
        ok = (ix >= -1) & (ix <= nx) & (iy >= -1) & (iy <= ny)
        for dy in (-1, 0, 1):
            for dx in (-1, 0, 1):
                jx, jy = ix[ok] + dx, iy[ok] + dy
                keep = (jx >= 0) & (jx < nx) & (jy >= 0) & (jy < ny)
                mask[jy[keep], jx[keep]] = True
    return mask


def orient_all(geom: Polygon | MultiPolygon) -> Polygon | MultiPolygon:
    """Exteriors counter-clockwise and holes clockwise, for (multi)polygons."""
    if isinstance(geom, MultiPolygon):
        return MultiPolygon([orient(p, 1.0) for p in geom.geoms])
    if isinstance(geom, Polygon):
        return orient(geom, 1.0)
    polys = [g for g in getattr(geom, "geoms", []) if isinstance(g, Polygon) and g.area > 0]
    return MultiPolygon([orient(p, 1.0) for p in polys])


def validate_polygon(poly: Polygon, where: str) -> Polygon:
    """Refuse invalid or empty polygons with shapely's reason and location."""
    if poly.is_empty or poly.convex_hull.area <= 0:
        raise GeometryError(f"{where}: the outline has zero area")
    if not poly.is_valid:
        reason = shapely.is_valid_reason(poly)
        raise GeometryError(f"{where}: invalid outline: {_reason_mm(reason)}")
    if poly.area <= 0:
        raise GeometryError(f"{where}: the outline has zero area")
    return orient(poly, 1.0)


def _reason_mm(reason: str) -> str:
    # shapely: "Self-intersection[12.5 3.25]" -> "self-intersection at (12.5, 3.25) mm"
    if "[" in reason and reason.endswith("]"):
        what, at = reason[:-1].split("[", 1)
        xy = at.split()
        if len(xy) >= 2:
            return f"{what.strip().lower()} at ({float(xy[0]):.4g}, {float(xy[1]):.4g}) mm"
    return reason


def domain_from_rings(rings: list[np.ndarray], where: str, filled: bool = False) -> Domain | None:
    """Rebuild a domain from outline loops read back from a mask; None if they are just
    one axis-aligned box.

    Args:
        rings: ``[k, 2]`` vertex arrays, mm.
        where: file name for messages.
        filled: the rings are filled polygons whose holes are keyhole cuts (GDSII/OASIS);
            otherwise exteriors run counter-clockwise and holes clockwise (DXF).
    """
    if len(rings) == 1 and len(rings[0]) == 4:
        r = rings[0]
        xs, ys = np.unique(r[:, 0]), np.unique(r[:, 1])
        if len(xs) == 2 and len(ys) == 2:
            return None
    if filled:
        geom = shapely.union_all([Polygon(r).buffer(0) for r in rings if len(r) >= 3])
        if geom.is_empty:
            raise GeometryError(f"{where}: the outline polygons have zero area")
        return Domain(orient_all(geom), 0.0, False, where)
    polys = [Polygon(r) for r in rings if len(r) >= 3]
    shells = [p for p in polys if p.exterior.is_ccw]
    holes = [p for p in polys if not p.exterior.is_ccw]
    parts = []
    for sh in shells:
        inner = [h.exterior.coords for h in holes if sh.contains(h.representative_point())]
        parts.append(validate_polygon(Polygon(sh.exterior.coords, inner), where))
    if not parts:
        raise GeometryError(f"{where}: no counter-clockwise outer loop among the outline rings")
    geom = parts[0] if len(parts) == 1 else MultiPolygon(parts)
    return Domain(orient_all(geom), 0.0, False, where)


def box_protruding(
    xy: np.ndarray, box: tuple[float, float, float, float], dot_radius: float | np.ndarray
) -> np.ndarray:
    """``[n]`` bool: the dot of radius ``dot_radius`` (mm, scalar or ``[n]``) reaches
    outside ``box`` ``(xmin, ymin, xmax, ymax)``."""
    return (
        (xy[:, 0] - dot_radius < box[0])
        | (xy[:, 0] + dot_radius > box[2])
        | (xy[:, 1] - dot_radius < box[1])
        | (xy[:, 1] + dot_radius > box[3])
    )
