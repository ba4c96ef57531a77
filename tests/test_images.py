"""Density maps from images (optdot.config.images) and the fast cell shares of an outline."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest
import shapely
from PIL import Image

from optdot.config.schema import load_job
from optdot.errors import JobError
from optdot.geometry.domain import polygon_cell_fractions
from optdot.orchestration.pipeline import generate, qa

from .conftest import SAMPLES


def _image_jobs(tmp_path: Path, sample: str) -> tuple[Path, Path, np.ndarray]:
    """The sample's map as a 16-bit PNG (fill_range [0, max]) and a float32 TIFF, both
    top-down; their jobs and the CSV grid (row 0 = bottom)."""
    grid = load_job(SAMPLES / sample / "job.toml").density.grid
    hi = float(grid.max())
    Image.fromarray(np.round(grid[::-1] / hi * 65535).astype(np.uint16)).save(tmp_path / "m.png")
    Image.fromarray(grid[::-1].astype(np.float32)).save(tmp_path / "m.tif")
    text = (SAMPLES / sample / "job.toml").read_text()
    png, tif = tmp_path / "png.toml", tmp_path / "tif.toml"
    png.write_text(
        text.replace('grid = "density.csv"', f'image = "m.png"\nfill_range = [0, {hi!r}]')
    )
    tif.write_text(text.replace('grid = "density.csv"', 'image = "m.tif"'))
    return png, tif, grid


@pytest.mark.parametrize("sample", ["led", "tsuno"])
def test_a_png_or_tiff_map_gives_the_csv_maps_dot_count(tmp_path, sample):
    png, tif, grid = _image_jobs(tmp_path, sample)
    want = load_job(SAMPLES / sample / "job.toml").n_dots
    for job, tol in ((load_job(png), 0.5 / 65535 * grid.max()), (load_job(tif), 1e-7)):
        assert job.n_dots == want
        np.testing.assert_allclose(job.density.grid, grid, rtol=0, atol=tol)


def test_a_pattern_from_the_png_meets_the_csv_maps_coverage(tmp_path):
    png, _, _ = _image_jobs(tmp_path, "tiny")
    csv_job = load_job(SAMPLES / "tiny" / "job.toml")
    p = generate(load_job(png))
    own = qa(p, load_job(png)).metrics["coverage_rel_rms_smoothed"]
    against_csv = qa(p, csv_job).metrics["coverage_rel_rms_smoothed"]
    assert abs(own - against_csv) < 0.005
    assert qa(p, csv_job).passed


def test_images_are_top_down(tmp_path):
    """Row 0 of the file is the panel's top edge: a map bright only in its top rows
    puts every dot in the top half of the panel."""
    img = np.zeros((20, 30), np.uint8)
    img[:10] = 255  # top half of the image
    Image.fromarray(img).save(tmp_path / "top.png")
    (tmp_path / "job.toml").write_text(
        '[domain]\nwidth = 3.0\nheight = 2.0\n[density]\nimage = "top.png"\n'
        "fill_range = [0.0, 0.3]\n[dots]\ndiameter = 0.046\n[optimize]\nmax_iter = 20\n"
    )
    job = load_job(tmp_path / "job.toml")
    assert job.density.grid[-1].min() == pytest.approx(0.3) and job.density.grid[0].max() == 0
    p = generate(job)
    assert p.n > 100 and p.xy[:, 1].min() > 1.0 - 0.046


def test_value_range_and_inverted_fill_range(tmp_path):
    img = np.array([[100, 200], [150, 100]], np.uint16)
    Image.fromarray(img).save(tmp_path / "m.tif")
    (tmp_path / "job.toml").write_text(
        '[domain]\nwidth = 2.0\nheight = 2.0\n[density]\nimage = "m.tif"\n'
        "fill_range = [0.4, 0.0]\nvalue_range = [100, 200]\n[dots]\ndiameter = 0.046\n"
    )
    grid = load_job(tmp_path / "job.toml").density.grid
    np.testing.assert_allclose(grid, [[0.2, 0.4], [0.4, 0.0]])  # flipped: row 0 = bottom


@pytest.mark.parametrize(
    "density,image,message",
    [
        ('image = "m.png"', "rgb", "not a grayscale map"),
        ('image = "m.png"', "gray8", "give density.fill_range"),
        ('image = "m.png"\nfill_range = [0, 0.3]\nvalue_range = [0, 100]', "gray8", "outside"),
        ('image = "m.png"\ngrid = "m.csv"', "gray8", "one of density.grid or density.image"),
        ('grid = "m.csv"\nfill_range = [0, 0.3]', "gray8", "apply to density.image only"),
        ('image = "m.png"\nfill_range = [0, 1.5]', "gray8", "within [0, 1]"),
        ('image = "m.png"\nfill_range = [0.2, 0.2]', "gray8", "two different numbers"),
        ('image = "m.png"\nfill_range = [0, 0.3]', "truncated", "not a readable PNG/TIFF"),
        ('image = "m.csv"\nfill_range = [0, 0.3]', "gray8", "must be .png"),
        ('image = "none.png"\nfill_range = [0, 0.3]', "gray8", "not found"),
    ],
)
def test_bad_image_maps_are_one_clear_line(tmp_path, density, image, message):
    rng = np.random.default_rng(0)
    gray = rng.integers(0, 255, (8, 8), dtype=np.uint8)
    if image == "rgb":
        Image.fromarray(np.dstack([gray] * 3)).save(tmp_path / "m.png")
    else:
        Image.fromarray(gray).save(tmp_path / "m.png")
    if image == "truncated":
        data = (tmp_path / "m.png").read_bytes()
        (tmp_path / "m.png").write_bytes(data[: len(data) // 2])
    (tmp_path / "m.csv").write_text("0.1,0.2\n0.2,0.1\n")
    (tmp_path / "job.toml").write_text(
        f"[domain]\nwidth = 2.0\nheight = 2.0\n[density]\n{density}\n[dots]\ndiameter = 0.046\n"
    )
    with pytest.raises(JobError, match=re.escape(message)) as e:
        load_job(tmp_path / "job.toml")
    assert "\n" not in str(e.value)


def _shares_per_cell(geom, x0, y0, cw, ch, nx, ny) -> np.ndarray:
    """The reference: one shapely box per cell."""
    iy, ix = np.mgrid[0:ny, 0:nx]
    cells = shapely.box(x0 + ix * cw, y0 + iy * ch, x0 + (ix + 1) * cw, y0 + (iy + 1) * ch)
    inside = shapely.contains(geom, cells)
    frac = inside.astype(np.float64)
    edge = ~inside & shapely.intersects(geom, cells)
    frac[edge] = shapely.area(shapely.intersection(cells[edge], geom)) / (cw * ch)
    return frac


@pytest.mark.parametrize("seed", range(8))
def test_cell_shares_of_an_outline_equal_one_box_per_cell(seed):
    """Scanlines for whole cells, exact intersections only along the boundary: the same
    numbers as intersecting every cell (holes, several parts, coarse and fine grids)."""
    rng = np.random.default_rng(seed)
    c = rng.uniform(5, 15, 2)
    ang = np.sort(rng.uniform(0, 2 * np.pi, 12))
    rad = rng.uniform(3, 8, 12)
    outer = shapely.Polygon(np.c_[c[0] + rad * np.cos(ang), c[1] + rad * np.sin(ang)])
    hole = shapely.Point(c).buffer(1.0 + rng.uniform(0, 1))
    geom = outer.difference(hole) if outer.contains(hole) else outer
    geom = geom.union(shapely.box(18, 18, 19.5, 19.7))
    nx, ny = (int(v) for v in rng.integers(5, 90, 2))
    cw, ch = 20 / nx, 20.5 / ny
    got = polygon_cell_fractions(geom, 0.0, 0.0, cw, ch, nx, ny)
    assert np.array_equal(got, _shares_per_cell(geom, 0.0, 0.0, cw, ch, nx, ny))
