"""The viewing area (``[domain] active_area`` or ``bezel``): the part of the panel a
viewer sees. QA's visibility and ``simulate``'s figures are judged inside it, every
geometric check over the whole panel; plots draw it."""

from __future__ import annotations

import json

import numpy as np
import pytest

from optdot.config.schema import load_job
from optdot.config.viewing import viewing
from optdot.errors import JobError
from optdot.geometry.density import DensityMap
from optdot.quality.visibility import LuminanceGrid, visibility

from .conftest import SAMPLES, cli, write_job


@pytest.mark.parametrize(
    "key, value, area",
    [
        ("active_area", "[0.5, 0.25, 1.5, 1.25]", (0.5, 0.25, 1.5, 1.25)),
        ("bezel", "0.25", (0.25, 0.25, 1.75, 1.25)),
        ("bezel", "[0, 0.5, 0.1, 0]", (0.0, 0.5, 1.9, 1.5)),
    ],
)
def test_the_viewing_area_is_read_from_the_domain(tmp_path, key, value, area):
    job = load_job(write_job(tmp_path, np.full((3, 4), 0.2), domain={key: value}))
    assert job.viewing_area == pytest.approx(area)


def test_a_job_without_one_sees_the_whole_panel(tmp_path):
    assert load_job(write_job(tmp_path, np.full((3, 4), 0.2))).viewing_area is None


@pytest.mark.parametrize(
    "extra, words",
    [
        ({"active_area": "[0, 0, 1]"}, ["domain.active_area", "[x0, y0, x1, y1]"]),
        ({"active_area": "[1, 0, 0.5, 1]"}, ["domain.active_area", "x0 < x1"]),
        ({"active_area": "[0, 0, 3, 1]"}, ["domain.active_area", "past the panel"]),
        ({"bezel": "-1"}, ["domain.bezel", ">= 0"]),
        ({"bezel": "1.0"}, ["domain.bezel", "hides the whole panel"]),
        ({"bezel": '"wide"'}, ["domain.bezel", "must be"]),
        ({"bezel": "[1, 2]"}, ["domain.bezel", "[left, bottom, right, top]"]),
        ({"bezel": "0.1", "active_area": "[0, 0, 1, 1]"}, ["active_area", "bezel", "not both"]),
    ],
)
def test_a_bad_viewing_area_is_one_clear_line(tmp_path, extra, words):
    path = write_job(tmp_path, np.full((3, 4), 0.2), domain=extra)
    with pytest.raises(JobError) as e:
        load_job(path)
    assert all(w in str(e.value) for w in words), str(e.value)
    rc, err, _ = cli("check", path)
    assert rc == 2 and len(err) == 1 and "domain." in err[0], err


def _map_with_bump(at, view):
    """A 20 x 20 mm map at fill 0.2 delivered exactly, with 5 % more dot area in a
    Gaussian of sigma 0.4 mm at ``at``: ``(density, grid)``."""
    density = DensityMap(np.full((20, 20), 0.2), 20.0, 20.0)
    g = LuminanceGrid.over(density, view)
    g.sums[:] = density.deposited(g.x0, g.y0, g.cw, g.ch, g.nx, g.ny) * g.cw * g.ch
    x = g.x0 + (np.arange(g.nx) + 0.5) * g.cw
    y = g.y0 + (np.arange(g.ny) + 0.5) * g.ch
    r2 = (x[None, :] - at[0]) ** 2 + (y[:, None] - at[1]) ** 2
    g.sums += 0.05 * g.sums * np.exp(-r2 / (2 * 0.4**2))
    return density, g


def test_visibility_is_judged_in_the_viewing_area_and_the_panels_largest_stated():
    """A bright blob 1 mm from the bottom edge: seen over the whole panel; behind a
    4 mm bezel at that edge it is not judged, and the whole panel's largest names it."""
    view = viewing("notebook")
    density, g = _map_with_bump((10.0, 1.0), view)
    whole, _ = visibility(g, density, None, view)
    assert whole["max_jnd"] > 1.0 and "panel_max_jnd" not in whole
    seen, arrays = visibility(g, density, None, view, area=(0.0, 4.0, 20.0, 20.0))
    assert seen["max_jnd"] < 0.5 * whole["max_jnd"]
    assert seen["blobs_over_1_jnd"] == 0
    assert all(b["y_mm"] >= 4.0 for b in seen["blobs"])
    assert seen["panel_max_jnd"] == pytest.approx(whole["max_jnd"])
    assert seen["panel_max_jnd_at_mm"] == pytest.approx(whole["max_jnd_at_mm"])
    assert seen["viewing_area_mm"] == [0.0, 4.0, 20.0, 20.0]
    # the picture is the whole panel's: the hidden blob is drawn
    assert np.abs(arrays["jnd"][0]).max() == pytest.approx(whole["max_jnd"])
    # inside the area, the same blob counts
    inside, _ = visibility(g, density, None, view, area=(0.0, 0.0, 20.0, 16.0))
    assert inside["max_jnd"] == pytest.approx(whole["max_jnd"])


@pytest.mark.slow  # over 1.5 s
def test_qa_judges_visibility_in_the_viewing_area_and_everything_else_on_the_panel(tmp_path):
    """The tiny sample with a bezel: the QA line says "in the viewing
    area", the JSON carries the area and the panel's largest, the report draws the frame;
    collisions, protrusion and coverage are counted over the whole panel."""
    job_text = (SAMPLES / "tiny" / "job.toml").read_text()
    (tmp_path / "density.csv").write_text((SAMPLES / "tiny" / "density.csv").read_text())
    plain = tmp_path / "plain.toml"
    plain.write_text(job_text)
    framed = tmp_path / "framed.toml"
    framed.write_text(job_text.replace("[domain]", "[domain]\nbezel = [0, 0.3, 0, 0]"))
    assert load_job(framed).viewing_area is not None
    rc, err, _ = cli("generate", plain, "-o", tmp_path / "d.npz", "-q")
    assert rc == 0, err
    docs = {}
    for job in (plain, framed):
        out = tmp_path / f"{job.stem}.json"
        rc, err, text = cli(
            "qa",
            tmp_path / "d.npz",
            "--job",
            job,
            "--json",
            out,
            "--html",
            out.with_suffix(".html"),
        )
        assert rc in (0, 1), err
        docs[job.stem] = (json.loads(out.read_text()), text, out.with_suffix(".html").read_text())
    (p, ptext, _), (f, ftext, fhtml) = docs["plain"], docs["framed"]
    assert "in the viewing area" in ftext and "the whole panel's largest" in ftext
    assert "in the viewing area" not in ptext
    vis = f["metrics"]["visibility"]
    assert vis["viewing_area_mm"][1] == pytest.approx(0.3)
    assert vis["panel_max_jnd"] == pytest.approx(p["metrics"]["visibility"]["max_jnd"])
    assert vis["max_jnd"] <= vis["panel_max_jnd"] + 1e-12
    assert "the bezel hides the rest" in fhtml
    for key in ("pairs_below_collision", "protruding", "coverage_rel_rms_smoothed"):
        assert f["metrics"][key] == p["metrics"][key], key


def _lgp_with(tmp_path, domain_line: str):
    """The lgp sample's guide with a uniform 0.2 map and ``domain_line`` in [domain]."""
    np.savetxt(tmp_path / "map.csv", np.full((20, 30), 0.2), delimiter=",")
    text = (SAMPLES / "lgp" / "job.toml").read_text()
    text = text.replace("[domain]", f"[domain]\n{domain_line}")
    text = text.replace("[dots]", '[density]\ngrid = "map.csv"\n\n[dots]')
    path = tmp_path / "job.toml"
    path.write_text(text)
    return path


@pytest.mark.slow
def test_simulate_measures_the_viewing_area_and_reports_the_hot_spots_hidden_outside(tmp_path):
    """With a 3 mm bezel at the LED edge: the measured bins are the viewing area's, the
    9 spots sit at 1/6, 1/2, 5/6 of it, the LED hot spots under the bezel are reported
    (brighter than anything measured), the plot is written."""
    from optdot.optics.simulate import simulate

    job = load_job(_lgp_with(tmp_path, "bezel = [0, 3, 0, 0]"))
    sim = simulate(job.bench, 200_000, seed=1, bin_mm=0.5)
    yc = (np.arange(sim.measured.shape[0]) + 0.5) * sim.bin[1]
    assert sim.measured[yc < 3.0].sum() == 0 and sim.measured[yc > 3.0].all()
    assert sim.border == 0.0
    assert sim.spots[:, 1].min() == pytest.approx(3.0 + 17.0 / 6)
    peak, (x, y) = sim.hidden_peak()
    assert y < 3.0 and peak > sim.rms()[3], (peak, sim.rms())
    s = sim.summary()
    assert s["viewing_area_mm"] == [0.0, 3.0, 30.0, 20.0] and s["outside_max"] == peak
    rc, err, out = cli(
        "simulate", tmp_path / "job.toml", "--rays", 100_000, "--png", tmp_path / "l.png"
    )
    assert rc == 0, err
    assert "over the viewing area, bins" in out and "hidden by the bezel" in out
    assert (tmp_path / "l.png").stat().st_size > 0


def test_simulate_without_a_viewing_area_leaves_out_its_border_and_says_what_is_outside(
    tmp_path,
):
    from optdot.optics.simulate import simulate

    job = load_job(_lgp_with(tmp_path, ""))
    sim = simulate(job.bench, 100_000, seed=1, bin_mm=1.0)
    assert sim.border == 5.0 and sim.area is None
    assert sim.measured.sum() == 20 * 10
    peak, (x, y) = sim.hidden_peak()
    assert y < 5.0 and peak > sim.rms()[3]  # the LED edge's hot spots
    assert "viewing_area_mm" not in sim.summary()


def test_a_border_that_leaves_nothing_to_measure_is_one_clear_line(tmp_path):
    """A 5 mm border on a 6 mm-wide panel printed "RMS nan%" and wrote NaN into the
    JSON; now it says so, exit 2."""
    path = _lgp_with(tmp_path, "")
    rc, err, _ = cli(
        "simulate", path, "--rays", 10_000, "--border", 12, "--json", tmp_path / "s.json"
    )
    assert rc == 2 and len(err) == 1 and "--border" in err[0], err
    assert not (tmp_path / "s.json").exists()


def test_design_levels_the_luminance_over_the_viewing_area():
    """The design step's level is the viewing area's mean luminance: with the cells
    under the bezel four times as bright, a map whose seen cells already give the target
    keeps its shape there (ratio to the old map the same in every seen cell)."""
    from types import SimpleNamespace

    from optdot.optics.design import _guide_step

    def _step(phi, counts, inside, live, target, smoothing, lo, level, seen):
        step = _guide_step(inside, live, target, smoothing, lo, level, level, 1.0, seen)
        return step(phi, SimpleNamespace(counts=counts))

    ny, nx = 6, 8
    phi = np.full((ny, nx), 0.2)
    counts = np.full((ny, nx), 100.0)
    counts[:2] = 400.0  # under the bezel
    inside = np.ones((ny, nx))
    live = inside > 0
    seen = np.ones((ny, nx), bool)
    seen[:2] = False
    target = np.ones((ny, nx))
    new = _step(phi, counts, inside, live, target, 0.0, 0.0, 0.3, seen)
    assert np.allclose(new[2:], new[2:].flat[0])  # seen cells: on target, unchanged shape
    assert (new[:2] < new[2:].min()).all()  # hidden hot cells lowered
    assert new[:2].mean() / new[2:].mean() == pytest.approx(0.5**0.8)
    # judged over the whole panel, the level is the mean of both: the seen cells are
    # raised as if too dark, the hidden ones lowered further
    judged_all = _step(phi, counts, inside, live, target, 0.0, 0.0, 0.3, np.ones_like(seen))
    assert judged_all[:2].mean() / judged_all[2:].mean() == pytest.approx(0.25**0.8)


@pytest.mark.slow  # over 1.5 s
def test_the_report_judges_the_simulation_in_the_viewing_area(tmp_path):
    """``qa --simulation`` of a job with a bezel: the report's luminance section says its
    figures are the viewing area's and names the brightest bin outside it."""
    path = _lgp_with(tmp_path, "bezel = [0, 3, 0, 0]")
    np.savetxt(tmp_path / "map.csv", np.full((8, 12), 0.05), delimiter=",")  # 14k dots
    rc, err, _ = cli("generate", path, "-o", tmp_path / "d.npz", "-q")
    assert rc == 0, err
    rc, err, _ = cli(
        "simulate", path, tmp_path / "d.npz", "--rays", 100_000, "--json", tmp_path / "s.json"
    )
    assert rc == 0, err
    rc, err, _ = cli(
        "qa", tmp_path / "d.npz", "--job", path, "--simulation", tmp_path / "s.json",
        "--html", tmp_path / "r.html", "--json", tmp_path / "r.json",
    )  # fmt: skip
    assert rc == 0, err
    html = (tmp_path / "r.html").read_text()
    assert "over the viewing area (dashed)" in html and "Outside it the brightest bin" in html
    sim = json.loads((tmp_path / "r.json").read_text())["metrics"]["simulation"]
    assert sim["viewing_area_mm"] == [0.0, 3.0, 30.0, 20.0] and sim["outside_max_at_mm"][1] < 3


def _dashed_frames(monkeypatch):
    """Record every dashed line and dashed contour a matplotlib figure draws."""
    import matplotlib

    matplotlib.use("Agg")
    from matplotlib.axes import Axes

    drawn: list = []
    plot, contour = Axes.plot, Axes.contour

    def recording_plot(self, *args, **kw):
        if kw.get("ls") == "--" or kw.get("linestyle") == "--":
            drawn.append(("plot", args))
        return plot(self, *args, **kw)

    def recording_contour(self, *args, **kw):
        if kw.get("linestyles") == "--":
            drawn.append(("contour", args))
        return contour(self, *args, **kw)

    monkeypatch.setattr(Axes, "plot", recording_plot)
    monkeypatch.setattr(Axes, "contour", recording_contour)
    return drawn


@pytest.mark.slow
def test_the_jnd_figure_draws_the_viewing_area(monkeypatch):
    from optdot.quality.gate import QAResult
    from optdot.quality.report import _jnd_figure

    view = viewing("notebook")
    density, g = _map_with_bump((10.0, 1.0), view)
    area = (0.0, 4.0, 20.0, 20.0)
    drawn = _dashed_frames(monkeypatch)
    for a in (None, area):
        metrics, arrays = visibility(g, density, None, view, area=a)
        result = QAResult(checks=[], metrics={"visibility": metrics}, arrays=arrays)
        assert _jnd_figure(result)
    assert len(drawn) == 1  # only the figure with a viewing area has a frame
    xs, ys = drawn[0][1]
    assert (min(xs), min(ys), max(xs), max(ys)) == area


@pytest.mark.slow
def test_the_luminance_plot_draws_the_measured_region(tmp_path, monkeypatch):
    from optdot.optics.simulate import simulate
    from optdot.optics.writing import luminance_png

    job = load_job(_lgp_with(tmp_path, "bezel = [0, 3, 0, 0]"))
    sim = simulate(job.bench, 20_000, seed=1, bin_mm=0.5)
    drawn = _dashed_frames(monkeypatch)
    luminance_png(tmp_path / "l.png", sim, "t")
    # the bins as traced and their smoothed view: the measured region on each
    assert len(drawn) == 2 and all(d[0] == "contour" for d in drawn)
    for _, (_, _, mask) in drawn:
        assert np.array_equal(mask, sim.measured.astype(float))
