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
    trace_cap,
)
from optdot.optics.rays import ray_state
from optdot.optics.simulate import simulate

N = 1.49  # PMMA
#: Normal-incidence Fresnel reflectance of PMMA in air.
R0 = ((N - 1) / (N + 1)) ** 2


@nb.njit
def _caps(code, k, n, px, py, d):  # pragma: no cover - compiled
    """``trace_cap`` for rays ``i`` entering at ``(px[i], py[i])`` going ``d[i]``:
    ``[m, 4]`` (where, dx, dy, dz)."""
    out = np.zeros((len(px), 4))
    for i in range(len(px)):
        _, w, a, b, c = trace_cap(
            ray_state(5, i), code, k, n, px[i], py[i], d[i, 0], d[i, 1], d[i, 2]
        )
        out[i, 0], out[i, 1], out[i, 2], out[i, 3] = w, a, b, c
    return out


def _straight_down(count: int, r: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    d = np.zeros((count, 3))
    d[:, 2] = -1.0
    return np.full(count, r), np.zeros(count), d


@pytest.mark.parametrize("code", [BUMP, DIMPLE])
@pytest.mark.parametrize("k", [0.25, 1.0])
def test_light_meeting_a_cap_head_on_passes_as_fresnel_says(code, k):
    """A ray down the cap's axis meets it at normal incidence, whatever its height: it
    passes (a bump's into the air below, a dimple's through the cavity and out of its
    open base) with 1 - R0 and comes straight back up with R0 (then along the axis
    again, out through the plane)."""
    out = _caps(code, k, N, *_straight_down(100_000, 0.0))
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


def _weighted_bump_share(k: float, n: float, nr=48, ntheta=48, npsi=96, bounces=40) -> float:
    """The share of a Lambertian flux, uniform over the footprint, that a bump of height
    ``k`` passes into the air: a quadrature over the entry radius (the cap is round, so
    entry points on one radius stand for all), the polar angle (cosine-weighted) and the
    azimuth, every ray followed through the cap with no random numbers: at each meeting
    with the sphere its weight splits into Fresnel's reflected share, followed on, and
    the transmitted, counted; what reaches the plane again goes back up."""
    rs = np.sqrt((np.arange(nr) + 0.5) / nr)
    st = np.sqrt((np.arange(ntheta) + 0.5) / ntheta)
    psi = 2 * np.pi * (np.arange(npsi) + 0.5) / npsi
    r, s, q = (v.ravel() for v in np.meshgrid(rs, st, psi, indexing="ij"))
    p = np.column_stack([r, np.zeros_like(r), np.zeros_like(r)])
    d = np.column_stack([s * np.cos(q), s * np.sin(q), -np.sqrt(1 - s * s)])
    w = np.full(len(r), 1.0 / len(r))
    big = (1 + k * k) / (2 * k)
    c = np.array([0.0, 0.0, big - k])
    passed = 0.0
    for _ in range(bounces):
        o = p - c
        b = np.einsum("ij,ij->i", d, o)
        cc = np.einsum("ij,ij->i", o, o) - big * big
        t_s = -b + np.sqrt(np.maximum(b * b - cc, 0.0))
        t_p = np.where(d[:, 2] > 0, -p[:, 2] / np.where(d[:, 2] > 0, d[:, 2], 1.0), np.inf)
        on = t_s < t_p  # the rest leave through the plane: back up
        p, d, w, t_s = p[on] + t_s[on, None] * d[on], d[on], w[on], t_s[on]
        m = (p - c) / big
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


def test_a_profile_on_a_footprint_it_does_not_fit_is_refused(tmp_path):
    """A spherical cap is a circle's: an ellipse, dots of several sizes and a stack that
    prints its dots on a film are refused."""
    np.savetxt(tmp_path / "map.csv", np.full((8, 12), 0.2), delimiter=",")
    ellipse = GUIDE.replace(
        "diameter = 0.046\n{dots}",
        'shape = "ellipse"\nlength = 0.08\nwidth = 0.04\nprofile = "bump"\nheight = 0.01',
    )
    sizes = GUIDE.replace(
        "diameter = 0.046\n{dots}", 'diameter = [0.046, 0.08]\nprofile = "bump"\nheight = 0.01'
    )
    for text, said in ((ellipse, "ellipse dots take profile = 'ink'"), (sizes, "one size")):
        path = tmp_path / "j.toml"
        path.write_text(text.format(name="x", dots="", reflector=0.9, finish="diffuse"))
        with pytest.raises(JobError, match=said):
            load_job(path)
    film = GUIDE.format(
        name="f", dots='profile = "bump"\nheight = 0.01', reflector=0.9, finish="diffuse"
    )
    film += '[backlight]\nkind = "edge"\nprint = "film"\n[backlight.film]\nthickness = 0.1\n'
    (tmp_path / "f.toml").write_text(film)
    with pytest.raises(JobError, match="prints them on a film"):
        load_job(tmp_path / "f.toml")


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
