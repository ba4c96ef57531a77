"""Numbers as a reader of the gate's lines and the report meets them: a JND just under
the limit is not printed as the limit, and a grain figure is not held to random dots' 1
where the map itself changes."""

from __future__ import annotations

import pytest

from optdot.quality.gate import jnd_text
from optdot.quality.report import _grain_text


@pytest.mark.parametrize(
    "value, text",
    [(0.9973, "0.997"), (0.99996, "0.99996"), (1.0, "1.00"), (1.004, "1.004"), (0.16, "0.16"),
     (2.345, "2.35"), (0.5, "0.50")],
)  # fmt: skip
def test_a_jnd_is_printed_on_its_side_of_the_limit(value, text):
    assert jnd_text(value) == text


def _grain(fill):
    return {"grain": {"window_mm": [0, 0, 10, 10], "fill_range": fill, "dots": 5000,
                      "s_ka_0.3_1": 1.5, "s_ka_1_3": 0.2}}  # fmt: skip


def test_grain_on_a_changing_map_is_not_judged_against_random_dots():
    even = _grain([0.2, 0.2])
    assert "<b>1.5</b>" in _grain_text(even) and "Random (Poisson) dots give 1" in _grain_text(even)
    changing = _grain([0.05, 0.3])
    text = _grain_text(changing)
    assert "<b>" not in text and "not compared with random dots' 1" in text


@pytest.mark.slow
def test_a_shaped_report_draws_footprints_and_their_angles(tmp_path):
    """The QA report of prisms drew 121.8 µm circles in its true-scale zoom and said
    "diameter 121.8–121.8 µm"; the angle histogram was in the JSON only."""
    import numpy as np

    from optdot.config.schema import load_job
    from optdot.geometry.shapes import KINDS
    from optdot.orchestration.pipeline import generate, qa
    from optdot.quality.report import write_html

    from .conftest import write_job

    dots = {"shape": '"rounded_rectangle"', "length": 0.12, "width": 0.03,
            "corner_radius": 0.005, "diameter": None}  # fmt: skip
    path = write_job(tmp_path, np.full((4, 4), 0.2), dots=dots,
                     orientation={"random": "true"}, optimize={"gap": 0.005})  # fmt: skip
    job = load_job(path)
    r = qa(generate(job), job)
    xy, feet, _ = r.arrays["zoom"]
    assert feet.kind is KINDS["rounded_rectangle"] and feet.n == len(xy) > 0
    write_html(r, tmp_path / "r.html")
    page = (tmp_path / "r.html").read_text()
    assert "rounded_rectangle: length 120 µm, width 30 µm, corner_radius 5 µm" in page
    assert "diameter 121.8" not in page
    assert "<figcaption>angles</figcaption>" in page


@pytest.mark.slow
def test_a_direct_lit_simulation_shows_its_halo_and_its_noise(tmp_path):
    """``simulate`` printed the halo of one LED but drew it nowhere; its luminance PNG
    was mostly noise with nothing saying so. Now the JSON holds the lit-alone map, the
    PNG and the report draw it, and both say what is structure and what is noise."""
    import json

    from .conftest import cli
    from .test_backlight import direct_job

    path = direct_job(tmp_path)
    out = tmp_path / "s.json"
    rc, err, text = cli("simulate", path, "--rays", 40_000, "--json", out,
                        "--png", tmp_path / "s.png")  # fmt: skip
    assert rc == 0, err
    assert "rays bring the noise to 1 %" in text
    doc = json.loads(out.read_text())
    halo = doc["halo"]
    assert len(halo["map"]) == len(halo["map"][0]) > 4 and max(map(max, halo["map"])) > 0.5
    assert doc["luminance_structure"] >= 0 and doc["rays_for_1pct_noise"] > 40_000
    assert (tmp_path / "s.png").stat().st_size > 20_000
    rc, err, _ = cli("generate", path, "-o", tmp_path / "p.npz", "-q")
    assert rc == 0, err
    rc, err, _ = cli("qa", tmp_path / "p.npz", "--job", path, "--simulation", out,
                     "--html", tmp_path / "r.html", "-q")  # fmt: skip
    page = (tmp_path / "r.html").read_text()
    assert "lit alone (below)" in page and "smoothed view" in page
