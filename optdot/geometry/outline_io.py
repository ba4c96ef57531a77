"""Outline files: DXF, WKT and GeoJSON panels with holes, and keep-out zones.

DXF: closed LWPOLYLINE/POLYLINE/CIRCLE/ELLIPSE/SPLINE, or LINE/ARC pieces that chain into
loops; curves are flattened to a stated tolerance. The outermost loop is the panel and
loops inside it are holes. shapely validates the result before any work; a bad outline
is refused with shapely's reason and where (:class:`~optdot.errors.GeometryError`).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import shapely
from shapely.geometry import MultiPolygon, Polygon

from ..errors import GeometryError
from .domain import DEFAULT_TOLERANCE, validate_polygon


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
