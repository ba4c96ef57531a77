import subprocess
import sys

import numpy as np
import pytest

from optdot.config.schema import load_job
from optdot.io.patterns import pattern_csv_bytes
from optdot.orchestration.pipeline import generate
from optdot.relax.legalize import check_guarantee, legalize
from optdot.testing import close_pairs

from .conftest import SAMPLES, write_job


def assert_guarantee(job, p):
    v = check_guarantee(p.xy, job.density, job.domain, p.radius, job.min_distance)
    assert v.ok, v
    assert len(close_pairs(p.xy, job.diameter)) == 0  # independent engine (GEOS)
    assert abs(p.n - job.n_dots) <= max(1, 0.001 * job.n_dots)


def test_tiny_sample_guarantee_and_determinism(tiny_job, tiny_pattern):
    assert_guarantee(tiny_job, tiny_pattern)
    again = generate(tiny_job)
    assert pattern_csv_bytes(again) == pattern_csv_bytes(tiny_pattern)
    other = generate(tiny_job.with_overrides(seed=2))
    assert pattern_csv_bytes(other) != pattern_csv_bytes(tiny_pattern)


@pytest.mark.parametrize("formulation", ["paper", "optdot"])
def test_dense_map_with_gap(tmp_path, formulation):
    g = np.full((4, 6), 0.6)
    g[0, 0] = 0.0
    job = load_job(
        write_job(tmp_path, g, optimize={"gap": 0.004, "formulation": f'"{formulation}"'})
    )
    p = generate(job)
    assert_guarantee(job, p)
    assert len(close_pairs(p.xy, 0.050)) == 0


def test_relaxation_improves_on_initial(tiny_job):
    p = generate(tiny_job.with_overrides(max_iter=0))
    q = generate(tiny_job)
    # even with no iteration the guarantee pass delivers a legal pattern
    assert_guarantee(tiny_job, p)
    assert len(close_pairs(q.xy, 0.060)) < len(close_pairs(p.xy, 0.060))


def test_legalize_fixes_planted_defects(tiny_job, tiny_pattern):
    xy = tiny_pattern.xy.copy()
    xy[1] = xy[0] + [0.01, 0.0]  # collision
    xy[2] = [0.001, 1.0]  # protruding and in the empty column
    home = tiny_job.density.cell_index(tiny_pattern.xy)
    res = legalize(xy, tiny_job.density, home, tiny_job.domain, 0.023, 0.046)
    v = check_guarantee(res.xy, tiny_job.density, tiny_job.domain, 0.023, 0.046)
    assert v.ok and res.pair_fixes >= 1 and res.dot_fixes >= 1


def test_uniform_sample_counts():
    job = load_job(SAMPLES / "uniform" / "job.toml").with_overrides(max_iter=30)
    p = generate(job)
    assert_guarantee(job, p)


def test_npy_grid_equals_csv(tmp_path):
    g = np.array([[0.1, 0.2, 0.0], [0.3, 0.4, 0.2]])
    a = load_job(write_job(tmp_path, g))
    np.save(tmp_path / "g.npy", g)
    b = load_job(write_job(tmp_path, g, density={"grid": '"g.npy"'}))
    np.testing.assert_array_equal(a.density.grid, b.density.grid)
    assert a.n_dots == b.n_dots


@pytest.mark.parametrize("method", ["optdot", pytest.param("md", marks=pytest.mark.slow)])
def test_same_bytes_on_one_and_two_threads(method):
    """Parallel kernels sum in fixed blocks, not per thread: 12k dots span several penalty
    (4,096-dot) and L-BFGS (16,384-entry) blocks, and the pattern is bit-identical."""
    import numba

    job = load_job(SAMPLES / "uniform" / "job.toml").with_overrides(max_iter=15, method=method)
    before = numba.get_num_threads()
    try:
        numba.set_num_threads(1)
        one = generate(job)
        numba.set_num_threads(min(2, numba.config.NUMBA_NUM_THREADS))
        two = generate(job)
    finally:
        numba.set_num_threads(before)
    assert one.n > 8192
    assert pattern_csv_bytes(one) == pattern_csv_bytes(two)
    assert one.xy.tobytes() == two.xy.tobytes()


@pytest.mark.slow
def test_the_generate_command_loads_only_what_generating_needs():
    """Imports are a quarter of a small job's command: QA (scipy.spatial among it),
    scipy's sparse solvers (a map with dead cells), Dask, pyarrow, matplotlib and the
    mask writers load only in the commands and runs that use them."""
    heavy = (
        "optdot.quality.gate", "scipy.spatial", "scipy.sparse", "dask", "distributed",
        "pyarrow", "matplotlib", "gdstk", "ezdxf",
    )  # fmt: skip
    code = (
        "import sys, optdot.cli.main, optdot.orchestration.pipeline, optdot.stages, "
        "optdot.relax.lowpass; "
        f"print(sorted(m for m in {heavy!r} if m in sys.modules))"
    )
    run = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert run.stdout.strip() == "[]", run.stdout


@pytest.mark.parametrize(("preset", "huge"), [(None, "False"), ("1", "True")])
def test_the_command_asks_numpy_for_no_huge_pages_unless_the_user_did(preset, huge):
    """numpy's request for transparent huge pages stalls large runs on kernel compaction
    (optdot.console): the command turns it off before numpy loads, for itself and its
    workers; a NUMPY_MADVISE_HUGEPAGE the user set is kept."""
    import os

    env = {k: v for k, v in os.environ.items() if k != "NUMPY_MADVISE_HUGEPAGE"}
    if preset is not None:
        env["NUMPY_MADVISE_HUGEPAGE"] = preset
    code = (
        "import os, sys\n"
        "sys.argv = ['optdot', '--version']\n"
        "from optdot import console\n"
        "try:\n    console.run()\nexcept SystemExit:\n    pass\n"
        "import numpy\n"
        "print(numpy._core.multiarray._get_madvise_hugepage(), "
        "os.environ['NUMPY_MADVISE_HUGEPAGE'])"
    )
    run = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True, env=env
    )
    assert run.stdout.split()[-2:] == [huge, preset or "0"], run.stdout
