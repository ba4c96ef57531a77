"""The tiles' panel-wide field: every tile's throw deposited on one coarse
lattice, one Neumann solve, each throw moved along it before it relaxes
(:mod:`optdot.stages.throw`)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from optdot import stages
from optdot.config.schema import load_job
from optdot.geometry.density import DensityMap
from optdot.orchestration.job_settings import job_spacing, stage_settings
from optdot.orchestration.tiling import tasks
from optdot.orchestration.tiling.plan import plan_tiles
from optdot.orchestration.tiling.run import tiny_job
from optdot.relax.lowpass import (
    CoarseField,
    Lattice,
    _deposit,
    coarse_field,
    coverage_error,
    deposit_part,
    gradient_at,
    live_potential,
)

from .conftest import SAMPLES


def _bincount_deposit(xy, weight, x0, y0, h, shape):
    """The cloud-in-cell deposit as numpy writes it: four ``np.bincount`` (one a corner of
    the clouds) added in turn; what :func:`_deposit` must equal bit for bit."""
    ny, nx = shape
    gx = (xy[:, 0] - x0) / h[0] - 0.5
    gy = (xy[:, 1] - y0) / h[1] - 0.5
    ix = np.floor(gx).astype(np.int64)
    iy = np.floor(gy).astype(np.int64)
    fx, fy = gx - ix, gy - iy
    inside = (gx >= -0.5) & (gx < nx - 0.5) & (gy >= -0.5) & (gy < ny - 0.5)
    out = np.zeros(ny * nx)
    for dx, wx in ((0, 1.0 - fx), (1, fx)):
        for dy, wy in ((0, 1.0 - fy), (1, fy)):
            cx, cy = ix + dx, iy + dy
            keep = inside | ((cx >= 0) & (cx < nx) & (cy >= 0) & (cy < ny))
            cx = np.clip(cx[keep], 0, nx - 1)
            cy = np.clip(cy[keep], 0, ny - 1)
            w = (weight * wx * wy)[keep]
            out += np.bincount(cy * nx + cx, w, minlength=ny * nx)
    return out.reshape(ny, nx)


def grid_cases(points: int, fewest_cells: int, spill: float):
    """Hypothesis cases of points on a small grid: ``n`` points (up to ``points``), an
    ``nx`` by ``ny`` grid (``fewest_cells`` to 9 a side), points reaching ``spill``
    cells past it, a ``seed``."""
    return given(
        n=st.integers(0, points),
        nx=st.integers(fewest_cells, 9),
        ny=st.integers(fewest_cells, 9),
        spill=st.floats(0.0, spill),
        seed=st.integers(0, 2**31),
    )


@settings(max_examples=40, deadline=None)
@grid_cases(200, 2, 3.0)
def test_the_gradient_sampled_at_points_is_numpys_gradient_interpolated(n, nx, ny, spill, seed):
    """:func:`gradient_at` gives ``np.gradient`` interpolated by ``map_coordinates``
    (linear, indices clamped), at points inside the grid, between its border cells'
    centres and past them (a window's dots near or beyond its edge), to rounding; a
    single-precision potential differenced in double."""
    from scipy.ndimage import map_coordinates

    rng = np.random.default_rng(seed)
    phi = rng.normal(size=(ny, nx))
    if seed % 2:  # a window's potential, solved in single precision
        phi = phi.astype(np.float32)
    hx, hy = 0.3, 0.2
    row = rng.uniform(-spill, ny - 1 + spill, n)
    col = rng.uniform(-spill, nx - 1 + spill, n)
    row[: n // 5] = np.round(row[: n // 5])  # some on cell centres
    uy, ux = np.gradient(phi.astype(np.float64), hy, hx)
    want = np.column_stack([
        map_coordinates(ux, [row, col], order=1, mode="nearest"),
        map_coordinates(uy, [row, col], order=1, mode="nearest"),
    ])  # fmt: skip
    got = gradient_at(phi, hx, hy, row, col)
    assert got.shape == (n, 2)
    np.testing.assert_allclose(got, want, rtol=1e-12, atol=1e-12)


@settings(max_examples=40, deadline=None)
@grid_cases(300, 1, 2.0)
def test_the_compiled_deposit_sums_as_numpy_does(n, nx, ny, spill, seed):
    """The compiled cloud-in-cell deposit gives numpy's sums bit for bit (the same order
    of additions), for dots inside the grid, on its border cells' outer halves and past
    it (a neighbour tile's dots, which give only what falls in), so the correction's
    fields keep their bytes."""
    rng = np.random.default_rng(seed)
    hx, hy = 0.3, 0.2
    x0, y0 = -1.0, 2.0
    lo = np.array([x0, y0]) - spill * np.array([hx, hy])
    hi = np.array([x0 + nx * hx, y0 + ny * hy]) + spill * np.array([hx, hy])
    xy = lo + rng.random((n, 2)) * (hi - lo)
    xy[: n // 10] = np.round(xy[: n // 10] / 0.1) * 0.1  # some on cell faces and centres
    w = rng.random(n)
    got = _deposit(xy, w, x0, y0, (hx, hy), (ny, nx))
    want = _bincount_deposit(xy, w, x0, y0, (hx, hy), (ny, nx))
    assert got.shape == (ny, nx)
    np.testing.assert_array_equal(got, want)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_parts_deposited_tile_by_tile_add_up_to_one_deposit(seed):
    rng = np.random.default_rng(seed)
    box = (1.0, 2.0, 13.0, 9.0)
    lattice = Lattice.over(box, 0.37, 1 << 20)
    xy = rng.uniform(box[:2], box[2:], (4000, 2))
    xy[:200, 0] = box[0] + rng.uniform(0, 0.1, 200)  # dots right by the walls
    xy[200:400, 1] = box[3] - rng.uniform(0, 0.1, 200)
    w = rng.uniform(0.5, 2.0, len(xy))
    whole = _deposit(xy, w, box[0], box[1], (lattice.hx, lattice.hy), (lattice.ny, lattice.nx))
    summed = np.zeros_like(whole)
    cut_x, cut_y = [box[0], 4.3, 9.1, box[2] + 1], [box[1], 5.55, box[3] + 1]
    for a, b in zip(cut_x[:-1], cut_x[1:], strict=True):
        for c, d in zip(cut_y[:-1], cut_y[1:], strict=True):
            mine = (xy[:, 0] >= a) & (xy[:, 0] < b) & (xy[:, 1] >= c) & (xy[:, 1] < d)
            part = deposit_part(xy[mine], w[mine], lattice)
            rows, cols = part.w.shape
            assert rows < lattice.ny or cols < lattice.nx  # a part, not the whole lattice
            summed[part.j0 : part.j0 + rows, part.i0 : part.i0 + cols] += part.w
    np.testing.assert_allclose(summed, whole, rtol=0, atol=1e-12)


def test_a_dot_past_a_wall_keeps_its_weight_in_the_panels_lattice():
    """A dot a few micrometres past the box (the relaxation's soft walls let one out
    until the guarantee pass brings it back) is deposited whole at the box's edge."""
    box = (0.0, 0.0, 6.0, 4.0)
    lattice = Lattice.over(box, 0.25, 1 << 16)
    xy = np.array([[3.0, -0.005], [-0.004, 2.0], [6.003, 4.002], [6.0, 4.0], [2.0, 2.0]])
    w = np.array([1.0, 2.0, 3.0, 4.0, 5.0])
    part = deposit_part(xy, w, lattice)
    assert part.w.sum() == pytest.approx(w.sum(), rel=1e-12)
    one = deposit_part(xy[:1], w[:1], lattice)  # all of it on the bottom row
    assert one.j0 == 0 and one.w[0].sum() == pytest.approx(1.0, rel=1e-12)


def _planted(job, amplitude: float):
    """The led job's dots on a jittered square lattice whose density varies by
    ``amplitude`` along x at a 10 mm wavelength, and the field :func:`coarse_field` finds."""
    rng = np.random.default_rng(3)
    x0, y0, x1, y1 = job.box
    a = 0.1
    g = np.mgrid[x0 + a / 2 : x1 : a, y0 + a / 2 : y1 : a].reshape(2, -1).T
    g += rng.normal(0, 0.01, g.shape)
    k = 2 * np.pi / 10.0
    g[:, 0] -= amplitude / k * np.sin(k * (g[:, 0] - x0))  # density ~ 1 + amplitude cos
    xy = g[(g[:, 0] > x0) & (g[:, 0] < x1) & (g[:, 1] > y0) & (g[:, 1] < y1)]
    area = np.full(len(xy), job.density.grid.mean() * a * a)
    lattice = Lattice.over(job.box, 0.25, 1 << 20)
    uniform = type(job.density)(np.full((4, 4), job.density.grid.mean()), x1 - x0, y1 - y0)
    field = coarse_field([deposit_part(xy, area, lattice)], lattice, uniform, 0.7, 1.0)
    return xy, area, uniform, field


def test_the_field_removes_a_planted_long_wave():
    job = load_job(SAMPLES / "led" / "job.toml")
    xy, area, uniform, field = _planted(job, 0.02)
    before = coverage_error(xy, area, uniform, 0.1, 1.0, job.box)
    after = coverage_error(xy + field.displacement(xy), area, uniform, 0.1, 1.0, job.box)
    inner = (slice(20, -20), slice(20, -20))
    assert before[inner].std() > 0.01
    assert after[inner].std() < 0.2 * before[inner].std()


def test_nothing_crosses_the_walls():
    """The displacement normal to a wall is 0 on it (face gradients), where a gradient
    taken at the border cells' centres slides the first strip of dots into the wall."""
    job = load_job(SAMPLES / "led" / "job.toml")
    _, _, _, field = _planted(job, 0.02)
    x0, y0, x1, y1 = job.box
    y = np.linspace(y0 + 1, y1 - 1, 7)
    for x in (x0, x1):
        u = field.displacement(np.column_stack([np.full(7, x), y]))
        np.testing.assert_array_equal(u[:, 0], 0.0)
    inside = field.displacement(np.column_stack([np.full(7, x0 + 2.5), y]))
    assert np.abs(inside[:, 0]).min() > 0.01  # the planted wave moves dots in between


def _wall_error(xy, area, density, box, h=0.05, sigma=1.0):
    """The eye's reading: coverage and map blurred against zeros past the walls, their
    ratio less 1, ``[ny, nx]`` on a grid of ``h``."""
    from scipy.ndimage import gaussian_filter

    nx, ny = round((box[2] - box[0]) / h), round((box[3] - box[1]) / h)
    got = _deposit(xy, area, box[0], box[1], (h, h), (ny, nx)) / (h * h)
    want = density.deposited(box[0], box[1], h, h, nx, ny)
    s = sigma / h
    return gaussian_filter(got, s, mode="constant") / gaussian_filter(want, s, mode="constant") - 1


def test_one_step_removes_an_excess_along_a_wall():
    """Dots that carry the map, plus 1 % more in the first 0.2 mm along the left wall,
    varying along it at a 5 mm wavelength: one step of the field leaves a tenth of the
    error the eye reads along that wall (0.10). Blurred against zeros past the wall (the
    map alike, half of it there) and moving relative error, a quarter stayed (0.25)."""
    rng = np.random.default_rng(5)
    box = (0.0, 0.0, 12.0, 10.0)
    fill = 0.2
    density = DensityMap(np.full((10, 12), fill), 12.0, 10.0)
    a = 0.05
    xy = np.mgrid[a / 2 : 12 : a, a / 2 : 10 : a].reshape(2, -1).T
    xy += rng.uniform(-0.01, 0.01, xy.shape)
    area = np.full(len(xy), fill * a * a)
    wall = xy[:, 0] < 0.2
    area[wall] *= 1 + 0.05 * (1 + np.cos(2 * np.pi * xy[wall, 1] / 5.0))
    area *= fill * 120.0 / area.sum()  # the map's count: only the layering is wrong
    lattice = Lattice.over(box, 0.15, 1 << 20)
    field = coarse_field([deposit_part(xy, area, lattice)], lattice, density, 0.3, 1.0)
    rows = slice(40, -40)  # along the wall, 2 mm from the corners
    before = _wall_error(xy, area, density, box)[rows, 0]
    after = _wall_error(xy + field.displacement(xy), area, density, box)[rows, 0]
    assert before.std() > 0.002
    assert after.std() < 0.15 * before.std(), (before.std(), after.std())


def _live_laplacian(psi, live, hx, hy):
    lap = np.zeros_like(psi)
    d = (psi[:, 1:] - psi[:, :-1]) * (live[:, 1:] & live[:, :-1]) / hx**2
    lap[:, :-1] += d
    lap[:, 1:] -= d
    d = (psi[1:, :] - psi[:-1, :]) * (live[1:, :] & live[:-1, :]) / hy**2
    lap[:-1, :] += d
    lap[1:, :] -= d
    return lap


def test_the_potential_on_live_cells_solves_their_own_laplacian():
    """:func:`live_potential` against the 5-point Laplacian of the live cells alone
    (no face to a dead cell): the residual is tiny and dead cells stay 0."""
    rng = np.random.default_rng(2)
    ny, nx, hx, hy = 24, 31, 0.2, 0.3
    live = np.ones((ny, nx), bool)
    live[5:12, 8:20] = False  # a hole
    live[18:, 25:] = False  # a notch at a corner
    a = np.where(live, rng.normal(size=(ny, nx)), 0.0)
    a[live] -= a[live].mean()
    psi = live_potential(a, live, hx, hy)
    assert (psi[~live] == 0).all()
    lap = _live_laplacian(psi, live, hx, hy)
    np.testing.assert_allclose(lap[live], a[live], atol=1e-4 * np.abs(a).max())
    # an island of live cells in a dead ring: each piece solved less its own mean
    live[14:22, 2:8] = False
    live[16:20, 4:6] = True
    a = np.where(live, rng.normal(size=(ny, nx)), 0.0)
    a[live] -= a[live].mean()
    psi = live_potential(a, live, hx, hy)
    island = np.zeros_like(live)
    island[16:20, 4:6] = True
    lap = _live_laplacian(psi, live, hx, hy)
    for piece in (island, live & ~island):
        want = a[piece] - a[piece].mean()
        np.testing.assert_allclose(lap[piece], want, atol=1e-4 * np.abs(a).max())
    # and the whole box live: the cosine transform, the same equation
    full = rng.normal(size=(ny, nx))
    full -= full.mean()
    every = np.ones((ny, nx), bool)
    psi = live_potential(full, every, hx, hy)
    np.testing.assert_allclose(_live_laplacian(psi, every, hx, hy), full, atol=1e-9)


def test_a_moved_throw_stays_in_the_panel_and_out_of_zero_cells():
    job = tiny_job()  # 6 x 6 mm, one quarter of fill 0
    s = stage_settings(job)
    xy = stages.throw(s, 800, 5, None, "test")
    g = Lattice.over(job.box, 0.5, 1 << 16)
    # a field that pushes everything 0.4 mm down and left
    ux = np.full((g.ny, g.nx + 1), -0.4, np.float32)
    uy = np.full((g.ny + 1, g.nx), -0.4, np.float32)
    push = CoarseField(g, ux, uy, 10.0)
    moved = stages.coarse_shift(s, push, xy)
    assert not job.density.empty_mask(moved).any()
    assert (moved >= 0).all() and (moved <= 6.0).all()
    went = np.hypot(*(moved - xy).T) > 0
    assert 0.5 < went.mean() < 1.0  # most moved; those that would land in the dark stayed
    np.testing.assert_array_equal(moved[~went], xy[~went])


def test_a_tiled_throw_loses_its_long_wavelength_grain():
    """The led sample's 8 tiles' throws, moved along the field solved from all of them:
    the coverage error at the field's blur and longer falls (0.51 -> 0.30 % RMS at 7
    spacings, 0.16 -> 0.05 % at 14); a tile's windows cannot see those wavelengths."""
    job = load_job(SAMPLES / "led" / "job.toml")
    plan = plan_tiles(job, 10.0)
    raw = [tasks.initial_task(job, plan, *t) for t in plan.tiles()]
    s = stage_settings(job)
    field = stages.coarse_solve(s, [stages.coarse_part(s, xy) for xy in raw])
    moved = np.concatenate([stages.coarse_shift(s, field, xy) for xy in raw])
    raw = np.concatenate(raw)
    area = np.full(len(raw), np.pi * (0.5 * job.diameter) ** 2)
    sp = job_spacing(job)
    for sigma, gain in ((7, 1.4), (14, 2.5)):
        a = coverage_error(raw, area, job.density, 0.5 * sp, sigma * sp, job.box)
        b = coverage_error(moved, area, job.density, 0.5 * sp, sigma * sp, job.box)
        assert b.std() * gain < a.std(), sigma


def test_only_a_steep_map_gets_the_wide_passs_rounds(tmp_path):
    """The rounds (each a barrier over the tiles) go to maps whose blurred fill changes by
    over 10 % between neighbouring lattice cells: a designed LED front does (0.4), a
    panel's smooth gradient does not (0.02) and keeps one round; a uniform map reads 0."""
    from optdot.config.schema import load_job
    from optdot.orchestration.job_settings import formulation_for, stage_settings
    from optdot.relax.lowpass import steepness
    from optdot.stages import wide_rounds
    from optdot.stages.correction import STEEP, _wide_lattice

    from .conftest import write_job
    from .test_visibility import _led_front_map

    def job_of(grid, w, h, where):
        where.mkdir()
        return load_job(
            write_job(where, grid, domain={"width": w, "height": h},
                      density={"interpolation": '"linear"'})
        )  # fmt: skip

    steep = job_of(_led_front_map(), 16.0, 8.0, tmp_path / "a")
    y = np.linspace(0, 1, 40)[:, None]
    smooth = job_of(np.repeat(0.08 + 0.34 * y**1.5, 60, axis=1), 60.0, 40.0, tmp_path / "b")
    flat = job_of(np.full((4, 6), 0.2), 6.0, 4.0, tmp_path / "c")
    rounds = formulation_for(steep).lowpass_last_steps
    assert rounds > 1
    steep, smooth, flat = (stage_settings(j) for j in (steep, smooth, flat))
    assert wide_rounds(steep) == rounds and wide_rounds(smooth) == 1 == wide_rounds(flat)
    from optdot.stages import wide_sigma

    def steep_of(settings):
        s = wide_sigma(settings)
        return steepness(settings.density, _wide_lattice(settings, s), s)

    assert steep_of(steep) > 3 * STEEP and steep_of(smooth) < 0.5 * STEEP
    assert steep_of(flat) == pytest.approx(0.0, abs=1e-9)
