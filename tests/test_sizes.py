"""Per-dot diameters through every file format, the exporters, the readers and QA."""

from __future__ import annotations

import numpy as np
import pytest

from optdot import Pattern, exporters, qa
from optdot.exporters.readback import read_any
from optdot.io.patterns import load_pattern, save_pattern


@pytest.fixture(scope="module")
def mixed():
    """Dots of three sizes on a loose grid (no pair closer than its diameters)."""
    rng = np.random.default_rng(7)
    g = np.stack(np.meshgrid(np.arange(20), np.arange(15)), -1).reshape(-1, 2) * 0.2 + 0.15
    xy = np.round(g + rng.uniform(-0.02, 0.02, g.shape), 6)
    d = rng.choice([0.030, 0.046, 0.120], len(xy))
    return Pattern(xy, d, (0.0, 0.0, 4.2, 3.2))


def _by_position(p: Pattern) -> tuple[np.ndarray, np.ndarray]:
    o = np.lexsort(p.xy.T[::-1])
    return p.xy[o], p.diameter[o]


@pytest.mark.parametrize("fmt", ["gds", "oas", "dxf", "csv", "npz"])
def test_round_trip_keeps_every_diameter(mixed, fmt, tmp_path):
    path = tmp_path / f"m.{fmt}"
    if fmt == "npz":
        save_pattern(mixed, path)
    else:
        exporters.write(mixed, fmt, path)
    back = read_any(path)
    xy0, d0 = _by_position(mixed)
    xy1, d1 = _by_position(back)
    np.testing.assert_allclose(xy1, xy0, atol=1e-9)
    np.testing.assert_allclose(d1, d0, atol=1e-6)  # the 1 nm database unit
    q0, q1 = qa(mixed), qa(back)
    for key in ("pairs_below_collision", "pairs_below_close", "protruding", "nn_min_mm"):
        assert q1.metrics[key] == pytest.approx(q0.metrics[key]), key


def test_klayout_reads_one_cell_per_diameter(mixed, tmp_path):
    kdb = pytest.importorskip("klayout.db")
    path = tmp_path / "m.gds"
    exporters.write(mixed, "gds", path)
    layout = kdb.Layout()
    layout.read(str(path))
    names = sorted(c.name for c in layout.each_cell() if c.name.startswith("DOT"))
    assert names == ["DOT_120000", "DOT_30000", "DOT_46000"]
    found = []
    top = layout.top_cell()
    for inst in top.each_inst():
        cell = layout.cell(inst.cell_index)
        box = cell.bbox()
        d_um = box.width() * layout.dbu
        for t in inst.cell_inst.each_trans():
            found.append((round(t.disp.x * layout.dbu / 1000, 6), d_um / 1000))
    assert len(found) == mixed.n
    # each dot's cell is as wide as its diameter (polygon within 0.01 µm of the circle)
    sizes = sorted({round(d, 3) for _, d in found})
    assert sizes == [0.03, 0.046, 0.12]


def test_ezdxf_reads_each_radius(mixed, tmp_path):
    import ezdxf

    path = tmp_path / "m.dxf"
    exporters.write(mixed, "dxf", path)
    doc = ezdxf.readfile(path)
    assert len(doc.audit().errors) == 0
    radii = np.sort([c.dxf.radius for c in doc.modelspace().query("CIRCLE")])
    np.testing.assert_allclose(radii, np.sort(mixed.radius), atol=1e-9)


def test_uniform_npz_keeps_a_scalar_diameter(tiny_pattern, tmp_path):
    save_pattern(tiny_pattern, tmp_path / "u.npz")
    with np.load(tmp_path / "u.npz") as z:
        assert z["diameter"].shape == ()
    assert load_pattern(tmp_path / "u.npz").uniform_diameter == tiny_pattern.uniform_diameter


def test_coverage_counts_each_dots_own_area(mixed):
    from optdot.pattern import coverage_image

    img, (x0, x1, y0, y1) = coverage_image(mixed, 50)
    total = img.sum() * (x1 - x0) / img.shape[1] * (y1 - y0) / img.shape[0]
    assert total == pytest.approx(mixed.areas.sum())
