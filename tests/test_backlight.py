"""The tracer's direct-lit stacks: a Lambertian point source's irradiance on a
plane, a partially reflecting film over a diffuse reflector, energy conservation ray by
ray, real dots against the coverage mode, the halo of one LED, the scattering draws, and
bad input in one line."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from optdot.config.schema import load_job
from optdot.optics.halo import halo
from optdot.optics.rays import tilt as _tilt
from optdot.optics.scene import Coverage, scene_of
from optdot.optics.simulate import simulate, traced
from optdot.optics.tables import FATES

from .conftest import cli, one_error

FILM = {"thickness": 0.2, "refractive_index": 1.59}
#: No dots anywhere.
BARE = Coverage(np.zeros((1, 1)), 0.0, 0.0, 1e3, 1e3)


def _toml(sections: dict) -> str:
    out = []
    for name, keys in sections.items():
        if isinstance(keys, list):
            for row in keys:
                out.append(f"[[{name}]]")
                out += [f"{k} = {_value(v)}" for k, v in row.items()]
            continue
        out.append(f"[{name}]")
        out += [f"{k} = {_value(v)}" for k, v in keys.items()]
    return "\n".join(out) + "\n"


def _value(v) -> str:
    if isinstance(v, str):
        return f'"{v}"'
    return repr(v).replace("(", "[").replace(")", "]")


def direct_job(
    tmp: Path,
    width: float = 20.0,
    height: float = 20.0,
    fill: float | None = 0.3,
    leds: dict | None = None,
    cavity: dict | None = None,
    film: dict | None = None,
    sheets: list | None = None,
    top: dict | None = None,
) -> Path:
    """A direct-lit job on a ``width x height`` mm panel with a uniform map of ``fill``
    (None: no map; trace it with a coverage of its own)."""
    sections: dict = {"domain": {"width": width, "height": height}}
    if fill is not None:
        np.savetxt(tmp / "map.csv", np.full((4, 4), fill), delimiter=",")
        sections["density"] = {"grid": "map.csv"}
    sections |= {
        "dots": {"diameter": 0.046},
        "backlight": {"kind": "direct", **(top or {})},
        "backlight.leds": leds or {"pitch": [5.0, 5.0], "size": 0.2},
        "backlight.cavity": cavity or {"gap": 1.5},
        "backlight.film": film or FILM,
    }
    if sheets:
        sections["backlight.sheets"] = sheets
    path = tmp / "job.toml"
    path.write_text(_toml(sections))
    return path


def _point_source(tmp: Path, h: float = 2.0) -> Path:
    """One 10 µm Lambertian LED at the centre of a 40 mm square, a clear film of index 1
    (no Fresnel, no refraction) ``h`` above it, nothing sent back: the rays that leave the
    top are the irradiance of the plane at height ``h``."""
    return direct_job(
        tmp,
        40.0,
        40.0,
        None,
        leds={"positions": [[20.0, 20.0]], "size": 0.01},
        cavity={"gap": h, "reflector": 0.0},
        film={"thickness": 1e-6, "refractive_index": 1.0},
        top={"frame": 0.0},
    )


def test_a_lambertian_point_source_lights_a_plane_as_cos4_over_h2(tmp_path):
    """E(r) = P cos^4(theta) / (pi h^2): the share of the light landing within r of the
    foot is sin^2(theta) = r^2 / (r^2 + h^2), ring by ring within 1 % (and 4 sigma)."""
    h, rays = 2.0, 1_000_000
    job = load_job(_point_source(tmp_path, h), need_map=False)
    scene = scene_of(job.bench, rays, coverage=BARE)
    fates = np.zeros(len(FATES), np.int64)
    r = np.concatenate(
        [np.hypot(x - 20, y - 20) for x, y, _ in traced(job.bench, scene, 3, rays, fates)]
    )
    edges = np.array([0.0, 0.5, 1.0, 2.0, 3.0, 5.0, 8.0, 14.0])
    got = np.histogram(r, edges)[0] / rays
    cum = edges**2 / (edges**2 + h * h)
    want = np.diff(cum)
    sigma = np.sqrt(want * (1 - want) / rays)
    assert np.all(np.abs(got - want) <= np.maximum(0.01 * want, 4 * sigma)), (got, want)
    assert fates[FATES.index("unfinished")] == 0


def test_the_halo_of_a_bare_lambertian_source_has_the_closed_form_widths(tmp_path):
    """cos^4 falls to 1/2 at r = h tan(arccos 2^-1/4) and to 1/10 at h tan(arccos
    10^-1/4): widths 1.287 h and 2.941 h, within 2 %; the profile follows cos^4 within
    3 % out to where it is 0.2."""
    h = 2.0
    job = load_job(_point_source(tmp_path, h), need_map=False)
    got = halo(job.bench, 1_000_000, seed=1, coverage=BARE)
    w50 = 2 * h * math.tan(math.acos(0.5**0.25))
    w10 = 2 * h * math.tan(math.acos(0.1**0.25))
    assert got["width50_mm"] == pytest.approx(w50, rel=0.02)
    assert got["width10_mm"] == pytest.approx(w10, rel=0.02)
    prof = np.array(got["profile"])
    want = (h * h / (h * h + prof[:, 0] ** 2)) ** 2
    keep = (want > 0.2) & (prof[:, 0] > 0.3)  # the first rings hold few rays
    assert np.all(np.abs(prof[keep, 1] - want[keep]) < 0.03), prof[keep][:5]
    assert got["share_own_cell"] is None  # a list of LEDs has no pitch cell


def _fresnel(c: np.ndarray, n1: float, n2: float) -> np.ndarray:
    """Unpolarised Fresnel reflectance (the average of s and p) at incidence cosine c."""
    s = n1 / n2 * np.sqrt(1 - c * c)
    t = np.sqrt(np.maximum(0, 1 - s * s))
    rs = (n1 * c - n2 * t) / (n1 * c + n2 * t)
    rp = (n1 * t - n2 * c) / (n1 * t + n2 * c)
    return np.where(s >= 1, 1.0, 0.5 * (rs * rs + rp * rp))


#: Angles in air, rad, for the closed forms' averages over a Lambertian source.
THETA = np.linspace(0, math.pi / 2, 200_001)


def _through_the_film(n: float) -> np.ndarray:
    """``[THETA]`` the share a clear film of index ``n`` passes of a ray at each angle in
    air: ``(1 - R) / (1 + R)``, R its faces' Fresnel reflectance."""
    r = _fresnel(np.cos(THETA), 1.0, n)
    return (1 - r) / (1 + r)


def _lambertian_mean(f: np.ndarray) -> float:
    """``f`` (``[THETA]``) averaged over a Lambertian source's ``sin(2 theta) d theta``."""
    g = f * np.sin(2 * THETA)
    return float(np.sum(0.5 * (g[1:] + g[:-1]) * np.diff(THETA)))


def _film_over_a_point(tmp: Path, cavity: dict, top: dict) -> Path:
    """One 10 µm LED at the centre of a 200 mm square under a clear 0.2 mm film of index
    1.59, ``cavity`` and ``top`` as given."""
    return direct_job(
        tmp,
        200.0,
        200.0,
        None,
        leds={"positions": [[100.0, 100.0]], "size": 0.01},
        cavity=cavity,
        film={"thickness": 0.2, "refractive_index": 1.59},
        top=top,
    )


def test_a_clear_film_passes_1_minus_r_over_1_plus_r_of_a_lambertian_source(tmp_path):
    """A clear slab of index 1.59 over the point source, nothing sent back: a ray at theta
    in air crosses with (1 - R)^2 (1 + R^2 + R^4 ...) = (1 - R) / (1 + R) (R at the air
    face; the inside face's R is the same by Snell, and light inside the escape cone
    never stays trapped), so the share out of the top is that averaged over
    sin(2 theta) d theta, within 1 % and 4 sigma. Refraction, Fresnel at both faces and
    multiple reflection in the film are all in it."""
    path = _film_over_a_point(tmp_path, {"gap": 0.5, "reflector": 0.0}, {"frame": 0.0})
    rays = 400_000
    sim = simulate(load_job(path, need_map=False), rays, seed=8, coverage=BARE)
    t = _through_the_film(1.59)
    want = _lambertian_mean(t)
    got = sim.fates["extracted"] / rays
    sigma = math.sqrt(want * (1 - want) / rays)
    assert abs(got - want) <= max(0.01 * want, 4 * sigma), (got, want)
    assert sim.fates["lost_bottom"] + sim.fates["extracted"] + sim.fates["lost_edges"] == rays


@pytest.mark.parametrize("finish", ["specular", "diffuse"])
def test_a_mirror_returns_each_ray_at_its_angle(tmp_path, finish):
    """A clear film of index 1.59 over a point source, a reflector of 0.5 under it, mirror
    walls (they keep a ray's angle to the faces). The film passes T = (1 - R) / (1 + R)
    of a ray at theta in air and returns the rest (R its faces' Fresnel reflectance).
    Over a mirror a ray keeps theta, so the share out of the top is T / (1 - Rr (1 - T))
    averaged over the source's sin(2 theta); over a diffuse sheet each return is
    Lambertian again, so it is <T> / (1 - Rr (1 - <T>)). The two differ by 0.0075 (16
    sigma at these rays); each finish is within 4 sigma of its own."""
    rr, rays = 0.5, 400_000
    cavity = {"gap": 0.5, "reflector": rr, "reflector_finish": finish}
    path = _film_over_a_point(tmp_path, cavity, {"frame": 1.0, "frame_finish": "specular"})
    sim = simulate(load_job(path, need_map=False), rays, seed=4, coverage=BARE)
    t = _through_the_film(1.59)
    mirror = _lambertian_mean(t / (1 - rr * (1 - t)))
    lambert = _lambertian_mean(t) / (1 - rr * (1 - _lambertian_mean(t)))
    want = mirror if finish == "specular" else lambert
    got = sim.fates["extracted"] / rays
    sigma = math.sqrt(want * (1 - want) / rays)
    assert abs(got - want) <= 4 * sigma, (got, want, mirror, lambert)
    assert abs(mirror - lambert) > 12 * sigma
    assert sim.fates["extracted"] + sim.fates["lost_bottom"] == rays


def test_a_ray_out_to_a_mirror_comes_back_as_often_as_the_series_says():
    """Behind a face of Fresnel reflectance r, a mirror of reflectance Rr: a ray returns
    through the face with Rr (1 - r) (1 + r Rr + (r Rr)^2 ...) = Rr (1 - r) / (1 - r Rr),
    within 4 sigma of 200,000 draws (the guide's bottom, where r > 0)."""
    from optdot.optics.rays import mirrored as _mirrored

    rr, r_face, n = 0.9, 0.6, 200_000
    state = np.uint64(12345)
    back = 0
    for _ in range(n):
        state, ok = _mirrored(state, rr, r_face)
        state = np.uint64(state)  # numba hands a uint64 back as a Python int
        back += ok
    want = rr * (1 - r_face) / (1 - r_face * rr)
    assert abs(back / n - want) <= 4 * math.sqrt(want * (1 - want) / n), (back / n, want)


def test_the_reflector_finish_reaches_the_scene_and_bad_ones_get_one_line(tmp_path):
    """``reflector_finish`` of a guide and of a cavity sets the reflector face's finish;
    another word is refused in one line naming the key."""
    from optdot.optics.tables import F_REFL_FINISH

    for finish, code in (("specular", 1.0), ("diffuse", 0.0)):
        path = direct_job(tmp_path, cavity={"gap": 1.5, "reflector_finish": finish})
        assert scene_of(load_job(path), 1000).stack.face[0, F_REFL_FINISH] == code
    path = direct_job(tmp_path, cavity={"gap": 1.5, "reflector_finish": "glossy"})
    one_error(("simulate", path, "--rays", "1000"), 2, "backlight.cavity.reflector_finish")
    guide = tmp_path / "guide.toml"
    guide.write_text(
        "[domain]\nwidth = 10.0\nheight = 10.0\n[dots]\ndiameter = 0.046\n"
        '[light_guide]\nthickness = 0.4\nreflector_finish = "specular"\n'
        '[[light_guide.leds]]\nedge = "left"\npositions = [5.0]\nwidth = 2.0\n'
    )
    job = load_job(guide, need_map=False)
    assert job.light_guide.reflector_finish == "specular"
    assert scene_of(job.bench, 1000, coverage=BARE).stack.face[0, F_REFL_FINISH] == 1.0
    guide.write_text(guide.read_text().replace('"specular"', '"matte"'))
    one_error(("simulate", guide, "--rays", "1000"), 2, "light_guide.reflector_finish")


def test_a_uniform_film_over_a_diffuse_reflector_transmits_t_over_1_minus_r_rr(tmp_path):
    """Ink everywhere (fill 1) on a film of index 1, mirror frame: every pass through the
    ink transmits T, reflects R back to the reflector, which returns Rr; the share out of
    the top is T / (1 - R Rr), within 1 % and 4 sigma; the rest split as R (1 - Rr) / (1 -
    R Rr) to the reflector and (1 - R - T) / (1 - R Rr) to the ink."""
    t, r, rr, rays = 0.3, 0.6, 0.9, 400_000
    path = direct_job(
        tmp_path,
        fill=None,
        cavity={"gap": 1.0, "reflector": rr},
        film={
            "thickness": 0.1,
            "refractive_index": 1.0,
            "dot_reflectance": r,
            "dot_transmittance": t,
        },
        top={"frame": 1.0, "frame_finish": "specular"},
    )
    job = load_job(path, need_map=False)
    sim = simulate(
        job.bench, rays, seed=2, coverage=Coverage(np.ones((1, 1)), 0.0, 0.0, 20.0, 20.0)
    )
    d = 1 - r * rr
    for fate, want in (
        ("extracted", t / d),
        ("lost_bottom", r * (1 - rr) / d),
        ("absorbed_dots", (1 - r - t) / d),
    ):
        got = sim.fates[fate] / rays
        sigma = math.sqrt(want * (1 - want) / rays)
        assert abs(got - want) <= max(0.01 * want, 4 * sigma), (fate, got, want)
    assert sim.fates["lost_edges"] == 0


@pytest.mark.parametrize("haze", ["none", "lambertian", 12.0])
def test_energy_is_conserved_ray_by_ray_in_a_direct_stack(tmp_path, haze):
    """Every ray ends in one fate, and every way out of a lossy stack is taken: ink,
    reflector, a diffuse frame, film absorption and a sheet that absorbs."""
    path = direct_job(
        tmp_path,
        fill=0.4,
        film={**FILM, "absorption": 0.5, "haze": haze},
        sheets=[{"transmittance": 0.5, "reflectance": 0.4, "gap": 0.3}],
        cavity={"gap": 1.5, "reflector": 0.9},
        top={"frame": 0.8},
    )
    sim = simulate(load_job(path), 100_000, seed=4)
    f = sim.fates
    assert sum(f.values()) == sim.rays == sim.injected == 100_000
    assert f["extracted"] == int(sim.counts.sum())
    assert f["unfinished"] == 0 and f["not_coupled"] == 0
    for k in (
        "extracted",
        "absorbed_bulk",
        "absorbed_dots",
        "lost_edges",
        "lost_bottom",
        "absorbed_sheets",
    ):
        assert f[k] > 0, (k, f)
    assert abs(sum(sim.summary()["shares"].values()) - 1) < 1e-12


def test_a_sheet_that_sends_light_back_lifts_the_recycled_share(tmp_path):
    """A diffuser that reflects half of what meets it and absorbs nothing: less light
    leaves, more is lost at the bottom, and what leaves is flatter (the sheet spreads
    what it sends back across the cavity)."""
    bare_job = load_job(direct_job(tmp_path, fill=None), need_map=False)
    bare = simulate(bare_job.bench, 400_000, seed=1, coverage=BARE)
    (tmp_path / "s").mkdir()
    sheet = direct_job(tmp_path / "s", fill=None, sheets=[{"transmittance": 0.5}])
    with_sheet = simulate(load_job(sheet, need_map=False), 400_000, seed=1, coverage=BARE)
    assert with_sheet.fates["absorbed_sheets"] == 0
    assert with_sheet.fates["lost_bottom"] > 2 * bare.fates["lost_bottom"]
    assert with_sheet.efficiency < bare.efficiency
    assert with_sheet.rms()[0] < 0.8 * bare.rms()[0]


def test_real_dots_match_the_coverage_mode_on_a_film(tmp_path):
    """A 10 x 10 mm film at fill 0.3 over four LEDs: the real pattern's efficiency and
    shares agree with the coverage mode's within 4 sigma (and 1 % of the light)."""
    from optdot.orchestration.pipeline import generate

    path = direct_job(tmp_path, 10.0, 10.0, 0.3, cavity={"gap": 1.0})
    job = load_job(path)
    pattern = generate(job)
    rays = 400_000
    cov = simulate(job.bench, rays, seed=6)
    real = simulate(job.bench, rays, seed=6, dots=pattern)
    assert real.mode == "dots" and cov.mode == "coverage"
    for k in ("extracted", "absorbed_dots", "lost_bottom", "lost_edges"):
        a, b = cov.fates[k] / rays, real.fates[k] / rays
        sigma = math.sqrt(2 * max(a, 1e-6) * (1 - a) / rays)
        assert abs(a - b) <= max(4 * sigma, 0.01 * a), (k, a, b)


def test_the_same_seed_gives_the_same_counts(tmp_path):
    path = direct_job(tmp_path, sheets=[{"transmittance": 0.6, "spread": 20.0}])
    job = load_job(path)
    a = simulate(job.bench, 50_000, seed=9)
    b = simulate(job.bench, 50_000, seed=9)
    c = simulate(job.bench, 50_000, seed=10)
    assert a.fates == b.fates and np.array_equal(a.counts, b.counts)
    assert not np.array_equal(a.counts, c.counts)


def test_a_gaussian_tilt_keeps_its_side_and_spreads_by_sigma():
    """The haze and sheet draw: a 2-D Gaussian angle of sigma per axis has mean square
    2 sigma^2 (Rayleigh); it never crosses the face."""
    sigma = math.radians(5.0)
    state = np.uint64(12345)
    ang = []
    for _ in range(20_000):
        state, x, y, z = _tilt(np.uint64(state), 0.0, 0.0, 1.0, sigma)
        assert z > 0
        assert abs(x * x + y * y + z * z - 1) < 1e-12
        ang.append(math.acos(min(1.0, z)))
    ms = float(np.mean(np.square(ang)))
    assert ms == pytest.approx(2 * sigma * sigma, rel=0.05)
    state, x, y, z = _tilt(np.uint64(7), 0.6, 0.0, -0.8, math.radians(30.0))
    assert z < 0


@pytest.mark.parametrize(
    "change, words",
    [
        ({"leds": {"positions": [[25.0, 5.0]], "size": 0.2}}, ["backlight.leds", "outside"]),
        ({"cavity": {"gap": 0.0}}, ["backlight.cavity.gap", "0 < x"]),
        ({"cavity": {"gap": 1.0, "reflector": 1.2}}, ["backlight.cavity.reflector"]),
        ({"film": {"thickness": 0.2, "dot_reflectance": -0.1}}, ["dot_reflectance"]),
        (
            {"film": {"thickness": 0.2, "dot_reflectance": 0.8, "dot_transmittance": 0.3}},
            ["dot_transmittance", "<= 1"],
        ),
        ({"leds": {"pitch": [0.1, 5.0], "size": 0.2}}, ["pitch", "larger than the LEDs"]),
        ({"leds": {"positions": [[5.0, 5.0], [5.1, 5.0]], "size": 0.2}}, ["closer than"]),
        ({"sheets": [{"transmittance": 0.7, "reflectance": 0.5}]}, ["sheets[0]", "<= 1"]),
        ({"top": {"print": "guide"}}, ["backlight.print"]),
        ({"film": {"thickness": 0.2, "haze": "fog"}}, ["backlight.film.haze"]),
    ],
    ids=[
        "led-outside",
        "gap-0",
        "reflector",
        "ink-r",
        "ink-r+t",
        "pitch",
        "leds-overlap",
        "sheet",
        "print",
        "haze",
    ],
)
def test_bad_stacks_get_one_line(tmp_path, change, words):
    kw = dict(change)
    path = direct_job(tmp_path, **kw)
    one_error(("simulate", path, "--rays", "1000"), 2, str(path), *words)


def test_a_stack_with_nothing_to_print_on_is_refused(tmp_path):
    path = direct_job(tmp_path)
    text = path.read_text()
    start = text.index("[backlight.film]")
    path.write_text(text[:start])
    one_error(("simulate", path), 2, "no film to print on")
    path.write_text(text.replace('kind = "direct"', 'kind = "edge"'))
    one_error(("simulate", path), 2, "[light_guide]")


def test_simulate_prints_the_halo_and_writes_it(tmp_path):
    path = direct_job(tmp_path, sheets=[{"transmittance": 0.65}])
    rc, err, out = cli("simulate", path, "--rays", "100000", "--json", tmp_path / "s.json")
    assert rc == 0, err
    text = out
    assert "halo of the LED at" in text and "in its own pitch cell" in text
    import json

    doc = json.loads((tmp_path / "s.json").read_text())
    h = doc["halo"]
    assert 0 < h["width50_mm"] < h["width10_mm"] and 0 < h["share_own_cell"] < h["share_3x3"] <= 1
    assert doc["bin_mm"] == [0.5, 0.5]  # a tenth of the pitch
    assert "absorbed_sheets" in doc["counts"]


# -- design ----------------------------------------------------------------------------


def test_period_classes_group_cells_alike_within_their_pitch_cells_and_towards_the_frame(
    tmp_path,
):
    """On a 4 x 3 grid of 5 mm pitch cells, 1 mm design cells: every cell of an inner pitch
    cell shares its class with the same cell of every other inner pitch cell, edge pitch
    cells share along their edge, corners keep their own, and nothing else is merged;
    :func:`fold` is the weighted mean over a class (brute force)."""
    from optdot.optics.periodic import fold, period_classes

    job = load_job(direct_job(tmp_path, 20.0, 15.0, leds={"pitch": [5.0, 5.0], "size": 0.2}))
    c = period_classes(job.bench, 20, 15, 1.0, 1.0)
    assert c is not None and c.shape == (15, 20)
    blocks = c.reshape(3, 5, 4, 5).transpose(0, 2, 1, 3)  # [row, col, phase y, phase x]
    assert np.array_equal(blocks[1, 1], blocks[1, 2])  # inner cells alike (one inner row)
    assert np.array_equal(blocks[0, 1], blocks[0, 2])  # bottom edge, along it
    assert not np.array_equal(blocks[0, 0], blocks[0, 1])  # a corner is not an edge
    assert not np.array_equal(blocks[0, 1], blocks[1, 1])  # an edge is not the inside
    assert len(np.unique(blocks[1, 1])) == 25  # the phases stay apart
    assert len(np.unique(c)) == 9 * 25  # 3 x 3 classes of pitch cells, 25 phases each
    rng = np.random.default_rng(0)
    v, w = rng.normal(size=(15, 20)), rng.uniform(0.5, 1, size=(15, 20))
    got = fold(v * w, w, c)
    for k in np.unique(c)[:40]:
        m = c == k
        assert np.allclose(got[m], (v * w)[m].sum() / w[m].sum() * w[m])
    # a cell that does not divide the pitch: no classes
    assert period_classes(job.bench, 30, 15, 20 / 30, 1.0) is None


@pytest.mark.slow  # over 1.5 s
def test_designing_a_film_evens_a_direct_lit_backlight_and_puts_ink_over_the_leds(tmp_path):
    """The film rule on a 20 x 20 mm mini-LED cell array: the designed map's luminance
    RMS (coverage mode, the panel less 5 mm) is under a quarter of the bare film's, the ink
    is densest over the LEDs and sparsest between them, its emptiest judged cell is at
    the range's floor, and the job written with it loads and traces."""
    from optdot.optics.design import design
    from optdot.optics.writing import write_design

    path = direct_job(
        tmp_path,
        fill=None,
        leds={"pitch": [5.0, 5.0], "size": 0.2, "profile": "batwing"},
        sheets=[{"transmittance": 0.65}],
    )
    text = path.read_text() + "[design]\nfill_range = [0.0, 0.7]\nrays = 400000\n"
    path.write_text(text)
    job = load_job(path, need_map=False)
    got = design(job.bench, seed=3, iterations=8)
    assert got.fill.shape == (40, 40) and got.cell == (0.5, 0.5)
    # judged in 1 mm bins with 2M rays (noise ~1.5 %, a tenth of the bare film's RMS)
    bare = simulate(job.bench, 2_000_000, seed=1, coverage=BARE, bins=(20, 20))
    cov = Coverage(got.fill, 0.0, 0.0, 0.5, 0.5)
    new = simulate(job.bench, 2_000_000, seed=1, coverage=cov, bins=(20, 20))
    cells = got.fill.reshape(4, 10, 4, 10).mean(axis=(0, 2))  # by phase in the pitch cell
    assert cells[4:6, 4:6].min() > 0.4 > 0.1 > cells[0, 0]  # LEDs at the pitch centres
    assert got.fill[10:30, 10:30].min() < 0.02
    rms_bare, rms_new = bare.rms()[0], new.rms()[0]
    assert rms_new < rms_bare / 4, (rms_bare, rms_new)
    write_design(got, job.bench, tmp_path / "map.csv", None, tmp_path / "map.toml")
    again = load_job(tmp_path / "map.toml")
    assert again.backlight == job.backlight
    assert simulate(again.bench, 20_000, seed=1).fates["extracted"] > 0


def test_a_design_that_needs_dense_ink_asks_for_larger_dots(tmp_path):
    """At a fill the job's 46 µm dots cannot hold with QA's 14 µm gap, the design says
    which diameters can (the claim (1 + g / D)^2 fill at most 0.75, past 0.675 0.80) and
    writes them into the job it makes; beyond what 1 mm dots reach it refuses."""
    from optdot.optics.design import SIZE_CLAIM, sizes_asked

    job = load_job(direct_job(tmp_path))
    assert sizes_asked(job.bench, 0.2) is None
    lo, hi = sizes_asked(job.bench, 0.57)
    assert lo == 0.046 and hi == 0.096  # 14 µm / (sqrt(0.75 / 0.57) - 1) = 95.2 µm, up
    assert 0.57 * (1 + 0.014 / hi) ** 2 <= SIZE_CLAIM
    lo, hi = sizes_asked(job.bench, 0.72)  # past 0.675: up to the 0.80 random patterns hold
    assert hi == 0.259 and 0.72 * (1 + 0.014 / hi) ** 2 <= 0.80
    with pytest.raises(Exception, match="1 mm reach"):
        sizes_asked(job.bench, 0.79)


def _guide(tmp: Path, film: bool) -> Path:
    """The lgp sample's guide (30 x 20 mm, three LEDs on its bottom edge, 3 mm under the
    bezel) printed with ``guide.csv``; with ``film``, a dotted film 50 µm above it and a
    diffuser, the job printing the film (the guide's map is ``other_map``)."""
    text = (
        'name = "g"\n[domain]\nwidth = 30.0\nheight = 20.0\nbezel = 3.0\n'
        "[dots]\ndiameter = 0.046\n"
        "[light_guide]\nthickness = 0.4\n[[light_guide.leds]]\n"
        'edge = "bottom"\npositions = [5.0, 15.0, 25.0]\nwidth = 2.0\n'
        "[design]\ncell = 1.0\nfill_range = [0.0, 0.4]\nrays = 400000\n"
    )
    if film:
        text += (
            '[backlight]\nkind = "edge"\nprint = "film"\nother_map = "guide.csv"\n'
            '[backlight.film]\nthickness = 0.1\ngap = 0.05\nhaze = "lambertian"\n'
            "[[backlight.sheets]]\ntransmittance = 0.65\n"
        )
    else:
        text += '[density]\ngrid = "guide.csv"\n'
    (tmp / f"g{int(film)}.toml").write_text(text)
    return tmp / f"g{int(film)}.toml"


@pytest.mark.slow
def test_a_film_designed_over_a_guide_lifts_its_9_point_uniformity(tmp_path):
    """The guide's map designed first (six iterations: near its design, as a user's first
    try), then a film over it, its map designed by the film rule with the guide's dots
    fixed: the 9-point uniformity rises by more than twice its noise, the luminance's
    structure (its RMS less the Monte Carlo noise) halves, the LEDs' hot spot under the
    bezel dims, and the ink goes where the bare guide is brightest. The film's and the
    guide's dots are both traced."""
    from optdot.optics.design import design

    np.savetxt(tmp_path / "guide.csv", np.full((2, 2), 0.2), delimiter=",")
    g = design(load_job(_guide(tmp_path, False)), seed=1, iterations=6)
    np.savetxt(tmp_path / "guide.csv", g.fill, delimiter=",")
    guide = simulate(load_job(_guide(tmp_path, False)), 8_000_000, seed=2, bins=(30, 20))
    job = load_job(_guide(tmp_path, True), need_map=False)
    got = design(job.bench, seed=5, iterations=8)
    cov = Coverage(got.fill, 0.0, 0.0, 1.0, 1.0)
    with_film = simulate(job.bench, 8_000_000, seed=2, coverage=cov, bins=(30, 20))
    u0, s0 = guide.uniformity9()
    u1, s1 = with_film.uniformity9()
    assert u1 > u0 + 2 * math.hypot(s0, s1), (u0, u1, s0, s1)

    def structure(sim):
        rms, noise, _, _ = sim.rms()
        return math.sqrt(max(rms * rms - noise * noise, 0.0))

    assert structure(with_film) < 0.5 * structure(guide)
    assert with_film.hidden_peak()[0] < guide.hidden_peak()[0] - 0.05
    assert with_film.fates["absorbed_dots"] > guide.fates["absorbed_dots"]  # ink on both
    assert np.corrcoef(guide.luminance.ravel(), got.fill.ravel())[0, 1] > 0.3


# -- hostile input (a helper's round of ~200 cases) -------------------------------------


def test_batches_do_not_change_the_counts(tmp_path, monkeypatch):
    """Batches are sized to take about BATCH_SECONDS (so a slow stack still hears Ctrl-C
    and SIGTERM between them); each ray's stream depends on its index only, so batches of
    1,024 rays give the same fates and bins as one batch."""
    import optdot.optics.simulate as sim_mod

    job = load_job(direct_job(tmp_path, sheets=[{"transmittance": 0.6}]))
    one = simulate(job.bench, 20_000, seed=4)
    monkeypatch.setattr(sim_mod, "BATCH_SECONDS", 1e-9)
    many = simulate(job.bench, 20_000, seed=4)
    assert many.fates == one.fates and np.array_equal(many.counts, one.counts)
    assert np.array_equal(many.spots, one.spots)


def test_a_fine_grid_gets_bounded_bins_and_a_bin_too_fine_is_refused(tmp_path):
    """A 50 µm pitch would make pitch / 10 bins of 5 µm (36 million over 30 x 30 mm):
    the default stays at a million at most, and an explicit bin past the limit is refused
    in one line before any memory is taken."""
    from optdot.optics.simulate import DEFAULT_BINS, default_bin

    leds = {"pitch": [0.05, 0.05], "size": 0.02}
    job = load_job(direct_job(tmp_path, 30.0, 30.0, leds=leds))
    b = default_bin(job.bench)
    assert (30.0 / b) ** 2 <= DEFAULT_BINS * 1.0001
    one_error(("simulate", tmp_path / "job.toml", "--bin", "0.01", "--no-halo"), 2,
              "job.toml", "9,000,000", "--bin")  # fmt: skip


def test_a_stack_where_no_light_leaves_says_so_without_nan(tmp_path):
    path = direct_job(tmp_path, film={"thickness": 100.0, "absorption": 10.0})
    rc, err, out = cli("simulate", path, "--rays", "5000")
    assert rc == 0, err
    assert "nan%" not in out and "nan," not in out and "no light reached them" in out
    assert "no light left the top" in out


@pytest.mark.parametrize(
    "edit, words",
    [
        (lambda t: t.replace("gap = 1.5", "gap = " + "9" * 400), ["cavity.gap", "64-bit"]),
        (lambda t: t.replace('kind = "direct"\n', ""), ["missing required key backlight.kind"]),
        (
            lambda t: (
                t + "[light_guide]\nthickness = 0.4\n[[light_guide.leds]]\n"
                'edge = "bottom"\npositions = [5.0]\n'
            ),
            ["two different backlights"],
        ),  # fmt: skip
        (
            lambda t: t.replace("pitch = [5.0, 5.0]", "pitch = [1e-200, 1e-200]").replace(
                "size = 0.2", "size = 1e-300"
            ),
            ["more than 1,000,000 LEDs"],
        ),  # fmt: skip
    ],
    ids=["huge-int", "no-kind", "direct-and-guide", "countless-leds"],
)
def test_more_bad_stacks_get_one_line(tmp_path, edit, words):
    path = direct_job(tmp_path)
    path.write_text(edit(path.read_text()))
    line = one_error(("simulate", path, "--rays", "1000"), 2, str(path), *words)
    assert len(line) < 300


def test_a_missing_other_map_is_named(tmp_path):
    text = (Path(__file__).parents[1] / "samples" / "lgp_film" / "job.toml").read_text()
    (tmp_path / "job.toml").write_text(text.replace("guide_map.csv", "nope.csv"))
    one_error(("simulate", tmp_path / "job.toml"), 2, "nope.csv", "backlight.other_map")


def test_a_film_design_needs_two_iterations_and_a_slowly_leaking_stack_is_advised(tmp_path):
    path = direct_job(tmp_path, fill=None)
    one_error(("design", path, "-o", tmp_path / "m.csv", "--iterations", "1"), 2,
              "design.iterations = 1", "at least 2")  # fmt: skip
    assert not (tmp_path / "m.csv").exists()
    trap = direct_job(
        tmp_path,
        cavity={"gap": 1.5, "reflector": 1.0},
        film={"thickness": 0.2, "dot_reflectance": 1.0, "dot_transmittance": 0.0},
        sheets=[{"transmittance": 1e-6, "reflectance": 0.999999}],
        top={"frame": 1.0, "frame_finish": "specular"},
    )
    line = one_error(("simulate", trap, "--rays", "2000"), 2, "light hardly leaves")
    assert "a sheet that transmits more" in line and "edge_reflectance" not in line


def test_a_guide_design_needs_two_iterations_too(tmp_path):
    """One iteration only traces the flat start: a guide's map of one iteration was that
    flat map at the fill floor, written with exit 0."""
    path = Path(__file__).parents[1] / "samples" / "lgp" / "job.toml"
    one_error(("design", path, "-o", tmp_path / "m.csv", "--iterations", "1"), 2,
              "design.iterations = 1", "at least 2", "flat map")  # fmt: skip
    assert not (tmp_path / "m.csv").exists()


@pytest.mark.slow
@pytest.mark.parametrize("leak, refused", [(0.0002, True), (0.0006, False)])
def test_a_near_lossless_stack_is_refused_or_warned_of(tmp_path, leak, refused):
    """Reflector 1, a specular frame of 1, ink that reflects all, no haze and one sheet
    letting 0.02 % through: 24 % of its rays ended unfinished at the event limit and the
    run passed the probe with exit 0 (efficiency 76 % where nothing absorbs). Now the
    probe refuses it; a stack that leaks a little more runs, and says what share of its
    rays it lost to the limit (on stderr and in the JSON)."""
    import json

    trap = direct_job(
        tmp_path,
        cavity={"gap": 1.5, "reflector": 1.0},
        film={"thickness": 0.2, "dot_reflectance": 1.0, "dot_transmittance": 0.0,
              "haze": "none"},
        sheets=[{"transmittance": leak, "reflectance": 1 - leak}],
        top={"frame": 1.0, "frame_finish": "specular"},
    )  # fmt: skip
    args = ("simulate", trap, "--rays", "1000", "--no-halo", "--json", tmp_path / "s.json")
    if refused:
        one_error(args, 2, "light hardly leaves", "would end unfinished")
        assert not (tmp_path / "s.json").exists()
        return
    rc, err, out = cli(*args)
    assert rc == 0, err
    got = json.loads((tmp_path / "s.json").read_text())
    unfinished = got["shares"]["unfinished"]
    assert unfinished > 0.005
    assert err[-1].startswith("optdot: warning: ") and f"{unfinished:.1%}" in err[-1]
    assert got["warnings"] and "unfinished" in got["warnings"][0]
