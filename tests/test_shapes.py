"""The dot's footprint (:mod:`optdot.geometry.shapes`): each question answered by the
kind against an independent answer (shapely's geometry, brute force), and the pattern,
the dataset and every exporter asking it rather than a diameter."""

from __future__ import annotations

import numpy as np
import pytest
import shapely
from hypothesis import given, settings
from hypothesis import strategies as st

from optdot.geometry.shapes import CIRCLE, KINDS, Footprints, polygon_vertices


def _discs(n: int, seed: int) -> tuple[np.ndarray, Footprints]:
    rng = np.random.default_rng(seed)
    return rng.uniform(0, 0.5, (n, 2)), Footprints.circles(rng.uniform(0.02, 0.09, n))


def test_circle_area_and_extent_are_the_discs():
    xy, dots = _discs(50, 1)
    d = dots.diameter
    np.testing.assert_allclose(dots.area(), np.pi * (d / 2) ** 2, rtol=1e-15)
    np.testing.assert_array_equal(dots.extent(), 0.5 * d)
    for k in range(5):  # the polygon's area approaches the disc's from inside
        poly = shapely.Polygon(dots.outline(k, 1e-6))
        assert 0 < dots.area()[k] - poly.area < 1e-3 * dots.area()[k]
        assert poly.is_valid and shapely.Polygon(dots.outline(k, 1e-6)).exterior.is_ccw


@settings(max_examples=40, deadline=None, derandomize=True, database=None)
@given(st.integers(2, 40), st.integers(0, 2**32 - 1))
def test_circle_gaps_match_shapely_on_every_pair(n, seed):
    """Edge-to-edge distance of every pair against shapely's distance between the two
    polygons (disjoint pairs; polygons inscribed within 0.01 µm), and its sign against
    whether they intersect."""
    xy, dots = _discs(n, seed)
    i, j = np.triu_indices(n, 1)
    gap = dots.gap(xy, i, j)
    polys = [shapely.Polygon(dots.outline(k, 1e-5) + xy[k]) for k in range(n)]
    for a, b, g in zip(i, j, gap, strict=True):
        meets = polys[a].intersects(polys[b])
        if g > 2e-5:
            assert not meets
            assert polys[a].distance(polys[b]) == pytest.approx(g, abs=2e-5)
        elif g < -2e-5:
            assert meets


def test_containment_is_within_the_radius_of_the_dot():
    xy, dots = _discs(30, 4)
    rng = np.random.default_rng(5)
    k = rng.integers(0, 30, 4000)
    pts = xy[k] + rng.uniform(-0.05, 0.05, (4000, 2))
    inside = dots.contains(pts, k, xy)
    want = np.hypot(*(pts - xy[k]).T) <= 0.5 * dots.diameter[k]
    np.testing.assert_array_equal(inside, want)
    assert 0 < inside.mean() < 1


def test_footprints_take_and_broadcast():
    dots = Footprints.circles(0.046, 5)
    assert dots.n == 5 and dots.kind is CIRCLE and KINDS["circle"] is CIRCLE
    assert dots.take(np.array([0, 3])).n == 2
    assert dots.take(np.array([True, False, True, False, False])).diameter.tolist() == [
        0.046,
        0.046,
    ]
    assert np.all(dots.angles == 0)


def test_polygon_vertices_hold_the_tolerance():
    for r, tol in ((23.0, 0.01), (23.0, 1.0), (0.5, 0.01), (1.0, 5.0)):
        n = polygon_vertices(r, tol)
        assert n >= 8
        assert r * (1 - np.cos(np.pi / n)) <= tol + 1e-12 or n == 8


def test_pattern_and_dataset_chunks_carry_footprints(tmp_path, tiny_pattern):
    """A pattern's and a dataset's chunks are footprints of the same dots."""
    from optdot.io.dataset import open_dataset
    from optdot.io.dataset_write import save_dataset

    (_, xy, dots), *rest = list(tiny_pattern.chunks())
    assert not rest and dots.kind is CIRCLE and tiny_pattern.kind is CIRCLE
    np.testing.assert_array_equal(dots.diameter, tiny_pattern.diameter)
    np.testing.assert_array_equal(tiny_pattern.areas, dots.area())
    save_dataset(tiny_pattern, tmp_path / "d.parquet")
    ds = open_dataset(tmp_path / "d.parquet")
    got = [c for c in ds.chunks()]
    assert ds.kind is CIRCLE and sum(c[2].n for c in got) == tiny_pattern.n
    xy2, dots2 = ds.read_part(0)
    assert isinstance(dots2, Footprints) and dots2.n == len(xy2)


def test_groups_are_the_distinct_sizes_in_order():
    rng = np.random.default_rng(2)
    d = rng.choice([0.03, 0.046, 0.0460004, 0.09], 500)
    dots = Footprints.circles(d)
    got = list(dots.groups(1e6))
    assert [k for k, _ in got] == [(30000,), (46000,), (90000,)]  # 0.0460004 -> 46000 nm
    idx = np.concatenate([i for _, i in got])
    assert sorted(idx.tolist()) == list(range(500))
    for key, i in got:
        assert np.all(np.diff(i) > 0) and np.all(np.round(d[i] * 1e6) == key[0])


def test_speos_directions_follow_the_footprints_orientation(tmp_path):
    """Each mapping line's X and Y directions are the footprint's axes: (cos a, sin a, 0)
    and (-sin a, cos a, 0); a circle (a = 0) keeps the panel's axes with no "-0"."""
    from optdot.exporters.options import ExportOptions
    from optdot.exporters.speos import write_speos

    angles = np.array([0.0, np.pi / 6, -np.pi / 2])

    class Turned:  # a dot source whose footprints carry orientations
        n = 3
        nominal_diameter = 0.05
        outline = None  # the box: no caps

        def chunks(self):
            dots = Footprints.circles(np.array([0.05, 0.05, 0.1]))
            yield (
                (0, 0),
                np.array([[1.0, 2.0], [3.0, 4.0], [5.0, 6.0]]),
                Footprints(dots.kind, dots.size, angles),
            )

    write_speos(Turned(), tmp_path / "m.OPT3DMapping", ExportOptions())
    lines = (tmp_path / "m.OPT3DMapping").read_text().splitlines()
    assert lines[0] == "3"
    rows = np.array([[float(v) for v in ln.split()] for ln in lines[1:]])
    np.testing.assert_allclose(rows[:, 3:5], np.column_stack([np.cos(angles), np.sin(angles)]),
                               atol=1e-6)  # fmt: skip
    np.testing.assert_allclose(rows[:, 6:8], np.column_stack([-np.sin(angles), np.cos(angles)]),
                               atol=1e-6)  # fmt: skip
    np.testing.assert_allclose(rows[:, 9], [1, 1, 2])
    assert "-0.000000" not in lines[1]


#: Shaped dots the tests try: an 80 × 40 µm ellipse and a needle of 16:1, a 120 × 30 µm
#: rectangle with 5 µm corners, a capsule, a sharp square (mm).
SHAPED = [
    ("ellipse", (0.08, 0.04)),
    ("ellipse", (0.16, 0.01)),
    ("rounded_rectangle", (0.12, 0.03, 0.005)),
    ("rounded_rectangle", (0.1, 0.04, 0.02)),
    ("rounded_rectangle", (0.05, 0.05, 0.0)),
]


def _shaped(name: str, size, n: int, seed: int, spread: float = 0.2):
    rng = np.random.default_rng(seed)
    dots = Footprints(KINDS[name], np.tile(size, (n, 1)), rng.uniform(-np.pi, np.pi, n))
    return rng.uniform(0, spread, (n, 2)), dots


@pytest.mark.parametrize(("name", "size"), SHAPED)
@pytest.mark.slow
def test_shaped_gaps_match_shapely_and_bound_every_direction(name, size):
    """The exact edge-to-edge distance of oriented shapes against shapely's distance
    between polygons 5e-8 mm from them, its sign against whether they intersect, and
    the separation along 2,000 directions never exceeding it (it is their maximum)."""
    xy, dots = _shaped(name, size, 30, 7)
    i, j = np.triu_indices(30, 1)
    gap = dots.gap(xy, i, j)
    polys = [shapely.Polygon(dots.outline(k, 5e-8) + xy[k]) for k in range(30)]
    apart = 0
    for a, b, g in zip(i, j, gap, strict=True):
        if polys[a].intersects(polys[b]):
            assert g <= 1e-7
        else:
            assert polys[a].distance(polys[b]) == pytest.approx(g, abs=1.2e-7)
            apart += 1
    assert 60 < apart < len(i)  # both cases met
    kind, t = dots.kind, np.linspace(0, 2 * np.pi, 2000, endpoint=False)
    d = xy[j] - xy[i]
    f = d[:, :1] * np.cos(t) + d[:, 1:] * np.sin(t)
    for k in (i, j):
        f = f - np.array([kind.support(t, dots.size[q], dots.angles[q]) for q in k])
    assert np.all(f.max(axis=1) <= gap + 1e-12)
    # the sampling's own error: second order in the step for ellipses, first at corners
    np.testing.assert_allclose(f.max(axis=1), gap, atol=1e-5 if name == "ellipse" else 1e-3)


@pytest.mark.parametrize(("name", "size"), SHAPED)
def test_shaped_area_extent_containment_and_outline_agree_with_shapely(name, size):
    xy, dots = _shaped(name, size, 12, 3)
    rng = np.random.default_rng(4)
    k = rng.integers(0, 12, 2000)
    pts = xy[k] + rng.uniform(-0.09, 0.09, (2000, 2))
    inside = dots.contains(pts, k, xy)
    polys = [shapely.Polygon(dots.outline(q, 1e-8) + xy[q]) for q in range(12)]
    shapely.prepare(polys)
    want = shapely.covers(np.array(polys)[k], shapely.points(pts))
    np.testing.assert_array_equal(inside, want)
    assert 0.02 < inside.mean() < 0.9
    for q in range(12):
        coarse = shapely.Polygon(dots.outline(q, 1e-4) + xy[q])
        assert coarse.is_valid and coarse.exterior.is_ccw
        assert polys[q].hausdorff_distance(coarse) <= 1.05e-4  # within the tolerance
        assert polys[q].area == pytest.approx(dots.area()[q], rel=1e-6)
        far = np.hypot(*(np.asarray(polys[q].exterior.coords) - xy[q]).T).max()
        assert far == pytest.approx(dots.extent()[q], rel=1e-6)


@pytest.mark.parametrize(("name", "size"), SHAPED)
def test_a_mask_polygon_is_read_back_as_its_footprint(name, size):
    """``fit`` recovers size and orientation (an axis: modulo 180°, or 90° for a square)
    from the polygon a mask holds, snapped to a 1 nm grid."""
    kind = KINDS[name]
    for angle in (0.0, 0.3, -1.2, 1.5707963):
        ring = np.round((kind.outline(np.array(size), angle, 1e-5) + [3.0, -2.0]) * 1e6) * 1e-6
        fit = kind.fit(ring, 1e-5 + 2e-6)  # the outline's tolerance and the grid
        assert fit.ok
        np.testing.assert_allclose(fit.centre, [3.0, -2.0], atol=2e-6)
        np.testing.assert_allclose(fit.size[:2], size[:2], atol=2e-5)
        period = np.pi / 2 if size[0] == size[1] else np.pi
        turn = (fit.angle - angle + period / 2) % period - period / 2
        assert abs(turn) < 1e-4
        assert not CIRCLE.fit(ring, 1e-5 + 2e-6).ok  # nor is it read as a disc
        np.testing.assert_allclose(fit.size, size, atol=3e-6)  # vertices on the outline


@pytest.mark.parametrize(("name", "size"), [*SHAPED, ("circle", (0.05,))])
def test_the_separation_direction_is_the_gaps_gradient(name, size):
    """Moving j by ``h u`` widens the gap by ``h`` (the direction is the gap's gradient in
    the centre difference, Danskin's theorem), and no other unit step widens it more."""
    xy, dots = _shaped(name, size, 20, 9, spread=0.15)
    i, j = np.triu_indices(20, 1)
    gap, u = dots.separation(xy, i, j)
    np.testing.assert_allclose(np.hypot(*u.T), 1.0, rtol=1e-12)
    h = 1e-7
    a, s = dots.angles, dots.size
    moved = dots.kind.gap(xy[j] - xy[i] + h * u, s[i], a[i], s[j], a[j])
    np.testing.assert_allclose((moved - gap) / h, 1.0, atol=1e-3)
    for t in np.linspace(0, 2 * np.pi, 12, endpoint=False):
        v = np.array([np.cos(t), np.sin(t)])
        other = dots.kind.gap(xy[j] - xy[i] + h * v, s[i], a[i], s[j], a[j])
        assert np.all((other - gap) / h <= 1.0 + 1e-3)
