"""Laser dotting paths: ``[laser]`` and ``export --laser``. The points read back by
independent readers (gcodeparser for G-code, ezdxf's HPGL/2 reader for PLT, numpy for the
CSV), the path against the pattern's order and a brute-force bound, the machining time's
closed form, the laser's sizes in the generated dots, and refusals."""

from __future__ import annotations

import math
import warnings

import numpy as np
import pytest

from optdot.config.schema import load_job
from optdot.io.patterns import load_pattern
from optdot.orchestration.pipeline import generate
from optdot.printing.laser import Laser, path_length, serpentine, shortest_path

from .conftest import SAMPLES, cli, one_error, write_job


@pytest.fixture(scope="module")
def led_paths(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("laser")
    job = tmp / "job.toml"
    job.write_text(
        (SAMPLES / "tiny" / "job.toml")
        .read_text()
        .replace('"density.csv"', f'"{SAMPLES / "tiny" / "density.csv"}"')
        + "\n[laser]\nspeed = 300\nacceleration = 3000\ndwell = 0.002\n"
    )
    rc, err, _ = cli("export", job, "--csv", tmp / "p.csv", "-q")
    assert rc == 0, err
    lines = {}
    for name in ("p.nc", "p.plt", "l.csv"):
        rc, err, _ = cli("export", tmp / "p.csv", "--job", job, "--laser", tmp / name)
        assert rc == 0, err
        lines[name] = err[-1]
    return tmp, load_pattern(tmp / "p.csv"), lines


def _same_points(got: np.ndarray, want: np.ndarray, atol: float) -> None:
    """The same points, one for one, each within ``atol``."""
    from scipy.spatial import cKDTree

    d, i = cKDTree(want).query(got)
    assert len(got) == len(want) and d.max() <= atol and len(set(i.tolist())) == len(want)


def test_gcode_reads_back_point_for_point(led_paths):
    from gcodeparser import parse_gcode_lines

    tmp, p, _ = led_paths
    moves, fires = [], 0
    for line in parse_gcode_lines((tmp / "p.nc").read_text()):
        if line.command == ("G", 0):
            moves.append((line.params["X"], line.params["Y"]))
        elif line.command == ("M", 3):
            assert line.params["S"] == 1
            fires += 1
    assert len(moves) == fires == p.n
    xy = np.array(moves)
    _same_points(xy, p.xy, 7.1e-5)  # 4 decimals: 0.05 µm a coordinate
    assert path_length(xy) == pytest.approx(shortest_path(p.xy, (0, 0, 3, 2))[2], rel=1e-4)


def test_hpgl_reads_back_in_micrometres(led_paths):
    from ezdxf.addons.hpgl2 import api

    tmp, p, _ = led_paths
    data = (tmp / "p.plt").read_bytes()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        doc = api.to_dxf(b"\x1b%0B" + data)  # the PCL switch into HPGL/2 its reader wants
    lines = [e.dxf.start for e in doc.modelspace() if e.dxftype() == "LINE"]
    pts = np.array([(v.x, v.y) for v in lines])
    assert len(pts) == p.n
    # the reader moves the drawing to its origin, in plotter units of 25 µm
    got = (pts - pts.min(axis=0)) * 0.025
    want = np.round(p.xy * 1e3) * 1e-3
    _same_points(got, want - want.min(axis=0), 1e-6)


def test_csv_is_the_path_with_sizes_and_sets(led_paths):
    tmp, p, line = led_paths
    rows = np.loadtxt(tmp / "l.csv", delimiter=",", skiprows=1)
    assert np.array_equal(rows[:, 0], np.arange(p.n))
    _same_points(rows[:, 1:3], p.xy, 1e-9)
    assert np.all(rows[:, 3] == 0.046) and np.all(rows[:, 4] == 1)
    # the path: at least 3x shorter than the pattern's order, within 1.5x of the sum of
    # each dot's nearest-neighbour distance (no path is shorter than half of that)
    from scipy.spatial import cKDTree

    ours = path_length(rows[:, 1:3])
    assert path_length(p.xy) > 3 * ours
    nn = cKDTree(p.xy).query(p.xy, k=2)[0][:, 1].sum()
    assert ours < 1.5 * nn
    assert f"{ours:,.1f} mm" in line["l.csv"]


def test_machining_time_is_the_trapezoid_sum(led_paths):
    tmp, p, lines = led_paths
    rows = np.loadtxt(tmp / "l.csv", delimiter=",", skiprows=1)
    d = np.hypot(*np.diff(rows[:, 1:3], axis=0).T)
    v, a = 300.0, 3000.0
    t = sum(dd / v + v / a if dd >= v * v / a else 2 * math.sqrt(dd / a) for dd in d)
    t += 0.002 * p.n
    laser = Laser(speed=v, acceleration=a, dwell=0.002)
    assert laser.machining_time(rows[:, 1:3]) == pytest.approx(t, rel=1e-12)
    assert f"about {t:.1f} s to machine" in lines["l.csv"]
    # a long move reaches the speed: d/v + v/a; a short one does not: 2 sqrt(d/a)
    assert laser.move_time(np.array([100.0]))[0] == pytest.approx(100 / 300 + 0.1)
    assert laser.move_time(np.array([3.0]))[0] == pytest.approx(2 * math.sqrt(0.001))


def test_serpentine_visits_every_dot_once_band_by_band():
    rng = np.random.default_rng(3)
    xy = rng.uniform(0, 10, (500, 2))
    order = serpentine(xy, 1.0, 0.0)
    assert np.array_equal(np.sort(order), np.arange(500))
    band = np.floor(xy[order, 1]).astype(int)
    assert np.all(np.diff(band) >= 0)
    for b in range(10):
        x = xy[order][band == b, 0]
        assert np.all(np.diff(x) >= 0) if b % 2 == 0 else np.all(np.diff(x) <= 0)


def test_laser_sizes_are_the_dots_sizes(tmp_path):
    """A range of diameters dotted by a laser of three sizes: every dot takes one of
    them, and the guarantee holds for the sizes it takes; the sets follow the sizes."""
    grid = np.tile(np.linspace(0.05, 0.35, 6), (4, 1))
    path = write_job(
        tmp_path, grid,
        dots={"diameter": "[0.04, 0.12]", "spacing": 0.15},
        laser={"sizes": "[0.05, 0.08, 0.11, 0.2]"},
    )  # fmt: skip
    job = load_job(path)
    assert job.sizes.levels == (0.05, 0.08, 0.11) and job.diameter == 0.05
    p = generate(job)
    assert set(np.round(p.diameter, 6)) <= {0.05, 0.08, 0.11}
    assert len(set(np.round(p.diameter, 6))) >= 2
    d = np.hypot(*(p.xy[:, None] - p.xy[None]).transpose(2, 0, 1))
    np.fill_diagonal(d, 1)
    assert np.all(d - 0.5 * (p.diameter[:, None] + p.diameter[None]) >= -1e-9)
    rc, err, _ = cli("export", path, "--laser", tmp_path / "l.csv", "-q")
    assert rc == 0, err
    rows = np.loadtxt(tmp_path / "l.csv", delimiter=",", skiprows=1)
    sets = {0.05: 1, 0.08: 2, 0.11: 3}
    assert all(sets[round(dd, 6)] == s for dd, s in zip(rows[:, 3], rows[:, 4], strict=True))


def test_one_size_takes_the_nearest_laser_size(tmp_path):
    path = write_job(tmp_path, np.full((2, 2), 0.2), laser={"sizes": "[0.03, 0.05]"})
    job = load_job(path)
    assert job.diameter == 0.05 and job.sizes is None


ELLIPSE = {"shape": '"ellipse"', "length": 0.08, "width": 0.04, "diameter": None}


@pytest.mark.parametrize(
    ("laser", "dots", "words"),
    [
        ({"sizes": "[0.2, 0.3]"}, None, ("none fits dots.diameter = 46 µm",)),
        ({"sizes": "[0.2]"}, {"diameter": "[0.04, 0.1]"}, ("none fits the dots' range 40-100 µm",)),
        ({"sizes": "[0.05, -1]"}, None, ("laser.sizes", "> 0")),
        ({"sizes": "[0.05]"}, ELLIPSE, ("round craters",)),
        ({"speed": 0}, None, ("laser.speed = 0", "x > 0")),
        ({"dwell": -1}, None, ("laser.dwell = -1", "0 <= x")),
    ],
)  # fmt: skip
def test_bad_laser_gets_one_line(tmp_path, laser, dots, words):
    path = write_job(
        tmp_path, np.full((2, 2), 0.2), laser=laser, **({"dots": dots} if dots else {})
    )
    one_error(["generate", path, "-o", tmp_path / "p.csv"], 2, str(path), *words)


def test_shaped_dots_and_unknown_suffixes_are_refused(tmp_path):
    dots = {"shape": '"ellipse"', "length": 0.08, "width": 0.04, "diameter": None}
    path = write_job(tmp_path, np.full((2, 2), 0.2), dots=dots, optimize={"gap": 0.005})
    one_error(["export", path, "--laser", tmp_path / "l.nc"], 2, "round craters", "ellipses")
    path = write_job(tmp_path, np.full((2, 2), 0.2))
    one_error(["export", path, "--laser", tmp_path / "l.txt"], 2, "G-code", "HPGL/2", ".csv")
    assert not (tmp_path / "l.txt").exists()


def test_a_mirror_on_a_laser_path_is_refused(tmp_path):
    """A laser dots the part itself: a process's mirror (for masks printed emulsion side
    down) has no meaning in its path, and is refused rather than silently dropped."""
    path = write_job(tmp_path, np.full((2, 2), 0.2), process={"mirror": '"x"'})
    one_error(["export", path, "--laser", tmp_path / "l.nc"], 2, "process.mirror = 'x'", "laser")
    assert not (tmp_path / "l.nc").exists()
