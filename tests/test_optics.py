"""The light-guide tracer and the designer: the 1-D closed forms, energy
conservation, real dots against the coverage mode, reproducibility, bad input, and the
loop design -> generate -> simulate end to end."""

from __future__ import annotations

import dataclasses
import json
import math
import tomllib
from pathlib import Path

import numpy as np
import pytest

from optdot.config.schema import load_job
from optdot.errors import JobError
from optdot.optics.design import design
from optdot.optics.rays import fresnel as _fresnel
from optdot.optics.rays import last_at_most
from optdot.optics.simulate import Coverage, simulate
from optdot.optics.tables import FATES, UNCOUPLED, UNFINISHED
from optdot.optics.trace import RAY_CHUNK, trace

from .conftest import SAMPLES, cli, one_error

N, T, TILT = 1.49, 0.5, 30.0
L = 100.0  # guide length, mm


def _spacing() -> float:
    """Horizontal distance between bottom-face hits of the collimated source's rays."""
    sg = math.sin(math.radians(TILT)) / N
    return 2 * T * math.sqrt(1 - sg * sg) / sg


def _one_d_job(tmp: Path, both_ends: bool, cells: int = 400, **guide) -> Path:
    """A 100 x 4 mm strip lit at x = 0 (and x = 100) by the collimated source, dots that
    send what they meet straight out (the 1-D model's extractor), nothing else lost."""
    leds = '[[light_guide.leds]]\nedge = "left"\npositions = [2.0]\nwidth = 4.0\n'
    leds += f'profile = "collimated"\ntilt = {TILT}\n'
    if both_ends:
        leds += leds.replace('"left"', '"right"')
    keys = {
        "thickness": T,
        "absorption": 0.0,
        "dot_albedo": 1.0,
        "dot_scatter": '"extract"',
        "edge_finish": '"absorbing"',
        "reflector": 0.0,
        **guide,
    }
    text = (
        f'[domain]\nwidth = {L}\nheight = 4.0\n[density]\ngrid = "phi.csv"\n'
        "[dots]\ndiameter = 0.046\n[design]\ncell = 2.0\nfill_range = [0.0, 0.5]\n"
        "[light_guide]\n" + "".join(f"{k} = {v}\n" for k, v in keys.items()) + leds
    )
    np.savetxt(tmp / "phi.csv", np.full((2, cells), 0.1), delimiter=",")
    (tmp / "job.toml").write_text(text)
    return tmp / "job.toml"


def _with_map(job, phi: np.ndarray):
    return Coverage(np.repeat(phi[None, :], 2, axis=0), 0.0, 0.0, L / len(phi), 2.0)


def _one_end_map(x: np.ndarray, e: float) -> np.ndarray:
    """Exitance uniform with one lit end: mu = E / (l (1 - E x / l)) per mm; per hit the
    dot is met with probability 1 - exp(-mu spacing) (kappa phi is its small-fill limit)."""
    mu = e / (L * (1 - e * x / L))
    return 1 - np.exp(-mu * _spacing())


def _both_ends_map(x: np.ndarray, e: float) -> np.ndarray:
    """Both ends lit with P0 each, exitance m uniform: F B = K, F - B = m (x0 - x),
    mu = m / sqrt(m^2 (x - x0)^2 + 4 K); m l = 2 P0 E."""
    p0, x0 = 1.0, L / 2
    m = 2 * p0 * e / L
    k = p0 * (p0 - m * L / 2)
    mu = m / np.sqrt(m * m * (x - x0) ** 2 + 4 * k)
    return 1 - np.exp(-mu * _spacing())


@pytest.mark.parametrize("both_ends", [False, True])
@pytest.mark.slow
def test_closed_forms_are_traced_within_one_percent(tmp_path, both_ends):
    job = load_job(_one_d_job(tmp_path, both_ends))
    x = (np.arange(400) + 0.5) * L / 400
    e = 0.8 if not both_ends else 0.7
    phi = _both_ends_map(x, e) if both_ends else _one_end_map(x, e)
    sim = simulate(job.bench, 1_000_000, seed=1, coverage=_with_map(job, phi), bins=(20, 1))
    assert sim.fates["extracted"] + sim.fates["lost_edges"] == sim.injected
    assert abs(sim.efficiency / e - 1) < 0.01, sim.efficiency
    prof = sim.counts[0] / sim.counts[0].mean()
    sigma = 1 / np.sqrt(sim.counts[0].mean())
    assert np.abs(prof - 1).max() < 4.5 * sigma and np.abs(prof - 1).max() < 0.02, prof
    # the same map a tenth too dense near the LEDs is seen
    bent = phi * np.where(x < 30, 1.1, 1.0)
    worse = simulate(job.bench, 1_000_000, seed=1, coverage=_with_map(job, bent), bins=(20, 1))
    prof = worse.counts[0] / worse.counts[0].mean()
    assert np.abs(prof - 1).max() > 0.04


@pytest.mark.slow
def test_design_recovers_the_one_end_closed_form(tmp_path):
    job = load_job(_one_d_job(tmp_path, False), need_map=False)
    got = design(job.bench, seed=2, rays=2_000_000, iterations=16)
    phi = got.fill[0]
    x = (np.arange(len(phi)) + 0.5) * got.cell[0]
    # the closed form whose largest fill is the range's top, as the design's level rule
    lo, hi = 1e-6, 0.99999
    for _ in range(80):
        e = 0.5 * (lo + hi)
        lo, hi = (e, hi) if _one_end_map(x[-1:], e)[0] < 0.5 else (lo, e)
    want = _one_end_map(x, e)
    rel = phi / want - 1
    assert abs(np.median(rel)) < 0.01 and np.sqrt(np.mean(rel**2)) < 0.015, rel
    assert abs(got.last.efficiency / e - 1) < 0.01, (got.last.efficiency, e)
    prof = got.last.counts.sum(axis=0).reshape(10, -1).sum(axis=1).astype(float)
    assert np.abs(prof / prof.mean() - 1).max() < 0.03, prof  # exitance flat (10 mm bins)


@pytest.mark.slow
def test_design_follows_a_target_map(tmp_path):
    path = _one_d_job(tmp_path, True)
    np.savetxt(tmp_path / "target.csv", [np.linspace(0.5, 1.5, 10)], delimiter=",")
    text = path.read_text().replace("[design]\n", '[design]\ntarget = "target.csv"\n')
    path.write_text(text)
    job = load_job(path, need_map=False)
    assert tmp_path / "target.csv" in job.inputs
    got = design(job.bench, seed=4, rays=1_000_000, iterations=16)
    prof = got.last.counts[0].astype(float)
    want = np.interp(
        np.arange(50) + 0.5, np.linspace(0, 50, 10, endpoint=False) + 2.5, np.linspace(0.5, 1.5, 10)
    )
    ratio = (prof / prof.mean()) / (want / want.mean())
    smooth = np.convolve(ratio, np.ones(5) / 5, mode="valid")
    assert np.abs(smooth - 1).max() < 0.04, smooth
    assert prof[-5:].mean() > 2 * prof[:5].mean()


def _lossy_job(tmp: Path, outline: bool = False) -> Path:
    """Every loss channel open: bulk, dots, edges, reflector, Fresnel at the LED."""
    grid = np.array([[0.1, 0.2, 0.3], [0.15, 0.25, 0.35]])
    np.savetxt(tmp / "density.csv", grid, delimiter=",")
    text = (
        '[domain]\nwidth = 6.0\nheight = 4.0\n[density]\ngrid = "density.csv"\n'
        "[dots]\ndiameter = 0.046\n[optimize]\nmax_iter = 40\n"
        "[light_guide]\nthickness = 0.4\nabsorption = 0.05\ndot_albedo = 0.8\n"
        "reflector = 0.7\nedge_reflectance = 0.6\n"
        '[[light_guide.leds]]\nedge = "bottom"\npositions = [1.5, 4.5]\nwidth = 1.0\n'
        '[[light_guide.leds]]\nedge = "right"\npositions = [2.0]\nwidth = 1.0\n'
        "profile = [[0, 1.0], [40, 0.8], [80, 0.1], [90, 0.0]]\npower = 2.0\n"
    )
    (tmp / "job.toml").write_text(text)
    return tmp / "job.toml"


@pytest.fixture(scope="module")
def lossy(tmp_path_factory):
    from optdot.orchestration.pipeline import generate

    tmp = tmp_path_factory.mktemp("lossy")
    job = load_job(_lossy_job(tmp))
    return job, generate(job)


def test_energy_is_conserved_ray_by_ray(lossy):
    job, pattern = lossy
    for dots in (None, pattern):
        sim = simulate(job.bench, 200_000, seed=5, dots=dots)
        f = sim.fates
        assert sum(f.values()) == sim.rays == 200_000
        assert sim.injected == sim.rays - f["not_coupled"]
        assert f["extracted"] == int(sim.counts.sum())
        assert f["unfinished"] == 0
        for k in FATES[:UNFINISHED]:  # every fate of a bare guide but "unfinished"
            assert f[k] > 0, (k, f)
        assert abs(sum(sim.summary()["shares"].values()) - 1) < 1e-12


def test_fresnel_at_normal_incidence_and_beyond_the_critical_angle():
    assert _fresnel(1.0, 1.0, N) == pytest.approx(((N - 1) / (N + 1)) ** 2, rel=1e-12)
    assert _fresnel(1.0, N, 1.0) == pytest.approx(((N - 1) / (N + 1)) ** 2, rel=1e-12)
    crit = math.asin(1 / N)
    assert _fresnel(math.cos(crit + 0.01), N, 1.0) == 1.0
    assert _fresnel(math.cos(crit - 0.01), N, 1.0) < 1.0


def test_each_ray_goes_to_the_emitter_its_index_falls_in():
    """Rays are shared out by power: ray i belongs to the last emitter whose first ray is
    <= i, also where an emitter got no rays (found by bisection: 150,000 LEDs no longer
    cost a scan each ray)."""
    rng = np.random.default_rng(3)
    for n in (1, 2, 3, 7, 150, 1000):
        share = rng.integers(0, 4, n) * (rng.random(n) < 0.7)  # some get none
        start = np.concatenate([[0], np.cumsum(share)]).astype(np.int64)
        for i in range(int(start[-1])):
            want = int(np.searchsorted(start[:n], i, side="right") - 1)
            assert last_at_most(start, i, n) == want, (n, i)


def test_same_seed_same_counts_on_any_thread_count(lossy):
    import numba

    job, pattern = lossy
    before = numba.get_num_threads()
    try:
        numba.set_num_threads(1)
        one = simulate(job.bench, 50_000, seed=9, dots=pattern)
        numba.set_num_threads(max(2, before))
        two = simulate(job.bench, 50_000, seed=9, dots=pattern)
    finally:
        numba.set_num_threads(before)
    assert one.fates == two.fates and np.array_equal(one.counts, two.counts)
    other = simulate(job.bench, 50_000, seed=10, dots=pattern)
    assert not np.array_equal(other.counts, one.counts)


def test_a_ray_ends_the_same_whatever_call_or_chunk_traced_it(lossy):
    """The tracer's threads run chunks of :data:`RAY_CHUNK` rays: every ray, at a chunk's
    edges too and from any first index, ends as it does traced alone (and a ray turned
    back at birth has the direction 0 wherever it was traced)."""
    from optdot.optics.scene import scene_of

    job, pattern = lossy
    scene = scene_of(job.bench, 10_000, dots=pattern)
    first, count = 37, 3 * RAY_CHUNK + 5
    fate, x, y, d = trace(11, first, count, scene)
    came = fate != UNCOUPLED  # a ray turned back at birth has the direction 0
    assert not came.all() and not d[~came].any()
    edges = [0, 1, RAY_CHUNK - 1, RAY_CHUNK, 2 * RAY_CHUNK + 1, count - 2, count - 1]
    for j in edges + list(range(5, count, 97)):
        f1, x1, y1, d1 = trace(11, first + j, 1, scene)
        assert (f1[0], x1[0], y1[0]) == (fate[j], x[j], y[j]), j
        assert np.array_equal(d1[0], d[j]), j
    tail = trace(11, first + RAY_CHUNK + 3, count - RAY_CHUNK - 3, scene)
    assert all(
        np.array_equal(a[RAY_CHUNK + 3 :], b) for a, b in zip((fate, x, y), tail[:3], strict=True)
    )
    assert np.array_equal(d[RAY_CHUNK + 3 :], tail[3])
    assert len(set(fate.tolist())) > 2  # rays end in several ways


@pytest.mark.slow
def test_real_dots_agree_with_the_coverage_mode_in_5mm_cells(tmp_path):
    from optdot.orchestration.pipeline import generate

    grid = np.array([[0.08, 0.16, 0.3, 0.45]] * 2)
    np.savetxt(tmp_path / "density.csv", grid, delimiter=",")
    (tmp_path / "job.toml").write_text(
        '[domain]\nwidth = 20.0\nheight = 10.0\n[density]\ngrid = "density.csv"\n'
        "[dots]\ndiameter = 0.046\n[optimize]\nmax_iter = 30\n"
        "[light_guide]\nthickness = 0.4\n"
        '[[light_guide.leds]]\nedge = "left"\npositions = [5.0]\nwidth = 2.0\n'
    )
    job = load_job(tmp_path / "job.toml")
    pattern = generate(job)
    a = simulate(job.bench, 1_500_000, seed=1, bin_mm=5.0)
    b = simulate(job.bench, 1_500_000, seed=2, dots=pattern, bin_mm=5.0)
    ca, cb = a.counts.astype(float), b.counts.astype(float)
    z = (ca - cb) / np.sqrt(ca + cb)
    assert np.abs(z).max() < 3.0 and np.mean(z**2) < 2.0, z
    assert abs(a.efficiency - b.efficiency) < 3 * math.sqrt(2) * a.summary()["efficiency_sigma"]
    # a pattern missing every fifth dot is told apart
    keep = np.arange(pattern.n) % 5 != 0
    sparse = dataclasses.replace(pattern, xy=pattern.xy[keep], diameter=pattern.diameter[keep])
    c = simulate(job.bench, 1_500_000, seed=2, dots=sparse, bin_mm=5.0).counts.astype(float)
    assert np.abs((ca - c) / np.sqrt(ca + c)).max() > 4


BAD = [
    ("", "light_guide has no LEDs"),
    ('[[light_guide.leds]]\nedge = "bottom"\npositions = [29.5]\nwidth = 2.0\n', "off the bottom"),
    ('[[light_guide.leds]]\nedge = "front"\npositions = [5.0]\n', "edge = 'front'"),
    ('[[light_guide.leds]]\nedge = "left"\npositions = []\n', "positions"),
    (
        '[[light_guide.leds]]\nedge = "left"\npositions = [5.0]\nprofile = [[0, 1], [95, 0]]\n',
        "profile",
    ),
]


@pytest.mark.parametrize("leds,words", BAD)
def test_bad_leds_are_refused_in_one_line(tmp_path, leds, words):
    (tmp_path / "job.toml").write_text(
        "[domain]\nwidth = 30.0\nheight = 20.0\n[dots]\ndiameter = 0.046\n"
        "[light_guide]\nthickness = 0.4\n" + leds
    )
    one_error(["design", tmp_path / "job.toml", "-o", tmp_path / "m.csv"], 2, words)
    assert not (tmp_path / "m.csv").exists()


def test_a_design_whose_written_job_would_be_the_job_it_reads_names_the_option(tmp_path):
    """``design g.toml -o g.csv`` writes its job to g.toml by default, the job it reads:
    refused before anything runs, in one line naming ``--job-out``."""
    (tmp_path / "g.toml").write_text(
        (SAMPLES / "lgp" / "job.toml").read_text().replace('"lgp_map.csv"', '"none.csv"')
    )
    before = (tmp_path / "g.toml").read_bytes()
    one_error(["design", tmp_path / "g.toml", "-o", tmp_path / "g.csv"], 2, "'--job-out'",
              "defaults to the map's name with .toml")  # fmt: skip
    assert (tmp_path / "g.toml").read_bytes() == before and not (tmp_path / "g.csv").exists()


@pytest.mark.parametrize(
    "key,value,words",
    [
        ("thickness", "0.0", "light_guide.thickness = 0.0"),
        ("thickness", "-1", "light_guide.thickness"),
        ("dot_albedo", "1.2", "light_guide.dot_albedo = 1.2"),
        ("dot_albedo", "-0.1", "light_guide.dot_albedo"),
        ("reflector", "2", "light_guide.reflector"),
        ("refractive_index", "0.9", "light_guide.refractive_index"),
        ("dot_scatter", '"mirror"', "dot_scatter"),
        ("colour", '"red"', "unknown key 'light_guide.colour'"),
    ],
)
def test_bad_guide_values_are_refused_in_one_line(tmp_path, key, value, words):
    text = (SAMPLES / "lgp" / "job.toml").read_text()
    lines = [ln for ln in text.splitlines() if not ln.startswith(f"{key} ")]
    at = lines.index("[light_guide]") + 1
    lines.insert(at, f"{key} = {value}")
    (tmp_path / "job.toml").write_text("\n".join(lines) + "\n")
    one_error(["simulate", tmp_path / "job.toml"], 2, words)


def test_an_led_where_the_outline_has_no_edge_is_refused(tmp_path):
    # a panel with its bottom-right corner cut away: no bottom edge beyond x = 20
    (tmp_path / "job.toml").write_text(
        "[domain]\nwidth = 30.0\nheight = 20.0\n"
        'outline = "outline.wkt"\n[dots]\ndiameter = 0.046\n'
        "[light_guide]\nthickness = 0.4\n"
        '[[light_guide.leds]]\nedge = "bottom"\npositions = [5.0, 25.0]\nwidth = 2.0\n'
    )
    (tmp_path / "outline.wkt").write_text("POLYGON ((0 0, 20 0, 30 10, 30 20, 0 20, 0 0))")
    one_error(
        ["design", tmp_path / "job.toml", "-o", tmp_path / "m.csv"],
        2,
        "LED at 25 mm on the bottom edge is not on the panel outline",
    )


def test_a_job_without_a_map_says_to_design_one(tmp_path):
    one_error(
        ["generate", SAMPLES / "lgp" / "job.toml", "-o", tmp_path / "d.npz"],
        2,
        "no [density] map yet",
        "optdot design",
    )


@pytest.mark.slow
def test_design_generate_simulate_end_to_end(tmp_path):
    rc, err, out = cli(
        "design",
        SAMPLES / "lgp" / "job.toml",
        "-o",
        tmp_path / "map.csv",
        "--rays",
        400_000,
        "--iterations",
        10,
        "-q",
    )
    assert rc == 0, err
    assert {p.name for p in tmp_path.iterdir()} == {"map.csv", "map.png", "map.toml"}
    fill = np.loadtxt(tmp_path / "map.csv", delimiter=",")
    assert fill.shape == (40, 60) and 0 <= fill.min() and fill.max() <= 0.4 + 1e-9
    # along the LED edge the map is thin in front of each LED, dense between them
    front = fill[:2, [9, 10, 29, 30, 49, 50]].mean()
    between = fill[:2, [19, 20, 39, 40]].mean()
    assert front < 0.5 * between, (front, between)
    from PIL import Image

    png = np.asarray(Image.open(tmp_path / "map.png"))
    assert png.dtype == np.uint16 and np.allclose(png[::-1] / 65535, fill, atol=1e-4)
    job = load_job(tmp_path / "map.toml")
    assert job.light_guide == load_job(SAMPLES / "lgp" / "job.toml", need_map=False).light_guide
    rc, err, _ = cli("generate", tmp_path / "map.toml", "-o", tmp_path / "dots.npz", "-q")
    assert rc == 0, err
    rc, err, out = cli(
        "simulate",
        tmp_path / "map.toml",
        tmp_path / "dots.npz",
        "--rays",
        1_000_000,
        "--json",
        tmp_path / "sim.json",
        "--png",
        tmp_path / "sim.png",
    )
    assert rc == 0, err
    first = (tmp_path / "sim.json").read_bytes()
    rc, err, _ = cli(
        "simulate",
        tmp_path / "map.toml",
        tmp_path / "dots.npz",
        "--rays",
        1_000_000,
        "--json",
        tmp_path / "sim.json",
        "-q",
    )
    assert rc == 0 and (tmp_path / "sim.json").read_bytes() == first  # same seed, same bytes
    doc = json.loads(first)
    assert doc["mode"] == "dots" and doc["uniformity_9point"] > 0.85, doc["uniformity_9point"]
    assert "9-point uniformity" in out and "efficiency" in out
    lum = np.array(doc["luminance"])
    assert lum.shape == (20, 30)
    assert (tmp_path / "sim.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    # QA shows the simulation beside the JND map
    rc, err, _ = cli(
        "qa",
        tmp_path / "dots.npz",
        "--job",
        tmp_path / "map.toml",
        "--simulation",
        tmp_path / "sim.json",
        "--html",
        tmp_path / "qa.html",
        "--json",
        tmp_path / "qa.json",
        "-q",
    )
    assert rc == 0, err
    got = json.loads((tmp_path / "qa.json").read_text())["metrics"]["simulation"]
    assert got["uniformity_9point"] == doc["uniformity_9point"] and got["same_pattern"]
    page = (tmp_path / "qa.html").read_text()
    assert "<h2>Simulated luminance</h2>" in page and "another pattern" not in page
    assert page.index("Will a viewer see it?") < page.index("Simulated luminance")
    (tmp_path / "bad.json").write_text(
        '{"luminance": [[1, 2], [3]], "box_mm": [0, 0, 1, 1],'
        ' "efficiency": 1, "uniformity_9point": 1, "rays": 1,'
        ' "mode": "dots"}'
    )
    one_error(
        ["qa", tmp_path / "dots.npz", "--simulation", tmp_path / "bad.json"],
        2,
        "bad.json: the luminance map or box_mm is malformed",
    )


def test_the_designed_job_is_the_original_with_its_map(tmp_path):
    from optdot.config.writer import job_toml, rebased

    src = SAMPLES / "outline" / "job.toml"
    raw = tomllib.loads(src.read_text())
    moved = rebased(raw, src.parent, tmp_path)
    assert tomllib.loads(job_toml(moved)) == moved
    (tmp_path / "job.toml").write_text(job_toml(moved))
    a, b = load_job(src), load_job(tmp_path / "job.toml")
    assert np.array_equal(a.density.grid, b.density.grid)
    assert a.domain.geometry.equals(b.domain.geometry)


@pytest.mark.parametrize("fill_range, iterations", [([0.3, 0.35], 2), ([0.3, 0.35], 3),
                                                    ([0.0, 0.4], 3), ([0.0, 0.4], 2)])  # fmt: skip
def test_design_honours_its_fill_range_with_few_iterations(tmp_path, fill_range, iterations):
    """A floor above the continuation's start, or too few iterations to climb from 1/8 of
    the top, gave maps under the floor (0.044 with [0.3, 0.35]) and tops far short of it
    (0.11 of 0.4 in 3 iterations): the map stays in the range and reaches its top."""
    text = (SAMPLES / "lgp" / "job.toml").read_text()
    text = text.replace("fill_range = [0.0, 0.4]", f"fill_range = {fill_range}")
    (tmp_path / "job.toml").write_text(text)
    job = load_job(tmp_path / "job.toml", need_map=False)
    fill = design(job.bench, seed=1, rays=40_000, iterations=iterations).fill
    lo, hi = fill_range
    assert fill.min() >= lo - 1e-12 and fill.max() <= hi + 1e-12
    if iterations > 1:
        assert fill.max() == pytest.approx(hi)


def test_design_never_writes_a_job_the_tool_refuses(tmp_path):
    """fill_range up to 0.85 was taken and gave a job `check` refused (0.847 > 0.80):
    the range's top must be under the densest fill a random pattern reaches."""
    text = (SAMPLES / "lgp" / "job.toml").read_text()
    (tmp_path / "job.toml").write_text(text.replace("[0.0, 0.4]", "[0.0, 0.85]"))
    one_error(
        ["design", tmp_path / "job.toml", "-o", tmp_path / "m.csv"], 2,
        "design.fill_range", "< 0.8", "densest fill",
    )  # fmt: skip
    assert not (tmp_path / "m.csv").exists()


def test_the_guide_as_a_scene_gives_the_single_slab_kernels_counts():
    """The edge-lit guide traced as a one-slab scene of the stack tracer draws the same
    numbers in the same order as the single-slab kernel it replaced: these fates are what
    that kernel (optdot 840ef03) gave for this job, rays and seed, ray for ray."""
    job = load_job(SAMPLES / "lgp" / "job.toml", need_map=False)
    grid = np.linspace(0.05, 0.35, 40)[:, None] * np.ones((1, 60))
    sim = simulate(job.bench, 300_000, seed=3, coverage=Coverage(grid, 0.0, 0.0, 0.5, 0.5))
    assert sim.fates == {
        "extracted": 201618,
        "absorbed_bulk": 1602,
        "absorbed_dots": 51215,
        "lost_edges": 17721,
        "lost_bottom": 615,
        "not_coupled": 27229,
        "unfinished": 0,
    }


def test_updates_agree_while_the_map_converges_and_disagree_once_noise_moves_it():
    """:class:`optdot.optics.design.Update`: a map approaching its fixed point along a
    slow mode moves the same cells the same way each step (agreement near +1); a map at
    its fixed point moved only by the damped step's noise (``e <- (1 - g) e + g eps``)
    undoes part of each last move (negative); the level (a uniform factor) is not a
    direction; cells off ``live`` are not counted."""
    from optdot.optics.design import GAMMA, Update

    rng = np.random.default_rng(5)
    live = np.ones((30, 40), bool)
    live[:, :3] = False
    slow = np.outer(np.linspace(-1, 1, 30), np.linspace(1, 2, 40))
    trend, noise = Update(), Update()
    e = np.zeros(live.shape)
    for t in range(6):
        far = 0.5 * 0.7**t * slow  # the distance left along the slow mode, shrinking
        near = 0.5 * 0.7 ** (t + 1) * slow
        wild = rng.normal(0, 5, live.shape) * ~live  # dead cells: anything
        trend.measure(np.exp(far + wild), np.exp(near + 0.3 + wild), live)
        step = (1 - GAMMA) * e + GAMMA * rng.normal(0, 0.05, live.shape)
        noise.measure(np.exp(e), np.exp(step + 0.3 * t), live)
        e = step
    assert trend.agreement > 0.99 and not trend.settled()
    assert noise.agreement < -0.2 and noise.settled()
    once = Update()  # one disagreement after a trend is not yet settled
    for t in range(3):
        once.measure(np.exp(0.1 * t * slow), np.exp(0.1 * (t + 1) * slow), live)
    once.measure(np.exp(0.3 * slow), np.exp(0.25 * slow), live)
    assert once.agreement < 0 and not once.settled()
    assert math.isnan(Update().agreement) and not Update().settled()


@pytest.mark.slow
def test_design_stops_when_the_map_no_longer_changes_anything_the_rays_resolve(tmp_path):
    """``design`` ran its 16 iterations whatever happened (the lgp sample's RMS sat at the
    rays' noise from its 7th). It stops once a full trace finds no structure beyond the
    noise and the map's last two updates disagree (noise moves it, not a trend), a
    guide's level at its top, and says why; a film the same (its border cells, outside
    where the luminance is judged, still climbing are caught by the updates agreeing).
    ``design.tolerance = 0`` runs them all; a tolerance is a share of the mean, 0..1."""
    from dataclasses import replace

    from optdot.optics.design import SETTLED_SHARE, design

    job = load_job(SAMPLES / "lgp" / "job.toml", need_map=False)
    film = load_job(SAMPLES / "minled" / "job.toml", need_map=False)
    for j in (job, film):
        got = design(j.bench, seed=1, rays=60_000)
        n = len(got.history)
        assert n < 16 and got.stopped.startswith(f"stopped after {n} of at most 16")
        judged = got.history[-2]  # the trace that found nothing left to correct
        rms, noise = judged["luminance_rms"], judged["luminance_rms_noise"]
        assert max(rms**2 - noise**2, 0.0) ** 0.5 <= SETTLED_SHARE * noise + 1e-12
        agree = [h["update_agreement"] for h in got.history[1:-1]]
        assert max(agree[-2:]) <= 0 < max(agree)  # a trend, then noise twice
        assert "updates took turns" in got.stopped
        assert got.history[-1]["rays"] == 60_000
    every = design(replace(job, design=replace(job.design, tolerance=0.0)), seed=1, rays=60_000)
    assert len(every.history) == 16 and every.stopped == "ran its 16 iterations"


def test_a_design_with_a_target_stops_on_its_structure_against_the_target(tmp_path):
    """With a target the luminance's structure is judged against it (a 1-2-3 ramp: the
    RMS against a flat luminance stays ~30 % and the design never stopped); a design of
    under 10 rays a cell (each cell's luminance mostly noise) is refused."""
    from dataclasses import replace

    job = load_job(SAMPLES / "lgp" / "job.toml", need_map=False)
    ramp = np.repeat([[1.0, 2.0, 3.0]], 2, axis=0)
    aimed = replace(job, design=replace(job.design, target=ramp))
    got = design(aimed.bench, seed=1, rays=60_000)
    assert len(got.history) < 16 and "against the target" in got.stopped
    judged = got.history[-2]
    assert judged["luminance_rms_target"] < judged["luminance_rms"]
    with pytest.raises(JobError, match="under 10 a cell"):  # a map of noise, never settled
        design(job.bench, seed=1, rays=1000)
    hidden = replace(job, viewing_area=(14.9, 9.9, 15.1, 10.1))  # not one design cell's centre
    with pytest.raises(JobError, match="smaller bezel or a larger active_area"):
        design(hidden.bench, seed=1, rays=60_000)
    text = (SAMPLES / "lgp" / "job.toml").read_text().replace("[design]", "[design]\ntolerance = 2")
    (tmp_path / "job.toml").write_text(text)
    one_error(("check", tmp_path / "job.toml"), 2, "design.tolerance = 2.0", "0 <= x <= 1")
