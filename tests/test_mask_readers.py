"""What a drawing says is what optdot reads: DXF units, block references with
their transforms, circles seen from below, GDS/OASIS reference magnification, rotation and
mirroring, overflowed GDSII arrays, and coordinates a GDSII integer cannot hold.

Every case here passed a wrong pattern or wrote a wrong mask with exit 0 before the fix;
positions are checked against KLayout, which no one here wrote.
"""

from __future__ import annotations

import json
import math
import shutil

import ezdxf
import gdstk
import numpy as np
import pytest

from optdot.config.schema import load_job
from optdot.errors import ExportError, PatternFileError
from optdot.exporters.readback import read_any
from optdot.io.patterns import save_pattern

from .conftest import SAMPLES, cli, one_error


def _job(tmp_path, outline: str) -> str:
    shutil.copy(SAMPLES / "tiny" / "density.csv", tmp_path / "density.csv")
    (tmp_path / "j.toml").write_text(
        f'[domain]\noutline = "{outline}"\n[density]\ngrid = "density.csv"\n'
        "[dots]\ndiameter = 0.046\n[optimize]\nmax_iter = 40\nseed = 1\n"
    )
    return str(tmp_path / "j.toml")


def test_a_dxf_outline_in_inches_is_converted_and_its_block_holes_are_holes(tmp_path):
    doc = ezdxf.new("R2010", units=1)  # inches
    msp = doc.modelspace()
    msp.add_lwpolyline([(0, 0), (0.16, 0), (0.16, 0.1), (0, 0.1)], close=True)
    hole = doc.blocks.new("HOLE")
    hole.add_lwpolyline([(-1, -1), (1, -1), (1, 1), (-1, 1)], close=True)
    # a 2 x 1 hundredths-of-an-inch slot, rotated 90 degrees, drawn once and placed twice
    msp.add_blockref(
        "HOLE", (0.05, 0.05), dxfattribs={"xscale": 0.01, "yscale": 0.005, "rotation": 90}
    )
    msp.add_blockref(
        "HOLE", (0.11, 0.05), dxfattribs={"xscale": 0.01, "yscale": 0.005, "rotation": 90}
    )
    doc.saveas(tmp_path / "inch.dxf")
    job = load_job(_job(tmp_path, "inch.dxf"))
    x0, y0, x1, y1 = job.domain.geometry.bounds
    assert (x1 - x0, y1 - y0) == pytest.approx((0.16 * 25.4, 0.1 * 25.4), abs=1e-9)
    holes = job.domain.geometry.interiors
    assert len(holes) == 2
    hx = sorted(np.asarray(h.coords)[:, 0].min() for h in holes)
    # rotated 90 degrees: the 0.005 in half-height now runs along x
    assert hx == pytest.approx([(0.05 - 0.005) * 25.4, (0.11 - 0.005) * 25.4], abs=2e-3)


def test_a_minsert_grid_of_holes_and_a_self_referencing_block(tmp_path):
    doc = ezdxf.new("R2010", units=4)
    msp = doc.modelspace()
    msp.add_lwpolyline([(0, 0), (3, 0), (3, 2), (0, 2)], close=True)
    hole = doc.blocks.new("H")
    hole.add_circle((0, 0), 0.1)
    ref = msp.add_blockref("H", (0.5, 0.5))
    ref.grid(size=(2, 3), spacing=(1.0, 1.0))  # 2 rows, 3 columns
    doc.saveas(tmp_path / "grid.dxf")
    assert len(load_job(_job(tmp_path, "grid.dxf")).domain.geometry.interiors) == 6

    loop = doc.blocks.new("LOOP")
    loop.add_blockref("LOOP", (0.1, 0))
    msp.add_blockref("LOOP", (1, 1))
    doc.saveas(tmp_path / "loop.dxf")
    one_error(["generate", _job(tmp_path, "loop.dxf"), "-o", tmp_path / "o.csv"], 2, "nested")


def test_an_outline_in_a_unit_without_a_length_is_refused(tmp_path):
    doc = ezdxf.new("R2010", units=18)  # astronomical units
    doc.modelspace().add_lwpolyline([(0, 0), (3, 0), (3, 2), (0, 2)], close=True)
    doc.saveas(tmp_path / "au.dxf")
    one_error(["generate", _job(tmp_path, "au.dxf"), "-o", tmp_path / "o.csv"], 2, "$INSUNITS")


def test_dot_dxfs_in_inches_in_blocks_and_seen_from_below(tmp_path):
    doc = ezdxf.new("R2010", units=1)
    doc.layers.add("DOTS")
    msp = doc.modelspace()
    msp.add_circle((0.1, 0.1), 0.001, dxfattribs={"layer": "DOTS"})
    # extrusion -Z: object x runs the other way, so OCS (-0.2, 0.1) is WCS (0.2, 0.1)
    msp.add_circle((-0.2, 0.1), 0.001, dxfattribs={"layer": "DOTS", "extrusion": (0, 0, -1)})
    blk = doc.blocks.new("D")
    blk.add_circle((0, 0), 0.001, dxfattribs={"layer": "0"})  # takes the INSERT's layer
    msp.add_blockref("D", (0.3, 0.1), dxfattribs={"layer": "DOTS", "xscale": 2, "yscale": 2})
    doc.saveas(tmp_path / "dots.dxf")
    p = read_any(tmp_path / "dots.dxf")
    order = np.argsort(p.xy[:, 0])
    np.testing.assert_allclose(p.xy[order], np.array([[0.1, 0.1], [0.2, 0.1], [0.3, 0.1]]) * 25.4)
    np.testing.assert_allclose(p.diameter[order], np.array([2, 2, 4]) * 0.001 * 25.4)

    blk2 = doc.blocks.new("E")
    blk2.add_circle((0, 0), 0.001, dxfattribs={"layer": "0"})
    msp.add_blockref("E", (0.4, 0.1), dxfattribs={"layer": "DOTS", "xscale": 2, "yscale": 1})
    doc.saveas(tmp_path / "stretched.dxf")
    with pytest.raises(PatternFileError, match="holds circle and ellipse dots"):
        read_any(tmp_path / "stretched.dxf")


def _klayout_dots(path) -> tuple[np.ndarray, np.ndarray]:
    """(centres mm, diameters mm) of the shapes on layer 1/0, as KLayout flattens them."""
    import klayout.db as kdb

    ly = kdb.Layout()
    ly.read(str(path))
    it = ly.top_cell().begin_shapes_rec(ly.layer(1, 0))
    c, d = [], []
    while not it.at_end():
        poly = it.shape().dpolygon.transformed(it.dtrans())
        pts = np.array([(q.x, q.y) for q in poly.each_point_hull()])
        centre = pts.mean(axis=0)
        c.append(centre)
        d.append(2 * np.hypot(*(pts - centre).T).mean())
        it.next()
    return np.array(c) * 1e-3, np.array(d) * 1e-3  # µm -> mm


@pytest.mark.parametrize("fmt", ["gds", "oas"])
def test_reference_transforms_are_applied_as_klayout_applies_them(tmp_path, fmt):
    lib = gdstk.Library(unit=1e-6, precision=1e-9)
    dot = gdstk.Cell("DOT")
    dot.add(gdstk.ellipse((0, 0), 23, tolerance=0.01, layer=1))
    tile = gdstk.Cell("T0_0")
    tile.add(gdstk.Reference(dot, (100, 0)))
    tile.add(gdstk.Reference(dot, (160, 50), magnification=3))  # 138 µm: overlaps (100, 0)
    tile.add(gdstk.Reference(dot, (400, 0), columns=3, rows=2, spacing=(60, 70)))
    top = gdstk.Cell("TOP")
    top.add(gdstk.Reference(tile, (1000, 1000), rotation=math.pi / 2))
    top.add(gdstk.Reference(tile, (3000, 1000), x_reflection=True, magnification=2))
    top.add(gdstk.Reference(tile, (5000, 3000), rotation=0.3, x_reflection=True))
    lib.add(dot, tile, top)
    path = tmp_path / f"t.{fmt}"
    (lib.write_gds if fmt == "gds" else lib.write_oas)(str(path))
    p = read_any(path)
    ref_c, ref_d = _klayout_dots(path)
    assert p.n == len(ref_c) == 24
    a = np.lexsort(np.round(p.xy, 4).T[::-1])
    b = np.lexsort(np.round(ref_c, 4).T[::-1])
    np.testing.assert_allclose(p.xy[a], ref_c[b], atol=2e-6)
    np.testing.assert_allclose(p.diameter[a], ref_d[b], atol=3e-6)
    assert p.diameter.max() == pytest.approx(0.276, abs=2e-6)  # 46 µm x 3 x 2
    rc, err, out = cli("qa", path, "--json", tmp_path / "q.json")
    assert rc == 1, (err, out)  # the magnified dots overlap: the gate fails, not a PASS
    metrics = json.loads((tmp_path / "q.json").read_text())["metrics"]
    assert metrics["pairs_below_collision"] == 3


def _aref_gds(path, columns: int, rows: int) -> None:
    """A GDSII file whose top cell places a 46 µm dot cell by one array reference."""
    lib = gdstk.Library(unit=1e-6, precision=1e-9)
    dot = gdstk.Cell("DOT")
    dot.add(gdstk.ellipse((0, 0), 23, tolerance=0.01, layer=1))
    top = gdstk.Cell("TOP")
    top.add(gdstk.Reference(dot, (100, 100), columns=columns, rows=rows, spacing=(60, 60)))
    lib.add(dot, top)
    lib.write_gds(str(path))


def test_an_overflowed_gdsii_array_is_refused(tmp_path):
    _aref_gds(tmp_path / "a.gds", 40000, 1)
    with pytest.raises(PatternFileError, match="32767"):
        read_any(tmp_path / "a.gds")


@pytest.mark.parametrize(
    "colrow", [(0xFFFF, 0xFFFF), (0xFFFF, 1), (0x8000, 2), (0, 2), (3, 0), (0, 0)]
)
def test_an_aref_whose_colrow_wrapped_is_refused_not_read_as_one_dot(tmp_path, colrow):
    """COLROW 0xFFFF x 0xFFFF: gdstk reads each as 2**64 - 1, whose product wraps to a
    size of 1, and the array was read as one dot (qa passed it)."""
    import struct

    _aref_gds(tmp_path / "a.gds", 3, 2)
    raw = bytearray((tmp_path / "a.gds").read_bytes())
    at = raw.find(bytes([0, 8, 0x13, 2]))  # the COLROW record: 8 bytes, type 0x1302
    raw[at + 4 : at + 8] = struct.pack(">HH", *colrow)
    (tmp_path / "a.gds").write_bytes(bytes(raw))
    with pytest.raises(PatternFileError, match="overflowed AREF|places no dot"):
        read_any(tmp_path / "a.gds")


def test_a_dot_beyond_the_gdsii_range_is_refused_whatever_box_it_claims(tmp_path):
    shutil.copytree(SAMPLES / "tiny", tmp_path / "tiny")
    (tmp_path / "far.csv").write_text("x_mm,y_mm,diameter_mm\n1,1,0.046\n3000,1,0.046\n")
    # without a job the dots' own box is the panel: the writer's range check refuses
    one_error(
        ["export", tmp_path / "far.csv", "--gds", tmp_path / "far.gds", "--force", "--no-job"],
        2,
        "32-bit",
    )
    assert not (tmp_path / "far.gds").exists()
    # with a job, a dot 3 m outside its panel is refused before anything is written
    one_error(
        ["export", tmp_path / "far.csv", "--job", tmp_path / "tiny" / "job.toml",
         "--gds", tmp_path / "far.gds", "--force"],
        2, "outside this job's panel",
    )  # fmt: skip
    assert not (tmp_path / "far.gds").exists()


def test_a_top_cell_named_like_a_tile_or_dot_cell_is_refused(tmp_path, tiny_pattern):
    from optdot.exporters.gds import write_gds
    from optdot.exporters.options import ExportOptions
    from optdot.io.dataset import open_dataset
    from optdot.io.dataset_write import write_dataset
    from optdot.io.manifest import pattern_manifest

    half = tiny_pattern.xy[:, 0] < np.median(tiny_pattern.xy[:, 0])
    with write_dataset(tmp_path / "d.parquet", pattern_manifest(tiny_pattern)) as w:
        for k, sel in enumerate((half, ~half)):  # two tiles: one cell each
            w.write_part(k, (k, 0), tiny_pattern.xy[sel], tiny_pattern.shape.take(sel))
    ds = open_dataset(tmp_path / "d.parquet")
    with pytest.raises(ExportError, match="'T0_0' is used by the top cell and tile"):
        write_gds(ds, tmp_path / "m.gds", ExportOptions(top_cell="T0_0"))
    assert not (tmp_path / "m.gds").exists()
    sized = tiny_pattern.__class__(
        xy=tiny_pattern.xy,
        diameter=np.where(np.arange(tiny_pattern.n) % 2, 0.046, 0.03),
        box=tiny_pattern.box,
    )
    with pytest.raises(ExportError, match="DOT_30000"):
        write_gds(sized, tmp_path / "m.gds", ExportOptions(top_cell="DOT_30000"))
    save_pattern(tiny_pattern, tmp_path / "p.csv")
    one_error(
        [
            "export",
            tmp_path / "d.parquet",
            "--gds",
            tmp_path / "m.gds",
            "--top-cell",
            "T0_0",
            "--no-job",
        ],  # fmt: skip
        2,
        "cell name",
    )
