"""Tiled generation (optdot.orchestration.tiling), the Parquet dataset and streamed hierarchical
masks.

The Dask cases run the real command on a LocalCluster: the led sample (111k dots) in
8 tiles of 10 mm, on 2 workers and on 1 worker, must give the same bytes."""

from __future__ import annotations

import json
import signal
import subprocess
import sys
import time
import weakref

import numpy as np
import pytest
from scipy.spatial import cKDTree

from optdot.config.schema import load_job
from optdot.errors import PatternFileError
from optdot.io.dataset import MANIFEST, load_dataset, open_dataset
from optdot.orchestration.pipeline import generate_tiled, qa
from optdot.orchestration.tiling.plan import plan_tiles, tile_integrals
from optdot.orchestration.tiling.run import InProcess, field_name, wide_steps
from optdot.orchestration.tiling.tasks import initial_tile
from optdot.relax.legalize import legalize
from optdot.testing import close_pairs

from .conftest import SAMPLES
from .conftest import optdot as _optdot

LED = SAMPLES / "led" / "job.toml"
#: The led sample in 8 tiles of 10 mm.
TILED = ("--tiles", "on", "--tile-size", "10")


def optdot(*args, check=True) -> subprocess.CompletedProcess:
    """The command in a child process (tests/conftest.py), checked by default."""
    return _optdot(*args, check=check)


@pytest.mark.parametrize("sample,side", [("led", 10.0), ("led", 7.0), ("outline", 8.0)])
def test_tile_quotas_sum_to_the_jobs_dot_count(sample, side):
    job = load_job(SAMPLES / sample / "job.toml")
    plan = plan_tiles(job, side=side)
    assert plan.count > 1
    assert int(plan.quotas.sum()) == job.n_dots
    w = tile_integrals(job, plan.xs, plan.ys)
    exact = job.n_dots * w / w.sum()
    assert np.abs(plan.quotas - exact).max() < 1.0  # largest remainders: within one dot


def test_initial_tile_dots_lie_in_their_tile_and_follow_the_map():
    job = load_job(LED)
    plan = plan_tiles(job, side=10.0)
    for i, j in plan.tiles():
        xy = initial_tile(job, plan, i, j)
        x0, y0, x1, y1 = plan.rect(i, j)
        assert len(xy) == plan.quotas[j, i]
        assert (xy[:, 0] >= x0).all() and (xy[:, 0] <= x1).all()
        assert (xy[:, 1] >= y0).all() and (xy[:, 1] <= y1).all()
        assert not job.density.empty_mask(xy).any()
    # dots per map cell over the whole panel follow rho x cell area (Sobol: tight)
    xy = np.concatenate([initial_tile(job, plan, i, j) for i, j in plan.tiles()])
    got = np.bincount(job.density.cell_index(xy), minlength=job.density.grid.size)
    got = got.reshape(job.density.shape).sum(axis=1)  # per row of cells
    want = job.density.grid.sum(axis=1) / job.density.grid.sum() * len(xy)
    assert np.abs(got - want).max() <= 12  # a random throw: off by ~sqrt(want), 18..50
    assert np.sqrt(want).mean() > 30


def test_frozen_dots_keep_their_positions_exactly():
    from optdot.orchestration.job_settings import formulation_for, problem_of, settings_for
    from optdot.relax.optdot import relax_staged

    job = load_job(LED)
    rng = np.random.default_rng(5)
    xy0 = rng.uniform([10.0, 5.0], [11.0, 6.0], (300, 2))
    frozen = rng.random(300) < 0.3
    rho = job.density.at(xy0)
    assert (rho > 0).all()
    xy = relax_staged(
        problem_of(job), formulation_for(job), xy0, rho, settings_for(job), frozen=frozen
    ).xy
    assert np.array_equal(xy[frozen], xy0[frozen])
    assert np.abs(xy[~frozen] - xy0[~frozen]).max() > 1e-4  # the others moved


def test_a_frozen_partner_leaves_the_whole_push_to_the_other_dot(tiny_job):
    xy = np.array([[1.0, 0.75], [1.03, 0.75], [1.5, 0.75]])
    frozen = np.array([True, False, False])
    home = tiny_job.density.cell_index(xy)
    leg = legalize(xy, tiny_job.density, home, tiny_job.domain, 0.023, 0.046, frozen=frozen)
    assert np.array_equal(leg.xy[0], np.round(xy[0], 6))
    assert np.hypot(*(leg.xy[1] - leg.xy[0])) >= 0.046


@pytest.mark.slow
def test_a_tiled_job_in_process_meets_the_guarantee_with_the_exact_count():
    job = load_job(SAMPLES / "outline" / "job.toml")
    plan = plan_tiles(job, side=8.0)
    p = generate_tiled(job, plan=plan, executor=InProcess())
    assert p.n == job.n_dots
    pairs = cKDTree(p.xy).query_pairs(job.min_distance, output_type="ndarray")
    assert len(pairs) == 0
    r = qa(p, job)
    assert r.passed, r.failures()
    assert r.metrics["seams"]["tiles"] == [plan.nx, plan.ny]


@pytest.fixture(scope="module")
def tiled(tmp_path_factory):
    """The led sample tiled on a 2-worker and on a 1-worker LocalCluster."""
    d = tmp_path_factory.mktemp("tiled")
    common = ["generate", LED, *TILED]
    r2 = optdot(*common, "--workers", "2", "-o", d / "two.parquet")
    optdot(*common, "--workers", "1", "-o", d / "one.parquet", "-q")
    return d, r2


@pytest.mark.slow
def test_two_workers_and_one_give_the_same_bytes(tiled):
    d, r2 = tiled
    two, one = d / "two.parquet", d / "one.parquet"
    names = sorted(p.name for p in two.iterdir())
    assert names == sorted(p.name for p in one.iterdir())
    assert len(names) == 9 and MANIFEST in names
    for name in names:
        assert (two / name).read_bytes() == (one / name).read_bytes(), name
    assert "local cluster: 2 workers, dashboard http" in r2.stderr
    assert "8 tiles (4 x 2)" in r2.stderr


@pytest.fixture(scope="module")
def tiled_sizes(tmp_path_factory):
    """The led_sizes sample (30-120 µm dots) tiled on a 2-worker and a 1-worker cluster."""
    d = tmp_path_factory.mktemp("tiled_sizes")
    job = SAMPLES / "led_sizes" / "job.toml"
    common = ["generate", job, *TILED, "--max-iter", "60", "-q"]
    optdot(*common, "--workers", "2", "-o", d / "two.parquet")
    optdot(*common, "--workers", "1", "-o", d / "one.parquet")
    return d, load_job(job).with_overrides(max_iter=60)


@pytest.mark.slow
def test_varying_sizes_tile_with_the_same_bytes_on_two_workers_and_one(tiled_sizes):
    d, job = tiled_sizes
    two, one = d / "two.parquet", d / "one.parquet"
    names = sorted(p.name for p in two.iterdir())
    assert len(names) == 9
    for name in names:
        assert (two / name).read_bytes() == (one / name).read_bytes(), name
    p = load_dataset(two)
    assert p.n == job.n_dots and p.uniform_diameter is None
    # no pair closer than its mixed-pair limit: mean diameter + gap (cKDTree, all pairs)
    reach = float(p.diameter.max()) + job.optimize.gap
    pairs = cKDTree(p.xy).query_pairs(reach, output_type="ndarray")
    dist = np.hypot(*(p.xy[pairs[:, 0]] - p.xy[pairs[:, 1]]).T)
    limit = 0.5 * (p.diameter[pairs[:, 0]] + p.diameter[pairs[:, 1]]) + job.optimize.gap
    # (a few hundred pairs within reach of the largest dots: the check sees real pairs)
    assert len(pairs) > 200 and (dist >= limit - 1e-9).all()
    manifest = open_dataset(two).manifest
    assert manifest["diameter_mm"] == float(np.median(p.diameter))
    assert manifest["uniform_diameter_mm"] is None
    r = qa(p, job)
    assert r.passed, r.failures()
    assert r.metrics["seams"]["passed"], r.metrics["seams"]


@pytest.mark.slow
def test_the_tiled_pattern_passes_qa_and_its_seams_are_not_found(tiled):
    d, _ = tiled
    job = load_job(LED)
    p = load_dataset(d / "two.parquet")
    assert p.n == job.n_dots
    r = qa(p, job)
    assert r.passed, r.failures()
    seams = r.metrics["seams"]
    assert seams["passed"], seams
    assert seams["band_dots"] > 10_000


@pytest.mark.slow
def test_pandas_and_dask_read_the_dataset_as_it_is(tiled):
    pd = pytest.importorskip("pandas")
    import dask.dataframe as dd

    d, _ = tiled
    path = d / "two.parquet"
    ds = open_dataset(path)
    df = pd.read_parquet(path)
    assert list(df.columns) == ["x_mm", "y_mm", "diameter_mm"] and len(df) == ds.n
    assert len(dd.read_parquet(str(path)).compute()) == ds.n
    ours = load_dataset(path)
    assert np.array_equal(np.sort(df["x_mm"].to_numpy()), np.sort(ours.xy[:, 0]))


def _klayout_centres(path, layer=1, datatype=0) -> np.ndarray:
    import klayout.db as kdb

    ly = kdb.Layout()
    ly.read(str(path))
    li = ly.layer(layer, datatype)
    it = ly.top_cell().begin_shapes_rec(li)
    out = []
    while not it.at_end():
        box = it.shape().bbox().transformed(it.trans())
        out.append(((box.left + box.right) // 2, (box.bottom + box.top) // 2))
        it.next()
    a = np.array(out, dtype=np.int64)
    return a[np.lexsort((a[:, 1], a[:, 0]))]


@pytest.mark.parametrize("fmt", ["gds", "oas"])
@pytest.mark.slow
def test_hierarchical_masks_hold_exactly_the_dots_of_the_flat_export(tiled, tmp_path, fmt):
    from optdot import exporters

    d, _ = tiled
    src = d / "two.parquet"
    tiled_mask = tmp_path / f"tiled.{fmt}"
    optdot("export", src, f"--{fmt}", tiled_mask, "--job", LED, "-q")
    flat = tmp_path / f"flat.{fmt}"
    exporters.write(load_dataset(src), fmt, flat)
    a, b = _klayout_centres(tiled_mask), _klayout_centres(flat)
    assert len(a) == open_dataset(src).n
    assert np.array_equal(a, b)
    import klayout.db as kdb

    ly = kdb.Layout()
    ly.read(str(tiled_mask))
    names = {ly.cell(c).name for c in ly.each_cell_bottom_up()}
    assert {"TOP", "DOT", "T0_0", "T3_1"} <= names  # one cell per tile
    r = optdot("qa", tiled_mask, "--job", LED, check=False)
    assert r.returncode == 0, r.stdout + r.stderr


@pytest.mark.parametrize("fmt", ["gds", "oas"])
@pytest.mark.slow
def test_flattened_masks_of_a_dataset_hold_plain_polygons(tiled, tmp_path, fmt):
    """--flatten was ignored for datasets (a hierarchical mask came out): now a dataset
    and the same dots in memory both give one polygon per dot and no dot cell."""
    import klayout.db as kdb

    from optdot import exporters
    from optdot.exporters import ExportOptions

    d, _ = tiled
    src = d / "two.parquet"
    mask = tmp_path / f"flat-tiles.{fmt}"
    optdot("export", src, f"--{fmt}", mask, "--job", LED, "--flatten", "-q")
    whole = tmp_path / f"flat-whole.{fmt}"
    exporters.write(load_dataset(src), fmt, whole, ExportOptions(flatten=True))
    for path in (mask, whole):
        ly = kdb.Layout()
        ly.read(str(path))
        names = {ly.cell(c).name for c in ly.each_cell_bottom_up()}
        assert "DOT" not in names, names
        polygons = sum(ly.cell(c).shapes(ly.layer(1, 0)).size() for c in ly.each_cell_bottom_up())
        assert polygons == open_dataset(src).n
    assert np.array_equal(_klayout_centres(mask), _klayout_centres(whole))


@pytest.mark.slow
def test_a_dataset_without_its_manifest_or_with_a_changed_part_is_refused(tiled, tmp_path):
    import shutil

    d, _ = tiled
    copy = tmp_path / "c.parquet"
    shutil.copytree(d / "two.parquet", copy)
    part = copy / "part-00003.parquet"
    data = bytearray(part.read_bytes())
    data[100] ^= 0xFF
    part.write_bytes(bytes(data))
    with pytest.raises(PatternFileError, match="checksum"):
        load_dataset(copy)
    (copy / MANIFEST).unlink()
    with pytest.raises(PatternFileError, match="no _manifest.json"):
        load_dataset(copy)


@pytest.mark.slow
def test_an_interrupted_tiled_run_leaves_the_previous_dataset(tiled, tmp_path):
    import shutil

    d, _ = tiled
    out = tmp_path / "run.parquet"
    shutil.copytree(d / "one.parquet", out)
    before = {p.name: p.read_bytes() for p in out.iterdir()}
    args = ["generate", LED, *TILED, "--seed", "9", "-o", out]
    proc = subprocess.Popen(
        [sys.executable, "-P", "-m", "optdot", *map(str, args)], stderr=subprocess.PIPE, text=True
    )
    deadline = time.time() + 60
    while time.time() < deadline and "dashboard" not in (err := proc.stderr.readline()):
        pass
    time.sleep(1.0)  # tiles are being relaxed
    proc.send_signal(signal.SIGINT)
    rest = proc.communicate(timeout=120)[1]
    assert proc.returncode == 130, err + rest
    assert {p.name: p.read_bytes() for p in out.iterdir()} == before
    _only_the_staging_dir_beside(out, kept=None)  # a second in: maybe nothing to keep yet


def _only_the_staging_dir_beside(out, kept: bool | None = True):
    """Beside ``out`` nothing but the run's staging directory (kept to resume from):
    its resume record, the fields it kept and finished parts, nothing else. ``kept``
    None: the directory may be gone (a run stopped before it made anything to resume
    from leaves none)."""
    from optdot.io.dataset_write import EXTRA, RESUME, staging_dir

    staging = staging_dir(out)
    beside = sorted(p.name for p in out.parent.iterdir())
    if kept is None and beside == [out.name]:
        return
    assert beside == sorted([out.name, staging.name])
    inside = [p.name for p in staging.iterdir() if not p.name.startswith(EXTRA)]
    assert sorted(inside)[0] == RESUME, inside
    assert all(n.startswith("part-") for n in sorted(inside)[1:]), inside


@pytest.mark.slow
def test_cluster_faults_are_one_line(tmp_path):
    out = tmp_path / "x.parquet"
    r = optdot(
        "generate",
        LED,
        "--tiles",
        "on",
        "--scheduler",
        "tcp://127.0.0.1:9",
        "-o",
        out,
        check=False,
    )
    assert r.returncode == 4 and "cannot reach the Dask scheduler" in r.stderr, r.stderr
    assert len(r.stderr.strip().splitlines()) == 1
    r = optdot(
        "generate",
        LED,
        *TILED,
        "--worker-memory",
        "0.05",
        "-o",
        out,
        check=False,
    )
    assert r.returncode == 2 and "cannot" not in r.stderr and "a worker needs at least" in r.stderr
    assert not out.exists()


@pytest.mark.slow
def test_a_full_disk_while_writing_the_dataset_keeps_the_old_one(tiled, tmp_path):
    import shutil

    from .test_faults import optdot_limited

    d, _ = tiled
    out = tmp_path / "full.parquet"
    shutil.copytree(d / "one.parquet", out)
    before = {p.name: p.read_bytes() for p in out.iterdir()}
    r = optdot_limited(
        200_000,
        "generate",
        LED,
        *TILED,
        "--seed",
        "4",
        "-o",
        out,
        "-q",
    )
    assert r.returncode == 2, r.stderr
    assert len(r.stderr.strip().splitlines()) == 1 and str(out) in r.stderr, r.stderr
    assert {p.name: p.read_bytes() for p in out.iterdir()} == before
    _only_the_staging_dir_beside(out)


@pytest.mark.slow
def test_a_directory_that_is_not_a_dataset_is_never_replaced(tmp_path):
    victim = tmp_path / "precious.parquet"
    victim.mkdir()
    (victim / "notes.txt").write_text("keep me")
    r = optdot("generate", SAMPLES / "tiny" / "job.toml", "-o", victim, "-q", check=False)
    assert r.returncode == 2 and "not an optdot dataset" in r.stderr
    assert (victim / "notes.txt").read_text() == "keep me"


@pytest.mark.slow  # over 2 s on 2 cores
def test_a_small_job_writes_a_one_part_dataset_with_todays_dots(tmp_path, tiny_pattern):
    out = tmp_path / "t.parquet"
    optdot("generate", SAMPLES / "tiny" / "job.toml", "-o", out, "-q")
    m = json.loads((out / MANIFEST).read_text())
    assert m["tiles"]["nx"] == 1 and len(m["parts"]) == 1
    assert np.array_equal(load_dataset(out).xy, tiny_pattern.xy)


def _parts_source(xy: np.ndarray, box, cuts: int):
    """``xy`` split into ``cuts x cuts`` parts by position, as a QA source."""
    from optdot.geometry.shapes import Footprints
    from optdot.quality.source import Source

    ix = np.minimum((xy[:, 0] - box[0]) / (box[2] - box[0]) * cuts, cuts - 1).astype(int)
    iy = np.minimum((xy[:, 1] - box[1]) / (box[3] - box[1]) * cuts, cuts - 1).astype(int)
    parts = [xy[(iy == j) & (ix == i)] for j in range(cuts) for i in range(cuts)]
    xy_all = np.vstack(parts)
    return xy_all, Source(
        box=box,
        outline=None,
        uniform_diameter=0.046,
        nominal_diameter=0.046,
        counts=[len(p) for p in parts],
        read=lambda k: (parts[k], Footprints.circles(0.046, len(parts[k]))),
        cache_parts=3,
    )


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_qa_part_by_part_with_halos_equals_qa_of_the_whole(seed):
    """Dense clusters (pairs across part borders) beside sparse regions (nearest
    neighbours beyond the halo, re-queried): every count and distance as in one part."""
    from optdot.pattern import Pattern
    from optdot.quality.measure import measure
    from optdot.quality.source import source_of

    rng = np.random.default_rng(seed)
    box = (0.0, 0.0, 12.0, 12.0)
    dense = rng.uniform(4.0, 8.0, (6000, 2))  # ~40 µm apart: many close pairs
    sparse = rng.uniform(0.0, 12.0, (60, 2))  # ~1.5 mm apart: beyond the 1 mm halo
    xy, src = _parts_source(np.vstack([dense, sparse]), box, cuts=4)
    whole = measure(source_of(Pattern(xy, 0.046, box)), None, 1.0, 0.060, 0.046)
    parts = measure(src, None, 1.0, 0.060, 0.046)
    a, b = whole.metrics, parts.metrics
    want_close = len(close_pairs(xy, 0.060))  # GEOS, the independent engine
    assert a["pairs_below_close"] == b["pairs_below_close"] == want_close > 1000
    assert a["pairs_below_collision"] == b["pairs_below_collision"] > 100
    assert a["dots_in_close_pairs_fraction"] == b["dots_in_close_pairs_fraction"]
    assert a["nn_min_mm"] == b["nn_min_mm"]
    assert a["nn_percentiles_mm"] == b["nn_percentiles_mm"]
    assert b["qa_requeried_dots"] > 0
    assert b["psi6_local_mean"] == pytest.approx(a["psi6_local_mean"], rel=1e-12)
    assert b["psi6_coherence_2mm"] == pytest.approx(a["psi6_coherence_2mm"], rel=1e-12)
    assert b["protruding"] == a["protruding"]


@pytest.mark.slow
def test_qa_of_the_dataset_tile_by_tile_equals_qa_in_memory(tiled):
    d, _ = tiled
    job = load_job(LED)
    path = d / "two.parquet"
    mem = qa(load_dataset(path), job, close=0.075)
    ds = qa(None, job, close=0.075, dataset=open_dataset(path))
    a, b = mem.metrics, ds.metrics
    assert b["pairs_below_close"] == a["pairs_below_close"] > 1000  # many cross tile borders
    for key in (
        "pairs_below_collision",
        "dots_in_close_pairs_fraction",
        "nn_min_mm",
        "nn_percentiles_mm",
        "nn_normalized_percentiles",
        "protruding",
        "in_empty_cells",
        "coverage_rel_rms_smoothed",
        "coverage_per_cell_rel_rms",
        "dots_expected",
    ):
        assert b[key] == a[key], key
    assert b["psi6_local_mean"] == pytest.approx(a["psi6_local_mean"], rel=1e-12)
    va, vb = a["visibility"], b["visibility"]  # the luminance grid filled tile by tile
    assert vb["max_jnd"] == pytest.approx(va["max_jnd"], rel=1e-9)
    assert vb["max_jnd_at_mm"] == va["max_jnd_at_mm"]
    assert vb["jnd_percentiles"] == pytest.approx(va["jnd_percentiles"], rel=1e-9)
    assert [x["jnd"] for x in vb["blobs"]] == pytest.approx([x["jnd"] for x in va["blobs"]])
    # the wall profile summed part by part (dots in any order) is the whole pattern's
    wa, wb = a["walls"], b["walls"]
    assert wb["relative"] == pytest.approx(wa["relative"], rel=1e-9, abs=1e-12)
    assert wb["worst_relative"] == pytest.approx(wa["worst_relative"], rel=1e-9)
    for name, v in a["edge_band_coverage_ratio"].items():
        assert b["edge_band_coverage_ratio"][name] == pytest.approx(v, rel=1e-12)
    for name, v in a["seams"]["measures"].items():
        assert b["seams"]["measures"][name]["band"] == pytest.approx(v["band"], rel=1e-9)
    assert [c.passed for c in ds.checks] == [c.passed for c in mem.checks]


class _Counting(InProcess):
    """Runs tasks in process, counting them by kind; ``stop_after`` finished tiles, the
    run is interrupted (as Ctrl-C would) before the next one is written."""

    def __init__(self, stop_after: int | None = None, memory: int = 0) -> None:
        super().__init__(memory)
        self.kinds: dict[str, int] = {}
        self.stop_after = stop_after

    def submit(self, kind, key, fn, *args):
        self.kinds[kind] = self.kinds.get(kind, 0) + 1
        return fn(*args)

    def finished(self, handles):
        from optdot.orchestration.tiling.tasks import FinalDots

        done = 0
        for h in handles:
            if self.stop_after is not None and done == self.stop_after:
                raise KeyboardInterrupt
            done += isinstance(h, FinalDots)
            yield h


@pytest.mark.parametrize("memory", [0, 1], ids=["held", "slim"])
@pytest.mark.slow
def test_an_interrupted_tiled_run_resumes_with_the_bytes_of_an_uninterrupted_one(tmp_path, memory):
    """Ctrl-C after 3 of 8 tiles: the target is untouched, the 3 tiles are kept beside it;
    the same run again makes only the 5 others' guarantee passes and writes the bytes of a
    run that was never interrupted. Another seed starts over. The same when the workers'
    memory is short (``slim``): the wide pass then holds the first passes' positions
    alone, and the containers are thrown again, to the same bytes."""
    from optdot.io.dataset_write import staging_dir

    job = load_job(LED).with_overrides(max_iter=15)
    plan = plan_tiles(job, side=10.0)
    assert plan.count == 8
    full = tmp_path / "full.parquet"
    generate_tiled(job, full, plan=plan, executor=InProcess())
    out = tmp_path / "resumed.parquet"
    with pytest.raises(KeyboardInterrupt):
        generate_tiled(job, out, plan=plan, executor=_Counting(stop_after=3, memory=memory))
    assert not out.exists()
    staging = staging_dir(out)
    kept = sorted(p.name for p in staging.iterdir())
    # the record, the throw's field and every round's of the wide pass, the 3 parts
    rounds = [field_name(r) for r in range(wide_steps(job))]
    assert len(rounds) > 1
    fields = ["_extra-coarse.npz", *(f"_extra-{n}.npz" for n in rounds), "_resume.json"]
    assert kept[: len(fields)] == fields, kept
    assert len(kept) == len(fields) + 3 and all(k.startswith("part-") for k in kept[-3:])
    again = _Counting(memory=memory)
    said = []
    generate_tiled(job, out, plan=plan, executor=again, announce=said.append)
    assert again.kinds["legal"] == 5 and "resuming: 3 of 8 tiles" in said[0]
    assert again.kinds.get("slim", 0) == (5 if memory else 0), again.kinds
    # the fields are read, not made again from every tile: only the 5 tiles' own
    # corrections are made and moved along every round's field (all 8, and their
    # deposits in every round, to remake the wide fields)
    assert "coarse" not in again.kinds and not set(rounds) & set(again.kinds)
    assert "deposit" not in again.kinds
    assert not [k for k in again.kinds if k.startswith("wdeposit")], again.kinds
    assert again.kinds["correct"] == again.kinds["shift"] == 5, again.kinds
    assert not staging.exists()
    names = sorted(p.name for p in full.iterdir())
    assert names == sorted(p.name for p in out.iterdir())
    for name in names:
        assert (full / name).read_bytes() == (out / name).read_bytes(), name
    # a run of another seed does not take those tiles
    with pytest.raises(KeyboardInterrupt):
        generate_tiled(job, out, plan=plan, executor=_Counting(stop_after=2))
    other = _Counting()
    generate_tiled(job.with_overrides(seed=9), out, plan=plan, executor=other)
    assert other.kinds["legal"] == 8


@pytest.mark.slow
def test_a_damaged_kept_field_is_made_again(tmp_path):
    """A kept field whose bytes no longer match its record is dropped and made again from
    every tile; the result is still the uninterrupted run's."""
    from optdot.io.dataset_write import staging_dir

    job = load_job(LED).with_overrides(max_iter=15)
    plan = plan_tiles(job, side=10.0)
    full = tmp_path / "full.parquet"
    generate_tiled(job, full, plan=plan, executor=InProcess())
    out = tmp_path / "resumed.parquet"
    with pytest.raises(KeyboardInterrupt):
        generate_tiled(job, out, plan=plan, executor=_Counting(stop_after=3))
    kept = staging_dir(out) / "_extra-wide.npz"
    data = bytearray(kept.read_bytes())
    data[-100] ^= 0xFF
    kept.write_bytes(bytes(data))
    again = _Counting()
    generate_tiled(job, out, plan=plan, executor=again)
    # every round is made again (each from the dots the round before moved)
    rounds = [field_name(r) for r in range(wide_steps(job))]
    assert all(again.kinds[n] == 1 for n in rounds) and again.kinds["wdeposit"] == 8
    assert all(again.kinds[f"wdeposit{r}"] == 8 for r in range(1, len(rounds)))
    assert "coarse" not in again.kinds  # the other field was intact
    for name in sorted(p.name for p in full.iterdir()):
        assert (full / name).read_bytes() == (out / name).read_bytes(), name


def test_a_resume_record_keeps_only_its_own_checked_extras(tmp_path):
    """Extras named in a resume record are taken only when they are files of the staging
    directory named as extras with their recorded checksum: an entry of another type, a
    path out of it or a wrong checksum is dropped (and the file, if inside, removed)."""
    from optdot.files import sha256_file
    from optdot.io.dataset_write import RESUME, _open_staging, staging_dir

    target = tmp_path / "x.parquet"
    staging = staging_dir(target)
    staging.mkdir()
    (tmp_path / "secret.npz").write_bytes(b"not ours")
    good = staging / "_extra-wide.npz"
    good.write_bytes(b"field")
    bad = staging / "_extra-coarse.npz"
    bad.write_bytes(b"changed")
    extras = {
        "wide": {"file": good.name, "sha256": sha256_file(good)},
        "coarse": {"file": bad.name, "sha256": "0" * 64},
        "other": {"file": "../secret.npz", "sha256": sha256_file(tmp_path / "secret.npz")},
        "odd": 5,
    }
    (staging / RESUME).write_text(json.dumps({"key": "k", "parts": {}, "extras": extras}))
    _, parts, kept = _open_staging(target, "k")
    assert parts == {} and list(kept) == ["wide"]
    assert good.exists() and not bad.exists() and (tmp_path / "secret.npz").exists()


def test_a_foreign_directory_in_the_staging_place_is_never_removed(tmp_path):
    from optdot.errors import ExportError
    from optdot.io.dataset_write import staging_dir

    job = load_job(LED).with_overrides(max_iter=2)
    out = tmp_path / "x.parquet"
    theirs = staging_dir(out)
    theirs.mkdir()
    (theirs / "notes.txt").write_text("mine")
    with pytest.raises(ExportError, match="not an optdot staging directory"):
        generate_tiled(job, out, plan=plan_tiles(job, side=10.0), executor=InProcess())
    assert (theirs / "notes.txt").read_text() == "mine" and not out.exists()


@pytest.mark.slow
def test_export_takes_a_dataset_as_the_dots(tiled, tmp_path):
    """The library's export() takes an opened dataset where a pattern goes: masks stream
    from it, the CSV reads it whole; KLayout reads the dataset's dots from the GDS."""
    from optdot.orchestration.pipeline import export

    d, _ = tiled
    ds = open_dataset(d / "two.parquet")
    out = {"gds": tmp_path / "x.gds", "csv": tmp_path / "x.csv"}
    result = export(ds, out, load_job(LED))
    assert result.passed
    assert len(_klayout_centres(out["gds"])) == ds.n
    assert len(out["csv"].read_text().splitlines()) == ds.n + 1


class _Watching(InProcess):
    """Keeps a weak reference to every relaxed, corrected and final tile it makes, and to
    the first passes' positions the wide pass holds when ``memory`` is short."""

    def __init__(self, memory: int = 0) -> None:
        super().__init__(memory)
        kinds = ("relax", "correct", "slim", "shift", "legal")
        self.refs: dict[str, list] = {k: [] for k in kinds}

    def submit(self, kind, key, fn, *args):
        out = fn(*args)
        if kind in self.refs:
            self.refs[kind].append(weakref.ref(out))
        return out


@pytest.mark.parametrize("memory", [0, 1], ids=["held", "slim"])
def test_a_tiled_run_lets_go_of_each_tile_once_handed_over(memory):
    """Memory: the run holds a relaxed, corrected or final tile only while a task still
    needs it (holding every one to the end took the monitor panel to 4 GiB). When the
    last tile reaches the sink, every earlier tile's results are gone. When the
    workers' memory is short (``slim``), the wide pass holds only the first passes'
    positions across its barrier, not their containers (the 55-inch TV: 6.9 → 5.7 GB);
    and the outputs are the same."""
    from optdot.orchestration.tiling.run import run_tiles, slim_first_passes, tiny_job

    job = tiny_job()
    ex = _Watching(memory)
    alive_at_last: dict[str, int] = {}
    plan = plan_tiles(job, side=3.0)

    sinks = []

    def sink(tile, xy, d):
        sinks.append(tile)
        if len(sinks) == plan.count:
            # (an empty tile's correction hands its merged dots on, which the run keeps)
            alive_at_last.update({k: sum(_dots(r()) > 0 for r in v) for k, v in ex.refs.items()})

    got = {}
    run_tiles(job, plan, ex, lambda t, xy, d: (got.__setitem__(t, xy), sink(t, xy, d)))
    assert plan.count == 4 and len(ex.refs["relax"]) == 4 and len(ex.refs["shift"]) == 4
    # only the tile in the sink's hands is alive, and the tiles' first correction passes
    # (3: one tile is empty), whole or their positions: the wide pass's shifts are made
    # from them, and they are kept to the end for a shift lost with a dead worker
    slim = slim_first_passes(plan, memory)
    assert slim == bool(memory)
    held = {"correct": 0 if slim else 3, "slim": 3 if slim else 0}
    assert alive_at_last == {"relax": 0, "shift": 0, "legal": 1, **held}
    other = {}
    run_tiles(job, plan, InProcess(1 - memory), lambda t, xy, d: other.__setitem__(t, xy))
    assert got.keys() == other.keys()
    for t, xy in got.items():
        np.testing.assert_array_equal(xy, other[t])


def _dots(held) -> int:
    """Dots in a tile result still alive (0 when it is gone)."""
    if held is None:
        return 0
    return len(held.xy) if hasattr(held, "xy") else len(held)


def _free_port() -> int:
    import socket

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.mark.slow
def test_a_cluster_started_by_hand_gives_the_local_clusters_bytes(tmp_path):
    """A ``dask scheduler`` without a dashboard and two ``dask worker`` processes started
    by hand on this machine: ``--scheduler tcp://...`` writes the bytes the embedded local
    cluster writes, and names no dashboard (the client's link template made one up)."""
    import sys
    import time

    port = _free_port()
    address = f"tcp://127.0.0.1:{port}"
    quiet = {"stdout": subprocess.DEVNULL, "stderr": subprocess.DEVNULL}
    sched = subprocess.Popen(
        [sys.executable, "-m", "distributed.cli.dask_scheduler", "--host", "127.0.0.1",
         "--port", str(port), "--no-dashboard"], **quiet,
    )  # fmt: skip
    workers = [
        subprocess.Popen(
            [
                sys.executable,
                "-m",
                "distributed.cli.dask_worker",
                address,
                "--nthreads",
                "1",
                "--no-dashboard",
                "--memory-limit",
                "2GB",
            ],
            **quiet,
        )  # fmt: skip
        for _ in range(2)
    ]
    try:
        here = tmp_path / "local.parquet"
        there = tmp_path / "remote.parquet"
        optdot("generate", LED, *TILED, "--max-iter", "15", "-o", here)
        deadline = time.monotonic() + 60
        r = None
        while time.monotonic() < deadline:  # the scheduler takes a moment to listen
            r = optdot(
                "generate", LED, *TILED, "--max-iter", "15", "--scheduler", address,
                "-o", there, check=False,
            )  # fmt: skip
            if r.returncode != 4:
                break
            time.sleep(1)
        assert r is not None and r.returncode == 0, r.stderr
        said = r.stdout + r.stderr
        assert "dashboard http" not in said and "dashboard n/a" in said, said
        names = sorted(p.name for p in here.iterdir())
        assert names == sorted(p.name for p in there.iterdir())
        for name in names:
            assert (here / name).read_bytes() == (there / name).read_bytes(), name
    finally:
        for p in [*workers, sched]:
            p.terminate()
        for p in [*workers, sched]:
            try:
                p.wait(timeout=20)
            except subprocess.TimeoutExpired:
                p.kill()


def _edit_record(staging, edit) -> None:
    from optdot.io.dataset_write import RESUME

    doc = json.loads((staging / RESUME).read_text())
    edit(doc)
    (staging / RESUME).write_text(json.dumps(doc))


@pytest.mark.slow
def test_a_tampered_resume_record_remakes_the_parts_it_no_longer_vouches_for(tmp_path):
    """A part entry turned into a string, a part key that is no number, an edited dot
    count: each ended in an internal error (exit 70) or a message with no way forward;
    the part is now remade, and the result is the uninterrupted run's."""
    from optdot.errors import ExportError
    from optdot.io.dataset_write import staging_dir

    job = load_job(LED).with_overrides(max_iter=15)
    plan = plan_tiles(job, side=10.0)
    full = tmp_path / "full.parquet"
    generate_tiled(job, full, plan=plan, executor=InProcess())
    edits = {
        "string": lambda d: d["parts"].update({k: "oops" for k in list(d["parts"])[:1]}),
        "key": lambda d: d["parts"].update({"x": d["parts"].pop(next(iter(d["parts"])))}),
        "count": lambda d: [e.update(count=e["count"] + 1) for e in list(d["parts"].values())[:1]],
    }
    for name, edit in edits.items():
        out = tmp_path / f"{name}.parquet"
        with pytest.raises(KeyboardInterrupt):
            generate_tiled(job, out, plan=plan, executor=_Counting(stop_after=3))
        _edit_record(staging_dir(out), edit)
        again = _Counting()
        generate_tiled(job, out, plan=plan, executor=again)
        assert again.kinds["legal"] == 6, (name, again.kinds)  # 5, and the one dropped
        for f in sorted(p.name for p in full.iterdir()):
            assert (full / f).read_bytes() == (out / f).read_bytes(), (name, f)
    # a directory of someone else's inside the staging directory: named, with the way out
    out = tmp_path / "dir.parquet"
    with pytest.raises(KeyboardInterrupt):
        generate_tiled(job, out, plan=plan, executor=_Counting(stop_after=3))
    (staging_dir(out) / "keep").mkdir()
    with pytest.raises(ExportError) as e:
        generate_tiled(job, out, plan=plan, executor=InProcess())
    msg = str(e.value)
    assert str(staging_dir(out)) in msg and "'keep'" in msg and "to start over" in msg, msg
    assert (staging_dir(out) / "keep").is_dir()
