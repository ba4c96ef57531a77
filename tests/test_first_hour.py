"""What a new user meets first: messages that say what to do, help that says what an
option does."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from .conftest import SAMPLES, cli, one_error


@pytest.mark.parametrize(
    "text, words",
    [
        ("0.1;0.2\n0.2;0.3\n", ["'0.1;0.2' is not a number", "semicolons", "comma-separated"]),
        ("0.1\t0.2\n0.2\t0.3\n", ["tabs", "comma-separated"]),
        ("left,right\n0.1,0.2\n", ["'left' is not a number", "a header row?", "#"]),
        ("10,20\n30,40\n", ["10.0", "packing limit", "looks like percent"]),
    ],
)
def test_a_csv_map_in_another_dialect_says_what_it_looks_like(tmp_path, text, words):
    from .conftest import write_job

    path = write_job(tmp_path, text)
    msg = one_error(["check", path], 2, "density.csv")
    assert all(w in msg for w in words), msg


def test_a_real_typo_in_a_map_gets_no_hint(tmp_path):
    from .conftest import write_job

    path = write_job(tmp_path, "0.1,0.2\n0.2,x3\n")
    msg = one_error(["check", path], 2, "line 2", "'x3' is not a number")
    assert "(" not in msg.split("number", 1)[1], msg


def test_a_relative_path_not_found_names_where_it_looked(tmp_path, monkeypatch):
    """Pasting a walk-through in the wrong folder: the message shows the absolute path."""
    monkeypatch.chdir(tmp_path)
    msg = one_error(["check", "../samples/lgp/job.toml"], 2, "job file not found")
    assert str(tmp_path.parent / "samples" / "lgp" / "job.toml") in msg, msg


def test_check_quiet_prints_nothing_and_its_help_says_so():
    rc, err, out = cli("check", SAMPLES / "led" / "job.toml", "-q")
    assert rc == 0 and out == "" and err == []
    rc, _, out = cli("check", "--help")
    assert "progress bar" not in out and "Print nothing" in out


@pytest.mark.parametrize("command", ["simulate", "design"])
def test_every_seed_option_says_what_it_does(command):
    rc, _, out = cli(command, "--help")
    assert rc == 0
    seed = out[out.index("--seed") :].split("\n  -")[0]
    assert "Monte Carlo seed" in seed, seed


def test_qa_help_names_the_dataset():
    rc, _, out = cli("qa", "--help")
    assert rc == 0 and "parquet" in out


def test_a_pattern_judged_against_another_jobs_panel_is_refused(tmp_path, tiny_pattern):
    """A pattern keeps its panel: QA, export and simulate with another job's panel say so
    in one line (it read 250,244 dots as protruding and 22,805 JND before)."""
    from optdot.io.patterns import save_pattern

    save_pattern(tiny_pattern, tmp_path / "tiny.npz")
    lgp = tmp_path / "lgp.toml"
    np_map = "\n".join(",".join(["0.2"] * 30) for _ in range(20))
    (tmp_path / "m.csv").write_text(np_map + "\n")
    text = (SAMPLES / "lgp" / "job.toml").read_text()
    lgp.write_text(text.replace("[dots]", '[density]\ngrid = "m.csv"\n\n[dots]'))
    words = ("tiny.npz", "made for a panel of 3 x 2 mm", "30 x 20 mm", "the job it was made with")
    one_error(["qa", tmp_path / "tiny.npz", "--job", lgp], 2, *words)
    one_error(
        ["export", tmp_path / "tiny.npz", "--job", lgp, "--gds", tmp_path / "x.gds"], 2, *words
    )
    one_error(["simulate", lgp, tmp_path / "tiny.npz", "--rays", 10_000], 2, *words)
    assert not (tmp_path / "x.gds").exists()
    # its own job is fine
    rc, err, _ = cli("qa", tmp_path / "tiny.npz", "--job", SAMPLES / "tiny" / "job.toml", "-q")
    assert rc == 0, err


def test_failed_checks_name_their_places_as_numbers(tmp_path, tiny_pattern):
    """A failed check's places print as ``(x, y) mm``, never numpy's repr."""
    from optdot.io.patterns import save_pattern

    save_pattern(tiny_pattern, tmp_path / "tiny.npz")
    job = (SAMPLES / "tiny" / "job.toml").read_text()
    (tmp_path / "density.csv").write_text(
        "\n".join(",".join(["0.3"] * 12) for _ in range(8)) + "\n"
    )
    (tmp_path / "job.toml").write_text(job)
    rc, _, out = cli("qa", tmp_path / "tiny.npz", "--job", tmp_path / "job.toml")
    assert rc == 1 and "FAIL" in out
    fails = [ln for ln in out.splitlines() if ln.startswith("FAIL") and " at " in ln]
    assert fails and all(ln.endswith(" mm") and "np." not in ln for ln in fails), fails


def test_the_reports_colour_bars_are_as_tall_as_their_plots():
    """A wide map drawn at equal aspect is shorter than its axes' box; the report's colour
    bar matches the map (a plain colour bar spans the box: taller than its plot)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    from optdot.quality.report import _colorbar, _wrap

    fig, ax = plt.subplots(figsize=(6, 4))
    im = ax.imshow(np.zeros((10, 40)), extent=(0, 40, 0, 10))
    _colorbar(fig, ax, im, "fill")
    fig.canvas.draw()
    cax = fig.axes[-1]
    plot, bar = ax.get_window_extent(), cax.get_window_extent()
    assert abs(bar.height - plot.height) < 0.02 * plot.height, (bar.height, plot.height)
    assert 0 < bar.x0 - plot.x1 < 0.1 * plot.width  # beside it
    plt.close(fig)
    long = "Coverage against distance from walls (edges, holes, zero-fill borders)"
    assert all(len(line) <= 52 for line in _wrap(long).splitlines())
    assert _wrap(long).replace("\n", " ") == long


@pytest.mark.parametrize(
    "tilt, words",
    [
        ("0", ["tilt = 0", "never meets a dot"]),
        ("89.9999999", ["no light enters the guide", "grazing"]),
    ],
)
def test_a_guide_no_light_can_leave_or_enter_is_refused(tmp_path, tilt, words):
    """A collimated source at tilt 0 (its light runs parallel to the faces: 96 % of the
    rays ended unfinished after 92 s for 1,000 rays) or at a grazing tilt (nothing
    coupled, "efficiency 0.00 %", exit 0): one line, exit 2, nothing written."""
    np_map = "\n".join(",".join(["0.2"] * 30) for _ in range(20))
    (tmp_path / "m.csv").write_text(np_map + "\n")
    text = (SAMPLES / "lgp" / "job.toml").read_text()
    text = text.replace("[dots]", '[density]\ngrid = "m.csv"\n\n[dots]')
    text = text.replace('profile = "lambertian"', f'profile = "collimated"\ntilt = {tilt}')
    (tmp_path / "job.toml").write_text(text)
    args = ["simulate", tmp_path / "job.toml", "--rays", 10_000, "--json", tmp_path / "s.json"]
    msg = one_error(args, 2, "job.toml")
    assert all(w in msg for w in words), msg
    assert not (tmp_path / "s.json").exists()


def test_a_keep_out_touching_the_edge_is_clear_slab_not_a_notch(tmp_path):
    """A keep-out holds no dots but is still the guide's slab: touching the panel's edge
    it was traced as a notch in the slab (efficiency 0.5593 against 0.5540 for the same
    keep-out 2 µm inside) and an LED on that stretch of edge was refused."""
    from optdot.config.schema import load_job
    from optdot.optics.simulate import simulate

    (tmp_path / "panel.wkt").write_text("POLYGON ((0 0, 30 0, 30 20, 0 20, 0 0))\n")
    np_map = "\n".join(",".join(["0.2"] * 30) for _ in range(20))
    (tmp_path / "m.csv").write_text(np_map + "\n")
    guide = (SAMPLES / "lgp" / "job.toml").read_text().split("[light_guide]")[1]
    effs = []
    for name, y0 in (("touch", 0.0), ("inside", 0.002)):
        ring = f"(20 {y0}, 28 {y0}, 28 4, 20 4, 20 {y0})"
        text = (
            f'[domain]\noutline = "panel.wkt"\nkeep_out = ["POLYGON ({ring})"]\n'
            '[density]\ngrid = "m.csv"\n[dots]\ndiameter = 0.046\n[light_guide]' + guide
        )
        path = tmp_path / f"{name}.toml"
        path.write_text(text.replace("positions = [5.0, 15.0, 25.0]", "positions = [5.0, 24.0]"))
        job = load_job(path)  # the LED at 24 mm sits on the keep-out's stretch of edge
        sim = simulate(job.bench, 400_000, seed=3)
        effs.append((sim.efficiency, sim.summary()["efficiency_sigma"]))
    (a, sa), (b, sb) = effs
    assert abs(a - b) < 3 * (sa**2 + sb**2) ** 0.5, effs


@pytest.mark.slow
def test_simulate_with_a_pattern_needs_no_map(tmp_path):
    """The real dots are traced, so a guide job without [density] runs with a pattern
    ("no [density] map yet; design one" before); without one it still asks for a map."""
    np_map = "\n".join(",".join(["0.2"] * 30) for _ in range(20))
    (tmp_path / "m.csv").write_text(np_map + "\n")
    text = (SAMPLES / "lgp" / "job.toml").read_text()
    (tmp_path / "mapped.toml").write_text(
        text.replace("[dots]", '[density]\ngrid = "m.csv"\n\n[dots]')
    )
    rc, err, _ = cli("generate", tmp_path / "mapped.toml", "-o", tmp_path / "d.npz", "-q")
    assert rc == 0, err
    rc, err, out = cli(
        "simulate", SAMPLES / "lgp" / "job.toml", tmp_path / "d.npz", "--rays", 20_000
    )
    assert rc == 0 and "real dots" in out, err
    one_error(["simulate", SAMPLES / "lgp" / "job.toml", "--rays", 20_000], 2, "no [density] map")


def test_a_pattern_of_another_panel_is_refused_in_any_format(tmp_path, tiny_pattern):
    """A CSV (no panel of its own) whose dots lie far outside the job's panel: one line
    naming how many, where they are and what to give (it read as 250,244 protruding dots
    and 22,805 JND, or traced as 0 % efficiency)."""
    from optdot.io.patterns import save_pattern
    from optdot.pattern import Pattern

    moved = Pattern(tiny_pattern.xy + [100.0, 0.0], tiny_pattern.diameter, (100, 0, 103, 2))
    save_pattern(moved, tmp_path / "far.csv")
    words = ("far.csv", "lie more than 1 mm outside", "the job it was made with")
    one_error(["qa", tmp_path / "far.csv", "--job", SAMPLES / "tiny" / "job.toml"], 2, *words)


def test_a_simulation_with_no_light_measured_writes_valid_json(tmp_path):
    """Every measured bin dark gave "RMS nan%" and NaN in the JSON (which JSON readers
    refuse): the figures of no light are null."""
    import json

    import numpy as np

    from optdot.config.schema import load_job
    from optdot.optics.simulate import simulate
    from optdot.optics.writing import simulation_json

    np_map = "\n".join(",".join(["0.2"] * 30) for _ in range(20))
    (tmp_path / "m.csv").write_text(np_map + "\n")
    text = (SAMPLES / "lgp" / "job.toml").read_text()
    (tmp_path / "job.toml").write_text(
        text.replace("[dots]", '[density]\ngrid = "m.csv"\n\n[dots]')
    )
    sim = simulate(load_job(tmp_path / "job.toml"), 5_000, seed=1)
    sim.counts = np.zeros_like(sim.counts)  # no light where it is measured
    text = simulation_json(sim, load_job(tmp_path / "job.toml"), None, None)
    assert "NaN" not in text
    doc = json.loads(text, parse_constant=lambda c: pytest.fail(f"non-JSON constant {c}"))
    assert doc["luminance_rms"] is None


def test_an_existing_mask_is_kept_unless_overwrite(tmp_path):
    """A signed-off mask is not replaced by a different one through a typo: the same run
    again succeeds (same bytes), another pattern is refused and changes nothing (not even
    the other outputs of the command), ``--overwrite`` replaces it."""
    job = SAMPLES / "tiny" / "job.toml"
    gds, oas, csv = tmp_path / "m.gds", tmp_path / "m.oas", tmp_path / "m.csv"
    outs = ["--gds", gds, "--oas", oas, "--csv", csv, "-q"]
    assert cli("export", job, *outs)[0] == 0
    first = {p: p.read_bytes() for p in (gds, oas, csv)}
    assert cli("export", job, *outs)[0] == 0  # same job, same seed: same bytes
    msg = one_error(["export", job, "--seed", 7, *outs], 2, "m.gds", "--overwrite")
    assert "nothing was written" in msg
    assert {p: p.read_bytes() for p in (gds, oas, csv)} == first
    assert sorted(p.name for p in tmp_path.iterdir()) == ["m.csv", "m.gds", "m.oas"]
    assert cli("export", job, "--seed", 7, *outs, "--overwrite")[0] == 0
    assert gds.read_bytes() != first[gds] and csv.read_bytes() != first[csv]
    # a CSV or a preview is no mask: replaced without the flag
    assert cli("export", job, "--csv", csv, "-q")[0] == 0
    assert csv.read_bytes() == first[csv]


@pytest.mark.slow
def test_a_guide_that_keeps_its_light_is_refused_in_a_second(tmp_path):
    """Hardly a dot (a fill of 1e-5), no absorption, mirror edges: light that enters never
    leaves (every ray ran to the event limit, days for a default run, Ctrl-C unheard). A
    probe of the run's first rays refuses it in one line; the same guide with dots runs."""
    import time

    def job(fill: str) -> Path:
        (tmp_path / "m.csv").write_text("\n".join([",".join([fill] * 30)] * 20) + "\n")
        text = (SAMPLES / "lgp" / "job.toml").read_text()
        text = text.replace("[dots]", '[density]\ngrid = "m.csv"\n\n[dots]')
        for key, value in (("absorption", "0"), ("edge_reflectance", "1"), ("reflector", "1")):
            text = re.sub(rf"^{key} = .*$", f"{key} = {value}", text, flags=re.M)
        text = text.replace("[light_guide]", '[light_guide]\nedge_finish = "specular"')
        (tmp_path / "job.toml").write_text(text)
        return tmp_path / "job.toml"

    t = time.perf_counter()
    args = ["simulate", job("0.00001"), "--rays", 10**9, "--json", tmp_path / "s.json"]
    msg = one_error(args, 2, "job.toml", "light hardly leaves this guide", "absorption > 0")
    assert time.perf_counter() - t < 30, msg  # not days
    assert not (tmp_path / "s.json").exists()
    rc, err, _ = cli("simulate", job("0.2"), "--rays", 20_000, "-q")
    assert rc == 0, err
    # light that leaves slowly but leaves (most rays out within the run's event limit):
    # traced, its few unfinished rays reported, not refused
    rc, err, out = cli("simulate", job("0.0005"), "--rays", 5_000, "-q")
    assert rc == 0, err


def test_ray_counts_may_be_written_as_a_tracer_user_writes_them():
    """``--rays 1e7`` (how BENCHMARKS and users write it) was refused as not an integer."""
    import click

    from optdot.cli.optics import RAYS

    assert RAYS.convert("2e6", None, None) == 2_000_000
    assert RAYS.convert("2_000_000", None, None) == RAYS.convert("2000000", None, None)
    for bad in ("2.5", "1e11", "1e2", "nan", "e6", "1e100", "2.5e0", "inf"):
        with pytest.raises(click.BadParameter):
            RAYS.convert(bad, None, None)


@pytest.mark.slow
def test_a_mask_is_kept_whatever_option_names_it(tmp_path):
    """A CSV, a report or a preview given a mask's name (any case) does not replace a
    different mask there: ``export --csv w.gds``, ``qa --json W.OAS`` exit 2 and change
    nothing; ``export --overwrite`` may."""
    job = SAMPLES / "tiny" / "job.toml"
    gds, oas = tmp_path / "w.gds", tmp_path / "W.OAS"
    assert cli("export", job, "--gds", gds, "--oas", oas, "-q")[0] == 0
    before = {p: p.read_bytes() for p in (gds, oas)}
    one_error(["export", job, "--csv", gds, "-q"], 2, "w.gds", "is kept", "--overwrite")
    one_error(["export", job, "--png", oas, "-q"], 2, "W.OAS", "is kept")
    one_error(["qa", gds, "--no-job", "--json", oas, "-q"], 2, "W.OAS", "another name")
    assert {p: p.read_bytes() for p in (gds, oas)} == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["W.OAS", "w.gds"]
    assert cli("export", job, "--csv", gds, "--overwrite", "-q")[0] == 0
    assert gds.read_bytes().startswith(b"x_mm,y_mm")
