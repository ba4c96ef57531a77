"""``[density] interpolation = "linear"``: the map as samples of a smooth field."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.interpolate import RegularGridInterpolator

from optdot import generate, load_job, qa
from optdot.errors import JobError
from optdot.geometry.density import DensityMap

from .conftest import write_job


def _bilinear(m: DensityMap, xy: np.ndarray) -> np.ndarray:
    """Reference: bilinear through the cell centres, constant beyond the outermost."""
    ny, nx = m.shape
    cw, ch = m.cell_size
    xs, ys = m.x0 + (np.arange(nx) + 0.5) * cw, m.y0 + (np.arange(ny) + 0.5) * ch
    f = RegularGridInterpolator((ys, xs), m.grid, method="linear")
    q = np.column_stack([np.clip(xy[:, 1], ys[0], ys[-1]), np.clip(xy[:, 0], xs[0], xs[-1])])
    return f(q)


@pytest.mark.parametrize("factor", [2, 4, 8])
def test_sub_cells_hold_the_bilinear_field_and_its_integral(factor):
    rng = np.random.default_rng(factor)
    m = DensityMap(rng.uniform(0, 0.6, (5, 7)), 7.0, 4.0, 1.0, -2.0)
    fine = m.interpolated(factor)
    assert fine.shape == (5 * factor, 7 * factor)
    ny, nx = fine.shape
    cw, ch = fine.cell_size
    cx, cy = np.meshgrid(1.0 + (np.arange(nx) + 0.5) * cw, -2.0 + (np.arange(ny) + 0.5) * ch)
    ref = _bilinear(m, np.column_stack([cx.ravel(), cy.ravel()])).reshape(ny, nx)
    np.testing.assert_allclose(fine.grid, ref, atol=1e-12)
    # the clamped bilinear field has the nearest map's integral, and the sub-cells carry it
    assert fine.grid.sum() * cw * ch == pytest.approx(m.grid.sum() * 1.0 * 0.8, rel=1e-12)


def test_a_sub_cell_is_zero_only_where_the_field_is():
    g = np.array([[0.0, 0.0, 0.4], [0.0, 0.3, 0.4]])
    fine = DensityMap(g, 3.0, 2.0).interpolated(4).grid
    zero = fine == 0
    # zero left of the first column's centres (both samples 0) and below the bottom
    # row's centres up to the third column's (0, 0 there); positive wherever a positive
    # sample weighs
    assert zero[:, :2].all()
    assert zero[:2, :6].all()
    assert zero.sum() == 8 * 2 + 2 * 4
    assert not zero[2:, 2:].any() and not zero[:, 6:].any()


def test_factor_must_be_even():
    with pytest.raises(ValueError, match="even"):
        DensityMap(np.ones((2, 2)) * 0.1, 1, 1).interpolated(3)


def test_large_maps_refine_less():
    m = DensityMap(np.full((1500, 1500), 0.2), 10, 10)
    assert m.interpolated().shape == (3000, 3000)  # 8x would be 144M sub-cells


def test_linear_job_places_dots_in_the_ramp_and_not_beyond_the_zero_samples(tmp_path):
    g = np.array([[0.0, 0.3, 0.3]])  # one row of 1 mm cells
    nearest = load_job(write_job(tmp_path, g, domain={"width": 3.0, "height": 1.0}))
    path = write_job(
        tmp_path, g, domain={"width": 3.0, "height": 1.0}, density={"interpolation": '"linear"'}
    )
    linear = load_job(path)
    assert linear.interpolation == "linear" and nearest.interpolation == "nearest"
    assert linear.n_dots == nearest.n_dots  # the integral is kept
    a, b = generate(nearest), generate(linear)
    assert a.xy[:, 0].min() > 1.0  # nearest: the first cell is empty
    assert b.xy[:, 0].min() > 0.5  # linear: zero left of the first centre ...
    assert (b.xy[:, 0] < 1.0).sum() > 20  # ... and a ramp from it to the next centre
    # the ramp: fewer dots in (0.5, 1.0) than in (1.0, 1.5), and the count follows the
    # integral of the linear field over each half cell (1/4 and 3/4 of 0.3 on average)
    per = np.histogram(b.xy[:, 0], bins=[0.5, 1.0, 1.5])[0]
    assert per[0] / per[1] == pytest.approx((0.075 / 2) / (0.225 / 2 + 0.0), rel=0.25)
    m = qa(b, linear).metrics
    assert m["in_empty_cells"] == 0 and m["pairs_below_collision"] == 0


def test_unknown_interpolation_is_refused(tmp_path):
    path = write_job(tmp_path, np.full((2, 2), 0.2), density={"interpolation": '"cubic"'})
    with pytest.raises(JobError, match="density.interpolation = 'cubic' must be one of"):
        load_job(path)
