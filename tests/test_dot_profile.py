"""3-D dots on the guide's face (:mod:`optdot.optics.faces.dot_profile`): closed forms of
a spherical cap (normal incidence, the critical angle of a hemisphere), the share of a
Lambertian flux a bump passes against an independent integral that follows every Fresnel
split with its weight, the job's keys, and the tracer through bumps and dimples."""

from __future__ import annotations

import math

import numba as nb
import numpy as np
import pytest

from optdot.config.schema import load_job
from optdot.errors import JobError
from optdot.optics.faces.dot_profile import (
    BUMP,
    CAUGHT,
    DIMPLE,
    INTO_AIR,
    INTO_GUIDE,
    ONTO_FACE,
    meet_profile,
    trace_cap,
    trace_prism,
)
from optdot.optics.rays import ray_state
from optdot.optics.simulate import simulate, traced_what

from .conftest import graded_guide
from .test_shaped_dots import PRISM_JOB

N = 1.49  # PMMA
#: No walls: a dot's ray is moved freely.
NO_WALLS = np.zeros((0, 4))
#: A print with no real dots and no fill, as ``meet_profile`` takes the print's tables
#: (``marks.dot_tables``: the coverage and its cells at 1, 2; cells, centres, footprints,
#: grid at 3 .. 7; the cells' angles at 8): a ray leaving a dot meets no other.
NO_PRINT = (
    False, np.zeros((1, 1)), np.ones(4), np.zeros(2, np.int64), np.zeros(0), np.zeros(0),
    np.zeros((0, 6)), np.array([0.0, 0.0, 1.0, 1.0, 1.0, 1.0, 0.0]), np.full((1, 3), np.nan),
)  # fmt: skip
#: Normal-incidence Fresnel reflectance of PMMA in air.
R0 = ((N - 1) / (N + 1)) ** 2


@nb.njit(cache=True)
def _caps(code, k, n, px, py, d, e=1.0):  # pragma: no cover - compiled
    """``trace_cap`` for rays ``i`` entering at ``(px[i], py[i])`` going ``d[i]`` (a cap
    ``e`` times longer than wide): ``[m, 4]`` (where, dx, dy, dz)."""
    out = np.zeros((len(px), 4))
    for i in range(len(px)):
        _, w, _, _, _, a, b, c = trace_cap(
            ray_state(5, i), code, k, e, n, px[i], py[i], d[i, 0], d[i, 1], d[i, 2]
        )
        out[i, 0], out[i, 1], out[i, 2], out[i, 3] = w, a, b, c
    return out


def _straight_down(count: int, r: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    d = np.zeros((count, 3))
    d[:, 2] = -1.0
    return np.full(count, r), np.zeros(count), d


@pytest.mark.parametrize("code", [BUMP, DIMPLE])
@pytest.mark.parametrize(("k", "e"), [(0.25, 1.0), (1.0, 1.0), (0.5, 2.5)])
def test_light_meeting_a_cap_head_on_passes_as_fresnel_says(code, k, e):
    """A ray down the cap's axis meets it at normal incidence, whatever its height and
    however long its ellipse: it passes (a bump's into the air below, a dimple's through
    the cavity and out of its open base) with 1 - R0 and comes straight back up with R0
    (then along the axis again, out through the plane)."""
    px, py, d = _straight_down(100_000, 0.0)
    out = _caps(code, k, N, px, py, d, e)
    passed = float(np.mean(out[:, 0] == INTO_AIR))
    sigma = math.sqrt(R0 * (1 - R0) / len(out))
    assert abs(passed - (1 - R0)) < 4 * sigma, passed
    assert np.all(np.isin(out[:, 0], (INTO_AIR, INTO_GUIDE)))
    back = out[out[:, 0] == INTO_GUIDE]
    assert np.allclose(back[:, 1:], [0.0, 0.0, 1.0])


@pytest.mark.parametrize(("code", "least"), [(BUMP, 0.8), (DIMPLE, 0.1)])
def test_a_hemisphere_holds_what_meets_it_past_the_critical_angle(code, least):
    """A vertical ray at ``r`` from a hemisphere's axis meets its surface at ``asin(r)``
    (the radius 1), and in a sphere every later meeting is at the same angle: past the
    critical angle ``asin(1/n)`` (r 0.70 > 0.671) every ray comes back up into the guide;
    just inside it (r 0.64) light crosses (a bump's most of it into the air; a dimple's
    into the cavity, where much meets the wall again). Directions stay unit vectors."""
    held = _caps(code, 1.0, N, *_straight_down(20_000, 0.70))
    assert np.all(held[:, 0] == INTO_GUIDE) and np.all(held[:, 3] > 0)
    passed = _caps(code, 1.0, N, *_straight_down(20_000, 0.64))
    assert np.mean(passed[:, 0] == INTO_AIR) > least
    for out in (held, passed):
        assert np.allclose(np.linalg.norm(out[:, 1:], axis=1), 1.0)


def _lambertian_rays(count: int, seed: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Rays uniform over the unit footprint, directions Lambertian (cosine-weighted)
    going down."""
    g = np.random.default_rng(seed)
    r, a = np.sqrt(g.random(count)), 2 * np.pi * g.random(count)
    s, psi = np.sqrt(g.random(count)), 2 * np.pi * g.random(count)
    d = np.column_stack([s * np.cos(psi), s * np.sin(psi), -np.sqrt(1 - s * s)])
    return r * np.cos(a), r * np.sin(a), d


def _weighted_bump_share(
    k: float, n: float, nr=48, ntheta=48, npsi=96, bounces=40, e=1.0, na=1
) -> float:
    """The share of a Lambertian flux, uniform over the footprint, that a bump of height
    ``k`` on an ellipse ``e`` times longer than wide passes into the air: a quadrature
    over the entry point (its radius, and ``na`` angles about the centre: one stands for
    all on a round cap), the polar angle (cosine-weighted) and the azimuth, every ray
    followed through the cap with no random numbers: at each meeting with the surface
    ``x²/e² + y² + (z - c)² = R²`` its weight splits into Fresnel's reflected share,
    followed on, and the transmitted, counted; what reaches the plane again goes back
    up."""
    rs = np.sqrt((np.arange(nr) + 0.5) / nr)
    aa = 2 * np.pi * (np.arange(na) + 0.5) / na if na > 1 else np.zeros(1)
    st = np.sqrt((np.arange(ntheta) + 0.5) / ntheta)
    psi = 2 * np.pi * (np.arange(npsi) + 0.5) / npsi
    r, a, s, q = (v.ravel() for v in np.meshgrid(rs, aa, st, psi, indexing="ij"))
    p = np.column_stack([e * r * np.cos(a), r * np.sin(a), np.zeros_like(r)])
    d = np.column_stack([s * np.cos(q), s * np.sin(q), -np.sqrt(1 - s * s)])
    w = np.full(len(r), 1.0 / len(r))
    big = (1 + k * k) / (2 * k)
    c = np.array([0.0, 0.0, big - k])
    scale = np.array([1 / e**2, 1.0, 1.0])  # the surface's weights
    passed = 0.0
    for _ in range(bounces):
        o = p - c
        aq = np.einsum("ij,ij->i", d * scale, d)
        b = np.einsum("ij,ij->i", d * scale, o)
        cc = np.einsum("ij,ij->i", o * scale, o) - big * big
        t_s = (-b + np.sqrt(np.maximum(b * b - aq * cc, 0.0))) / aq
        t_p = np.where(d[:, 2] > 0, -p[:, 2] / np.where(d[:, 2] > 0, d[:, 2], 1.0), np.inf)
        on = t_s < t_p  # the rest leave through the plane: back up
        p, d, w, t_s = p[on] + t_s[on, None] * d[on], d[on], w[on], t_s[on]
        g = (p - c) * scale
        m = g / np.linalg.norm(g, axis=1)[:, None]
        cos_i = np.einsum("ij,ij->i", d, m)
        sin_t = n * np.sqrt(np.maximum(1 - cos_i**2, 0.0))
        cos_t = np.sqrt(np.maximum(1 - sin_t**2, 0.0))
        rs_ = (n * cos_i - cos_t) / (n * cos_i + cos_t)
        rp_ = (n * cos_t - cos_i) / (n * cos_t + cos_i)
        refl = np.where(sin_t >= 1, 1.0, 0.5 * (rs_**2 + rp_**2))
        passed += float(np.sum(w * (1 - refl)))
        w = w * refl
        d = d - 2 * cos_i[:, None] * m
        if w.sum() < 1e-7:
            break
    return passed


@pytest.mark.parametrize("k", [0.2, 0.5, 1.0])
def test_a_bump_passes_the_share_of_a_lambertian_flux_an_independent_integral_gives(k):
    """The tracer's random rays against every Fresnel split followed with its weight over
    a quadrature (:func:`_weighted_bump_share`): the share of a Lambertian flux, uniform
    over the footprint, a bump passes into the air below, within 4 sigma and the
    quadrature's error. Taller caps pass more (steeper surfaces, fewer rays past the
    critical angle)."""
    count = 200_000
    out = _caps(BUMP, k, N, *_lambertian_rays(count, 1))
    got = float(np.mean(out[:, 0] == INTO_AIR))
    want = _weighted_bump_share(k, N)
    assert abs(got - want) < 4 * math.sqrt(want * (1 - want) / count) + 2e-3, (got, want)
    assert np.all(np.isin(out[:, 0], (INTO_AIR, INTO_GUIDE, CAUGHT)))
    assert np.mean(out[:, 0] == CAUGHT) < 1e-3


@pytest.mark.slow
def test_a_bump_on_an_ellipse_passes_the_share_an_independent_integral_gives():
    """A cap on an ellipse 2.5 times longer than wide (the circle's cap across the short
    axis, stretched along the long one): the tracer against the weighted quadrature over
    the ellipse, within 4 sigma and the quadrature's error; it is not the round cap's
    share (the long axis' gentler slope passes less)."""
    k, e, count = 0.6, 2.5, 200_000
    px, py, d = _lambertian_rays(count, 3)
    out = _caps(BUMP, k, N, e * px, py, d, e)
    got = float(np.mean(out[:, 0] == INTO_AIR))
    want = _weighted_bump_share(k, N, nr=24, ntheta=32, npsi=64, e=e, na=24)
    assert abs(got - want) < 4 * math.sqrt(want * (1 - want) / count) + 2e-3, (got, want)
    assert abs(want - _weighted_bump_share(k, N, nr=24, ntheta=32, npsi=64)) > 0.01
    assert np.allclose(np.linalg.norm(out[:, 1:], axis=1), 1.0)


def test_taller_bumps_pass_more_of_a_lambertian_flux():
    """A flat face passes a Lambertian flux from inside PMMA only within its escape cone
    (1/n² of it, less Fresnel); a cap's sloped surface lets more out."""
    shares = [_weighted_bump_share(k, N, nr=24, ntheta=24, npsi=48) for k in (0.1, 0.4, 1.0)]
    assert shares[0] < shares[1] < shares[2]
    assert shares[0] > 0.9 * (1 / N**2) * (1 - R0)  # nearly flat: about the escape cone


def test_a_dimple_sends_some_light_onto_the_face_beside_it():
    """Light reflected off a dimple's wall may go down onto the flat face beside it
    (:data:`ONTO_FACE`); every ray ends in one of the four ways, directions unit."""
    out = _caps(DIMPLE, 0.6, N, *_lambertian_rays(50_000, 2))
    where = np.bincount(out[:, 0].astype(int), minlength=4) / len(out)
    assert where[ONTO_FACE] > 0.01 and where[INTO_AIR] > 0.3 and where[INTO_GUIDE] > 0.1
    assert where.sum() == pytest.approx(1.0) and where[CAUGHT] < 1e-3
    assert np.allclose(np.linalg.norm(out[:, 1:], axis=1), 1.0)


# -- prisms ----------------------------------------------------------------------------

#: The critical angle of PMMA in air, degrees.
CRITICAL = math.degrees(math.asin(1 / N))


@nb.njit(cache=True)
def _prisms(cut, hu, hv, rc, t1, t2, n, pu, pv, d):  # pragma: no cover - compiled
    """``trace_prism`` for rays ``i`` entering at ``(pu[i], pv[i])`` going ``d[i]``:
    ``[m, 4]`` (where, du, dv, dz)."""
    out = np.zeros((len(pu), 4))
    for i in range(len(pu)):
        _, w, _, _, _, a, b, c = trace_prism(
            ray_state(7, i), cut, hu, hv, rc, t1, t2, n, pu[i], pv[i], d[i, 0], d[i, 1],
            d[i, 2],
        )  # fmt: skip
        out[i, 0], out[i, 1], out[i, 2], out[i, 3] = w, a, b, c
    return out


def _fresnel(cos_i: float, n1: float, n2: float) -> float:
    sin_t = n1 / n2 * math.sqrt(max(0.0, 1 - cos_i**2))
    if sin_t >= 1:
        return 1.0
    cos_t = math.sqrt(1 - sin_t**2)
    rs = (n1 * cos_i - n2 * cos_t) / (n1 * cos_i + n2 * cos_t)
    rp = (n1 * cos_t - n2 * cos_i) / (n1 * cos_t + n2 * cos_i)
    return 0.5 * (rs * rs + rp * rp)


HU, HV = 0.06, 0.015  # a 120 x 30 µm prism, mm


def test_a_45_degree_prism_sends_light_straight_back_the_way_it_came():
    """Light straight down into a raised prism of two 45° facets (past PMMA's critical
    angle, 42.2°) is totally reflected at one facet, crosses to the other, is totally
    reflected again and goes straight back up: all of it, wherever it enters."""
    g = np.random.default_rng(4)
    pu, pv = g.uniform(-HU, HU, 5000), g.uniform(-HV, HV, 5000)
    d = np.tile([0.0, 0.0, -1.0], (5000, 1))
    t = math.tan(math.radians(45))
    out = _prisms(False, HU, HV, 0.0, t, t, N, pu, pv, d)
    assert np.all(out[:, 0] == INTO_GUIDE)
    assert np.allclose(out[:, 1:], [0.0, 0.0, 1.0], atol=1e-12)


@pytest.mark.parametrize("facet", [30.0, CRITICAL - 1.0])
def test_a_raised_facet_passes_what_fresnel_says_at_snell_s_angle(facet):
    """Light straight down onto a raised prism's facet of angle ``a`` to the face meets
    it at incidence ``a``: 1 - R(a) leaves at the first meeting, into the air at Snell's
    angle ``asin(n sin a)`` from the facet's normal."""
    count = 40_000
    t1, t2 = math.tan(math.radians(facet)), math.tan(math.radians(60.0))
    pu, pv = np.full(count, -HU / 2), np.zeros(count)
    d = np.tile([0.0, 0.0, -1.0], (count, 1))
    out = _prisms(False, HU, HV, 0.0, t1, t2, N, pu, pv, d)
    a = math.radians(facet)
    m = np.array([-math.sin(a), 0.0, math.cos(a)])  # the facet's normal, s up into the prism
    cos_t = math.sqrt(1 - (N * math.sin(a)) ** 2)
    snell = N * np.array([0.0, 0.0, 1.0]) + (cos_t - N * math.cos(a)) * m
    want = 1 - _fresnel(math.cos(a), N, 1.0)
    first = (out[:, 0] == INTO_AIR) & np.all(
        np.abs(out[:, 1:] - [snell[0], snell[1], -snell[2]]) < 1e-9, axis=1
    )
    got = float(np.mean(first))
    assert abs(got - want) < 4 * math.sqrt(want * (1 - want) / count), (got, want)
    assert np.allclose(np.linalg.norm(out[:, 1:], axis=1), 1.0)


def test_a_prism_s_facets_hold_light_past_the_critical_angle():
    """Straight-down light meets both facets of a symmetric raised prism past the
    critical angle when they are 1° steeper than it (43.2°): all of it goes back up into
    the guide; 1° flatter (41.2°) about two thirds leave into the air."""
    g = np.random.default_rng(3)
    pu, pv = g.uniform(-HU, HU, 20_000), g.uniform(-HV, HV, 20_000)
    d = np.tile([0.0, 0.0, -1.0], (20_000, 1))
    steep, flat = (math.tan(math.radians(CRITICAL + s)) for s in (1.0, -1.0))
    held = _prisms(False, HU, HV, 0.0, steep, steep, N, pu, pv, d)
    passed = _prisms(False, HU, HV, 0.0, flat, flat, N, pu, pv, d)
    assert np.all(held[:, 0] == INTO_GUIDE) and np.all(held[:, 3] > 0)
    assert 0.6 < np.mean(passed[:, 0] == INTO_AIR) < 0.7


@pytest.mark.parametrize("facet", [30.0, 50.0])
def test_a_cut_facet_reflects_what_fresnel_says_into_the_mirror_direction(facet):
    """Light straight down in the guide onto a prism cut into the face meets its facet
    from the guide at incidence ``a``: R(a) (all of it past the critical angle) goes on
    in the mirror direction ``(-sin 2a, 0, cos 2a)``, up into the guide or down onto the
    flat face beside it; the rest enters the cavity."""
    count = 40_000
    t1, t2 = math.tan(math.radians(facet)), math.tan(math.radians(60.0))
    pu, pv = np.full(count, -HU / 2), np.zeros(count)
    d = np.tile([0.0, 0.0, -1.0], (count, 1))
    out = _prisms(True, HU, HV, 0.0, t1, t2, N, pu, pv, d)
    a = math.radians(facet)
    mirror = np.array([-math.sin(2 * a), 0.0, math.cos(2 * a)])
    back = np.all(np.abs(out[:, 1:] - mirror) < 1e-9, axis=1)
    assert np.all(out[back, 0] == (INTO_GUIDE if mirror[2] > 0 else ONTO_FACE))
    want = _fresnel(math.cos(a), N, 1.0)
    if want == 1.0:
        assert back.all()
    else:
        got = float(np.mean(back))
        assert abs(got - want) < 4 * math.sqrt(want * (1 - want) / count), (got, want)


def _weighted_prism_share(t1, t2, n, nu=40, nv=6, ntheta=24, npsi=48, bounces=80) -> float:
    """The share of a Lambertian flux, uniform over a rectangle's footprint, a raised
    prism of facet slopes ``t1``, ``t2`` passes into the air: every ray followed through
    the body's five planes with no random numbers, its weight split at each meeting into
    Fresnel's reflected share, followed on, and the transmitted, counted (the base
    plane: back into the guide)."""
    us = (np.arange(nu) + 0.5) / nu * 2 * HU - HU
    vs = (np.arange(nv) + 0.5) / nv * 2 * HV - HV
    st = np.sqrt((np.arange(ntheta) + 0.5) / ntheta)
    psi = 2 * np.pi * (np.arange(npsi) + 0.5) / npsi
    u, v, s, q = (x.ravel() for x in np.meshgrid(us, vs, st, psi, indexing="ij"))
    p = np.column_stack([u, v, np.zeros_like(u)])
    d = np.column_stack([s * np.cos(q), s * np.sin(q), np.sqrt(1 - s * s)])  # into the body
    g1, g2 = 1 / math.sqrt(1 + t1 * t1), 1 / math.sqrt(1 + t2 * t2)
    normals = np.array(
        [[0, 0, -1], [-t1 * g1, 0, g1], [t2 * g2, 0, g2], [0, 1, 0], [0, -1, 0]], float
    )
    offsets = np.array([0.0, t1 * HU * g1, t2 * HU * g2, HV, HV])
    w = np.full(len(u), 1.0 / len(u))
    passed = 0.0
    for _ in range(bounces):
        dn = d @ normals.T
        with np.errstate(divide="ignore", invalid="ignore"):
            t = np.where(dn > 0, (offsets - p @ normals.T) / dn, np.inf)
        k = np.argmin(t, axis=1)
        stay = k > 0  # the base: back into the guide
        p, d, w, k = p[stay], d[stay], w[stay], k[stay]
        p = p + t[stay, k][:, None] * d
        m = normals[k]
        cos_i = np.einsum("ij,ij->i", d, m)
        refl = np.array([_fresnel(c, n, 1.0) for c in cos_i])
        passed += float(np.sum(w * (1 - refl)))
        w = w * refl
        d = d - 2 * cos_i[:, None] * m
        if w.sum() < 1e-7:
            break
    return passed


@pytest.mark.slow
@pytest.mark.parametrize("facets", [(40.0, 55.0), (25.0, 70.0)])
def test_a_raised_prism_passes_the_share_an_independent_integral_gives(facets):
    """The tracer's random rays against every Fresnel split followed with its weight
    through the prism's planes (:func:`_weighted_prism_share`): the share of a Lambertian
    flux, uniform over a rectangle's footprint, a raised prism passes into the air."""
    t1, t2 = (math.tan(math.radians(f)) for f in facets)
    count = 100_000
    g = np.random.default_rng(5)
    pu, pv = g.uniform(-HU, HU, count), g.uniform(-HV, HV, count)
    s, psi = np.sqrt(g.random(count)), 2 * np.pi * g.random(count)
    d = np.column_stack([s * np.cos(psi), s * np.sin(psi), -np.sqrt(1 - s * s)])
    out = _prisms(False, HU, HV, 0.0, t1, t2, N, pu, pv, d)
    got = float(np.mean(out[:, 0] == INTO_AIR))
    want = _weighted_prism_share(t1, t2, N)
    assert abs(got - want) < 4 * math.sqrt(want * (1 - want) / count) + 3e-3, (got, want)
    assert np.mean(out[:, 0] == CAUGHT) < 1e-3


def test_a_ray_leaves_a_rounded_footprint_on_its_edge_along_its_normal():
    """``wall_exit`` against the rounded rectangle's distance function: from points
    inside, the exit lies on the edge (distance 0) and its normal is the distance's
    gradient there, on the straight sides and the corners' arcs alike."""
    from optdot.optics.faces.dot_profile import wall_exit

    hu, hv, rc = 0.06, 0.015, 0.01
    g = np.random.default_rng(6)

    def sdf(u, v):
        qu, qv = abs(u) - (hu - rc), abs(v) - (hv - rc)
        return math.hypot(max(qu, 0), max(qv, 0)) + min(max(qu, qv), 0) - rc

    arcs = 0
    for _ in range(3000):
        u, v = g.uniform(-hu, hu), g.uniform(-hv, hv)
        if sdf(u, v) >= 0:
            continue
        a = g.uniform(0, 2 * np.pi)
        t, mu, mv = wall_exit(u, v, math.cos(a), math.sin(a), hu, hv, rc)
        qu, qv = u + t * math.cos(a), v + t * math.sin(a)
        assert abs(sdf(qu, qv)) < 1e-12
        e = 1e-7
        grad = np.array([sdf(qu + e, qv) - sdf(qu - e, qv), sdf(qu, qv + e) - sdf(qu, qv - e)])
        assert np.allclose([mu, mv], grad / np.linalg.norm(grad), atol=1e-6)
        arcs += abs(qu) > hu - rc and abs(qv) > hv - rc
    assert arcs > 100


# -- the job and the tracer ------------------------------------------------------------

GUIDE = """
name = "{name}"
[domain]
width = 12.0
height = 8.0
[density]
grid = "map.csv"
[dots]
diameter = 0.046
{dots}
[light_guide]
thickness = 0.4
refractive_index = 1.49
absorption = 0.0002
dot_albedo = 0.9
reflector = {reflector}
reflector_finish = "{finish}"
edge_reflectance = 0.9
[[light_guide.leds]]
edge = "bottom"
positions = [6.0]
width = 2.0
profile = "lambertian"
"""


def _guide(tmp_path, dots: str, name: str = "g", reflector=0.95, finish="diffuse"):
    np.savetxt(tmp_path / "map.csv", np.full((8, 12), 0.2), delimiter=",")
    path = tmp_path / f"{name}.toml"
    path.write_text(GUIDE.format(name=name, dots=dots, reflector=reflector, finish=finish))
    return load_job(path)


def test_bumps_and_dimples_absorb_nothing_and_every_ray_ends_somewhere(tmp_path):
    """Moulded dots are the guide's own material: no light is absorbed in them (ink
    absorbs 1 - albedo of what it scatters), every ray ends in one fate, and a bump's or
    dimple's guide extracts more than white ink's here (no ink absorption)."""
    rays = 200_000
    ink = simulate(_guide(tmp_path, "", "ink").bench, rays, 1)
    for dots in ('profile = "bump"\nheight = 0.010', 'profile = "dimple"\ndepth = 0.015'):
        sim = simulate(_guide(tmp_path, dots, "p").bench, rays, 1)
        assert sim.fates["absorbed_dots"] == 0 and sum(sim.fates.values()) == rays
        assert sim.efficiency > ink.efficiency + 0.05
    assert ink.fates["absorbed_dots"] > 0


def test_a_profile_traces_the_same_rays_on_any_thread_count(tmp_path):
    """Same seed, same counts and the same luminance on one thread and on two."""
    bench = _guide(tmp_path, 'profile = "bump"\nheight = 0.012').bench
    was = nb.get_num_threads()
    try:
        nb.set_num_threads(1)
        one = simulate(bench, 50_000, 4)
        nb.set_num_threads(min(2, nb.config.NUMBA_NUM_THREADS))
        two = simulate(bench, 50_000, 4)
    finally:
        nb.set_num_threads(was)
    assert one.fates == two.fates and np.array_equal(one.luminance, two.luminance)


def test_a_mirror_under_bumps_returns_what_a_white_sheet_would_not_absorb(tmp_path):
    """Under a perfect mirror nothing is lost under the guide; under a black sheet
    (reflectance 0) everything a bump passes is: the guide then extracts only what the
    bumps send back up and the face's escape cone... less."""
    dots = 'profile = "bump"\nheight = 0.010'
    mirror = simulate(_guide(tmp_path, dots, "m", 1.0, "specular").bench, 100_000, 2)
    black = simulate(_guide(tmp_path, dots, "b", 0.0).bench, 100_000, 2)
    assert mirror.fates["lost_bottom"] == 0
    assert black.fates["lost_bottom"] > 0.3 * 100_000
    assert mirror.efficiency > black.efficiency + 0.3


@pytest.mark.parametrize(
    ("dots", "said"),
    [
        ('profile = "lens"', "dots.profile = 'lens' must be one of ink, bump, dimple"),
        ('profile = "bump"', "dots.profile = 'bump' needs dots.height (mm)"),
        ('profile = "bump"\nheight = 0.024', "dots.height = 0.024 must be in mm, 0.0001 <="),
        ('profile = "bump"\nheight = -0.01', "dots.height = -0.01 must be in mm"),
        ('profile = "bump"\nheight = 1e-300', "dots.height = 1e-300 must be in mm"),
        (
            'profile = "dimple"\nheight = 0.01',
            "dots.height belongs to dots.profile = 'bump', not 'dimple'",
        ),
        ("height = 0.01", "dots.height belongs to dots.profile = 'bump', not 'ink'"),
    ],
)
def test_a_profile_that_cannot_be_made_is_refused_in_one_line(tmp_path, dots, said):
    """Unknown profiles, a missing or stray height, and a cap taller than a hemisphere
    (0.024 mm on a 0.023 mm radius) are refused naming the key."""
    with pytest.raises(JobError) as e:
        _guide(tmp_path, dots)
    assert said in str(e.value) and "\n" not in str(e.value), str(e.value)


def test_a_dimple_deeper_than_the_guide_is_thick_is_refused(tmp_path):
    """A dimple 23 µm deep cannot be cut into a guide 20 µm thick (nor a bump stand as
    high as it: a 3-D dot's height is less than the guide's thickness)."""
    np.savetxt(tmp_path / "map.csv", np.full((8, 12), 0.2), delimiter=",")
    text = GUIDE.format(name="t", dots='profile = "dimple"\ndepth = 0.023', reflector=0.9,
                        finish="diffuse")  # fmt: skip
    (tmp_path / "t.toml").write_text(text.replace("thickness = 0.4", "thickness = 0.02"))
    with pytest.raises(JobError) as e:
        load_job(tmp_path / "t.toml")
    said = "dots.depth = 0.023 makes dimples 0.023 mm deep, not less than the guide's thickness"
    assert said in str(e.value) and "\n" not in str(e.value), str(e.value)


def test_a_profile_on_a_footprint_it_does_not_fit_is_refused(tmp_path):
    """A cap stands on a circle or an ellipse, a prism on a rectangle: a cap on a
    rectangle, a prism on a circle, a cap taller than the smallest of several sizes'
    half width, and a stack that prints its dots on a film are refused."""
    np.savetxt(tmp_path / "map.csv", np.full((8, 12), 0.2), delimiter=",")
    rect = GUIDE.replace(
        "diameter = 0.046\n{dots}",
        'shape = "rounded_rectangle"\nlength = 0.12\nwidth = 0.03\ncorner_radius = 0.0\n'
        'profile = "bump"\nheight = 0.01',
    )
    prism = GUIDE.replace("{dots}", 'profile = "prism"\nfacets = [45, 45]')
    sizes = GUIDE.replace(
        "diameter = 0.046\n{dots}", 'diameter = [0.046, 0.08]\nprofile = "bump"\nheight = 0.03'
    )
    for text, said in (
        (rect, "'bump' stands on circle or ellipse footprints; rounded_rectangle dots take "
         "profile = 'ink' or 'prism'"),
        (prism, "'prism' stands on rounded_rectangle footprints; circle dots take"),
        (sizes, "dots.height = 0.03 must be in mm, 0.0001 <= height <= 0.023 (half the "
         "width of the (smallest) dots, 0.046 mm wide"),
    ):  # fmt: skip
        path = tmp_path / "j.toml"
        path.write_text(text.format(name="x", dots="", reflector=0.9, finish="diffuse"))
        with pytest.raises(JobError) as e:
            load_job(path)
        assert said in str(e.value), str(e.value)
    film = GUIDE.format(
        name="f", dots='profile = "bump"\nheight = 0.01', reflector=0.9, finish="diffuse"
    )
    film += '[backlight]\nkind = "edge"\nprint = "film"\n[backlight.film]\nthickness = 0.1\n'
    (tmp_path / "f.toml").write_text(film)
    with pytest.raises(JobError, match="prints them on a film"):
        load_job(tmp_path / "f.toml")


PRISM_GUIDE = GUIDE.replace(
    "diameter = 0.046\n{dots}",
    'shape = "rounded_rectangle"\nlength = 0.12\nwidth = 0.03\ncorner_radius = 0.005\n{dots}',
)


def _prism_guide(tmp_path, dots: str, orientation: str = 'toward = "leds"', name="p"):
    np.savetxt(tmp_path / "map.csv", np.full((8, 12), 0.2), delimiter=",")
    text = PRISM_GUIDE.format(name=name, dots=dots, reflector=0.95, finish="diffuse")
    text = text.replace("[light_guide]", f"[orientation]\n{orientation}\n[light_guide]")
    path = tmp_path / f"{name}.toml"
    path.write_text(text)
    return load_job(path)


@pytest.mark.parametrize(
    ("dots", "said"),
    [
        ('profile = "prism"', "dots.profile = 'prism' needs dots.facets = [deg, deg]"),
        ('profile = "prism"\nfacets = [45]', "dots.facets = [45] must be two angles"),
        ('profile = "prism"\nfacets = [0, 45]', "dots.facets = [0, 45] must be two angles"),
        ('profile = "prism"\nfacets = [45, 90]', "a facet at 90 degrees or more does not close"),
        ('profile = "prism"\nfacets = [45, "a"]', "dots.facets = [45, 'a'] must be two"),
        ('profile = "prism"\nfacets = [45, true]', "must be two angles"),
        (
            'profile = "prism"\nfacets = [85, 85]\ncut = true',
            "makes prisms 0.6858 mm deep, not less than the guide's thickness (0.4 mm)",
        ),
        (
            'profile = "prism"\nfacets = [89.999, 89.999]',
            "makes prisms 3438 mm high, not less than the guide's thickness (0.4 mm)",
        ),
        ('profile = "bump"\nfacets = [45, 45]', "dots.facets belongs to dots.profile = 'prism'"),
        ("cut = true", "dots.cut belongs to dots.profile = 'prism', not 'ink'"),
    ],
)
def test_a_prism_that_cannot_be_made_is_refused_in_one_line(tmp_path, dots, said):
    """Facets missing, not two, not between 0.5 and 90 degrees (a facet at 90 does not
    close), a prism as deep or as high as the guide is thick (3.4 m at 89.999°: its rays
    would be caught in it), and a prism's keys under another profile."""
    with pytest.raises(JobError) as e:
        _prism_guide(tmp_path, dots)
    assert said in str(e.value) and "\n" not in str(e.value), str(e.value)


def test_a_prism_s_height_is_where_its_facets_meet(tmp_path):
    """Facets of 45° and 30° on a 0.12 mm length meet at ``L t1 t2 / (t1 + t2)``: the
    profile's height, what ``simulate`` reports with its facets (JSON and words)."""
    job = _prism_guide(tmp_path, 'profile = "prism"\nfacets = [45, 30]\ncut = true')
    t2 = math.tan(math.radians(30))
    assert job.profile.height == pytest.approx(0.12 * t2 / (1 + t2), rel=1e-12)
    from optdot.optics.simulate import traced_what

    sim = simulate(job.bench, 20_000, 1)
    assert traced_what(sim) == "map coverage (prisms cut 43.9 µm deep, facets 45° / 30°)"
    summary = sim.summary()["dot_profile"]
    assert summary == {
        "kind": "prism", "height_mm": job.profile.height, "facets_deg": [45.0, 30.0],
        "cut": True,
    }  # fmt: skip


def _cover_and_real(tmp_path, orientation: str, rays: int = 400_000) -> tuple[dict, dict]:
    """The summaries of cut 45° prisms (``orientation``) traced as the map's coverage and
    through the real dots; no light absorbed in them in either."""
    from optdot.orchestration.pipeline import generate

    job = _prism_guide(tmp_path, 'profile = "prism"\nfacets = [45, 45]\ncut = true', orientation)
    sims = simulate(job.bench, rays, 3), simulate(job.bench, rays, 3, dots=generate(job))
    for sim in sims:
        assert sim.fates["absorbed_dots"] == 0 and sum(sim.fates.values()) == rays
    return sims[0].summary(), sims[1].summary()


@pytest.mark.slow  # over 2 s on 2 cores
def test_real_prisms_trace_as_their_coverage_and_absorb_nothing(tmp_path):
    """Cut prisms at random angles traced through the real dots (each met where the ray's
    path passes through its cavity, in its own frame) and as the map's coverage (the
    twins of a lattice of the cell's fill about a point drawn on or off a dot): the
    guide extracts the same and sends the same on axis; no light is absorbed in them."""
    cover, real = _cover_and_real(tmp_path, "random = true")
    assert abs(cover["efficiency"] - real["efficiency"]) < 0.006
    a, b = cover["angles"], real["angles"]
    assert abs(a["on_axis"] - b["on_axis"]) < 4 * math.hypot(a["on_axis_sigma"], b["on_axis_sigma"])


@pytest.mark.slow  # over 2 s on 2 cores
def test_real_prisms_turned_along_the_light_extract_as_their_coverage(tmp_path):
    """Cut prisms turned along the light from their LED: the real dots and the coverage
    extract the same (on axis, see the next test)."""
    cover, real = _cover_and_real(tmp_path, 'toward = "leds"\nrelative = "parallel"')
    assert abs(cover["efficiency"] - real["efficiency"]) < 0.006


@pytest.mark.slow
def test_real_prisms_turned_along_the_light_send_on_axis_what_their_coverage_does(tmp_path):
    """Since session 43 a cut prism's cavity is met wherever a ray's path passes through
    it: these prisms are 60 µm deep on a 30 µm width, and every ray at the face meets
    the coverage's twins or the real dots along its path, a walk up to a millimetre long
    over which the angle toward the LED turns. Each twin stands at the print's angle
    where it stands (session 47): 1.230 ± 0.022 on axis against the real dots' 1.267 ±
    0.023 (these 4·10⁵ rays); with every twin at the angle of the point the ray crossed
    the face at, 1.57, 9 sigma off (the gap 2.7 times within 1 mm of the LED)."""
    cover, real = _cover_and_real(tmp_path, 'toward = "leds"\nrelative = "parallel"')
    a, b = cover["angles"], real["angles"]
    assert abs(a["on_axis"] - b["on_axis"]) < 4 * math.hypot(a["on_axis_sigma"], b["on_axis_sigma"])


@pytest.mark.slow  # over 1.5 s: 4e6 rays
def test_prisms_turned_toward_close_leds_trace_as_their_coverage_on_a_coarse_map(tmp_path):
    """Near an LED the angle toward it turns within a map's 1 mm cell: the coverage takes
    its dots' angles on cells of 0.1 mm, and cut prisms facing two LEDs 5 mm apart send
    as much light on axis as coverage as through their real dots (1.420 and 1.427 at 8e6
    rays; one angle per 1 mm cell gave 1.369, 7 sigma off). Since session 43 (a cut
    prism's cavity met wherever a ray's path passes through it) a walk among the twins
    runs up to a millimetre, across the map's rows: 1.495 as the coverage (its twins each
    at the print's angle where it stands, session 47; 1.856 with all at one) against 1.593
    through the real dots (6.2 sigma) while every twin stood as packed for the fill where
    the ray met the face; 1.551 (2.6 sigma) since twins in cells of fewer dots stand as
    many fewer (session 48; BENCHMARKS.md)."""
    from optdot.orchestration.pipeline import generate

    dots = 'shape = "rounded_rectangle"\nlength = 0.120\nwidth = 0.030\ncorner_radius = 0.005'
    dots += '\nprofile = "prism"\nfacets = [45, 45]\ncut = true'
    more = '[orientation]\ntoward = "leds"\nrelative = "parallel"'
    path = graded_guide(tmp_path, (0.10, 0.42), dots, more, optimize="gap = 0.005")
    job = load_job(path)
    rays = 2_000_000
    cover = simulate(job.bench, rays, 3).summary()["angles"]
    real = simulate(job.bench, rays, 3, dots=generate(job)).summary()["angles"]
    sigma = math.hypot(cover["on_axis_sigma"], real["on_axis_sigma"])
    assert abs(cover["on_axis"] - real["on_axis"]) < 3 * sigma, (cover["on_axis"], real["on_axis"])


@pytest.mark.slow  # over 2 s on 2 cores
def test_prisms_facing_their_led_send_more_light_on_axis_than_random_ones(tmp_path):
    """Cut 45° prisms whose facets face the LED (their length along the light) send more
    light straight out of the guide than prisms at random angles on the same map: on-axis
    luminance about 5 sigma apart here, held at over 3 (BENCHMARKS.md,
    ``benchmarks/profiles.py``: 1.306 against 1.126, 17 sigma, at 4e6 rays)."""
    dots = 'profile = "prism"\nfacets = [45, 45]\ncut = true'
    rays = 400_000
    facing = _prism_guide(tmp_path, dots, 'toward = "leds"\nrelative = "parallel"', "f")
    random = _prism_guide(tmp_path, dots, "random = true", "r")
    a = simulate(facing.bench, rays, 2).summary()["angles"]
    b = simulate(random.bench, rays, 2).summary()["angles"]
    assert a["on_axis"] - b["on_axis"] > 3 * math.hypot(a["on_axis_sigma"], b["on_axis_sigma"])


def test_a_prism_profile_traces_the_same_rays_on_any_thread_count(tmp_path):
    """Random angles drawn a ray: the same counts and luminance on one thread and two."""
    job = _prism_guide(tmp_path, 'profile = "prism"\nfacets = [40, 55]', "random = true")
    was = nb.get_num_threads()
    try:
        nb.set_num_threads(1)
        one = simulate(job.bench, 50_000, 4)
        nb.set_num_threads(min(2, nb.config.NUMBA_NUM_THREADS))
        two = simulate(job.bench, 50_000, 4)
    finally:
        nb.set_num_threads(was)
    assert one.fates == two.fates and np.array_equal(one.luminance, two.luminance)


@nb.njit(cache=True)
def _meet_rays(f, at, d, seed, pr, walls):  # pragma: no cover - compiled
    """``meet_profile`` for rays ``i`` going ``d[i]`` (the print's tables ``pr``, the
    panel's ``walls``): ``[m, 4]`` (act, dx, dy, dz)."""
    out = np.zeros((len(d), 4))
    for i in range(len(d)):
        _, act, _, _, a, b, c = meet_profile(
            ray_state(seed, i), f, N, at, 0.0, 0.0, pr, walls, d[i, 0], d[i, 1], d[i, 2]
        )
        out[i, 0], out[i, 1], out[i, 2], out[i, 3] = act, a, b, c
    return out


def _meet(f, at, d, seed):
    """:func:`_meet_rays` on :data:`NO_PRINT`, no walls. The print is handed in (not read
    as a global, whose arrays numba types read-only): the kernels ``meet_profile`` calls
    are then the tracer's, compiled once."""
    return _meet_rays(f, at, d, seed, NO_PRINT, NO_WALLS)


@pytest.mark.slow
def test_a_turned_dot_meets_a_ray_as_the_unturned_dot_meets_the_ray_turned_back():
    """A prism (and a cap on an ellipse) turned by 35° meets a ray as the unturned one
    meets that ray turned by -35°, and sends it on turned by +35°: the dot's frame is
    the footprint's, both ways (over a mirror, which keeps a ray's azimuth)."""
    from optdot.geometry.profile import BUMP as BUMP_CODE
    from optdot.geometry.profile import PRISM_CUT
    from optdot.optics import tables as t

    g = np.random.default_rng(8)
    s_, p = np.sqrt(g.random(2000)), 2 * np.pi * g.random(2000)
    d = np.column_stack([s_ * np.cos(p), s_ * np.sin(p), -np.sqrt(1 - s_ * s_)])
    a = math.radians(35.0)
    c, s = math.cos(a), math.sin(a)
    back = np.column_stack([c * d[:, 0] + s * d[:, 1], c * d[:, 1] - s * d[:, 0], d[:, 2]])
    for code, body in (
        (PRISM_CUT, (0.06, 0.015, 0.005, 1.0, math.tan(math.radians(30)))),
        (BUMP_CODE, (0.04, 0.02, 0.0, 0.0, 0.0)),
    ):
        row = np.zeros(t.F_COLS)
        row[t.F_KIND], row[t.F_REFL], row[t.F_REFL_FINISH] = t.BOTTOM_FACE, 0.9, 1.0
        row[t.F_PROFILE], row[t.F_PROF_K] = code, 0.6
        row[[t.F_PROF_U, t.F_PROF_V, t.F_PROF_C, t.F_PROF_T1, t.F_PROF_T2]] = body
        f = tuple(float(v) for v in row)
        turned = _meet(f, (-0.01, 0.004, c, s, math.nan), d, 9)
        plain = _meet(f, (-0.01, 0.004, 1.0, 0.0, math.nan), back, 9)
        same = turned[:, 0] == plain[:, 0]
        assert same.mean() > 0.99
        x, y = plain[same, 1], plain[same, 2]
        assert np.allclose(turned[same, 1], c * x - s * y, atol=1e-9)
        assert np.allclose(turned[same, 2], s * x + c * y, atol=1e-9)
        assert np.allclose(turned[same, 3], plain[same, 3], atol=1e-9)


def test_a_dot_of_another_size_is_its_footprint_scaled_under_the_same_height():
    """Met on a dot 1.5 times as wide as its row's (the half width the frame gives), a
    bump meets rays as a row of that size whose cap has the same height (a lower
    aspect), and a prism as one 1.5 times as long, wide and high (its facets keep their
    angles); the size changes what they do."""
    from optdot.geometry.profile import BUMP as BUMP_CODE
    from optdot.geometry.profile import PRISM_CUT
    from optdot.optics import tables as t

    g = np.random.default_rng(3)
    s_, p = np.sqrt(g.random(2000)), 2 * np.pi * g.random(2000)
    d = np.column_stack([s_ * np.cos(p), s_ * np.sin(p), -np.sqrt(1 - s_ * s_)])
    t30 = math.tan(math.radians(30))
    for code, k, small, big in (
        (BUMP_CODE, 0.6, (0.02, 0.02, 0.0), (0.03, 0.03, 0.0)),
        (PRISM_CUT, 0.0, (0.06, 0.015, 0.005), (0.09, 0.0225, 0.0075)),
    ):
        rows = []
        for body, aspect in ((small, k), (big, k / 1.5)):
            row = np.zeros(t.F_COLS)
            row[t.F_KIND], row[t.F_REFL], row[t.F_REFL_FINISH] = t.BOTTOM_FACE, 0.9, 1.0
            row[t.F_PROFILE], row[t.F_PROF_K] = code, aspect
            row[[t.F_PROF_U, t.F_PROF_V, t.F_PROF_C, t.F_PROF_T1, t.F_PROF_T2]] = (*body, 1.0, t30)
            rows.append(tuple(float(v) for v in row))
        scaled = _meet(rows[0], (-0.012, 0.005, 1.0, 0.0, big[1]), d, 5)
        own = _meet(rows[1], (-0.012, 0.005, 1.0, 0.0, math.nan), d, 5)
        same = scaled[:, 0] == own[:, 0]
        assert same.mean() > 0.99
        assert np.allclose(scaled[same, 1:], own[same, 1:], atol=1e-9)
        unscaled = _meet(rows[0], (-0.012, 0.005, 1.0, 0.0, math.nan), d, 5)
        assert (np.abs(unscaled[:, 1:] - own[:, 1:]).max(axis=1) > 1e-6).mean() > 0.05


@pytest.mark.slow
def test_bumps_of_several_sizes_trace_as_their_coverage(tmp_path):
    """Bumps 12 um high on dots 30-120 um wide (a hybrid pitch rule over a map from 0.08
    to 0.45): traced through the real dots (each its own size, read off its footprint)
    and as the map's coverage (each cell's dots at the size the rule gives its fill),
    the guide extracts the same and sends the same on axis."""
    from optdot.orchestration.pipeline import generate

    fill = np.repeat(np.linspace(0.08, 0.45, 8)[:, None], 12, axis=1)
    np.savetxt(tmp_path / "map.csv", fill, delimiter=",")
    dots = 'profile = "bump"\nheight = 0.012\nspacing = 0.15'
    text = GUIDE.format(name="z", dots=dots, reflector=0.95, finish="diffuse")
    path = tmp_path / "z.toml"
    path.write_text(text.replace("diameter = 0.046", "diameter = [0.03, 0.12]"))
    job = load_job(path)
    pattern = generate(job)
    assert np.ptp(pattern.diameter) > 0.05
    rays = 400_000
    cover, real = simulate(job.bench, rays, 3), simulate(job.bench, rays, 3, dots=pattern)
    a, b = cover.summary(), real.summary()
    assert abs(a["efficiency"] - b["efficiency"]) < 0.006, (a["efficiency"], b["efficiency"])
    a, b = a["angles"], b["angles"]
    assert abs(a["on_axis"] - b["on_axis"]) < 4 * math.hypot(a["on_axis_sigma"], b["on_axis_sigma"])


def test_a_map_being_designed_sizes_its_bumps_by_its_own_fill(tmp_path):
    """``design`` traces the coverage of the map it is making over the job's map: bumps of
    several sizes there have the size the rule gives that map's fill, not the job map's,
    also when both maps have the same cells (the coverage of 0.4 over a job whose map is
    0.05 traces as the job whose map is 0.4)."""
    from optdot.optics.scene import Coverage

    jobs = []
    for fill in (0.05, 0.4):
        np.savetxt(tmp_path / f"m{fill}.csv", np.full((8, 12), fill), delimiter=",")
        dots = 'profile = "bump"\nheight = 0.012\nspacing = 0.15'
        text = GUIDE.format(name="m", dots=dots, reflector=0.95, finish="diffuse")
        text = text.replace("diameter = 0.046", "diameter = [0.03, 0.12]")
        (tmp_path / "m.toml").write_text(text.replace("map.csv", f"m{fill}.csv"))
        jobs.append(load_job(tmp_path / "m.toml"))
    phi = np.full((8, 12), 0.4)
    designing = simulate(jobs[0].bench, 50_000, 2, coverage=Coverage(phi, 0, 0, 1, 1, phi))
    assert designing.fates == simulate(jobs[1].bench, 50_000, 2).fates


@pytest.mark.slow  # over 1.5 s: a pattern generated, gated and exported
def test_a_speos_mapping_keeps_the_caps_height_on_dots_of_several_sizes(tmp_path):
    """Bumps of one height on dots of several sizes: the Speos mapping scales each element
    by its diameter across and by 1 in depth (prisms and ink scale all three)."""
    from optdot.orchestration.pipeline import export, generate

    from .test_speos import parse

    fill = np.repeat(np.linspace(0.08, 0.45, 8)[:, None], 12, axis=1)
    np.savetxt(tmp_path / "map.csv", fill, delimiter=",")
    text = GUIDE.format(name="b", dots='profile = "bump"\nheight = 0.012\nspacing = 0.15',
                        reflector=0.95, finish="diffuse")  # fmt: skip
    path = tmp_path / "b.toml"
    path.write_text(text.replace("diameter = 0.046", "diameter = [0.03, 0.12]"))
    job = load_job(path)
    pattern = generate(job)
    export(pattern, {"speos": tmp_path / "b.OPT3DMapping"}, job, force=True)
    _, _, scale = parse(tmp_path / "b.OPT3DMapping")
    across = pattern.diameter / pattern.nominal_diameter
    np.testing.assert_allclose(scale[:, :2], np.repeat(across[:, None], 2, axis=1), atol=5e-7)
    assert np.ptp(scale[:, 0]) > 0.3 and np.all(scale[:, 2] == 1.0)
    assert (
        job.profile.keeps_height
        and not _prism_guide(tmp_path, 'profile = "prism"\nfacets = [45, 45]').profile.keeps_height
    )


def test_prisms_of_several_sizes_are_as_high_as_their_largest_allows(tmp_path):
    """Prisms scaled up to 4 times: the largest's height must stay under the guide's
    thickness (60° facets on 0.48 mm stand 0.416 mm in a 0.4 mm guide); up to 3 times
    they stand 0.312 mm and are traced."""
    np.savetxt(tmp_path / "map.csv", np.full((8, 12), 0.2), delimiter=",")
    for top, ok in ((3.0, True), (4.0, False)):
        text = PRISM_GUIDE.format(
            name="s", dots=f'profile = "prism"\nfacets = [60, 60]\nscale = [1.0, {top}]',
            reflector=0.95, finish="diffuse",
        )  # fmt: skip
        path = tmp_path / "s.toml"
        path.write_text(
            text.replace("[light_guide]", "[orientation]\nrandom = true\n[light_guide]")
        )
        if ok:
            job = load_job(path)
            assert job.profile.height == pytest.approx(0.36 * math.tan(math.radians(60)) / 2)
            assert job.profile.words() == "prisms up to 312 µm high, facets 60° / 60°"
            sim = simulate(job.bench, 20_000, 1)
            assert sum(sim.fates.values()) == 20_000 and sim.fates["absorbed_dots"] == 0
            assert traced_what(sim) == "map coverage (prisms up to 312 µm high, facets 60° / 60°)"
        else:
            with pytest.raises(JobError, match="makes prisms 0.4157 mm high, not less than"):
                load_job(path)


def test_ink_s_scatter_rule_is_refused_beside_a_profile(tmp_path):
    """``dot_scatter = "extract"`` idealises ink; a bump is traced as what it is."""
    np.savetxt(tmp_path / "map.csv", np.full((8, 12), 0.2), delimiter=",")
    text = GUIDE.format(name="s", dots='profile = "bump"\nheight = 0.01', reflector=0.9,
                        finish="diffuse")  # fmt: skip
    (tmp_path / "s.toml").write_text(text.replace("dot_albedo = 0.9", 'dot_scatter = "extract"'))
    with pytest.raises(JobError, match="dot_scatter = 'extract' is what ink dots do"):
        load_job(tmp_path / "s.toml")


def test_a_design_whose_dots_extract_nothing_stops_at_once(tmp_path):
    """Dots that send no light out of the guide (ink of albedo 0 here; a profile too flat
    to bend light out is the same) leave no luminance to design from: one line, at the
    first iteration, not 16 iterations of NaN."""
    from optdot.optics.design import design

    np.savetxt(tmp_path / "map.csv", np.full((8, 12), 0.2), delimiter=",")
    text = GUIDE.format(name="d", dots="", reflector=0.9, finish="diffuse")
    (tmp_path / "d.toml").write_text(text.replace("dot_albedo = 0.9", "dot_albedo = 0.0"))
    with pytest.raises(JobError, match="no light leaves the top through the map of iteration 1"):
        design(load_job(tmp_path / "d.toml").bench, rays=20_000)


def test_simulate_says_what_dots_it_traced(tmp_path):
    """The summary (JSON, and the command's first line) names a guide's 3-D dots and their
    height; an ink guide's summary carries no such field (its bytes as before)."""
    from optdot.cli.optics import _print_simulation

    bump = simulate(_guide(tmp_path, 'profile = "dimple"\ndepth = 0.012').bench, 20_000, 1)
    assert bump.summary()["dot_profile"] == {"kind": "dimple", "height_mm": 0.012}
    said = []
    _print_simulation(bump, 1.0, echo=said.append)
    assert "(dimples 12 µm deep)" in said[0]
    assert "dot_profile" not in simulate(_guide(tmp_path, "", "i").bench, 20_000, 1).summary()


@pytest.mark.parametrize(("facets", "refused"), [("[70, 20]", True), ("[45, 45]", False)])
def test_prisms_read_from_a_dxf_are_refused_only_when_their_facets_differ(
    tmp_path, facets, refused
):
    """The trace's check before it reads a DXF's prisms: facets that differ need the
    direction a DXF does not hold; equal facets look the same either way round."""
    from pathlib import Path

    from optdot.cli.tooling import traced_as_made

    job = _prism_guide(tmp_path, f'profile = "prism"\nfacets = {facets}')
    if not refused:  # on to the next check, which needs the dots
        with pytest.raises(AttributeError):
            traced_as_made(Path("p.dxf"), None, job)
        return
    with pytest.raises(JobError, match=r"p\.dxf: a DXF holds each prism's outline, not which"):
        traced_as_made(Path("p.dxf"), None, job)


@pytest.mark.slow
def test_a_dxf_of_prisms_whose_facets_differ_is_refused_by_simulate_not_traced(tmp_path):
    """A DXF keeps each prism's outline, the same either way round: read back, about half
    of the 70° / 20° prisms facing their LEDs came turned half a turn, and the trace said
    1.4 points more efficiency than the pattern's (a hostile tester's guide). ``simulate``
    refuses it in one line naming the facets; the GDSII mask of the same dots, which
    places each prism by its direction, traces as the pattern file does."""
    import json

    from .conftest import cli, one_error

    turned = 'toward = "leds"\nrelative = "parallel"'
    _prism_guide(tmp_path, 'profile = "prism"\nfacets = [70, 20]', turned)
    job, npz = tmp_path / "p.toml", tmp_path / "p.npz"
    dxf, gds = tmp_path / "p.dxf", tmp_path / "p.gds"
    for args in (
        ("generate", job, "-o", npz),
        ("export", npz, "--job", job, "--dxf", dxf, "--gds", gds),
    ):
        rc, err, _ = cli(*args, "-q")
        assert rc == 0, err
    one_error(("simulate", job, dxf, "--rays", "1000"), 2, str(dxf), "DXF", "[70, 20]")
    got = []
    for f in (npz, gds):
        out = tmp_path / f"{f.name}.json"
        rc, err, _ = cli("simulate", job, f, "--rays", "20000", "--json", out, "-q")
        assert rc == 0, err
        got.append(json.loads(out.read_text()))
    assert got[0]["efficiency"] == got[1]["efficiency"] and got[0]["angles"] == got[1]["angles"]


def test_check_names_the_profile_and_a_ray_count_that_is_no_number_is_refused(tmp_path):
    """``optdot check`` says what the dots are (prisms, their height and facets), and
    ``--rays abc`` is refused in one line that shows how to write a count."""
    from .conftest import cli, one_error

    _prism_guide(tmp_path, 'profile = "prism"\nfacets = [45, 30]\ncut = true')
    rc, err, out = cli("check", tmp_path / "p.toml")
    assert rc == 0 and "prisms cut 43.9 µm deep, facets 45° / 30° (" in out, (err, out)
    one_error(("simulate", tmp_path / "p.toml", "--rays", "abc"), 2,
              "'abc' is not a whole number (2000000, 2e6 or 2_000_000)")  # fmt: skip


def test_dots_of_a_size_the_rule_does_not_give_there_are_refused_naming_what_it_gives(tmp_path):
    """A graded job's dots (30-120 µm by the fill) traced from a CSV of 46 µm dots: 46 µm
    is in the range, on a step, and still not the job's where the dot stands; the one
    line says what the rule gives there."""
    from .conftest import one_error

    np.savetxt(tmp_path / "map.csv", np.full((8, 12), 0.2), delimiter=",")
    (tmp_path / "g.toml").write_text(
        '[domain]\nwidth = 12.0\nheight = 8.0\n[density]\ngrid = "map.csv"\n'
        '[dots]\ndiameter = [0.03, 0.12]\nspacing = 0.15\nprofile = "bump"\nheight = 0.015\n'
        '[light_guide]\nthickness = 0.4\n[[light_guide.leds]]\nedge = "bottom"\n'
        "positions = [6.0]\nwidth = 2.0\n"
    )
    (tmp_path / "d.csv").write_text("x_mm,y_mm,diameter_mm\n5,3,0.046\n7,5,0.046\n")
    args = ("simulate", tmp_path / "g.toml", tmp_path / "d.csv", "--rays", "1000")
    line = one_error(args, 2, "d.csv: 2 of its 2 dots are not this job's circle 30–120 µm on")
    assert "(the first: circle 46 µm at (5.000, 3.000) mm, where the job's size rule gives" in line


#: Cut 70° / 20° prisms facing two LEDs on a 6 x 3 mm guide (a hostile tester's job):
#: the direction test's guide, its facets given, on ``pmap.csv``.
DIRECTED = (
    PRISM_JOB.replace("height = 4.0", "height = 3.0")
    .replace('grid = "m.csv"', 'grid = "pmap.csv"')
    .replace("width = 0.04\ncorner_radius = 0.005", "width = 0.030\ncorner_radius = 0.0")
    .replace("FACETS", "[70, 20]\ncut = true")
    .replace("[light_guide]", "[optimize]\nseed = 1\ngap = 0.005\n[light_guide]")
)


def test_the_gate_fails_prisms_turned_half_a_turn_when_their_facets_differ(tmp_path):
    """70° / 20° prisms facing their LEDs (a hostile tester's job): their outlines are the
    same turned half a turn, their light is not (9-point 0.447 against 0.313 traced). The
    gate passed a CSV of every prism turned 180° and the led sample's DXF; now the angle
    check reads directions over 360° for such prisms: the turned CSV fails, the DXF fails
    saying a DXF holds outlines only, the pattern's own CSV and its GDSII mask pass."""
    from .conftest import cli

    np.savetxt(tmp_path / "pmap.csv", np.tile(np.linspace(0.1, 0.43, 12), (4, 1)), delimiter=",")
    job = tmp_path / "p.toml"
    job.write_text(DIRECTED)
    csv, gds, dxf = (tmp_path / f"p.{e}" for e in ("csv", "gds", "dxf"))
    rc, err, _ = cli("export", job, "--csv", csv, "--gds", gds, "--dxf", dxf, "-q")
    assert rc == 0, err
    lines = csv.read_text().splitlines()
    turned = [lines[0]] + [
        ",".join([*r.split(",")[:-1], f"{float(r.split(',')[-1]) + 180:.6f}"]) for r in lines[1:]
    ]
    (tmp_path / "turned.csv").write_text("\n".join(turned) + "\n")
    verdict = {}
    for f in (csv, gds, tmp_path / "turned.csv", dxf):
        rc, err, out = cli("qa", f, "--job", job)
        verdict[f.name] = (rc, [x for x in out.splitlines() if "orientation field" in x])
    assert verdict["p.csv"][0] == 0 and verdict["p.gds"][0] == 0, verdict
    assert verdict["turned.csv"][0] == 1 and "FAIL" in verdict["turned.csv"][1][0], verdict
    assert ": 180 (limit" in verdict["turned.csv"][1][0]
    assert verdict["p.dxf"][0] == 1 and "a DXF holds outlines" in verdict["p.dxf"][1][0]


def test_the_gate_judges_random_angles_by_their_spread(tmp_path):
    """A job of randomly turned prisms draws each angle where its dot was thrown, so no
    dot's angle can be checked: the gate judges their spread against uniform instead (a
    chi-square of the 5° histogram). The job's own export passes; a mask of the same
    panel's prisms facing their LEDs (a hostile tester's: 9 to 82 dots a bin) failed
    nothing before and fails now."""
    from .conftest import cli

    np.savetxt(tmp_path / "pmap.csv", np.tile(np.linspace(0.1, 0.43, 12), (4, 1)), delimiter=",")
    toward, rand = tmp_path / "toward.toml", tmp_path / "random.toml"
    toward.write_text(DIRECTED)
    rand.write_text(DIRECTED.replace('toward = "leds"\nrelative = "parallel"', "random = true"))
    for job in (toward, rand):
        rc, err, _ = cli("export", job, "--gds", tmp_path / f"{job.stem}.gds", "-q")
        assert rc == 0, err
    rc, _, out = cli("qa", tmp_path / "random.gds", "--job", rand)
    assert rc == 0 and "verdict: PASS\n" in out + "\n", out
    rc, _, out = cli("qa", tmp_path / "toward.gds", "--job", rand)
    line = [x for x in out.splitlines() if "random angles" in x]
    assert rc == 1 and line and line[0].startswith("FAIL"), out
