"""The luminance's angles (:mod:`optdot.optics.angles`): closed forms for the binning, Snell
for the way out, and a traced stack whose top is a Lambertian diffuser."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from optdot.config.schema import load_job
from optdot.optics.angles import STEP_DEG, Angles
from optdot.optics.simulate import simulate

from .conftest import cli, one_error
from .test_backlight import direct_job

SAMPLES = Path(__file__).resolve().parents[1] / "samples"


def _cos_power(m: float, n: int, seed: int) -> np.ndarray:
    """``[n, 3]`` directions of an emitter whose intensity goes as ``cos^m theta``: the
    flux in ``theta`` goes as ``cos^m sin``, so ``cos theta = u^(1 / (m + 1))``."""
    rng = np.random.default_rng(seed)
    c = rng.random(n) ** (1.0 / (m + 1.0))
    phi = rng.random(n) * 2 * math.pi
    s = np.sqrt(1 - c * c)
    return np.column_stack([s * np.cos(phi), s * np.sin(phi), c])


def test_a_lambertian_emitter_reads_1_at_every_angle_and_a_cos3_one_halves_at_45_degrees():
    """Intensity ``cos^m`` is luminance ``cos^(m - 1)``: ``m = 1`` (Lambertian) reads 1 in
    every bin and never halves; ``m = 3`` reads ``cos² theta`` relative to a Lambertian
    of the same flux (on axis ``(m + 1) / 2 = 2``) and halves at 45° in both planes."""
    flat = Angles.empty()
    flat.add(_cos_power(1.0, 2_000_000, 1))
    lum = flat.luminance()
    rings = np.nanmean(lum[:16], axis=1)  # the last rings hold few rays
    assert np.abs(rings - 1).max() < 0.02
    f = flat.figures()
    assert f["on_axis"] == pytest.approx(1.0, abs=4 * f["on_axis_sigma"])
    assert f["half_luminance_deg"] == {"horizontal": None, "vertical": None}
    assert f["rays"] == 2_000_000 == flat.total
    peaked = Angles.empty()
    peaked.add(_cos_power(3.0, 2_000_000, 2))
    g = peaked.figures()
    theta = (np.arange(18) + 0.5) * STEP_DEG
    want = 2 * np.cos(np.radians(theta)) ** 2  # bins' centres; exact within a bin's curvature
    assert np.nanmean(peaked.luminance()[:12], axis=1) == pytest.approx(want[:12], rel=0.02)
    assert g["on_axis"] == pytest.approx(2 * np.mean(np.cos(np.radians([0, 5]))) ** 2, rel=0.02)
    for name in ("horizontal", "vertical"):
        assert g["half_luminance_deg"][name] == pytest.approx(45.0, abs=1.0)


def test_the_planes_are_told_apart():
    """Light spread wide along x and narrow along y: the horizontal half angle is the
    wider; each plane's profile is its own sector (both sides of the normal)."""
    d = _cos_power(1.0, 1_000_000, 3)
    d[:, 1] *= 0.3  # squeeze towards the x-z plane
    d /= np.linalg.norm(d, axis=1)[:, None]
    a = Angles.empty()
    a.add(d)
    half = a.figures()["half_luminance_deg"]
    assert half["vertical"] < 40 and (half["horizontal"] is None or half["horizontal"] > 60)


def test_what_leaves_a_clear_top_follows_snell(tmp_path):
    """The edge-lit guide's clear top (PMMA, n 1.49): what it lets out leaves at every
    angle up to grazing (the escape cone opened by Snell), each direction unit, and the
    fates and places are those traced before directions were kept (the counts of
    ``test_optics``' fixed run hold)."""
    from optdot.optics.scene import Coverage, scene_of
    from optdot.optics.trace import trace

    job = load_job(SAMPLES / "lgp" / "job.toml", need_map=False)
    grid = np.linspace(0.05, 0.35, 40)[:, None] * np.ones((1, 60))
    scene = scene_of(job.bench, 200_000, coverage=Coverage(grid, 0.0, 0.0, 0.5, 0.5))
    fate, _, _, d = trace(3, 0, 200_000, scene)
    out = d[fate == 0].astype(np.float64)
    assert np.allclose(np.linalg.norm(out, axis=1), 1.0, atol=1e-6)
    sin_air = np.sqrt(out[:, 0] ** 2 + out[:, 1] ** 2)
    assert sin_air.max() > 0.99  # grazing exits: inside, sin was at most 1 / 1.49
    assert np.mean(sin_air > 1 / 1.49) > 0.3


def test_a_stack_under_a_lambertian_diffuser_leaves_lambertian_and_every_ray_is_counted(
    tmp_path,
):
    """A direct-lit stack whose top sheet scatters what it passes Lambertian: the traced
    luminance is a Lambertian's at every angle within its noise; the angles count every
    extracted ray; a film's top without a sheet is not (a clear face refracts the
    scattered light it carries, which Fresnel dims at grazing exits)."""
    sheets = [{"kind": "diffuser", "transmittance": 0.65}]
    job = load_job(direct_job(tmp_path, 10.0, 10.0, 0.3, sheets=sheets), need_map=True)
    sim = simulate(job.bench, 400_000, seed=5)
    a = sim.angles
    assert a.total == sim.fates["extracted"]
    lum = a.luminance()
    rings = a.counts[:14].sum(axis=1)
    flat = np.nanmean(lum[:14], axis=1)
    assert np.all(np.abs(flat - 1) < 4 / np.sqrt(rings) + 0.01)
    f = sim.summary()["angles"]
    assert f["on_axis"] == pytest.approx(1.0, abs=4 * f["on_axis_sigma"] + 0.01)
    assert f["half_luminance_deg"] == {"horizontal": None, "vertical": None}
    clear = simulate(load_job(direct_job(tmp_path, 10.0, 10.0, 0.3), need_map=True), 400_000)
    c = clear.summary()["angles"]
    assert c["on_axis"] > 1.1 and clear.angles.luminance()[16].mean() < 0.9


def test_a_simulation_file_s_angles_are_checked_and_the_command_says_what_it_cannot_judge(
    tmp_path,
):
    """``qa --simulation`` reads the angles back checked: a ragged table, a string in it,
    a figure that is not a number: one line naming the file and the field, no traceback.
    ``simulate`` says when too few rays left near the normal to state the on-axis
    luminance and half angles, and when the rays ended at the dots (an idealised
    extractor) so no angle was measured."""
    import json

    sheets = [{"kind": "diffuser", "transmittance": 0.65}]
    job = direct_job(tmp_path, 10.0, 10.0, 0.3, sheets=sheets)
    rc, err, out = cli("simulate", job, "--rays", "2000", "--json", tmp_path / "s.json")
    assert rc == 0 and "too few to judge the on-axis luminance" in out, out
    rc, err, out = cli("simulate", job, "--rays", "200000")
    assert rc == 0 and "angles: on-axis luminance" in out, out
    np.savetxt(tmp_path / "d.csv", np.array([[1.0, 1.0]]), delimiter=",", header="x_mm,y_mm")
    good = json.loads((tmp_path / "s.json").read_text())
    few = good["angles"]  # the file says it too: no half angle, not judged
    assert few["on_axis_rays"] < 100 and few["on_axis_judged"] is False
    assert few["half_luminance_deg"] == {"horizontal": None, "vertical": None}
    (tmp_path / "two.csv").write_text("x_mm,y_mm,diameter_mm\n1,1,0.046\n3,3,0.046\n")
    rc, err, _ = cli("qa", tmp_path / "two.csv", "--no-job", "--simulation", tmp_path / "s.json",
                     "--html", tmp_path / "r.html")  # fmt: skip
    assert rc in (0, 1) and not err, err  # (two dots on a panel: the gate may fail)
    page = (tmp_path / "r.html").read_text()
    assert "too few to judge the on-axis luminance" in page and "half luminance at" not in page
    for field, bad, words in (
        ("angular_luminance", [[1, 2], [3]], "all as long"),
        ("angular_luminance", [[1, "x"], [0, 1]], "not a number >= 0"),
        ("angles", {**good["angles"], "on_axis": "high"}, "angles.on_axis"),
    ):
        doc = {**good, field: bad}
        (tmp_path / "bad.json").write_text(json.dumps(doc))
        one_error(("qa", tmp_path / "d.csv", "--no-job", "--simulation", tmp_path / "bad.json"), 2,
                  "bad.json", words)  # fmt: skip
    text = (SAMPLES / "lgp" / "job.toml").read_text()
    text = text.replace("dot_albedo = 0.9", 'dot_albedo = 0.9\ndot_scatter = "extract"')
    (tmp_path / "guide.toml").write_text(text)
    grid = np.full((8, 12), 0.2)
    np.savetxt(tmp_path / "g.csv", grid, delimiter=",")
    (tmp_path / "guide.toml").write_text(text + '\n[density]\ngrid = "g.csv"\n')
    rc, err, out = cli("simulate", tmp_path / "guide.toml", "--rays", "20000")
    assert rc == 0 and "angles: none measured" in out, (out, err)
