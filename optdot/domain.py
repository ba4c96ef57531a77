"""Panel domains: the rectangle, or a CAD outline with holes and keep-outs (issue 7).

A :class:`Domain` is a shapely (Multi)Polygon in mm plus an ``edge_margin``: every dot
keeps ``r0 + edge_margin`` between its centre and every edge (outline, holes, keep-outs).
Outlines load from DXF (closed LWPOLYLINE/POLYLINE/CIRCLE/ELLIPSE/SPLINE, or LINE/ARC
pieces that chain into loops; curves flattened to a stated tolerance), WKT or GeoJSON;
the outermost loop is the panel and loops inside it are holes. shapely validates the
result before any work; a bad outline is refused with shapely's reason and where.

For the optimizer, :class:`EdgeIndex` holds the boundary as segments (interior on the
left) bucketed in a grid, and :func:`signed_distance` (compiled) gives each dot's
distance to the nearest edge, positive inside, with its gradient, in O(1) per dot.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path

import numba as nb
import numpy as np
import shapely
from shapely.geometry import MultiPolygon, Polygon
from shapely.geometry.polygon import orient

from .errors import GeometryError

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
    """

    geometry: Polygon | MultiPolygon
    edge_margin: float = 0.0
    rectangle: bool = False
    source: str = "panel"

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

    def cell_fractions(
        self, x0: float, y0: float, cw: float, ch: float, nx: int, ny: int
    ) -> np.ndarray:
        """``[ny, nx]`` share of each grid cell's area inside the domain."""
        return polygon_cell_fractions(self.geometry, x0, y0, cw, ch, nx, ny, self.rectangle)


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
    iy, ix = np.mgrid[0:ny, 0:nx]
    cells = shapely.box(x0 + ix * cw, y0 + iy * ch, x0 + (ix + 1) * cw, y0 + (iy + 1) * ch)
    shapely.prepare(geom)
    inside = shapely.contains(geom, cells)
    frac = inside.astype(np.float64)
    edge = ~inside & shapely.intersects(geom, cells)
    frac[edge] = shapely.area(shapely.intersection(cells[edge], geom)) / (cw * ch)
    return frac


def orient_all(geom: Polygon | MultiPolygon) -> Polygon | MultiPolygon:
    """Exteriors counter-clockwise and holes clockwise, for (multi)polygons."""
    if isinstance(geom, MultiPolygon):
        return MultiPolygon([orient(p, 1.0) for p in geom.geoms])
    if isinstance(geom, Polygon):
        return orient(geom, 1.0)
    polys = [g for g in getattr(geom, "geoms", []) if isinstance(g, Polygon) and g.area > 0]
    return MultiPolygon([orient(p, 1.0) for p in polys])


# ----------------------------------------------------------------------------- loading


def load_outline(
    path: Path, tolerance: float = DEFAULT_TOLERANCE, keep_out_layer: str | None = None
) -> tuple[Polygon, list[Polygon]]:
    """Read a panel outline (and, from a DXF, the keep-outs on ``keep_out_layer``).

    Args:
        path: ``.dxf``, ``.wkt`` or ``.geojson``/``.json`` file, mm.
        tolerance: flattening tolerance of arcs and curves, mm.
        keep_out_layer: DXF layer whose loops are keep-out zones.

    Returns:
        ``(panel, keep_outs)``: the validated panel polygon (with its holes) and the
        keep-out polygons.

    Raises:
        GeometryError: unreadable file, open or invalid loops (one line, file + reason).
    """
    if not path.exists():
        raise GeometryError(f"{path}: outline file not found")
    suffix = path.suffix.lower()
    if suffix == ".dxf":
        loops, keep = _dxf_loops(path, tolerance, keep_out_layer)
        panel = _polygon_from_loops(loops, path)
        return panel, [_polygon_from_loops([k], path) for k in keep]
    if suffix in (".wkt", ".txt"):
        geom = _parse(lambda: shapely.from_wkt(path.read_text(encoding="utf-8")), path, "WKT")
    elif suffix in (".geojson", ".json"):
        geom = _parse(lambda: _from_geojson(path.read_text(encoding="utf-8")), path, "GeoJSON")
    else:
        raise GeometryError(f"{path}: outline must be .dxf, .wkt or .geojson, not {suffix!r}")
    polys = _polygonal_parts(geom, path)
    if len(polys) != 1:
        raise GeometryError(f"{path}: expected one panel polygon, found {len(polys)}")
    return validate_polygon(polys[0], str(path)), []


def parse_keep_out(item: str, base: Path, tolerance: float) -> list[Polygon]:
    """A keep-out given in the job: a WKT polygon string or an outline file path."""
    text = item.strip()
    if text.split("(")[0].strip().upper() in ("POLYGON", "MULTIPOLYGON"):
        geom = _parse(lambda: shapely.from_wkt(text), Path("domain.keep_out"), "WKT")
        return [
            validate_polygon(p, "domain.keep_out")
            for p in _polygonal_parts(geom, Path("domain.keep_out"))
        ]
    panel, extra = load_outline(base / text, tolerance)
    return [panel, *extra]


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


def _parse(fn, path: Path, kind: str):
    try:
        return fn()
    except (shapely.errors.GEOSException, ValueError, TypeError, KeyError) as e:
        raise GeometryError(f"{path}: malformed {kind} ({str(e).splitlines()[0]})") from None


def _from_geojson(text: str):
    data = json.loads(text)
    if data.get("type") == "FeatureCollection":
        geoms = [shapely.geometry.shape(f["geometry"]) for f in data["features"]]
        return shapely.GeometryCollection(geoms)
    if data.get("type") == "Feature":
        return shapely.geometry.shape(data["geometry"])
    return shapely.geometry.shape(data)


def _polygonal_parts(geom, path: Path) -> list[Polygon]:
    parts = list(getattr(geom, "geoms", [geom]))
    polys = []
    for g in parts:
        if isinstance(g, Polygon):
            polys.append(g)
        elif isinstance(g, MultiPolygon):
            polys += list(g.geoms)
        elif g.geom_type in ("LineString", "LinearRing"):
            c = np.asarray(g.coords)
            raise GeometryError(
                f"{path}: open loop: a {g.geom_type} from ({c[0, 0]:.4g}, {c[0, 1]:.4g}) to "
                f"({c[-1, 0]:.4g}, {c[-1, 1]:.4g}) mm is not a polygon"
            )
    if not polys:
        raise GeometryError(f"{path}: no polygon found")
    return polys


def _dxf_loops(path: Path, tolerance: float, keep_layer: str | None):
    import ezdxf
    from ezdxf import path as dxfpath

    try:
        doc = ezdxf.readfile(str(path))
    except (OSError, ezdxf.DXFError) as e:
        raise GeometryError(f"{path}: cannot read DXF ({e})") from None
    closed: list[np.ndarray] = []
    keep: list[np.ndarray] = []
    pieces: list[np.ndarray] = []
    kinds = ("LWPOLYLINE", "POLYLINE", "CIRCLE", "ARC", "LINE", "ELLIPSE", "SPLINE")
    for e in doc.modelspace():
        if e.dxftype() not in kinds:
            continue
        try:
            p = dxfpath.make_path(e)
        except (TypeError, ValueError) as err:
            raise GeometryError(
                f"{path}: cannot read {e.dxftype()} {e.dxf.handle} ({err})"
            ) from None
        pts = np.array([(v.x, v.y) for v in p.flattening(tolerance)], dtype=np.float64)
        if len(pts) < 2:
            continue
        is_loop = p.is_closed or np.hypot(*(pts[0] - pts[-1])) <= tolerance
        target = keep if keep_layer is not None and e.dxf.layer == keep_layer else closed
        if is_loop:
            target.append(pts)
        elif target is keep:
            raise GeometryError(
                f"{path}: open keep-out loop on layer {keep_layer!r} at "
                f"({pts[0, 0]:.4g}, {pts[0, 1]:.4g}) mm"
            )
        else:
            pieces.append(pts)
    closed += _chain(pieces, max(tolerance, 1e-6), path)
    if not closed:
        raise GeometryError(
            f"{path}: no closed loop found (LWPOLYLINE, POLYLINE, CIRCLE or LINE/ARC)"
        )
    return closed, keep


def _chain(pieces: list[np.ndarray], tol: float, path: Path) -> list[np.ndarray]:
    """Join open pieces end to end into closed loops (endpoints within ``tol``)."""
    loops = []
    todo = list(pieces)
    while todo:
        cur = todo.pop(0)
        while np.hypot(*(cur[0] - cur[-1])) > tol:
            for k, q in enumerate(todo):
                if np.hypot(*(cur[-1] - q[0])) <= tol:
                    cur = np.vstack([cur, q[1:]])
                elif np.hypot(*(cur[-1] - q[-1])) <= tol:
                    cur = np.vstack([cur, q[::-1][1:]])
                else:
                    continue
                todo.pop(k)
                break
            else:
                raise GeometryError(
                    f"{path}: open loop: the outline is not closed near "
                    f"({cur[-1, 0]:.4g}, {cur[-1, 1]:.4g}) mm"
                )
        loops.append(cur)
    return loops


def _polygon_from_loops(loops: list[np.ndarray], path: Path) -> Polygon:
    """Outermost loop = panel, loops inside it = holes."""
    rings = []
    for pts in loops:
        if len(pts) < 4:
            raise GeometryError(
                f"{path}: a loop at ({pts[0, 0]:.4g}, {pts[0, 1]:.4g}) mm has fewer than 3 vertices"
            )
        rings.append(Polygon(pts))
    rings.sort(key=lambda p: -abs(p.area))
    shell = rings[0]
    if not shell.is_valid:
        validate_polygon(shell, str(path))
    holes = []
    for h in rings[1:]:
        if not h.is_valid:
            validate_polygon(h, str(path))
        if not shell.contains(h):
            c = h.representative_point()
            what = "crosses" if shell.intersects(h) else "lies outside"
            raise GeometryError(
                f"{path}: a loop near ({c.x:.4g}, {c.y:.4g}) mm {what} the outer loop"
            )
        for o in holes:
            if o.intersects(h):
                c = h.representative_point()
                raise GeometryError(
                    f"{path}: holes near ({c.x:.4g}, {c.y:.4g}) mm overlap or are nested"
                )
        holes.append(h)
    poly = Polygon(shell.exterior.coords, [h.exterior.coords for h in holes])
    return validate_polygon(poly, str(path))


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


# ----------------------------------------------------------------------------- edges


@dataclass(frozen=True, eq=False)
class EdgeIndex:
    """The domain boundary as segments bucketed in a grid, for :func:`signed_distance`.

    Attributes:
        seg: ``[S, 4]`` segments ``(ax, ay, bx, by)``, interior on the left, mm.
        prev, next: ``[S]`` int64 neighbouring segment on the same loop.
        x0, y0, cell: bucket grid origin and cell side, mm.
        nx, ny: bucket grid shape.
        start, items: CSR of the segments within ``cell`` of each bucket.
        inside: ``[nx * ny]`` int8, 1 if the bucket's centre is inside.
    """

    seg: np.ndarray
    prev: np.ndarray
    next: np.ndarray
    x0: float
    y0: float
    cell: float
    nx: int
    ny: int
    start: np.ndarray
    items: np.ndarray
    inside: np.ndarray

    @classmethod
    def build(cls, domain: Domain, reach: float) -> EdgeIndex:
        """Index ``domain``'s edges; distances below ``reach`` (mm) come out exact."""
        segs, prev, nxt = [], [], []
        for ring in domain.rings():
            k = len(ring)
            base = len(segs)
            for i in range(k):
                a, b = ring[i], ring[(i + 1) % k]
                segs.append((a[0], a[1], b[0], b[1]))
                prev.append(base + (i - 1) % k)
                nxt.append(base + (i + 1) % k)
        seg = np.asarray(segs, dtype=np.float64)
        bx0, by0, bx1, by1 = domain.box
        span = max(bx1 - bx0, by1 - by0)
        cell = max(reach, span / 2048.0, 1e-9)
        x0, y0 = bx0 - reach - cell, by0 - reach - cell
        nx = int((bx1 + reach + cell - x0) / cell) + 1
        ny = int((by1 + reach + cell - y0) / cell) + 1
        start, items = _bucket_segments(seg, x0, y0, cell, nx, ny, cell)
        iy, ix = np.divmod(np.arange(nx * ny), nx)
        centres = np.stack([x0 + (ix + 0.5) * cell, y0 + (iy + 0.5) * cell], axis=1)
        inside = domain.contains(centres).astype(np.int8)
        return cls(
            seg, np.asarray(prev), np.asarray(nxt), x0, y0, cell, nx, ny, start, items, inside
        )


@nb.njit(cache=True)
def _bucket_segments(seg, x0, y0, cell, nx, ny, reach):  # pragma: no cover - compiled
    counts = np.zeros(nx * ny + 1, np.int64)
    for pass_ in range(2):
        if pass_ == 1:
            start = np.cumsum(counts)
            fill = start[:-1].copy()
            items = np.empty(start[-1], np.int64)
        for s in range(seg.shape[0]):
            lo_x = min(seg[s, 0], seg[s, 2]) - reach
            hi_x = max(seg[s, 0], seg[s, 2]) + reach
            lo_y = min(seg[s, 1], seg[s, 3]) - reach
            hi_y = max(seg[s, 1], seg[s, 3]) + reach
            for cy in range(
                max(int((lo_y - y0) / cell), 0), min(int((hi_y - y0) / cell), ny - 1) + 1
            ):
                for cx in range(
                    max(int((lo_x - x0) / cell), 0), min(int((hi_x - x0) / cell), nx - 1) + 1
                ):
                    c = cy * nx + cx
                    if pass_ == 0:
                        counts[c + 1] += 1
                    else:
                        items[fill[c]] = s
                        fill[c] += 1
    return start, items


@nb.njit(cache=True, inline="always")
def _left(ax, ay, bx, by, px, py):  # pragma: no cover - compiled
    return (bx - ax) * (py - ay) - (by - ay) * (px - ax) > 0.0


@nb.njit(cache=True)
def _nearest(x, y, seg, prev, nxt, cand, lo, hi):  # pragma: no cover - compiled
    """Nearest boundary point among segments ``cand[lo:hi]``: (d, px, py, inside)."""
    best = np.inf
    bs = -1
    bt = 0.0
    for q in range(lo, hi):
        s = cand[q]
        ax, ay, bx, by = seg[s, 0], seg[s, 1], seg[s, 2], seg[s, 3]
        dx, dy = bx - ax, by - ay
        L2 = dx * dx + dy * dy
        t = 0.0 if L2 == 0.0 else min(max(((x - ax) * dx + (y - ay) * dy) / L2, 0.0), 1.0)
        px, py = ax + t * dx, ay + t * dy
        d2 = (x - px) ** 2 + (y - py) ** 2
        if d2 < best:
            best, bs, bt = d2, s, t
    s = bs
    ax, ay, bx, by = seg[s, 0], seg[s, 1], seg[s, 2], seg[s, 3]
    px, py = ax + bt * (bx - ax), ay + bt * (by - ay)
    if 0.0 < bt < 1.0:
        inside = _left(ax, ay, bx, by, x, y)
    else:
        # nearest point is a vertex: decide with both edges meeting there
        e1 = prev[s] if bt == 0.0 else s
        e2 = s if bt == 0.0 else nxt[s]
        l1 = _left(seg[e1, 0], seg[e1, 1], seg[e1, 2], seg[e1, 3], x, y)
        l2 = _left(seg[e2, 0], seg[e2, 1], seg[e2, 2], seg[e2, 3], x, y)
        ux1, uy1 = seg[e1, 2] - seg[e1, 0], seg[e1, 3] - seg[e1, 1]
        ux2, uy2 = seg[e2, 2] - seg[e2, 0], seg[e2, 3] - seg[e2, 1]
        convex = ux1 * uy2 - uy1 * ux2 > 0.0
        inside = (l1 and l2) if convex else (l1 or l2)
    return np.sqrt(best), px, py, inside


@nb.njit(cache=True)
def signed_distance(
    x, y, seg, prev, nxt, x0, y0, cell, nx, ny, start, items, inside, far
):  # pragma: no cover
    """Signed distance of (x, y) to the boundary (> 0 inside) and its gradient (ux, uy).

    Each bucket lists every segment within ``cell`` of it, so a nearest listed segment
    closer than ``cell`` is the true nearest. Otherwise the point is at least ``cell``
    from the boundary, on the same side as its bucket's centre (half a diagonal away):
    inside returns ``far`` (nothing to penalise); outside is measured on all segments.
    """
    ix = int(np.floor((x - x0) / cell))
    iy = int(np.floor((y - y0) / cell))
    d = np.inf
    if 0 <= ix < nx and 0 <= iy < ny:
        c = iy * nx + ix
        if start[c] < start[c + 1]:
            d, px, py, ins = _nearest(x, y, seg, prev, nxt, items, start[c], start[c + 1])
        if d >= cell:
            if inside[c]:
                return far, 0.0, 0.0
            d = np.inf
    if d == np.inf:
        d, px, py, ins = _nearest(x, y, seg, prev, nxt, np.arange(seg.shape[0]), 0, seg.shape[0])
    if d < 1e-15:
        return 0.0, 0.0, 0.0
    ux, uy = (x - px) / d, (y - py) / d
    if ins:
        return d, ux, uy
    return -d, -ux, -uy


#: The kernels' stand-in for "no outline" (a rectangle panel).
NO_EDGES = (
    np.zeros((0, 4)),
    np.zeros(0, np.int64),
    np.zeros(0, np.int64),
    np.zeros(1, np.int64),
    np.zeros(0, np.int64),
    np.zeros(0, np.int8),
    np.zeros(5),
)


def edge_args(edges: EdgeIndex | None) -> tuple:
    """The edge index as one tuple of arrays for the kernel (empty: rectangle)."""
    if edges is None:
        return NO_EDGES
    geo = np.array([edges.x0, edges.y0, edges.cell, edges.nx, edges.ny], dtype=np.float64)
    return (edges.seg, edges.prev, edges.next, edges.start, edges.items, edges.inside, geo)


@nb.njit(cache=True, inline="always")
def edge_signed_distance(x, y, ed):  # pragma: no cover - compiled
    """:func:`signed_distance` with the index packed by :func:`edge_args`."""
    seg, prev, nxt, start, items, inside, geo = ed
    return signed_distance(
        x,
        y,
        seg,
        prev,
        nxt,
        geo[0],
        geo[1],
        geo[2],
        int(geo[3]),
        int(geo[4]),
        start,
        items,
        inside,
        np.inf,
    )


def signed_distances(
    index: EdgeIndex, xy: np.ndarray, far: float = math.inf
) -> tuple[np.ndarray, np.ndarray]:
    """Vectorised :func:`signed_distance`: ``[n]`` distances and ``[n, 2]`` gradients."""
    return _signed_many(
        xy,
        index.seg,
        index.prev,
        index.next,
        index.x0,
        index.y0,
        index.cell,
        index.nx,
        index.ny,
        index.start,
        index.items,
        index.inside,
        far,
    )


@nb.njit(cache=True)
def _signed_many(
    xy, seg, prev, nxt, x0, y0, cell, nx, ny, start, items, inside, far
):  # pragma: no cover
    n = xy.shape[0]
    d = np.empty(n)
    u = np.empty((n, 2))
    for i in range(n):
        d[i], u[i, 0], u[i, 1] = signed_distance(
            xy[i, 0], xy[i, 1], seg, prev, nxt, x0, y0, cell, nx, ny, start, items, inside, far
        )
    return d, u
