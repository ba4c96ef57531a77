"""Outline files: DXF, WKT and GeoJSON panels with holes, and keep-out zones.

DXF: closed LWPOLYLINE/POLYLINE/CIRCLE/ELLIPSE/SPLINE, or LINE/ARC pieces that chain into
loops. Circles, arcs, bulges and ellipses are kept exact until it is known on which side
of them the panel lies, then flattened to the stated tolerance *on that side*
(:mod:`optdot.geometry.curves`): the polygon lies inside the drawn panel, so the spacing
guarantee against it holds against the drawing. The outermost loop is the panel and
loops inside it are holes. shapely validates the result before any work; a bad outline
is refused with shapely's reason and where (:class:`~optdot.errors.GeometryError`).

Why one module of ~450 lines: one concept (a panel file becomes a validated outline), three
formats whose loops go through the same nesting, orientation and validation; the DXF
entity walk (blocks, units) already lives in :mod:`optdot.geometry.dxf_entities` and the
curves in :mod:`optdot.geometry.curves`.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import shapely
from shapely.geometry import MultiPolygon, Polygon

from ..errors import GeometryError, one_line
from ..files import input_problem
from .curves import (
    Conic,
    Line,
    Sampled,
    Segment,
    bulge_arc,
    chain_points,
    reverse_chain,
    rough_points,
)
from .domain import DEFAULT_TOLERANCE, validate_polygon
from .dxf_entities import drawn_entities, mm_per_unit


def load_outline(
    path: Path,
    tolerance: float = DEFAULT_TOLERANCE,
    keep_out_layer: str | None = None,
    region_inside: bool = True,
) -> tuple[Polygon, list[Polygon]]:
    """Read a panel outline (and, from a DXF, the keep-outs on ``keep_out_layer``).

    Args:
        path: ``.dxf``, ``.wkt`` or ``.geojson``/``.json`` file, mm.
        tolerance: flattening tolerance of arcs and curves, mm.
        keep_out_layer: DXF layer whose loops are keep-out zones.
        region_inside: the dots go inside the outline (a panel); False for a keep-out
            file, whose curves are then flattened on their outer side.

    Returns:
        ``(panel, keep_outs)``: the validated panel polygon (with its holes) and the
        keep-out polygons.

    Raises:
        GeometryError: unreadable file, open or invalid loops (one line, file + reason).
    """
    problem = input_problem(path)
    if problem is not None:
        raise GeometryError(f"{path}: outline {problem}")
    suffix = path.suffix.lower()
    if suffix == ".dxf":
        loops, keep = _dxf_loops(path, tolerance, keep_out_layer)
        panel = _polygon_from_loops(loops, path, tolerance, region_inside)
        return panel, [_polygon_from_loops([k], path, tolerance, not region_inside) for k in keep]
    if suffix in (".wkt", ".txt"):
        geom = _parse(lambda: shapely.from_wkt(path.read_text(encoding="utf-8-sig")), path, "WKT")
    elif suffix in (".geojson", ".json"):
        geom = _parse(
            lambda: _from_geojson(path.read_text(encoding="utf-8-sig"), path), path, "GeoJSON"
        )
    else:
        raise GeometryError(f"{path}: outline must be .dxf, .wkt or .geojson, not {suffix!r}")
    polys = _polygonal_parts(geom, path)
    if len(polys) != 1:
        raise GeometryError(f"{path}: expected one panel polygon, found {len(polys)}")
    return validate_polygon(polys[0], str(path)), []


def keep_out_is_wkt(item: str) -> bool:
    """A ``domain.keep_out`` entry is WKT when it starts with a WKT geometry keyword
    (``POLYGON ((...``); anything else is a file name, parentheses and all."""
    text = item.strip()
    head = text.split("(", 1)[0].strip().upper()
    if "(" in text and head in (*_WKT_KINDS, "POLYGON", "MULTIPOLYGON"):
        return True
    words = head.split()
    return (
        len(words) == 2
        and words[0] in (*_WKT_KINDS, "POLYGON", "MULTIPOLYGON")
        and (words[1] in ("Z", "M", "ZM", "EMPTY"))
    )


def parse_keep_out(item: str, base: Path, tolerance: float) -> list[Polygon]:
    """A keep-out given in the job: a WKT polygon string or an outline file path (see
    :func:`keep_out_is_wkt`)."""
    text = item.strip()
    kind = (text.split("(")[0].strip().upper().split() or [""])[0]
    if not keep_out_is_wkt(text):
        panel, extra = load_outline(base / text, tolerance, region_inside=False)
        return [panel, *extra]
    if kind in ("POLYGON", "MULTIPOLYGON"):
        geom = _parse(lambda: shapely.from_wkt(text), Path("domain.keep_out"), "WKT")
        return [
            validate_polygon(p, "domain.keep_out")
            for p in _polygonal_parts(geom, Path("domain.keep_out"))
        ]
    if kind in _WKT_KINDS:
        raise GeometryError(f"domain.keep_out: {kind} is not an area; a keep-out is a POLYGON")
    raise GeometryError(f"domain.keep_out: {kind} is not a WKT polygon")


_WKT_KINDS = (
    "POINT",
    "MULTIPOINT",
    "LINESTRING",
    "MULTILINESTRING",
    "LINEARRING",
    "GEOMETRYCOLLECTION",
    "CIRCULARSTRING",
    "TRIANGLE",
)


def _parse(fn, path: Path, kind: str):
    """The geometry ``fn`` reads, in x-y (a 3-D outline's z is dropped: panels are flat);
    NaN or infinite coordinates are refused here, before GEOS sees them."""
    try:
        geom = fn()
        if geom is None:
            return None
        geom = shapely.force_2d(geom)
        if not np.isfinite(shapely.get_coordinates(geom)).all():
            raise GeometryError(f"{path}: NaN or infinite coordinate in the {kind} outline")
        return geom
    except UnicodeDecodeError:
        raise GeometryError(f"{path}: not UTF-8 text") from None
    except OSError as e:
        raise GeometryError(f"{path}: cannot read ({e.strerror or e})") from None
    except (
        shapely.errors.ShapelyError,
        ValueError,
        TypeError,
        KeyError,
        AttributeError,
        IndexError,
        RecursionError,
    ) as e:
        raise GeometryError(f"{path}: malformed {kind} ({one_line(e, True)})") from None


def _from_geojson(text: str, path: Path):
    data = json.loads(text)
    if not isinstance(data, dict):
        raise GeometryError(f"{path}: the top level is a {_json_kind(data)}, not a GeoJSON object")
    if data.get("type") == "FeatureCollection":
        features = data.get("features")
        if not isinstance(features, list):
            raise GeometryError(f"{path}: a FeatureCollection needs a features list")
        return shapely.GeometryCollection([_feature_geometry(f, path) for f in features])
    if data.get("type") == "Feature":
        return _feature_geometry(data, path)
    return shapely.geometry.shape(data)


def _feature_geometry(f, path: Path):
    if not isinstance(f, dict):
        raise GeometryError(f"{path}: a feature is a {_json_kind(f)}, not an object")
    g = f.get("geometry")
    if not isinstance(g, dict):
        raise GeometryError(f"{path}: a feature's geometry is {_json_kind(g)}, not an object")
    return shapely.geometry.shape(g)


def _json_kind(v) -> str:
    return {list: "list", str: "string", bool: "boolean", type(None): "null"}.get(
        type(v), "number" if isinstance(v, int | float) else type(v).__name__
    )


def _polygonal_parts(geom, path: Path) -> list[Polygon]:
    parts = list(getattr(geom, "geoms", [geom]))
    polys = []
    for g in parts:
        if isinstance(g, Polygon):
            polys.append(g)
        elif isinstance(g, MultiPolygon):
            polys += list(g.geoms)
        elif g.geom_type in ("LineString", "LinearRing") and not g.is_empty:
            c = np.asarray(g.coords)
            raise GeometryError(
                f"{path}: open loop: a {g.geom_type} from ({c[0, 0]:.4g}, {c[0, 1]:.4g}) to "
                f"({c[-1, 0]:.4g}, {c[-1, 1]:.4g}) mm is not a polygon"
            )
    if not polys:
        raise GeometryError(f"{path}: no polygon found")
    return polys


#: Radii of outline curves, mm: from the 1 nm database unit to 100 m.
MIN_RADIUS, MAX_RADIUS = 1e-6, 1e5


def _dxf_loops(path: Path, tolerance: float, keep_layer: str | None):
    """``(loops, keep_loops)``: closed chains of exact segments from the DXF's
    modelspace, the keep-out layer's apart."""
    import ezdxf

    try:
        doc = ezdxf.readfile(str(path))
    except OSError as e:
        raise GeometryError(f"{path}: cannot read DXF ({e.strerror or e})") from None
    except Exception as e:  # noqa: BLE001 - ezdxf's parser raises anything on a damaged file
        raise GeometryError(f"{path}: not a readable DXF file ({one_line(e, True)})") from None
    closed: list[list[Segment]] = []
    keep: list[list[Segment]] = []
    pieces: list[list[Segment]] = []
    kinds = ("LWPOLYLINE", "POLYLINE", "CIRCLE", "ARC", "LINE", "ELLIPSE", "SPLINE")
    scale = mm_per_unit(doc, path)
    for e in drawn_entities(doc.modelspace(), path):
        if e.dxftype() not in kinds:
            continue
        try:
            segs, is_closed = _entity_segments(e, tolerance / scale)
            if scale != 1.0:
                segs = [_mapped(s, lambda v, k=scale: v * k) for s in segs]
        except GeometryError as err:
            raise GeometryError(f"{path}: {e.dxftype()} {e.dxf.handle}: {err}") from None
        except (TypeError, ValueError, ArithmeticError, IndexError, AttributeError) as err:
            raise GeometryError(
                f"{path}: cannot read {e.dxftype()} {e.dxf.handle} ({one_line(err, True)})"
            ) from None
        if not segs:
            continue
        try:
            for seg in segs:
                if isinstance(seg, Conic):
                    seg.check(MIN_RADIUS, MAX_RADIUS)
        except GeometryError as err:
            raise GeometryError(f"{path}: {e.dxftype()} {e.dxf.handle}: {err}") from None
        is_loop = is_closed or np.hypot(*(segs[0].start - segs[-1].end)) <= tolerance
        target = keep if keep_layer is not None and e.dxf.layer == keep_layer else closed
        if is_loop:
            target.append(segs)
        elif target is keep:
            p = segs[0].start
            raise GeometryError(
                f"{path}: open keep-out loop on layer {keep_layer!r} at ({p[0]:.4g}, {p[1]:.4g}) mm"
            )
        else:
            pieces.append(segs)
    closed += _chain(pieces, max(tolerance, 1e-6), path)
    if not closed:
        raise GeometryError(
            f"{path}: no closed loop found (LWPOLYLINE, POLYLINE, CIRCLE or LINE/ARC)"
        )
    return closed, keep


def _entity_segments(e, tolerance: float) -> tuple[list[Segment], bool]:
    """The exact segments of one DXF entity (x-y of its world coordinates) and whether
    the entity is a closed loop by itself."""
    kind = e.dxftype()
    if kind == "LINE":
        return [Line(_xy(e.dxf.start), _xy(e.dxf.end))], False
    if kind in ("CIRCLE", "ARC"):
        r = float(e.dxf.radius)
        if not (math.isfinite(r) and MIN_RADIUS <= r <= MAX_RADIUS):
            raise GeometryError(f"radius {r!r} mm is out of range ({MIN_RADIUS:g}..{MAX_RADIUS:g})")
        c = e.dxf.center
        t0, t1 = 0.0, 2 * math.pi
        if kind == "ARC":
            t0, t1 = _sweep(math.radians(e.dxf.start_angle), math.radians(e.dxf.end_angle))
        arc = Conic(np.array([c.x, c.y]), np.array([r, 0.0]), np.array([0.0, r]), t0, t1)
        return [_to_wcs(arc, e.ocs(), c.z)], kind == "CIRCLE"
    if kind == "ELLIPSE":
        ce = e.construction_tool()
        t0, t1 = _sweep(float(ce.start_param), float(ce.end_param))
        full = t1 - t0 >= 2 * math.pi * (1 - 1e-12)
        axes = (ce.major_axis.magnitude, ce.minor_axis.magnitude)
        if not all(math.isfinite(a) and MIN_RADIUS <= a <= MAX_RADIUS for a in axes):
            raise GeometryError(
                f"ellipse axes {axes[0]:.4g}, {axes[1]:.4g} mm are out of range "
                f"({MIN_RADIUS:g}..{MAX_RADIUS:g})"
            )
        arc = Conic(_xy(ce.center), _xy(ce.major_axis), _xy(ce.minor_axis), t0, t1)
        return [arc], full
    if kind == "LWPOLYLINE":
        pts = [(float(x), float(y), float(b)) for x, y, b in e.get_points("xyb")]
        return _bulged(pts, bool(e.closed), e.ocs(), float(e.dxf.elevation))
    if kind == "POLYLINE":
        if e.is_2d_polyline:
            pts = [(v.dxf.location.x, v.dxf.location.y, float(v.dxf.bulge)) for v in e.vertices]
            return _bulged(pts, bool(e.is_closed), e.ocs(), float(e.dxf.elevation.z))
        if e.is_3d_polyline:
            w = [_xy(v.dxf.location) for v in e.vertices]
            if e.is_closed and w:
                w.append(w[0])
            return [Line(a, b) for a, b in zip(w[:-1], w[1:], strict=False)], bool(e.is_closed)
        raise GeometryError("polygon meshes and polyface meshes cannot be outlines")
    # SPLINE: sampled, the caller keeps a band of 2 tol clear of it
    from ezdxf import path as dxfpath

    p = dxfpath.make_path(e)
    pts = np.array([(v.x, v.y) for v in p.flattening(tolerance)], dtype=np.float64)
    if len(pts) < 2:
        return [], False
    return [Sampled(pts)], bool(p.is_closed)


def _sweep(start: float, end: float) -> tuple[float, float]:
    """Counter-clockwise angles from ``start`` to ``end`` (rad) as ``(t0, t1)`` with
    ``t0`` in ``[0, 2 pi)`` and ``0 < t1 - t0 <= 2 pi`` (equal angles: a full turn)."""
    if not (math.isfinite(start) and math.isfinite(end)):
        raise GeometryError(f"angles {start!r}, {end!r} are not finite")
    t0 = math.fmod(start, 2 * math.pi) % (2 * math.pi)
    span = math.fmod(end - start, 2 * math.pi) % (2 * math.pi)
    return t0, t0 + (span if span > 0 else 2 * math.pi)


def _bulged(pts, closed: bool, ocs, elevation: float) -> tuple[list[Segment], bool]:
    """Segments of a 2-D polyline: ``pts`` are ``(x, y, bulge)`` in its object
    coordinate system at ``elevation``."""
    if len(pts) < 2:
        return [], False
    xy = [np.array([x, y]) for x, y, _ in pts]
    n = len(xy)
    segs = []
    for i in range(n if closed else n - 1):
        a, b = xy[i], xy[(i + 1) % n]
        if np.array_equal(a, b):
            continue
        seg = bulge_arc(a, b, pts[i][2])
        segs.append(_to_wcs(seg, ocs, elevation))
    return segs, closed


def _to_wcs(seg: Segment, ocs, z: float) -> Segment:
    """A segment given in an entity's object coordinate system, in world x-y (an affine
    map, so circles under a tilted extrusion become the ellipses they project to)."""
    if not ocs.transform:
        return seg
    return _mapped(seg, lambda v: _xy(ocs.to_wcs((float(v[0]), float(v[1]), z))))


def _mapped(seg: Segment, f) -> Segment:
    """``seg`` under the affine map ``f`` (``[2] -> [2]`` points): a conic's centre and
    axes map to the image conic's, a sampled curve's points one by one."""
    if isinstance(seg, Sampled):
        return Sampled(np.array([f(p) for p in seg.pts], dtype=np.float64))
    if isinstance(seg, Line):
        return Line(f(seg.p), f(seg.q))
    c = f(seg.c)
    return Conic(
        c,
        f(seg.c + seg.M) - c,
        f(seg.c + seg.m) - c,
        seg.t0,
        seg.t1,
        None if seg.p is None else f(seg.p),
        None if seg.q is None else f(seg.q),
    )


def _xy(v) -> np.ndarray:
    return np.array([float(v[0]), float(v[1])], dtype=np.float64)


def _chain(pieces: list[list[Segment]], tol: float, path: Path) -> list[list[Segment]]:
    """Join open pieces end to end into closed loops (endpoints within ``tol``)."""
    loops = []
    todo = list(pieces)
    while todo:
        cur = todo.pop(0)
        while np.hypot(*(cur[0].start - cur[-1].end)) > tol:
            end = cur[-1].end
            for k, q in enumerate(todo):
                if np.hypot(*(end - q[0].start)) <= tol:
                    cur = cur + q
                elif np.hypot(*(end - q[-1].end)) <= tol:
                    cur = cur + reverse_chain(q)
                else:
                    continue
                todo.pop(k)
                break
            else:
                raise GeometryError(
                    f"{path}: open loop: the outline is not closed near "
                    f"({end[0]:.4g}, {end[1]:.4g}) mm"
                )
        loops.append(cur)
    return loops


def _polygon_from_loops(
    loops: list[list[Segment]], path: Path, tolerance: float, region_inside: bool = True
) -> Polygon:
    """Outermost loop = panel, loops inside it = holes; every curve flattened on the
    region's side (``region_inside``: the region is the polygon, else its outside, as for
    a keep-out)."""
    rough = []
    for segs in loops:
        pts = rough_points(segs, tolerance)
        if len(pts) < 4:
            raise GeometryError(
                f"{path}: a loop at ({pts[0, 0]:.4g}, {pts[0, 1]:.4g}) mm has fewer than 3 "
                "distinct vertices (repeated points are merged): it encloses no area"
            )
        rough.append((Polygon(pts), segs))
    rough.sort(key=lambda item: -abs(item[0].area))
    shell = rough[0][0]
    if not shell.is_valid:
        validate_polygon(shell, str(path))
    holes: list[Polygon] = []
    for h, _ in rough[1:]:
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
    rings = []
    for i, (poly, segs) in enumerate(rough):
        # travel each loop with the region on its left: the panel's outer loop
        # counter-clockwise and its holes clockwise (the other way for a keep-out)
        want_ccw = (i == 0) == region_inside
        if poly.exterior.is_ccw != want_ccw:
            segs = reverse_chain(segs)
        rings.append(chain_points(segs, tolerance, region_left=True))
    poly = Polygon(rings[0], rings[1:])
    splines = [s for segs in loops for s in segs if isinstance(s, Sampled)]
    if splines:
        # ezdxf's spline flattening has no one-sided bound: keep 2 tol clear of it
        band = shapely.union_all([shapely.LineString(s.pts).buffer(2 * tolerance) for s in splines])
        poly = poly.difference(band) if region_inside else poly.union(band)
        if not isinstance(poly, Polygon):
            raise GeometryError(f"{path}: the outline falls apart along its splines")
    return validate_polygon(poly, str(path))
