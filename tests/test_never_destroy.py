"""Outputs never destroy what is not ours: only a regular file or a new name is
replaced, a dataset directory is recognised by its own manifest and nothing else, and a
dataset someone added to or changed is refused on reading.

Each case here replaced a device node, a FIFO or a user's directory, or read a wrong
dataset, with exit 0 before the fix.
"""

from __future__ import annotations

import json
import os
import shutil
import stat

import numpy as np
import pytest

from optdot.io.dataset import MANIFEST
from optdot.io.dataset_write import save_dataset
from optdot.io.patterns import save_pattern

from .conftest import SAMPLES, cli, one_error


@pytest.fixture()
def tiny(tmp_path, tiny_pattern):
    for f in (SAMPLES / "tiny").iterdir():
        shutil.copy(f, tmp_path / f.name)
    save_pattern(tiny_pattern, tmp_path / "p.csv")
    return tmp_path


def test_a_fifo_in_place_of_an_output_is_refused_and_kept(tiny):
    fifo = tiny / "mask.gds"
    os.mkfifo(fifo)
    one_error(["export", tiny / "p.csv", "--gds", fifo], 2, "is a FIFO", "regular files")
    assert stat.S_ISFIFO(os.lstat(fifo).st_mode)
    one_error(["qa", tiny / "p.csv", "--json", fifo], 2, "is a FIFO")
    assert stat.S_ISFIFO(os.lstat(fifo).st_mode)


@pytest.mark.skipif(os.geteuid() != 0, reason="making a device node needs root")
def test_a_device_node_is_never_replaced(tiny):
    dev = tiny / "null"
    os.mknod(dev, 0o666 | stat.S_IFCHR, os.makedev(1, 3))  # a /dev/null of our own
    one_error(["export", tiny / "p.csv", "--gds", dev], 2, "character device")
    one_error(["qa", tiny / "p.csv", "--json", dev, "--html", tiny / "r.html"], 2, "device")
    assert stat.S_ISCHR(os.lstat(dev).st_mode)
    assert not (tiny / "r.html").exists()  # the set is refused as a whole, before the run


def test_an_output_through_a_symlink_replaces_the_file_and_keeps_the_link(tiny):
    real = tiny / "real.csv"
    real.write_text("old\n")
    link = tiny / "latest.csv"
    link.symlink_to(real.name)
    rc, err, _ = cli("export", tiny / "p.csv", "--csv", link, "--no-job")
    assert rc == 0, err
    assert link.is_symlink() and os.readlink(link) == real.name
    assert real.read_text().startswith("x_mm,y_mm")


def test_a_users_directory_with_a_stray_manifest_is_never_replaced(tiny):
    victim = tiny / "mine.parquet"
    victim.mkdir()
    (victim / MANIFEST).write_text("{}")
    (victim / "notes.txt").write_text("keep me")
    one_error(
        ["generate", tiny / "job.toml", "-o", victim, "-q"], 2, "not an optdot dataset", "never"
    )
    assert (victim / "notes.txt").read_text() == "keep me"
    assert (victim / MANIFEST).read_text() == "{}"


def test_a_dataset_holding_files_it_does_not_list_is_not_ours_to_replace(tiny, tiny_pattern):
    ds = tiny / "d.parquet"
    save_dataset(tiny_pattern, ds)
    rc, err, _ = cli("generate", tiny / "job.toml", "-o", ds, "-q")  # ours: replaced
    assert rc == 0, err
    (ds / ".notes").write_text("the user's")
    one_error(["generate", tiny / "job.toml", "-o", ds, "-q"], 2, ".notes", "not a part")
    assert (ds / ".notes").read_text() == "the user's"


def test_a_stray_part_in_a_dataset_is_refused(tiny, tiny_pattern):
    ds = tiny / "d.parquet"
    save_dataset(tiny_pattern, ds)
    assert cli("qa", ds, "--no-job")[0] == 0
    shutil.copy(ds / "part-00000.parquet", ds / "part-00001.parquet")  # pandas reads both
    one_error(["qa", ds], 2, "part-00001.parquet", "not a part the manifest lists")


def test_parts_whose_diameters_contradict_the_manifest_are_refused(tiny, tiny_pattern):
    import pyarrow as pa
    import pyarrow.parquet as pq

    ds = tiny / "d.parquet"
    save_dataset(tiny_pattern, ds)
    part = ds / "part-00000.parquet"
    t = pq.read_table(part)
    d = t.column("diameter_mm").to_numpy().copy()
    d[5] = 0.06
    pq.write_table(t.set_column(2, "diameter_mm", pa.array(d)), part)
    doc = json.loads((ds / MANIFEST).read_text())
    import hashlib

    doc["parts"][0]["sha256"] = hashlib.sha256(part.read_bytes()).hexdigest()
    (ds / MANIFEST).write_text(json.dumps(doc))
    one_error(["export", ds, "--gds", tiny / "m.gds", "--force"], 2, "manifest says every dot")
    assert not (tiny / "m.gds").exists()


@pytest.mark.parametrize(
    "field, value",
    [
        ("n", "many"),
        ("tiles", 5),
        ("box", [0, 0, "3", 2]),
        ("diameter_mm", None),
        ("meta", []),
        ("parts", [{"file": "../x.parquet", "count": 1, "tile": [0, 0], "sha256": "0" * 64}]),
        ("parts", [{"file": "part-00000.parquet", "count": "1", "tile": [0, 0]}]),
    ],
)
def test_a_manifest_field_of_the_wrong_type_is_one_line(tiny, tiny_pattern, field, value):
    ds = tiny / "d.parquet"
    save_dataset(tiny_pattern, ds)
    doc = json.loads((ds / MANIFEST).read_text())
    doc[field] = value
    (ds / MANIFEST).write_text(json.dumps(doc))
    one_error(["qa", ds], 2, "malformed manifest")
    one_error(["export", ds, "--gds", tiny / "m.gds"], 2, "malformed manifest")


def test_a_single_parquet_file_is_told_apart_from_a_missing_dataset(tiny):
    (tiny / "one.parquet").write_bytes(b"PAR1")
    one_error(["qa", tiny / "one.parquet"], 2, "single file")


def test_a_keep_out_file_with_parentheses_is_an_input_never_overwritten(tiny):
    keep = tiny / "frame (1).wkt"
    keep.write_text("POLYGON ((1 0.5, 2 0.5, 2 1.5, 1 1.5, 1 0.5))")
    (tiny / "outline.wkt").write_text("POLYGON ((0 0, 3 0, 3 2, 0 2, 0 0))")
    text = (
        (tiny / "job.toml")
        .read_text()
        .replace("[domain]", '[domain]\noutline = "outline.wkt"\nkeep_out = ["frame (1).wkt"]')
    )
    text = text.replace("width = 3.0\n", "").replace("height = 2.0\n", "")
    (tiny / "j.toml").write_text(text)
    before = keep.read_bytes()
    one_error(["export", tiny / "j.toml", "--dxf", keep, "-q"], 2, "is an input")
    assert keep.read_bytes() == before
    rc, err, _ = cli("generate", tiny / "j.toml", "-o", tiny / "k.csv", "-q")
    assert rc == 0, err
    xy = np.loadtxt(tiny / "k.csv", delimiter=",", skiprows=1)[:, :2]
    inside = (xy[:, 0] > 1) & (xy[:, 0] < 2) & (xy[:, 1] > 0.5) & (xy[:, 1] < 1.5)
    assert len(xy) > 100 and not inside.any()  # the file was read as the keep-out


@pytest.mark.parametrize(
    "args",
    [
        ("export", "{p}", "--csv", "{loop}.csv"),
        ("export", "{p}", "--gds", "{loop}.gds"),
        ("qa", "{p}", "--json", "{loop}.json"),
        ("generate", "{job}", "-o", "{loop}.csv"),
        ("generate", "{job}", "-o", "{loop}.parquet"),
    ],
    ids=["export-csv", "export-gds", "qa-json", "generate-csv", "generate-parquet"],
)
def test_an_output_that_is_a_symlink_loop_gets_one_line(tiny, args):
    """``ln -s loop.csv loop.csv``: exit 2 and one line naming it (was exit 70, an
    internal error from resolving the path); the link is left as it was."""
    loop = tiny / "loop"
    ext = args[-1].rsplit(".", 1)[1]
    link = tiny / f"loop.{ext}"
    link.symlink_to(link.name)
    filled = [a.format(p=tiny / "p.csv", job=tiny / "job.toml", loop=loop) for a in args]
    one_error(filled, 2, "symbolic link loop")
    assert link.is_symlink() and os.readlink(link) == link.name
