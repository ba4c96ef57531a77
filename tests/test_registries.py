"""The registries every seam reads: the dot kinds (:mod:`optdot.geometry.kinds`) and the
file formats (:data:`optdot.formats.FORMATS`). Each entry must answer every question the
pipeline asks of it, and answer it consistently with its other answers."""

from __future__ import annotations

import math
import re
from pathlib import Path

import numpy as np
import pytest

from optdot import exporters
from optdot.errors import PatternFileError
from optdot.exporters.readback import read_any
from optdot.formats import FORMATS, MASK_SUFFIXES, READ, format_of
from optdot.geometry.kinds import KINDS, Curve, drawn_as, support_bound
from optdot.geometry.kinds.polygon import Polygon, canonical
from optdot.geometry.shapes import Footprints

#: A polygon made for a job: a triangle, symmetric about no point.
TRIANGLE = Polygon(canonical([[-0.02, -0.03], [0.04, 0.0], [-0.02, 0.03]]))
#: One drawable size of each kind, mm (its ``params`` in order).
SIZES = {
    "circle": (0.046,),
    "ellipse": (0.080, 0.040),
    "rounded_rectangle": (0.120, 0.030, 0.005),
    "polygon": (TRIANGLE.l0, TRIANGLE.w0),
}


def _kind(name: str):
    """The kind of ``name`` a job has: the registry's, or a polygon made for one."""
    return TRIANGLE if name == "polygon" else KINDS[name]


def _bulged_area(ring: tuple[tuple[float, float, float], ...]) -> float:
    """The area enclosed by a closed polyline with bulges: its polygon's plus, per arc of
    bulge ``b`` over a chord ``c``, the circular segment's (``θ = 4 atan b``, radius
    ``c / (2 sin(θ/2))``, area ``r² (θ - sin θ) / 2``)."""
    pts = np.array([(x, y) for x, y, _ in ring])
    nxt = np.roll(pts, -1, axis=0)
    area = 0.5 * float(np.sum(pts[:, 0] * nxt[:, 1] - nxt[:, 0] * pts[:, 1]))
    for (_, _, b), p, q in zip(ring, pts, nxt, strict=True):
        if b:
            theta = 4.0 * math.atan(b)
            r = math.hypot(*(q - p)) / (2.0 * math.sin(0.5 * theta))
            area += 0.5 * r * r * (theta - math.sin(theta))
    return area


def _curve_area(c: Curve) -> float:
    if c.form == "disc":
        return math.pi * c.a * c.a
    if c.form == "ellipse":
        return math.pi * c.a * c.b
    assert c.form == "bulged", c.form
    return _bulged_area(c.ring)


def test_every_kind_is_sized_here_and_coded_by_its_place():
    assert set(SIZES) == set(KINDS)
    for code, kind in enumerate(KINDS.values()):
        assert kind.code == code and len(SIZES[kind.name]) == len(kind.params)


@pytest.mark.parametrize("name", sorted(SIZES))
def test_a_kind_s_cad_curve_encloses_its_area(name):
    """What DXF draws (a disc, an ellipse, arcs and lines) is the footprint: its area is
    the kind's to 1e-12, and the form an ELLIPSE entity is read as is the ellipse's."""
    kind = _kind(name)
    size = np.array(SIZES[name])
    curve = kind.curve(size)
    assert curve.form == kind.curve_form
    assert _curve_area(curve) == pytest.approx(float(kind.area(size[None])[0]), rel=1e-12)
    assert drawn_as("ellipse") is KINDS["ellipse"]


@pytest.mark.parametrize("name", sorted(SIZES))
def test_a_kind_s_support_bound_holds_its_footprint(name):
    """The compiled bound the exact-gap prefilter trusts is never under the footprint's
    true support (else a pair under the gap could be dropped): checked against the
    support of the outline's vertices in 720 directions either way (a triangle reaches
    further one way than the other), and equal to the kind's own support where the
    kind says it is exact (circle, ellipse)."""
    kind = _kind(name)
    size = np.array(SIZES[name])
    angle = 0.7
    a, b = kind.bound_params(size[None])[0]
    ring = kind.outline(size, angle, 1e-7)
    theta = np.linspace(0.0, 2.0 * np.pi, 720, endpoint=False)
    cp, sp = math.cos(angle), math.sin(angle)
    got = np.array(
        [support_bound(kind.code, math.cos(t), math.sin(t), a, b, cp, sp) for t in theta]
    )
    true = (ring @ np.stack([np.cos(theta), np.sin(theta)])).max(axis=0)
    back = (-ring @ np.stack([np.cos(theta), np.sin(theta)])).max(axis=0)
    assert np.all(got >= true - 1e-12) and np.all(got >= back - 1e-12)
    h = kind.support(theta, np.tile(size, (len(theta), 1)), np.full(len(theta), angle))
    assert np.all(got >= h - 1e-12)
    np.testing.assert_allclose(h, true, atol=2e-7)  # the outline within 1e-7 of it
    if name in ("circle", "ellipse"):
        np.testing.assert_allclose(got, h, rtol=1e-12)


@pytest.mark.parametrize("name", sorted(SIZES))
def test_a_kind_s_spheres_stand_for_it(name):
    """The multi-sphere circles of a kind relaxed by them cover its footprint (every
    outline vertex within one); another kind's are inscribed (every circle's rim on the
    footprint); a circle's are itself."""
    kind = _kind(name)
    size = np.array(SIZES[name])
    t, r = kind.spheres(size)
    ring = kind.outline(size, 0.0, 1e-7)
    d = np.hypot(ring[:, None, 0] - t[None], ring[:, None, 1]) - r[None]
    covered = bool(np.all(d.min(axis=1) <= 1e-12))
    u = np.linspace(0.0, 2.0 * np.pi, 64, endpoint=False)
    rim = np.concatenate(
        [
            np.column_stack([tk + rk * np.cos(u), rk * np.sin(u)])
            for tk, rk in zip(t, r, strict=True)
        ]
    )
    footprint = Footprints(kind, np.tile(size, (len(rim), 1)), np.zeros(len(rim)))
    shrunk = rim * (1 - 1e-9)
    inscribed = bool(footprint.contains(shrunk, np.arange(len(rim)), np.zeros((len(rim), 2))).all())
    assert covered == (kind.relaxation == "spheres" or name == "circle")
    assert inscribed == (kind.relaxation != "spheres")


def test_every_format_names_what_writes_and_reads_it():
    """Each record's writer and reader resolve; ``export`` writes exactly the formats
    with a writer; no suffix is two formats'; the masks' suffixes are the masks'."""
    seen: set[str] = set()
    for f in FORMATS.values():
        assert f.suffixes and not (seen & set(f.suffixes)), f.name
        seen |= set(f.suffixes)
        assert all(format_of(f"a{s.upper()}") is f for s in f.suffixes)
        for ref in (f.writer, f.reader):
            if ref is not None:
                assert callable(exporters.named(ref)), ref
        assert (f.writer is not None) == f.exported, f.name
    assert set(MASK_SUFFIXES) == {s for f in FORMATS.values() if f.mask for s in f.suffixes}
    assert format_of("a.txt") is None


def test_every_suffix_of_a_mask_reads_back(tiny_pattern, tmp_path):
    """A mask named by any of its format's suffixes (``.gdsii``, ``.oasis`` too) is read
    back by that format's reader, the same dots; an unknown one is named with the
    formats read."""
    want = np.sort(tiny_pattern.xy, axis=0)
    for name in READ:
        f = FORMATS[name]
        if not f.mask:
            continue
        for suffix in f.suffixes:
            path = tmp_path / f"m{suffix}"
            exporters.write(tiny_pattern, name, path)
            got = read_any(path)
            np.testing.assert_allclose(np.sort(got.xy, axis=0), want, atol=2e-6)
    with pytest.raises(PatternFileError, match=r"unknown format '\.txt' \(gds, oas, dxf, csv"):
        read_any(tmp_path / "m.txt")


#: What asks "is it a circle?" rather than asking the kind: identity with the registry's
#: circle, a job or pattern without a shape, or a kind's name compared.
CIRCLE_BRANCH = re.compile(
    r"\bis (not )?CIRCLE\b|[=!]= ?CIRCLE\b|shape is (not )?None"
    r"|\bkind\.name [=!]=|\bname [=!]= ?['\"](circle|ellipse|rounded_rectangle|polygon)['\"]"
)


def test_no_branch_on_the_kind_outside_the_registry():
    """The kinds' module answers for each kind (its :attr:`~Kind.round`, its formulas); a
    branch on the circle's identity or on a kind's name anywhere else is the second path
    a new kind would miss."""
    root = Path(__file__).resolve().parent.parent
    kinds = root / "optdot" / "geometry" / "kinds"
    hits = []
    for f in [*(root / "optdot").rglob("*.py"), *(root / "exporters").rglob("*.py")]:
        if kinds in f.parents:
            continue
        for n, line in enumerate(f.read_text().splitlines(), 1):
            if CIRCLE_BRANCH.search(line.split("#")[0]):
                hits.append(f"{f.relative_to(root)}:{n}: {line.strip()}")
    assert not hits, "\n".join(hits)


@pytest.mark.parametrize("name", sorted(SIZES))
def test_a_kind_s_equivalent_diameter_is_the_disc_of_its_area(name):
    """What sets a dot's spacing and count: the disc of the footprint's area; a round
    kind's own diameter to the last bit (a job's circle keeps its bytes)."""
    kind = _kind(name)
    size = np.array([SIZES[name]]) * np.array([[1.0], [1.7], [0.61]])
    got = kind.equivalent_diameter(size)
    np.testing.assert_allclose(got, 2.0 * np.sqrt(kind.area(size) / np.pi), rtol=1e-14)
    if kind.round:
        assert np.array_equal(got, size[:, 0])
        assert np.array_equal(kind.inradius(size), 0.5 * size[:, 0])


def test_a_job_that_names_no_kind_has_the_circle_of_its_diameter():
    from optdot.config.job import Job
    from optdot.geometry.density import DensityMap

    job = Job(2.0, 2.0, DensityMap(np.full((2, 2), 0.3), 2.0, 2.0), 0.046)
    assert job.shape.kind is KINDS["circle"] and job.shape.size == (0.046,)
    assert job.shape.equivalent_diameter == 0.046 and job.min_distance == 0.046 + job.optimize.gap
    assert job.dot_radius == 0.023


def test_every_sheet_kind_has_its_face_row():
    """A sheet kind the job accepts is one the scene knows how to trace (a kind added to
    the keys without its face would be traced as nothing)."""
    from optdot.config.backlight import SHEET_KINDS
    from optdot.optics.scene import SHEET_ROWS

    assert set(SHEET_ROWS) == set(SHEET_KINDS)


def test_stacks_are_asked_not_compared_outside_their_record():
    """What a stack is (direct-lit, printed on its film) is the backlight record's to
    say (:attr:`~optdot.config.backlight.Backlight.direct`, ``on_film``); a string
    compared elsewhere is a second place a new stack would have to be taught."""
    root = Path(__file__).resolve().parent.parent
    asked = re.compile(r"""\.(kind|print) [=!]= ?["'](direct|edge|film|guide|prism|diffuser)["']""")
    hits = [
        f"{f.relative_to(root)}:{n}"
        for f in (root / "optdot").rglob("*.py")
        if f.name != "backlight.py"
        for n, line in enumerate(f.read_text().splitlines(), 1)
        if asked.search(line)
    ]
    assert not hits, hits
