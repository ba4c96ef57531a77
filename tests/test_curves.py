"""The spacing guarantee against the curves the user drew.

Every dot centre must keep ``r0`` (within 1 nm) from the true circles, arcs and bulges of a
DXF outline, not only from the polygon they were flattened to. Distances here are
computed analytically from the drawing's own numbers.
"""

from __future__ import annotations

import math

import ezdxf
import numpy as np
import pytest

from optdot.config.schema import load_job
from optdot.geometry.curves import Conic, bulge_arc
from optdot.geometry.outline_io import load_outline
from optdot.orchestration.pipeline import generate
from tests.conftest import write_job

NM = 1e-6  # mm


def seg_distance(xy: np.ndarray, p, q) -> np.ndarray:
    """``[n]`` distance of points to the segment p-q."""
    p, q = np.asarray(p, float), np.asarray(q, float)
    d = q - p
    t = np.clip(((xy - p) @ d) / (d @ d), 0.0, 1.0)
    return np.hypot(*(xy - (p + t[:, None] * d)).T)


def arc_distance(xy: np.ndarray, c, r, a0, a1) -> np.ndarray:
    """``[n]`` distance of points to the ccw arc of radius r about c from a0 to a1 (rad)."""
    v = xy - np.asarray(c, float)
    ang = np.mod(np.arctan2(v[:, 1], v[:, 0]) - a0, 2 * np.pi)
    span = np.mod(a1 - a0, 2 * np.pi) or 2 * np.pi
    on = ang <= span
    ends = np.asarray(c) + r * np.array(
        [[math.cos(a0), math.sin(a0)], [math.cos(a1), math.sin(a1)]]
    )
    d_end = np.minimum(np.hypot(*(xy - ends[0]).T), np.hypot(*(xy - ends[1]).T))
    return np.where(on, np.abs(np.hypot(*v.T) - r), d_end)


def _job(tmp_path, dxf_name: str, rho: float = 0.45):
    grid = np.full((8, 8), rho)
    dom = {"outline": f'"{dxf_name}"', "width": None, "height": None}
    return load_job(write_job(tmp_path, grid, domain=dom, optimize={"max_iter": None}))


def test_dxf_circle_holes_keep_r0_from_the_true_circles(tmp_path):
    """A notched panel with two screw holes drawn as DXF CIRCLEs (flattened as Béziers,
    147 dots stood up to 0.45 µm too close to the true holes)."""
    holes = [((2.5, 2.5), 1.6), ((6.4, 5.6), 1.2)]
    doc = ezdxf.new("R2010", units=4)
    msp = doc.modelspace()
    outer = [(0, 0), (9, 0), (9, 4), (7.5, 4), (7.5, 4.6), (9, 4.6), (9, 8), (0, 8)]
    msp.add_lwpolyline(outer, close=True)
    for c, r in holes:
        msp.add_circle(c, r)
    doc.saveas(tmp_path / "holes.dxf")
    job = _job(tmp_path, "holes.dxf")
    p = generate(job)
    r0 = 0.5 * job.diameter
    for c, r in holes:
        d = np.hypot(*(p.xy - np.asarray(c)).T) - r
        assert d.min() >= r0 - NM, (c, r, (r0 - d.min()) * 1e6)
        # the dots do press on the hole: the test measures a contact, not empty space
        assert d.min() < r0 + 0.01
    sides = zip(outer, outer[1:] + outer[:1], strict=True)
    edges = np.min([seg_distance(p.xy, a, b) for a, b in sides], 0)
    assert edges.min() >= r0 - NM


def test_bulge_and_arc_outline_keeps_r0_from_the_true_curves(tmp_path):
    """Curved side as a bulged polyline (7 mm radius), a slot of LINEs and ARCs, and a
    round hole drawn as two ARCs (flattened loosely, 305
    dots stood up to 1.8 µm inside the r0 band)."""
    # outer: bottom edge, right edge, then a ccw bulge from (9, 6) to (0, 6) with radius 7
    chord = 9.0
    half = math.asin(0.5 * chord / 7.0)  # half the included angle
    bulge = math.tan(half / 2)  # tan(angle / 4), angle = 2 * half
    doc = ezdxf.new("R2010", units=4)
    msp = doc.modelspace()
    msp.add_lwpolyline([(0, 0, 0), (9, 0, 0), (9, 6, bulge), (0, 6, 0)], format="xyb", close=True)
    # slot: two lines and two half-circle arcs of radius 0.5
    msp.add_line((2.0, 1.5), (4.0, 1.5))
    msp.add_arc((4.0, 2.0), 0.5, -90, 90)
    msp.add_line((4.0, 2.5), (2.0, 2.5))
    msp.add_arc((2.0, 2.0), 0.5, 90, 270)
    # round hole of radius 0.9 drawn as two arcs
    msp.add_arc((6.5, 3.5), 0.9, 0, 180)
    msp.add_arc((6.5, 3.5), 0.9, 180, 360)
    doc.saveas(tmp_path / "bulge.dxf")
    job = _job(tmp_path, "bulge.dxf")
    p = generate(job)
    r0 = 0.5 * job.diameter
    arc = bulge_arc(np.array([9.0, 6.0]), np.array([0.0, 6.0]), bulge)
    c, R = arc.c, float(np.hypot(*arc.M))
    top = arc_distance(p.xy, c, R, arc.t0, arc.t1)
    assert (np.hypot(*(p.xy - c).T) <= R).all()
    slot = np.min(
        [
            seg_distance(p.xy, (2.0, 1.5), (4.0, 1.5)),
            seg_distance(p.xy, (4.0, 2.5), (2.0, 2.5)),
            arc_distance(p.xy, (4.0, 2.0), 0.5, -np.pi / 2, np.pi / 2),
            arc_distance(p.xy, (2.0, 2.0), 0.5, np.pi / 2, 3 * np.pi / 2),
        ],
        0,
    )
    hole = np.hypot(*(p.xy - (6.5, 3.5)).T) - 0.9
    sides = np.min(
        [
            seg_distance(p.xy, a, b)
            for a, b in [((0, 6), (0, 0)), ((0, 0), (9, 0)), ((9, 0), (9, 6))]
        ],
        0,
    )
    for name, d in (("arc", top), ("slot", slot), ("hole", hole), ("sides", sides)):
        assert d.min() >= r0 - NM, (name, (r0 - d.min()) * 1e6)
    assert min(top.min(), hole.min()) < r0 + 0.01  # dots touch the curves


@pytest.mark.parametrize("radius", [0.05, 7.0, 300.0, 5000.0])
@pytest.mark.parametrize("region_left", [True, False])
@pytest.mark.parametrize("sweep", [2 * math.pi, -2 * math.pi, 0.4, -1.3])
def test_flattening_is_on_the_safe_side_within_tolerance(radius, region_left, sweep):
    """Large radii too: the polygon stays on the region's side of the true circle and
    within the tolerance of it (at 300 mm a Bézier per 90° is ~80 µm off)."""
    tol = 1e-3
    arc = Conic(np.zeros(2), np.array([radius, 0.0]), np.array([0.0, radius]), 0.3, 0.3 + sweep)
    pts = arc.points(tol, region_left)
    # points densely along every edge of the polyline, their distance from the centre
    t = np.linspace(0, 1, 65)[:, None, None]
    along = pts[:-1][None] + t * (pts[1:] - pts[:-1])[None]
    rad = np.hypot(along[..., 0], along[..., 1])
    ccw = sweep > 0
    region_holds_centre = ccw == region_left
    if region_holds_centre:  # polygon inside the circle
        assert rad.max() <= radius * (1 + 1e-13)
        assert rad.min() >= radius - tol * (1 + 1e-9)
    else:  # polygon outside the circle
        assert rad.min() >= radius * (1 - 1e-13)
        assert rad.max() <= radius + tol * (1 + 1e-9)
    np.testing.assert_allclose(pts[0], arc.start, atol=1e-12 * radius)
    np.testing.assert_allclose(pts[-1], arc.end, atol=1e-12 * radius)


def test_keep_out_file_curves_are_flattened_outwards(tmp_path):
    """A keep-out drawn as a DXF circle is subtracted: its polygon must contain the circle."""
    doc = ezdxf.new("R2010", units=4)
    doc.modelspace().add_circle((1.0, 1.0), 0.5)
    doc.saveas(tmp_path / "ko.dxf")
    panel, _ = load_outline(tmp_path / "ko.dxf", 1e-3, region_inside=False)
    rad = np.hypot(*(np.asarray(panel.exterior.coords) - 1.0).T)
    assert rad.min() >= 0.5 - 1e-12 and rad.max() <= 0.5 + 1e-3 + 1e-12
    inside, _ = load_outline(tmp_path / "ko.dxf", 1e-3)
    rad = np.hypot(*(np.asarray(inside.exterior.coords) - 1.0).T)
    assert rad.max() <= 0.5 + 1e-12


def test_mirrored_ocs_arcs_and_ellipses(tmp_path):
    """An arc with extrusion (0, 0, -1) is mirrored in x; an ellipse is exact too."""
    doc = ezdxf.new("R2010", units=4)
    msp = doc.modelspace()
    msp.add_ellipse((5, 5), major_axis=(4, 0), ratio=0.5)
    # a circle hole drawn in a mirrored OCS: OCS centre (-5, 5) is WCS (5, 5)
    msp.add_circle((-5, 5), 0.6, dxfattribs={"extrusion": (0, 0, -1)})
    doc.saveas(tmp_path / "ell.dxf")
    panel, _ = load_outline(tmp_path / "ell.dxf", 1e-3)
    hole = np.asarray(panel.interiors[0].coords)
    np.testing.assert_allclose(hole.mean(0), (5, 5), atol=0.05)
    assert np.hypot(*(hole - (5, 5)).T).min() >= 0.6 - 1e-12
    ext = np.asarray(panel.exterior.coords) - 5.0
    e = (ext[:, 0] / 4) ** 2 + (ext[:, 1] / 2) ** 2  # <= 1 inside the ellipse
    assert e.max() <= 1 + 1e-12 and e.min() >= 1 - 1e-3
