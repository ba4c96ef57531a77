import json

import ezdxf
import numpy as np
import pytest
from click.testing import CliRunner

from optdot.cli import main
from optdot.io.patterns import load_pattern

from .conftest import SAMPLES, write_job

#: the quick end-to-end check (README: ``pytest -m smoke``)
pytestmark = pytest.mark.smoke

TINY = SAMPLES / "tiny" / "job.toml"


def run(*args):
    return CliRunner().invoke(main, [str(a) for a in args], catch_exceptions=False)


@pytest.fixture(scope="module")
def exported(tmp_path_factory):
    d = tmp_path_factory.mktemp("exp")
    outs = {f: d / f"t.{f}" for f in ("gds", "oas", "dxf", "csv", "svg", "png")}
    args = ["export", TINY, "-q"]
    for f, p in outs.items():
        args += [f"--{f}", p]
    r = run(*args)
    assert r.exit_code == 0, r.output
    return outs


def test_generate_csv_and_npz_roundtrip(tmp_path):
    r = run("generate", TINY, "-o", tmp_path / "a.csv", "-q")
    assert r.exit_code == 0, r.output
    text = (tmp_path / "a.csv").read_text().splitlines()
    assert text[0] == "x_mm,y_mm,diameter_mm"
    r = run("generate", TINY, "-o", tmp_path / "a.npz", "-q", "--seed", "1")
    a, b = load_pattern(tmp_path / "a.csv"), load_pattern(tmp_path / "a.npz")
    np.testing.assert_array_equal(a.xy, b.xy)
    run("generate", TINY, "-o", tmp_path / "b.npz", "-q")
    assert (tmp_path / "a.npz").read_bytes() == (tmp_path / "b.npz").read_bytes()


def test_export_same_bytes(exported, tmp_path):
    args = ["export", TINY, "-q"]
    for f in ("gds", "oas", "dxf", "csv"):
        args += [f"--{f}", tmp_path / f"t.{f}"]
    assert run(*args).exit_code == 0
    for f in ("gds", "oas", "dxf", "csv"):
        assert (tmp_path / f"t.{f}").read_bytes() == exported[f].read_bytes(), f


def _sorted(xy):
    return xy[np.lexsort(xy.T[::-1])]


@pytest.mark.parametrize("fmt", ["gds", "oas"])
def test_klayout_reads_masks(exported, fmt):
    kdb = pytest.importorskip("klayout.db")
    ref = load_pattern(exported["csv"])
    ly = kdb.Layout()
    ly.read(str(exported[fmt]))
    assert ly.dbu == pytest.approx(0.001)  # 1 nm database unit in µm
    top = ly.top_cell()
    # every dot as KLayout places it, through the hierarchy and any repetition
    it = top.begin_shapes_rec(ly.layer(1, 0))
    pts = []
    while not it.at_end():
        b = it.shape().bbox().transformed(it.trans())
        pts.append([b.center().x * 1e-6, b.center().y * 1e-6])
        it.next()
    centres = np.array(pts)
    assert len(centres) == ref.n
    assert np.abs(_sorted(centres) - _sorted(ref.xy)).max() <= 1e-6 + 1e-12
    dot = ly.cell("DOT")
    box = dot.bbox()
    assert box.width() * 1e-3 == pytest.approx(46.0, abs=0.002)  # µm
    # spacing check in KLayout: no two dots closer than one diameter (touching is allowed)
    region = kdb.Region(top.begin_shapes_rec(ly.layer(1, 0)))
    assert region.count() == ref.n
    assert region.isolated_check(1).count() == 0  # 1 nm: dots never overlap
    outline = kdb.Region(top.begin_shapes_rec(ly.layer(2, 0)))
    assert outline.bbox().width() == 3_000_000 and outline.bbox().height() == 2_000_000


def test_ezdxf_reads_dxf(exported):
    ref = load_pattern(exported["csv"])
    doc = ezdxf.readfile(exported["dxf"])
    auditor = doc.audit()
    assert not auditor.has_errors
    assert doc.header["$INSUNITS"] == 4
    circles = doc.modelspace().query('CIRCLE[layer=="DOTS"]')
    xy = np.array([(c.dxf.center.x, c.dxf.center.y) for c in circles])
    assert len(xy) == ref.n
    assert np.abs(_sorted(xy) - _sorted(ref.xy)).max() < 1e-9
    assert {c.dxf.radius for c in circles} == {0.023}
    assert len(doc.modelspace().query('LWPOLYLINE[layer=="OUTLINE"]')) == 1


def test_klayout_reads_dxf(exported):
    kdb = pytest.importorskip("klayout.db")
    ly = kdb.Layout()
    opt = kdb.LoadLayoutOptions()
    opt.dxf_unit = 1000.0  # drawing units are mm; KLayout ignores $INSUNITS
    opt.dxf_polyline_mode = 2
    ly.read(str(exported["dxf"]), opt)
    region = kdb.Region(ly.top_cell().begin_shapes_rec(ly.layer(kdb.LayerInfo("DOTS"))))
    assert region.count() == load_pattern(exported["csv"]).n


def test_dxf_r12(tmp_path, exported):
    r = run(
        "export",
        exported["csv"],
        "--dxf",
        tmp_path / "r12.dxf",
        "--dxf-version",
        "R12",
        "-q",
        "--no-job",
    )
    assert r.exit_code == 0, r.output
    doc = ezdxf.readfile(tmp_path / "r12.dxf")
    assert doc.dxfversion == "AC1009"
    assert len(doc.modelspace().query("CIRCLE")) == load_pattern(exported["csv"]).n
    # qa reads it back: R12's outline is a POLYLINE of VERTEX entities
    from optdot.exporters.readback import read_any

    back = read_any(tmp_path / "r12.dxf")
    want = load_pattern(exported["csv"])
    assert back.n == want.n
    np.testing.assert_allclose(back.box, want.box, atol=1e-9)


def test_previews(exported):
    assert exported["png"].read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert exported["svg"].read_text().count("<circle") == load_pattern(exported["csv"]).n


@pytest.mark.slow
def test_qa_clean_pattern_passes(exported, tmp_path):
    for fmt in ("csv", "gds", "oas", "dxf"):
        r = run(
            "qa",
            exported[fmt],
            "--job",
            TINY,
            "--json",
            tmp_path / "r.json",
            "--html",
            tmp_path / "r.html",
        )
        assert r.exit_code == 0, (fmt, r.output)
    rep = json.loads((tmp_path / "r.json").read_text())
    # the gate passes; what a viewer may see of a 3 x 2 mm sample is only advisory
    assert rep["verdict"] in ("PASS", "PASS WITH WARNINGS")
    assert all(c["passed"] or c["advisory"] for c in rep["checks"])
    assert rep["metrics"]["pairs_below_collision"] == 0
    html = (tmp_path / "r.html").read_text()
    assert "PASS" in html and html.count("data:image/png;base64,") >= 4


def test_qa_finds_planted_defects(exported, tmp_path):
    p = load_pattern(exported["csv"])
    xy = p.xy.copy()
    i = int(np.argmin(np.hypot(xy[:, 0] - 1.5, xy[:, 1] - 1.0)))
    planted = np.array(
        [xy[i] + [0.0, 0.02], [2.99, 1.0], [0.1, 1.0]]
    )  # collision, protruding, empty column
    d = np.hypot(*(xy[:, None, :] - planted[None]).transpose(2, 0, 1)).min(axis=1)
    keep = (d > 0.1) | (np.arange(len(xy)) == i)
    xy = np.vstack([xy[keep], planted])
    i = int(np.flatnonzero(keep).tolist().index(i))
    bad = tmp_path / "bad.csv"
    bad.write_text(
        "x_mm,y_mm,diameter_mm\n" + "".join(f"{x:.6f},{y:.6f},0.046000\n" for x, y in xy)
    )
    r = run("qa", bad, "--job", TINY, "--json", tmp_path / "r.json")
    assert r.exit_code == 1
    m = json.loads((tmp_path / "r.json").read_text())
    checks = {c["name"]: c for c in m["checks"]}
    assert m["metrics"]["pairs_below_collision"] == 1
    assert m["metrics"]["protruding"] == 1 and m["metrics"]["in_empty_cells"] == 1
    col = next(c for n, c in checks.items() if "collisions" in n)
    assert np.allclose(col["where"][0], xy[i] + [0.0, 0.01], atol=1e-6)
    # export refuses to write masks for it, and writes nothing
    r = run("export", bad, "--job", TINY, "--gds", tmp_path / "bad.gds")
    assert r.exit_code == 1 and not (tmp_path / "bad.gds").exists()
    r = run("export", bad, "--job", TINY, "--gds", tmp_path / "bad.gds", "--force", "-q")
    assert r.exit_code == 0 and (tmp_path / "bad.gds").exists()


def test_qa_pair_counts_match_brute_force():
    """QA's own pair counts (the cKDTree path of quality/measure.py) against all pairs."""
    from optdot.config.job import QAParams
    from optdot.pattern import Pattern
    from optdot.quality.gate import run_qa

    xy = np.random.default_rng(4).random((700, 2)) * 0.6
    d = np.hypot(*(xy[:, None, :] - xy[None, :, :]).T)[np.triu_indices(len(xy), 1)]
    p = Pattern(xy=xy, diameter=0.046, box=(0.0, 0.0, 0.6, 0.6))
    m = run_qa(p, None, QAParams(close_distance=0.060), 0.046).metrics
    assert m["pairs_below_collision"] == int((d < 0.046).sum()) > 0
    assert m["pairs_below_close"] == int((d < 0.060).sum())


# ----------------------------------------------------------------- bad input

BAD = {
    "nan": ("0.1,nan\n0.2,0.3\n", {}, "NaN"),
    "negative": ("0.1,-0.2\n0.2,0.3\n", {}, "negative"),
    "packing": ("0.1,0.95\n0.2,0.3\n", {}, "packing limit"),
    "allzero": ("0,0\n0,0\n", {}, "all zero"),
    "ragged": ("0.1,0.2\n0.2\n", {}, "wrong grid shape"),
    "text": ("0.1,abc\n0.2,0.3\n", {}, "not a number"),
    "empty": ("", {}, "empty"),
    "width": ("0.2,0.2\n", {"domain": {"width": -1.0}}, "domain.width"),
    "diameter": ("0.2,0.2\n", {"dots": {"diameter": 0.0}}, "dots.diameter"),
    "unknown_key": (
        "0.2,0.2\n",
        {"optimize": {"max_iters": 5}},
        "unknown key 'optimize.max_iters'",
    ),
    "method": ("0.2,0.2\n", {"optimize": {"method": '"foo"'}}, "optimize.method"),
    "memory": ("0.5,0.5\n", {"domain": {"width": 9000.0, "height": 9000.0}}, "GiB"),
}


@pytest.mark.parametrize("case", sorted(BAD))
def test_bad_job_inputs(tmp_path, case):
    grid, sections, needle = BAD[case]
    job = write_job(tmp_path, grid, **sections)
    out = tmp_path / "out.csv"
    r = run("generate", job, "-o", out)
    assert r.exit_code == 2, r.output
    lines = r.output.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in r.output
    assert needle in lines[0] and lines[0].startswith("optdot: error:")
    assert not out.exists() and not list(tmp_path.glob(".out.csv*"))


def test_missing_and_malformed_files(tmp_path):
    r = run("generate", tmp_path / "nope.toml", "-o", tmp_path / "o.csv")
    assert r.exit_code == 2 and "not found" in r.output
    (tmp_path / "bad.toml").write_text("[domain\nwidth=")
    r = run("generate", tmp_path / "bad.toml", "-o", tmp_path / "o.csv")
    assert r.exit_code == 2 and "malformed TOML" in r.output
    (tmp_path / "p.csv").write_text("a,b\n1,2\n")
    r = run("qa", tmp_path / "p.csv")
    assert r.exit_code == 2 and "header" in r.output
    r = run("export", TINY, "--gds", tmp_path / "no" / "dir.gds")
    assert r.exit_code == 2 and "does not exist" in r.output
    r = run("export", TINY, "--gds", tmp_path / "x.gds", "--tolerance", "-1")
    assert r.exit_code == 2 and "tolerance" in r.output and not (tmp_path / "x.gds").exists()


def test_bad_option_writes_nothing(tmp_path, exported):
    """A bad option is refused before any work (a failed *write* is tests/test_faults.py)."""
    out = tmp_path / "keep.gds"
    out.write_bytes(b"old")
    r = run("export", exported["csv"], "--gds", out, "--top-cell", "bad name!")
    assert r.exit_code == 2 and out.read_bytes() == b"old"


@pytest.mark.slow  # over 1.5 s
def test_shaped_dots_end_to_end(tmp_path):
    """Every command and format with shaped dots: an ellipse job turned toward its LEDs
    generated, exported to every format, each mask read back by qa, and simulated."""
    grid = np.tile(np.linspace(0.05, 0.25, 6), (4, 1))
    job = write_job(
        tmp_path,
        grid,
        dots={"diameter": None, "shape": '"ellipse"', "length": 0.08, "width": 0.04},
        orientation={"toward": '"leds"'},
        optimize={"max_iter": 60, "seed": 3, "gap": 0.005},
        light_guide={"thickness": 0.4},
    )
    job.write_text(
        job.read_text() + '[[light_guide.leds]]\nedge = "bottom"\npositions = [1.0]\nwidth = 0.5\n'
    )
    r = run("check", job)
    assert r.exit_code == 0, r.output
    assert "ellipses" in r.output
    outs = {f: tmp_path / f"s.{f}" for f in ("gds", "oas", "dxf", "csv", "svg", "png", "speos")}
    args = ["export", job, "-q"]
    for f, p in outs.items():
        args += [f"--{f}", p]
    r = run(*args)
    assert r.exit_code == 0, r.output
    assert outs["csv"].read_text().startswith("x_mm,y_mm,length_mm,width_mm,angle_deg\n")
    for f in ("gds", "oas", "dxf", "csv"):
        r = run("qa", outs[f], "--job", job, "--json", tmp_path / f"{f}.json", "-q")
        assert r.exit_code == 0, (f, r.output)
        m = json.loads((tmp_path / f"{f}.json").read_text())["metrics"]
        assert m["shape"]["kind"] == "ellipse" and m["pairs_below_collision"] == 0
    r = run("simulate", job, outs["csv"], "--rays", "20000", "-q")
    assert r.exit_code == 0, r.output
