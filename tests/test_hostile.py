"""Hostile inputs and wrong answers: each ends in one line on stderr,
a documented exit code and no traceback, and writes nothing.

Every case here ended in a traceback, an exit 0 with a wrong or overwritten file, or the
wrong exit code before the fix.
"""

from __future__ import annotations

import json
import shutil
import time

import ezdxf
import gdstk
import numpy as np
import pytest

from optdot.cli.main import EXIT_INTERNAL
from optdot.io.patterns import save_pattern

from .conftest import SAMPLES, cli, one_error

TINY_DIR = SAMPLES / "tiny"


@pytest.fixture()
def tiny(tmp_path):
    for f in TINY_DIR.iterdir():
        shutil.copy(f, tmp_path / f.name)
    return tmp_path


def with_domain(tiny, line: str) -> str:
    text = (tiny / "job.toml").read_text().replace("[domain]", f"[domain]\n{line}")
    (tiny / "j.toml").write_text(text)
    return str(tiny / "j.toml")


# --- case 4: files that ended in tracebacks -------------------------------------------


def test_npz_saved_as_npy_grid(tiny, tiny_pattern):
    save_pattern(tiny_pattern, tiny / "p.npz")
    shutil.copy(tiny / "p.npz", tiny / "grid.npy")
    job = (tiny / "job.toml").read_text().replace("density.csv", "grid.npy")
    (tiny / "j.toml").write_text(job)
    one_error(["generate", tiny / "j.toml", "-o", tiny / "x.csv"], 2, "grid.npy", ".npz archive")
    assert not (tiny / "x.csv").exists()


def test_npy_header_claiming_80_gb(tiny):
    hdr = "{'descr': '<f8', 'fortran_order': False, 'shape': (100000, 100000), }"
    hdr = hdr + " " * (118 - len(hdr)) + "\n"
    (tiny / "grid.npy").write_bytes(
        b"\x93NUMPY\x01\x00" + len(hdr).to_bytes(2, "little") + hdr.encode() + bytes(64)
    )
    job = (tiny / "job.toml").read_text().replace("density.csv", "grid.npy")
    (tiny / "j.toml").write_text(job)
    one_error(["generate", tiny / "j.toml", "-o", tiny / "x.csv"], 2, "grid.npy", "80,000,000,000")


@pytest.mark.parametrize(
    "content, words",
    [
        ([1, 2], "top level is a list"),
        (5, "top level is a number"),
        ({"type": "Feature", "geometry": None, "properties": {}}, "geometry is null"),
        ({"type": "FeatureCollection", "features": [3]}, "feature is a number"),
        ({"type": "FeatureCollection"}, "features list"),
    ],
)
def test_geojson_that_is_not_an_object(tiny, content, words):
    (tiny / "o.geojson").write_text(json.dumps(content))
    job = with_domain(tiny, 'outline = "o.geojson"')
    one_error(["generate", job, "-o", tiny / "x.csv"], 2, "o.geojson", words)


def test_truncated_dxf_outline(tiny):
    doc = ezdxf.new(units=4)
    doc.modelspace().add_lwpolyline([(0, 0), (3, 0), (3, 2), (0, 2)], close=True)
    doc.saveas(tiny / "o.dxf")
    data = (tiny / "o.dxf").read_bytes()
    (tiny / "o.dxf").write_bytes(data[: len(data) // 3])
    job = with_domain(tiny, 'outline = "o.dxf"').replace("width", "#").replace("height", "#")
    one_error(["generate", job, "-o", tiny / "x.csv"], 2, "o.dxf", "not a readable DXF")


@pytest.mark.parametrize("diameter", ["1e-160", "0.0001", "-1", "11"])
def test_absurd_diameter(tiny, diameter):
    text = (tiny / "job.toml").read_text().replace("diameter = 0.046", f"diameter = {diameter}")
    (tiny / "j.toml").write_text(text)
    one_error(["generate", tiny / "j.toml", "-o", tiny / "x.csv"], 2, "dots.diameter")


def test_dot_count_rounding_to_zero(tiny):
    np.savetxt(tiny / "density.csv", np.full((2, 3), 1e-6), delimiter=",")
    for args in (
        ["generate", tiny / "job.toml", "-o", tiny / "x.csv"],
        ["export", tiny / "job.toml", "--csv", tiny / "x.csv"],
    ):
        one_error(args, 2, "0 dots")
    assert not (tiny / "x.csv").exists()


def test_qa_dxf_circles_of_radius_zero(tmp_path):
    doc = ezdxf.new(units=4)
    for i in range(5):
        doc.modelspace().add_circle((0.5 + 0.1 * i, 0.5), 0, dxfattribs={"layer": "DOTS"})
    doc.saveas(tmp_path / "r0.dxf")
    one_error(["qa", tmp_path / "r0.dxf"], 2, "r0.dxf", "radius 0.0")


@pytest.mark.parametrize("far", [1e7, 1e12])
def test_qa_dots_absurdly_far_apart(tmp_path, far):
    np.savez(
        tmp_path / "far.npz",
        xy=np.array([[0.0, 0.0], [far, far]]),
        diameter=np.float64(0.046),
        box=np.array([-1.0, -1.0, far + 1, far + 1]),
    )
    one_error(["qa", tmp_path / "far.npz"], 2, "far.npz", "10000 mm")


def test_qa_npz_with_a_two_element_diameter(tmp_path):
    np.savez(
        tmp_path / "d.npz",
        xy=np.array([[0.0, 0.0], [1.0, 1.0], [2.0, 2.0]]),
        diameter=np.array([0.046, 0.05]),
        box=np.array([-1.0, -1.0, 3.0, 3.0]),
    )
    one_error(["qa", tmp_path / "d.npz"], 2, "d.npz", "diameter")


def test_path_component_over_255_bytes(tiny):
    long = tiny / ("a" * 300 + ".csv")
    one_error(["generate", tiny / "job.toml", "-o", long], 2, "file name is 304 bytes")


@pytest.mark.slow
def test_temporary_beside_a_long_name(tiny):
    """A 254-byte name is legal; its temporary file must be too."""
    long = tiny / ("b" * 250 + ".csv")
    rc, err, _ = cli("generate", tiny / "job.toml", "-o", long, "-q")
    assert rc == 0, err
    assert long.exists()


def test_generate_onto_a_directory_fails_before_the_run(tiny, monkeypatch):
    (tiny / "out.csv").mkdir()
    import optdot.orchestration.pipeline

    def never(*a, **k):
        raise AssertionError("the optimisation ran before the output was checked")

    monkeypatch.setattr(optdot.orchestration.pipeline, "generate", never)
    one_error(["generate", tiny / "job.toml", "-o", tiny / "out.csv"], 2, "is a directory")
    one_error(["generate", tiny / "job.toml", "-o", tiny / "nodir" / "x.csv"], 2, "does not exist")


# --- case 5: wrong answers ---------------------------------------------------------------


def _mask_of_squares(path, side_um=46.0, layer=1):
    lib = gdstk.Library(unit=1e-6, precision=1e-9)
    top = lib.new_cell("TOP")
    for i in range(20):
        for j in range(20):
            x, y = 100.0 * i, 100.0 * j
            top.add(gdstk.rectangle((x, y), (x + side_um, y + side_um), layer=layer))
    lib.write_gds(str(path)) if path.suffix == ".gds" else lib.write_oas(str(path))


@pytest.mark.parametrize("suffix", [".gds", ".oas"])
def test_qa_reads_squares_as_square_dots(tmp_path, suffix):
    """A square is a dot shape now (a rounded rectangle of length = width, corner 0): qa
    measures squares as squares (their exact gaps), not as discs."""
    from optdot.exporters.readback import read_any

    path = tmp_path / f"sq{suffix}"
    _mask_of_squares(path)
    p = read_any(path)
    assert p.kind.name == "rounded_rectangle" and p.n == 400
    np.testing.assert_allclose(p.dots.size, [[0.046, 0.046, 0.0]] * 400, atol=1e-9)
    i = np.array([0])
    j = np.array([int(np.argmin(np.hypot(*(p.xy - p.xy[0] - [0.1, 0.0]).T)))])
    assert p.dots.gap(p.xy, i, j)[0] == pytest.approx(0.1 - 0.046, abs=1e-9)
    rc, err, _ = cli("qa", path, "--no-job")
    assert rc == 0, err


def test_qa_refuses_a_dot_cell_that_is_not_round(tmp_path):
    lib = gdstk.Library(unit=1e-6, precision=1e-9)
    dot = lib.new_cell("DOT")
    dot.add(gdstk.regular_polygon((0, 0), 23, 6, layer=1))  # a hexagon
    top = lib.new_cell("TOP")
    top.add(gdstk.Reference(dot, (0, 0), columns=5, rows=5, spacing=(100, 100)))
    lib.write_gds(str(tmp_path / "hex.gds"))
    one_error(["qa", tmp_path / "hex.gds"], 2, "not a circle", "6 vertices")


def test_qa_reads_the_layer_it_is_told(tmp_path, tiny_pattern):
    out = tmp_path / "l5.gds"
    rc, err, _ = cli("export", TINY_DIR / "job.toml", "--gds", out, "--layer", "5", "-q")
    assert rc == 0, err
    one_error(["qa", out, "--job", TINY_DIR / "job.toml"], 2, "no dots on layer 1/0")
    report = tmp_path / "q.json"
    rc, err, _ = cli("qa", out, "--job", TINY_DIR / "job.toml", "--layer", "5", "--json", report)
    assert rc == 0, err
    assert json.loads(report.read_text())["metrics"]["dots"] == tiny_pattern.n


def test_dots_and_outline_on_the_same_layer_are_refused(tmp_path):
    one_error(
        ["export", TINY_DIR / "job.toml", "--gds", tmp_path / "a.gds", "--layer", "2"],
        2,
        "outline's layer",
    )
    assert not (tmp_path / "a.gds").exists()


@pytest.mark.slow
def test_too_coarse_a_tolerance_is_refused(tmp_path):
    one_error(
        ["export", TINY_DIR / "job.toml", "--gds", tmp_path / "a.gds", "--tolerance", "5"],
        2,
        "6-gons",
    )


def test_outputs_may_not_overwrite_inputs(tiny):
    before = (tiny / "density.csv").read_bytes()
    one_error(["generate", tiny / "job.toml", "-o", tiny / "density.csv"], 2, "is an input")
    assert (tiny / "density.csv").read_bytes() == before
    rc, _, _ = cli("generate", tiny / "job.toml", "-o", tiny / "p.csv", "-q")
    assert rc == 0
    pattern = (tiny / "p.csv").read_bytes()
    one_error(["qa", tiny / "p.csv", "--json", tiny / "p.csv"], 2, "is an input")
    one_error(
        ["qa", tiny / "p.csv", "--job", tiny / "job.toml", "--html", tiny / "job.toml"],
        2,
        "is an input",
    )
    one_error(["export", tiny / "p.csv", "--csv", tiny / "./p.csv"], 2, "is an input")
    one_error(["export", tiny / "job.toml", "--csv", tiny / "density.csv"], 2, "is an input")
    assert (tiny / "p.csv").read_bytes() == pattern
    assert (tiny / "density.csv").read_bytes() == before


# --- case 6: rough edges -----------------------------------------------------------------


@pytest.mark.parametrize(
    "args, words",
    [
        (["generate"], "Missing argument 'JOB_FILE'"),
        (["frobnicate"], "No such command"),
        (["qa", "x.csv", "--close", "-1"], "--close"),
        (["export", "x.csv"], "give at least one of"),
        (["generate", "job.toml", "-o", "x.csv", "--seed", "-5"], "--seed"),
    ],
)
def test_usage_errors_are_one_line(args, words):
    one_error(args, 2, words)


def test_bom_in_job_grid_and_pattern_is_read_over(tiny, tiny_pattern):
    bom = b"\xef\xbb\xbf"
    for name in ("job.toml", "density.csv"):
        (tiny / name).write_bytes(bom + (tiny / name).read_bytes())
    rc, err, _ = cli("generate", tiny / "job.toml", "-o", tiny / "p.csv", "-q")
    assert rc == 0, err
    plain = tiny / "plain"
    plain.mkdir()
    for f in TINY_DIR.iterdir():
        shutil.copy(f, plain / f.name)
    cli("generate", plain / "job.toml", "-o", plain / "p.csv", "-q")
    assert (tiny / "p.csv").read_bytes() == (plain / "p.csv").read_bytes()
    (tiny / "q.csv").write_bytes(bom + (tiny / "p.csv").read_bytes())
    rc, err, _ = cli("qa", tiny / "q.csv", "--job", plain / "job.toml", "-q")
    assert rc == 0, err


def test_keep_out_linestring_is_named_as_such(tiny):
    doc = ezdxf.new(units=4)
    doc.modelspace().add_lwpolyline([(0, 0), (3, 0), (3, 2), (0, 2)], close=True)
    doc.saveas(tiny / "o.dxf")
    text = (tiny / "job.toml").read_text()
    text = text.replace("width = 3.0\n", "").replace("height = 2.0\n", "")
    text = text.replace(
        "[domain]", '[domain]\noutline = "o.dxf"\nkeep_out = ["LINESTRING (0 0, 1 1)"]'
    )
    (tiny / "j.toml").write_text(text)
    one_error(["generate", tiny / "j.toml", "-o", tiny / "x.csv"], 2, "LINESTRING is not an area")


def test_impossible_edge_margin_is_bad_input(tiny):
    job = with_domain(tiny, "edge_margin = 0.9")
    one_error(["generate", job, "-o", tiny / "x.csv"], 2, "domain.edge_margin = 0.9", "room for")


def test_no_gdstk_lines_or_warnings_on_stderr(tmp_path):
    """gdstk warns (on stderr and as a Python warning) about a reference to a cell the
    file does not define; qa then crashed on it."""
    lib = gdstk.Library(unit=1e-6, precision=1e-9)
    top = lib.new_cell("TOP")
    top.add(gdstk.Reference("MISSING", (0, 0)), gdstk.ellipse((100, 100), 23, layer=1))
    lib.write_gds(str(tmp_path / "miss.gds"))
    one_error(["qa", tmp_path / "miss.gds"], 2, "missing cell 'MISSING'")
    (tmp_path / "bad.gds").write_bytes(b"\x00\x06\x00\x02\x00\x07" + bytes(100))
    (tmp_path / "bad.oas").write_bytes(b"%SEMI-OASIS\r\n" + bytes(50))
    for f in ("bad.gds", "bad.oas"):
        msg = one_error(["qa", tmp_path / f], 2, f)
        assert "[GDSTK]" not in msg


def test_a_command_line_that_cannot_load_says_so_in_one_line():
    """An install broken under the command line (a library that fails to import, numba
    with nowhere to cache): a 36-line traceback and exit 1, the QA gate's failure code."""
    import subprocess
    import sys

    code = "import sys; sys.modules['optdot.cli'] = None; from optdot.console import run; run()"
    r = subprocess.run([sys.executable, "-P", "-c", code], capture_output=True, text=True)
    assert r.returncode == EXIT_INTERNAL, r.stderr
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in r.stderr, lines
    assert lines[0].startswith("optdot: internal error: cannot load the command line: ")


@pytest.mark.parametrize(
    "planted",
    [ZeroDivisionError("a planted bug"), EOFError("Ran out of input")],
    ids=["bug", "eof"],
)
def test_an_internal_error_is_one_line_with_a_log(tiny, monkeypatch, tmp_path, planted):
    """An unexpected exception: one line naming a log with the traceback, exit 70. An
    ``EOFError`` too: click read it as a prompt's input ended and aborted, and the command
    said "interrupted" (exit 130) after a blank line though no signal came (a numba cache
    file cut short raised one)."""
    import optdot.orchestration.pipeline

    def bug(*a, **k):
        raise planted

    monkeypatch.setattr(optdot.orchestration.pipeline, "generate", bug)
    monkeypatch.setenv("TMPDIR", str(tmp_path))
    import tempfile

    monkeypatch.setattr(tempfile, "tempdir", None)
    rc, err, _ = cli("generate", tiny / "job.toml", "-o", tiny / "x.csv")
    assert rc == EXIT_INTERNAL, err
    assert len(err) == 1 and err[0].startswith("optdot: internal error: "), err
    assert f"{type(planted).__name__}: {planted}" in err[0]
    log = err[0].split("traceback in ")[1].rstrip(")")
    text = open(log).read()
    assert "Traceback" in text and str(planted) in text and "generate" in text
    assert log.startswith(str(tmp_path))
    assert not (tiny / "x.csv").exists()


def test_a_reader_crash_is_one_line(tmp_path, monkeypatch, tiny_pattern):
    """gdstk's C++ readers segfault or abort on some damaged files (found by the property
    tests): masks are read in a child process, and its death is a bad-input line."""
    import os
    import signal

    from optdot.exporters import readback, write
    from optdot.runtime.isolate import ChildCrashed, in_child

    with pytest.raises(ChildCrashed, match="SIGABRT"):
        in_child(os.abort)
    with pytest.raises(ZeroDivisionError):
        in_child(divmod, 1, 0)
    assert in_child(sum, [1, 2, 3]) == 6
    write(tiny_pattern, "gds", tmp_path / "m.gds")

    def crash(path, opts):
        os.kill(os.getpid(), signal.SIGSEGV)

    monkeypatch.setattr(readback, "_read_layout", crash)
    one_error(["qa", tmp_path / "m.gds"], 2, "m.gds: damaged GDS file", "SIGSEGV")


def _spin(seconds: float) -> str:
    end = time.process_time() + seconds
    while time.process_time() < end:
        pass
    return "done"


@pytest.mark.slow
def test_a_reader_that_hangs_is_stopped_and_one_that_works_is_not(monkeypatch):
    """A corrupted heap can deadlock the child (seen in CI): no CPU for STALL_SECONDS and
    it is killed and reported; a child busy for longer than that is left to finish."""
    from optdot.runtime import isolate

    monkeypatch.setattr(isolate, "STALL_SECONDS", 1.0)
    t0 = time.monotonic()
    with pytest.raises(isolate.ChildCrashed, match="hung"):
        isolate.in_child(time.sleep, 60)
    assert time.monotonic() - t0 < 10
    assert isolate.in_child(_spin, 2.5) == "done"


# --- the messages of the fifth round ------------------------------------------------------

ELLIPSE_MAP = (
    '[dots]\nshape = "ellipse"\nlength = 0.08\nwidth = 0.04\n\n[orientation]\nmap = "a.{}"\n'
)


def _ellipse_job(tiny, ext: str) -> str:
    text = (tiny / "job.toml").read_text().replace("[dots]\ndiameter = 0.046\n", "")
    (tiny / "e.toml").write_text(text + ELLIPSE_MAP.format(ext))
    return str(tiny / "e.toml")


def test_an_image_given_as_an_angle_map_is_named_as_one(tiny):
    """A PNG angle map: "'utf-8' codec can't decode byte 0x89"; now what it is."""
    from PIL import Image

    Image.fromarray(np.zeros((4, 4), np.uint8)).save(tiny / "a.png")
    one_error(("check", _ellipse_job(tiny, "png")), 2, "a.png", "is a PNG image", "CSV")


def test_a_value_is_echoed_as_a_number_not_numpy_s_repr(tiny):
    (tiny / "a.csv").write_text("0,10\n20,nan\n")
    line = one_error(("check", _ellipse_job(tiny, "csv")), 2, "row 2, column 2 = nan")
    assert "np.float64" not in line


def test_an_led_profile_of_strings_is_refused(tmp_path):
    from optdot.config.light_guide import profile_table
    from optdot.errors import JobError

    assert profile_table([[0, 1.0], [90, 0]], "leds", "job") == ((0.0, 1.0), (90.0, 0.0))
    for rows in ([["0", "1"], ["90", "0"]], [[0, True], [90, 0]]):
        with pytest.raises(JobError, match="two or more rows of numbers"):
            profile_table(rows, "leds", "job")


@pytest.mark.parametrize(
    "args, code",
    [(("check", "{job}"), 0), (("qa", "{p}", "--job", "{job}"), 0), (("qa", "{p}"), 5)],
    ids=["check", "qa", "qa-without-job"],
)
@pytest.mark.slow
def test_stdout_closed_early_keeps_the_command_s_own_code(tiny, tiny_pattern, args, code):
    """``optdot check JOB | true``: exit 1 (the gate's failure code) with nothing said;
    now the command finishes and exits with its own code, saying nothing of the pipe."""
    import os
    import subprocess
    import sys

    save_pattern(tiny_pattern, tiny / "p.npz")
    filled = [a.format(job=tiny / "job.toml", p=tiny / "p.npz") for a in args]
    read, write = os.pipe()
    os.close(read)  # the reader is gone before the first line
    try:
        got = subprocess.run(
            [sys.executable, "-P", "-m", "optdot", *filled],
            stdout=write, stderr=subprocess.PIPE, text=True,
        )  # fmt: skip
    finally:
        os.close(write)
    assert got.returncode == code, got.stderr
    assert "Broken pipe" not in got.stderr and "Traceback" not in got.stderr
