"""Measuring a pattern part by part, each part with a halo of its neighbours' dots, so a
panel of 10⁸ dots is measured in the memory of a few tiles and every number is the one
the whole pattern at once would give.

A :class:`~optdot.quality.source.Source` reads any :class:`~optdot.pattern.DotSource`: an
in-memory pattern (one part, no halo needed) or a partitioned dataset (one part per tile).
The passes add into :mod:`optdot.quality.sums`; :mod:`optdot.quality.summary` turns the
sums into numbers and plot data. Two passes:

1. **Each part alone** (:func:`_first_pass`): its bounding box, the dot area per map cell
   (coverage), dot counts per 2 mm square (densest region), the overview image, dots
   protruding from the panel or in zero-density cells, dot area in the edge bands and in
   bands of distance from the walls (:mod:`optdot.quality.wall_profile`). These
   are sums over dots, so parts add up exactly (counts are integers; float sums differ
   from one pass over all dots only in the order of addition).
2. **Each part with a halo** (:func:`_second_pass`): the dots of the other parts within
   ``H`` of the part's box, ``H = max(HALO_MM, 2 x the largest pair distance)``, read
   through a cache of recently used parts (parts come in tile order, so a few rows of
   tiles are held).

   - *Pairs* closer than a distance are found among own + halo dots (scipy ``cKDTree``);
     a pair of two own dots is counted by its part, a pair with a halo dot by the lower
     of the two parts' indices: each pair once. A dot is "in a close pair" whichever
     part counts the pair.
   - *k nearest neighbours* (nn and ψ6 over 6 neighbours) are exact for a dot whose k-th
     distance is at most ``H`` plus its distance to the edge of its part's box: any dot
     nearer lies in the halo. The rare dots beside a wide empty region that fail this
     are queried again with a halo as wide as their k-th distance (an upper bound of the
     true one), which makes them exact too.
   - ψ6 is summed per 2 mm patch and per tile band/interior (seams); nn and the
     normalised nn are kept per dot (16 B per dot, the only per-dot memory, so the
     percentiles are exact).

shapely/GEOS (:func:`optdot.testing.close_pairs`) stays the independent
cross-check of the pair counts in the tests.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from ..config.viewing import Viewing
from ..errors import ResourceError
from ..geometry.density import DensityMap
from ..geometry.domain import box_protruding
from ..geometry.orientation import Orientation, axis
from ..geometry.shapes import Footprints
from ..pattern import coverage_pixels
from ..runtime.memory import available_bytes
from ..spatial.window import bounds, in_rect
from .conformance import DotRule, footprint_text
from .metrics import (
    PatchGrid,
    SquareGrid,
    cell_area_sums,
    disc_area,
    edge_bands,
    nn_normalized,
    psi6_of,
)
from .seams import seam_sums
from .source import Source, gather
from .summary import Measured, summarize
from .sums import FirstSums, SecondSums, add_nested, cat, keep
from .visibility import LuminanceGrid, visibility
from .wall_profile import WallProfiler

#: Smallest halo around a part, mm: covers the 6 nearest neighbours at any fill > ~0.01
#: of 46 µm dots (beyond, the exact re-query takes over).
HALO_MM = 1.0
#: Neighbours per dot for ψ6 (the dot itself first).
K_NEAREST = 7
#: Most markers (close pairs, defects) kept for the report's plots; counts stay exact.
MAX_MARKS = 100_000
#: Most close-pair segments drawn in the zoom of the densest region.
MAX_SEGMENTS = 2000
#: Side of the densest region whose spectrum is taken, mm; of its zoom, mm.
DENSEST_MM, ZOOM_MM = 2.0, 1.0
#: Side of the square the grain (long-wavelength structure factor) is measured on, mm:
#: wavelengths up to 20 spacings need a window several times that.
GRAIN_MM = 10.0
#: Longest side of the overview image, pixels.
OVERVIEW_PX = 300


def measure(
    src: Source,
    density: DensityMap | None,
    smoothing: float,
    close: float,
    collision: float,
    gaps: tuple[float, float] | None = None,
    view: Viewing | None = None,
    area: tuple[float, float, float, float] | None = None,
    field: Orientation | None = None,
    ink: float | None = None,
    rule: DotRule | None = None,
) -> Measured:
    """Measure every QA number of ``src``.

    Args:
        density: the target map (None: no map numbers).
        smoothing: coverage smoothing, mm. close: too-close distance, mm.
        collision: centre distance below which dots collide, mm.
        gaps: ``(close_gap, collision_gap)``, mm, for dots of varying size: then a pair
            (i, j) is too close below the centre distance ``(d_i + d_j) / 2 + close_gap``
            and collides below ``(d_i + d_j) / 2 + collision_gap`` (an edge-gap rule),
            and ``close``/``collision`` are not used. Required when sizes vary.
        view: the viewing condition of the visibility check
            (:mod:`optdot.quality.visibility`; needs ``density``); None skips it.
        area: ``(x0, y0, x1, y1)`` mm, where the visibility is judged (the part of the
            panel a viewer sees); None: the whole panel.
        field: the orientation field shaped dots should follow (the job's); their
            angles' largest and mean difference from it are measured.
        ink: a printed film's ink contrast (luminance ``1 - ink * coverage``), or None
            (a guide's dots: luminance as the coverage); see the visibility check.
        rule: the footprints the job draws (:class:`~optdot.quality.conformance.DotRule`):
            the dots that are not one of them are counted (``metrics["footprints"]``);
            None: not checked.
    """
    if src.uniform_diameter is None and src.n and gaps is None:
        raise ValueError("dots of varying size are judged by edge gaps: pass gaps")
    if src.uniform_diameter is not None:
        gaps = None
    first = _first_pass(src, density, view, field, rule)
    second = _second_pass(src, density, first, close, collision, gaps)
    got = summarize(src, density, smoothing, close, collision, first, second, gaps, field)
    if first.size_lo is not None:
        got.metrics["footprint_mm"] = {
            "kind": src.kind.name,
            **{
                p: {"min": float(lo), "max": float(hi)}
                for p, lo, hi in zip(src.kind.params, first.size_lo, first.size_hi, strict=True)
            },
        }
    if rule is not None:
        got.metrics["footprints"] = {
            "job": rule.describe(),
            "not_the_jobs": first.stray,
            "first_not_the_jobs": first.stray_example,
        }
        got.where["footprints"] = [list(map(float, p)) for p in cat(first.where_stray, (2,))]
    if first.luminance is not None and view is not None and density is not None:
        vis, arrays = visibility(first.luminance, density, src.outline, view, area, ink)
        got.metrics["visibility"] = vis
        got.where["visibility"] = [vis["max_jnd_at_mm"]]
        got.arrays["jnd"] = arrays["jnd"]
    return got


def _first_pass(
    src: Source,
    density: DensityMap | None,
    view: Viewing | None = None,
    field: Orientation | None = None,
    rule: DotRule | None = None,
) -> FirstSums:
    x0, y0, x1, y1 = src.box
    onx, ony = coverage_pixels(src.box, src.nominal_diameter, OVERVIEW_PX)
    uniform = src.uniform_diameter
    squares = SquareGrid.of(src.box, DENSEST_MM)
    f = FirstSums(
        boxes=np.full((len(src.counts), 4), np.nan),
        cells=None
        if density is None
        else np.zeros(density.grid.size, np.int64 if uniform else float),
        squares=squares,
        square_counts=np.zeros((squares.nx, squares.ny)),
        overview=np.zeros((ony, onx)),
        overview_extent=(x0, x1, y0, y1),
    )
    if density is not None:
        if view is not None:
            f.luminance = LuminanceGrid.over(density, view)
        f.bands = edge_bands(src.box, src.outline, density)
        f.walls = WallProfiler(density, src.outline)
        f.band_sums = [0 if uniform is not None else 0.0 for _ in f.bands]
    for k in range(len(src.counts)):
        xy, dots = src.part(k)
        if not len(xy):
            continue
        d = dots.diameter
        f.boxes[k] = bounds(xy)
        if dots.angle is not None:
            _add_angles(f, xy, dots.angle, field, dots.kind.period)
        if rule is not None:
            _add_strays(f, xy, dots, rule)
        if not dots.kind.round:  # each size parameter's range, for the report
            lo, hi = dots.size.min(axis=0), dots.size.max(axis=0)
            f.size_lo = lo if f.size_lo is None else np.minimum(f.size_lo, lo)
            f.size_hi = hi if f.size_hi is None else np.maximum(f.size_hi, hi)
        if uniform is None:
            f.diameters.append(d)
        area = None if uniform is not None else dots.area()
        f.square_counts += squares.counts(xy)
        h, _, _ = np.histogram2d(
            xy[:, 1], xy[:, 0], bins=(ony, onx), range=((y0, y1), (x0, x1)), weights=area
        )
        f.overview += h
        r = dots.extent()
        if src.outline is None:
            out = box_protruding(xy, src.box, r)
        else:
            out = src.outline.protruding(xy, r, margin=False)
            f.outside += int((~src.outline.contains(xy)).sum())
            f.margin_violations += int(src.outline.protruding(xy, r).sum())
        f.protruding += int(out.sum())
        keep(f.where_protruding, xy[out], 20)
        keep(f.defects, xy[out], MAX_MARKS)
        if f.luminance is not None:
            f.luminance.add(xy, disc_area(uniform) if area is None else area)
        # coverage counts each dot's area: a shaped dot as the disc of its area
        dc = d if dots.kind.round else dots.equivalent_diameter()
        if f.walls is not None:
            f.walls.add(xy, dc)
        if density is not None:
            f.cells += cell_area_sums(xy, dc, uniform is not None, density)
            empty = density.empty_mask(xy)
            f.empty += int(empty.sum())
            keep(f.where_empty, xy[empty], 20)
            keep(f.defects, xy[empty], MAX_MARKS)
            for b, (_, inside, _) in enumerate(f.bands):
                sel = inside(xy)
                f.band_sums[b] += int(sel.sum()) if uniform is not None else area[sel].sum()
    cell = (x1 - x0) / onx * (y1 - y0) / ony
    if uniform is not None:
        f.overview *= np.pi * (0.5 * uniform) ** 2
    f.overview /= cell
    return f


#: How far from a dot a jump of the orientation field is looked for, mm, and the turn
#: that makes one, degrees: a dot this near a line where the field jumps (between two
#: LEDs it turns toward) may take either side's angle, as a mask's grid may move it
#: across; a smooth field turns by far less over this reach.
FIELD_REACH_MM, FIELD_JUMP_DEG = 1e-3, 5.0


def _add_angles(
    f: FirstSums, xy: np.ndarray, angle: np.ndarray, field: Orientation | None, period: float
):
    """Shaped dots' axes per 5° (-90..90°) and, with the field, their difference from it
    (modulo the footprint's ``period``, rad: turns that map it onto itself; modulo 2π
    where the field gives directions, prisms whose facets differ: turned half a turn,
    such a prism faces away from its LED, though its outline is the same)."""
    deg = np.degrees(axis(angle))
    h, _ = np.histogram(deg, bins=36, range=(-90.0, 90.0))
    f.angle_hist = h if f.angle_hist is None else f.angle_hist + h
    if field is None or not field.follows_position:  # random angles: their spread, judged
        return
    if field.period > np.pi:
        period = field.period
    here = field.at(xy)  # the field where the dot stands, or across a jump next to it
    err = np.abs(np.degrees(axis(angle - here, period)))
    for step in ((1, 0), (-1, 0), (0, 1), (0, -1)):
        there = field.at(xy + FIELD_REACH_MM * np.array(step))
        jump = np.abs(np.degrees(axis(there - here, field.period))) > FIELD_JUMP_DEG
        near = np.abs(np.degrees(axis(angle - there, period)))
        err = np.where(jump, np.minimum(err, near), err)
    f.field_error_max = max(f.field_error_max, float(err.max()))
    f.field_error_sum += float(err.sum())


def _add_strays(f: FirstSums, xy: np.ndarray, dots: Footprints, rule: DotRule) -> None:
    """Count the dots whose footprint the job does not draw, keep where they are and
    the first one in words."""
    bad = rule.stray(dots, xy)
    if not bad.any():
        return
    f.stray += int(bad.sum())
    keep(f.where_stray, xy[bad], 20)
    keep(f.defects, xy[bad], MAX_MARKS)
    if f.stray_example is None:
        i = int(np.flatnonzero(bad)[0])
        x, y = xy[i]
        text = footprint_text(dots.kind, dots.size[i]) + dots.kind.unlike(rule.shape.kind)
        f.stray_example = f"{text} at ({x:.3f}, {y:.3f}) mm"


def grain_window(densest, box) -> tuple[float, float, float, float]:
    """A square of :data:`GRAIN_MM` (at most the panel's sides) centred on the densest
    square, moved inside the panel box."""
    cx, cy = 0.5 * (densest[0] + densest[2]), 0.5 * (densest[1] + densest[3])
    wx, wy = min(GRAIN_MM, box[2] - box[0]), min(GRAIN_MM, box[3] - box[1])
    x0 = min(max(cx - wx / 2, box[0]), box[2] - wx)
    y0 = min(max(cy - wy / 2, box[1]), box[3] - wy)
    return x0, y0, x0 + wx, y0 + wy


def _second_pass(
    src: Source,
    density: DensityMap | None,
    first: FirstSums,
    close: float,
    collision: float,
    gaps: tuple[float, float] | None,
) -> SecondSums:
    n = src.n
    s = SecondSums(nn=np.full(n, np.inf))
    if gaps is None:
        reach = max(close, collision)
    else:  # the widest pair: two of the largest dots
        reach = max(float(d.max()) for d in first.diameters) + max(gaps)
    halo = max(HALO_MM, 2.0 * reach)
    boxes = first.boxes
    lo = np.nanmin(np.vstack([boxes[:, :2], [src.box[:2]]]), axis=0)
    hi = np.nanmax(np.vstack([boxes[:, 2:], [src.box[2:]]]), axis=0)
    patches = PatchGrid.over(lo, hi, 2.0)
    size = patches.nx * patches.ny
    p_cnt, p_re, p_im = np.zeros(size, np.int64), np.zeros(size), np.zeros(size)
    window = first.squares.densest(first.square_counts)
    s.grain_window = grain_window(window, src.box)
    zs = min(ZOOM_MM, window[2] - window[0])
    zoom = (window[0], window[1], window[0] + zs, window[1] + zs)
    offsets = np.concatenate([[0], np.cumsum(src.counts)]).astype(np.int64)
    for k in range(len(src.counts)):
        own, dots = src.part(k)
        m = len(own)
        if m == 0:
            continue
        d = dots.diameter
        hxy, hpart, halo_dots = gather(src, boxes, k, halo)
        hd = halo_dots.diameter
        pts = np.vstack([own, hxy]) if len(hxy) else own
        tree = cKDTree(pts)
        _check_pair_count(src, k, tree, reach)
        # pairs: own-own here; own-halo by the lower part index
        pr = tree.query_pairs(reach, output_type="ndarray")
        if len(pr):
            pr = pr[pr[:, 0] < m]  # query_pairs gives i < j; own dots come first
        flag = np.zeros(m, bool)
        if len(pr):
            dist = np.hypot(*(pts[pr[:, 0]] - pts[pr[:, 1]]).T)
            close_at, collision_at = close, collision
            if gaps is not None and not dots.kind.round:  # the exact edge gaps
                both = Footprints.concat([dots, halo_dots], dots.kind)
                dist = both.gap(pts, pr[:, 0], pr[:, 1])
                close_at, collision_at = gaps
                _cross_check(s, pts, both, pr[dist < gaps[0]], dist[dist < gaps[0]])
            elif gaps is not None:  # edge gaps: each pair's own centre distances
                dd = np.concatenate([d, hd])
                mean = 0.5 * (dd[pr[:, 0]] + dd[pr[:, 1]])
                close_at, collision_at = mean + gaps[0], mean + gaps[1]
            near = dist < close_at
            flag[pr[near, 0]] = True
            inner = pr[near & (pr[:, 1] < m), 1]
            flag[inner] = True
            mine = pr[:, 1] < m
            if len(hpart):
                mine |= hpart[np.clip(pr[:, 1] - m, 0, len(hpart) - 1)] > k
            order = np.lexsort((pr[:, 1], pr[:, 0]))
            pr, dist, near, mine = pr[order], dist[order], near[order], mine[order]
            collides = (dist < np.broadcast_to(collision_at, len(order))[order]) & mine
            for sel, count_attr, mids in (
                (near & mine, "pairs_close", s.close_mid),
                (collides, "pairs_collision", s.collision_mid),
            ):
                setattr(s, count_attr, getattr(s, count_attr) + int(sel.sum()))
                keep(mids, 0.5 * (pts[pr[sel, 0]] + pts[pr[sel, 1]]), MAX_MARKS)
            seg = near & mine
            a = pts[pr[seg, 0]]
            inz = in_rect(a, zoom, closed=False)
            keep(s.segments, np.stack([a[inz], pts[pr[seg, 1]][inz]], axis=1), MAX_SEGMENTS)
        s.close_dots += int(flag.sum())
        nn, psi, again = _nearest(src, boxes, k, own, pts, tree, halo)
        s.requeried += again
        s.nn[offsets[k] : offsets[k] + m] = nn
        s.psi_abs_sum += float(np.abs(psi).sum())
        s.psi_sum += complex(psi.sum())
        c, re, im = patches.sums(own, psi)
        p_cnt += c
        p_re += re
        p_im += im
        nn_n = None
        if density is not None:
            nn_n = nn_normalized(own, dots.extent(), density, nn)  # NaN where not defined
            s.nn_norm.append(nn_n[~np.isnan(nn_n)])
        if src.tiling is not None:
            part = seam_sums(
                own,
                dots.area(),
                *src.tiling,
                flag,
                np.abs(psi),
                nn_n,
            )
            s.seams = part if s.seams is None else add_nested(s.seams, part)
        s.window_xy.append(own[in_rect(own, window)])
        s.grain_xy.append(own[in_rect(own, s.grain_window, closed=False)])
        inz = in_rect(own, zoom, closed=False)
        s.zoom_xy.append(own[inz])
        s.zoom_d.append(dots.take(inz))
    s.patches = (patches, p_cnt, p_re, p_im)
    return s


#: Most near pairs of shaped dots QA checks again with shapely (the first ones met).
MAX_SHAPELY_PAIRS = 20_000
#: How close to the true footprints the polygons of that check are, mm.
SHAPELY_TOLERANCE = 1e-5


def _cross_check(s: SecondSums, pts, dots: Footprints, pairs: np.ndarray, gap: np.ndarray):
    """Check the exact edge gaps of near pairs (``[m, 2]`` indices into ``pts`` and
    ``dots``, their gaps ``[m]`` mm) against shapely's distance between polygons inscribed
    within :data:`SHAPELY_TOLERANCE` of the footprints: a polygon pair is never nearer
    than the footprints, nor farther by more than two tolerances, and meets exactly
    when they overlap by more than that. Counts the pairs checked and those that
    disagree, up to :data:`MAX_SHAPELY_PAIRS` pairs per pattern."""
    import shapely

    room = MAX_SHAPELY_PAIRS - s.shapely_pairs
    if room <= 0 or not len(pairs):
        return
    pairs, gap = pairs[:room], gap[:room]
    ends = np.unique(pairs)
    # one polygon per dot (dots of different sizes have different vertex counts)
    polys = {
        int(k): shapely.Polygon(dots.outline(int(k), SHAPELY_TOLERANCE) + pts[k]) for k in ends
    }
    a = np.array([polys[int(k)] for k in pairs[:, 0]], dtype=object)
    b = np.array([polys[int(k)] for k in pairs[:, 1]], dtype=object)
    dist = shapely.distance(a, b)
    slack = 2.0 * SHAPELY_TOLERANCE + 1e-9
    bad = (dist < gap - 1e-9) | (dist > np.maximum(gap, 0.0) + slack)
    s.shapely_pairs += len(pairs)
    s.shapely_disagree += int(bad.sum())


def _nearest(
    src: Source, boxes: np.ndarray, k: int, own: np.ndarray, pts: np.ndarray, tree, halo: float
) -> tuple[np.ndarray, np.ndarray, int]:
    """Exact nearest-neighbour distance and ψ6 of part ``k``'s dots ``own`` (``[m, 2]``),
    first among ``pts`` (own + halo, in ``tree``), then, for the dots this cannot settle,
    among ever wider halos.

    A dot is settled when its k-th distance is at most the halo plus its distance to the
    edge of the part's box, and there were k points to find (k = :data:`K_NEAREST`, or
    every dot of the pattern when it holds fewer).

    Returns:
        ``(nn [m], psi [m] complex, dots re-queried)``.
    """
    m = len(own)
    need = min(K_NEAREST, src.n)
    nn = np.full(m, np.inf)
    psi = np.zeros(m, complex)
    b = boxes[k]
    edge = np.minimum.reduce(
        [own[:, 0] - b[0], b[2] - own[:, 0], own[:, 1] - b[1], b[3] - own[:, 1]]
    )
    todo = np.arange(m)
    width = halo
    again = 0
    while len(todo):
        kk = min(need, len(pts))
        dist, idx = tree.query(own[todo], k=kk)
        if kk == 1:
            dist, idx = dist[:, None], idx[:, None]
        if kk == need:
            done = dist[:, -1] <= width + edge[todo]
            if len(src.counts) == 1:
                done[:] = True
        else:
            done = np.zeros(len(todo), bool)
        if kk > 1:
            nn[todo[done]] = dist[done, 1]
        psi[todo[done]] = psi6_of(pts, own[todo[done]], idx[done])
        todo = todo[~done]
        if not len(todo):
            break
        again += len(todo) if width == halo else 0
        # found distances bound the true ones from above; with too few points, double
        width = float(dist[~done, -1].max()) if kk == need else 2.0 * width
        hxy, _, _ = gather(src, boxes, k, width)
        pts = np.vstack([own, hxy]) if len(hxy) else own
        tree = cKDTree(pts)
    return nn, psi, again


#: Bytes per listed pair while pairs are judged (indices, distances, masks, sort order).
PAIR_BYTES = 96


def _check_pair_count(src, k: int, tree: cKDTree, reach: float) -> None:
    """Bound the pairs within ``reach`` before listing them: a file of duplicated or
    piled-up dots has pairs quadratic in its dots (20,000 identical rows: 2·10⁸), far
    more than a dot pattern (a few per dot) or the memory.

    First a bound that costs one sort: with the dots binned in squares of side ``reach``,
    every pair lies in one square or two neighbouring ones, so pairs ≤ ½ Σ n_c·Σ₉ n_c' ≤
    (9/2) Σ n_c² (about 6 per dot for a dot pattern). Only when that bound is over the
    limit are the pairs counted exactly (``count_neighbors``, no memory, ~1 s per 10⁶).

    Raises:
        ResourceError: more pairs than the available memory can list, with the count.
    """
    n = tree.n
    limit = max(16 * n, available_bytes() // (4 * PAIR_BYTES))
    pts = tree.data
    cells = np.floor((pts - pts.min(axis=0)) / reach).astype(np.int64)
    keys = cells[:, 0] * (int(cells[:, 1].max()) + 1) + cells[:, 1]
    _, per_cell = np.unique(keys, return_counts=True)
    if 4.5 * float(np.square(per_cell, dtype=np.float64).sum()) <= limit:
        return
    pairs = (int(tree.count_neighbors(tree, reach)) - n) // 2
    if pairs > limit:
        raise ResourceError(
            f"{src.label or 'the pattern'}: {pairs:,} pairs of dots closer than "
            f"{reach * 1e3:.0f} µm among {n:,} dots (part {k}): not a dot pattern "
            "(duplicated or piled-up dots?); listing them would need "
            f"{pairs * PAIR_BYTES / 2**30:.1f} GiB"
        )
