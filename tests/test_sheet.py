"""Production sheets: ``[sheet]``. The panel arrayed once (GDSII/OASIS an AREF, DXF an
INSERT with rows and columns: no dot written twice), fiducials, labels and cut lines on
their layers read back by KLayout and ezdxf, QA judging the one panel, and refusals."""

from __future__ import annotations

import numpy as np
import pytest

from optdot.config.schema import load_job

from .conftest import cli, one_error, write_job

SHEET = {
    "rows": 2,
    "columns": 3,
    "pitch": "[2.5, 2.0]",
    "fiducials": "[[-1.0, -1.0], [7.0, -1.0], [-1.0, 3.5]]",
    "date": '"2026-11-28"',
}
PROCESS = {"dot_gain": 0.005, "shrink": 0.004, "mirror": '"x"', "grid": 0.0001}


def _job(tmp, sheet=SHEET, **more):
    grid = np.tile(np.linspace(0.1, 0.3, 4), (3, 1))
    return write_job(tmp, grid, domain={"width": 2.0, "height": 1.5}, sheet=sheet, **more)


@pytest.fixture(scope="module")
def sheet(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("sheet")
    path = _job(tmp, process=PROCESS)
    out = {f: tmp / f"s.{f}" for f in ("gds", "oas", "dxf")}
    rc, err, _ = cli(
        "export",
        path,
        "--csv",
        tmp / "p.csv",
        *sum(([f"--{f}", p] for f, p in out.items()), []),
        "-q",
    )
    assert rc == 0, err
    return tmp, path, load_job(path), out


@pytest.mark.parametrize("fmt", ["gds", "oas"])
def test_klayout_reads_one_panel_arrayed(sheet, fmt):
    kdb = pytest.importorskip("klayout.db")
    tmp, _, job, out = sheet
    n = len(np.loadtxt(tmp / "p.csv", delimiter=",", skiprows=1))
    ly = kdb.Layout()
    ly.read(str(out[fmt]))
    top = ly.top_cell()
    assert top.name == "SHEET"
    insts = list(top.each_inst())
    assert len(insts) == 1
    arr = insts[0].cell_inst
    assert ly.cell(arr.cell_index).name == "TOP"
    # 3 columns 2.5 mm apart and 2 rows 2.0 mm apart (1 nm database units; GDSII and
    # OASIS name the array's two axes in either order)
    steps = {(arr.a.x, arr.a.y): arr.na, (arr.b.x, arr.b.y): arr.nb}
    assert steps == {(2500000, 0): 3, (0, 2000000): 2}
    panel = ly.cell(arr.cell_index)
    dots = panel.begin_shapes_rec(ly.layer(1, 0))
    count = 0
    while not dots.at_end():
        count += 1
        dots.next()
    assert count == n  # the panel's dots once, the sheet placing the panel 6 times

    def shapes(layer):
        return list(top.shapes(ly.layer(layer, 0)).each())

    assert len(shapes(10)) == 3  # fiducials
    assert len(shapes(12)) == 4 + 3  # cut lines: 3 columns, 2 rows
    labels = shapes(11)
    assert len(labels) > 6 * 20  # text as polygons, a label per panel
    # every label lies under a panel: below the top row's (its mask starts at y = 2.0)
    ys = [s.bbox().top * ly.dbu * 1e-3 for s in labels]
    assert max(ys) < 2.0


def test_ezdxf_reads_one_insert_array(sheet):
    import ezdxf

    tmp, _, _, out = sheet
    n = len(np.loadtxt(tmp / "p.csv", delimiter=",", skiprows=1))
    doc = ezdxf.readfile(out["dxf"])
    assert not doc.audit().has_errors
    msp = doc.modelspace()
    inserts = msp.query("INSERT")
    assert len(inserts) == 1
    ins = inserts[0]
    assert ins.dxf.name == "PANEL"
    assert (ins.dxf.column_count, ins.dxf.row_count) == (3, 2)
    assert (ins.dxf.column_spacing, ins.dxf.row_spacing) == (2.5, 2.0)
    assert len(doc.blocks.get("PANEL").query("CIRCLE[layer=='DOTS']")) == n
    assert len(msp.query("CIRCLE")) == 0  # no dot outside the panel's block
    assert len(msp.query("LWPOLYLINE[layer=='FIDUCIALS']")) == 3
    assert len(msp.query("LWPOLYLINE[layer=='CUT']")) == 7
    assert len(msp.query("LWPOLYLINE[layer=='LABELS']")) > 6 * 20


@pytest.mark.parametrize("fmt", ["gds", "oas", "dxf"])
def test_qa_judges_the_one_panel(sheet, fmt):
    _, path, _, out = sheet
    rc, err, stdout = cli("qa", out[fmt], "--job", path)
    assert rc == 0, (err, stdout)


def test_labels_name_the_job_the_run_and_the_panel(sheet):
    from optdot.orchestration.pipeline import generate, qa, sheet_labels

    _, _, job, _ = sheet
    result = qa(generate(job), job)
    labels = sheet_labels(job, result.provenance)
    assert len(labels) == 6
    sha = result.provenance["job"]["sha256"][:12]
    version = result.provenance["optdot"]
    for k, text in enumerate(labels):
        r, c = divmod(k, 3)
        assert text.endswith(f"r{r + 1}c{c + 1}")
        for word in (f"optdot {version}", "seed 3", f"job {sha}", "2026-11-28",
                     "gain 5um", "shrink 0.4%", "mirror x"):  # fmt: skip
            assert word in text, (word, text)


@pytest.mark.parametrize(
    ("sheet", "words"),
    [
        ({**SHEET, "pitch": "[1.0, 2.0]"}, ("sheet.pitch", "along x is under", "overlap")),
        ({**SHEET, "rows": 0}, ("sheet.rows = 0", "1..10000")),
        ({**SHEET, "fiducials": "[[1.0]]"}, ("sheet.fiducials", "[[x, y], ...]")),
        ({**SHEET, "fiducial": '"star"'}, ("sheet.fiducial = 'star'", "cross, disc")),
        ({**SHEET, "label_height": -1}, ("sheet.label_height = -1",)),
    ],
)  # fmt: skip
def test_a_bad_sheet_gets_one_line(tmp_path, sheet, words):
    path = _job(tmp_path, sheet)
    one_error(["generate", path, "-o", tmp_path / "p.csv"], 2, str(path), *words)
