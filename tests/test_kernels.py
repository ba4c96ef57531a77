"""A first run's compile in several processes (optdot.runtime.kernels): the list of kernels
is what the code calls, each unit is compiled once, helpers write numba's cache, and the
bytes of a run do not depend on who compiled its kernels."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from optdot.runtime import kernels

ROOT = Path(__file__).resolve().parents[1]
TINY = ROOT / "samples" / "tiny" / "job.toml"


def _recorded_with_this_numba() -> bool:
    import numba

    return json.loads(kernels.MANIFEST.read_text())["numba"] == numba.__version__


#: Why a test needs the list's signatures skips: a numba newer than the list's.
STALE = "kernels.json was recorded with another numba: python benchmarks/kernels.py --write"


def test_units_hold_each_function_in_one_unit_longest_first():
    """Each listed kernel in one unit, the longest units first, and every signature of a
    function (``_update_dot``'s four) in the same unit: two processes writing one
    function's cache at once can leave its index naming the wrong machine code."""
    listed = kernels.manifest()
    todo = [i for i, k in enumerate(listed) if "generate" in k.groups]
    work = kernels.units(todo)
    assert sorted(i for u in work for i in u) == todo
    where: dict[str, int] = {}  # a function's unit: all its signatures compiled together
    for k, u in enumerate(work):
        assert any(listed[i].depth == 0 for i in u)  # a kernel called from Python
        for i in u:
            assert where.setdefault(f"{listed[i].module}.{listed[i].name}", k) == k
    assert len({f"{listed[i].module}.{listed[i].name}" for i in todo}) == len(where)
    update = [u for u in work if any(listed[i].name == "_update_dot" for i in u)]
    assert len(update) == 1 and sum(listed[i].name == "_update_dot" for i in update[0]) >= 2
    totals = [sum(listed[i].seconds for i in u) for u in work]
    assert totals == sorted(totals, reverse=True)
    big = next(u for u in work if any(listed[i].name == "_penalty_kernel" for i in u))
    assert {listed[i].name for i in big} >= {"_penalty_kernel", "signed_distance"}


def test_claimed_units_are_left_to_their_claimer(tmp_path, monkeypatch):
    compiled: list[list[int]] = []
    monkeypatch.setattr(kernels, "compile_kernels", lambda m: compiled.append(m) or len(m))
    work = [[4, 7], [1], [2, 3, 5]]
    (tmp_path / "1").write_text("")  # another process has unit 1
    assert kernels.compile_claimed(work, str(tmp_path)) == 5
    assert compiled == [[4, 7], [2, 3, 5]]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["0", "1", "2"]
    assert kernels.compile_claimed(work, str(tmp_path)) == 0  # all claimed now
    assert compiled == [[4, 7], [2, 3, 5]]


def test_a_helper_whose_run_is_gone_compiles_nothing(tmp_path, monkeypatch):
    compiled: list[list[int]] = []
    monkeypatch.setattr(kernels, "compile_kernels", lambda m: compiled.append(m) or len(m))
    assert kernels.compile_claimed([[1], [2]], str(tmp_path), parent=os.getppid() + 1) == 0
    assert compiled == [] and not list(tmp_path.iterdir())
    assert kernels.compile_claimed([[1], [2]], str(tmp_path), parent=os.getppid()) == 2


FIRST_RUN = [
    sys.executable,
    "-P",
    "-m",
    "optdot",
    "generate",
    str(ROOT / "samples" / "tiny" / "job.toml"),
]


def _helpers_of(pid: int) -> list[int]:
    """The kernel helpers whose parent is ``pid`` (Linux /proc)."""
    found = []
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rsplit(")", 1)[1].split()
            cmd = (stat.parent / "cmdline").read_bytes()
        except OSError:
            continue
        if int(fields[1]) == pid and b"optdot.runtime.kernels" in cmd:
            found.append(int(stat.parent.name))
    return found


def _cpu_seconds(pid: int) -> float:
    """The CPU time process ``pid`` has used, s (Linux /proc: utime + stime)."""
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def _alive(pid: int) -> bool:
    """Whether process ``pid`` runs (not gone, not a zombie)."""
    try:
        return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0] != "Z"
    except OSError:
        return False


def _first_run_with_helpers(tmp_path) -> tuple[subprocess.Popen, list[int]]:
    """``optdot generate`` on the tiny sample with an empty kernel cache, once its
    helpers compile: the process and the helpers' ids."""
    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path / "cache"), OPTDOT_COMPILE_PROCESSES="2")
    run = subprocess.Popen(
        [*FIRST_RUN, "-o", str(tmp_path / "t.csv")], env=env, stderr=subprocess.PIPE, text=True
    )
    for _ in range(600):
        helpers = _helpers_of(run.pid)
        if len(helpers) == 2:
            time.sleep(1.0)  # into their compile
            return run, helpers
        time.sleep(0.05)
    run.kill()
    pytest.fail("no helpers started")


@pytest.mark.slow
@pytest.mark.skipif(not Path("/proc/self/stat").exists(), reason="reads /proc")
def test_a_first_run_stops_at_once_and_takes_its_helpers_along(tmp_path):
    """SIGTERM while a first run's helpers compile: the run compiled a unit itself and saw
    the stop only between kernels (9 s into the penalty kernel's, past a container's 10 s
    grace); now it waits on them and ends within a second, its helpers with it."""
    run, helpers = _first_run_with_helpers(tmp_path)
    used = _cpu_seconds(run.pid)
    time.sleep(2.0)
    assert _cpu_seconds(run.pid) - used < 0.5  # waiting on its helpers, not compiling
    start = time.monotonic()
    run.send_signal(signal.SIGTERM)
    _, err = run.communicate(timeout=30)
    assert time.monotonic() - start < 1.5 and run.returncode == 130, err
    assert err.strip() == "optdot: interrupted"
    time.sleep(0.3)
    assert not [h for h in helpers if _alive(h)]
    assert not (tmp_path / "t.csv").exists()


@pytest.mark.slow
@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="the parent-death signal")
def test_helpers_end_with_their_run_even_killed(tmp_path):
    """A first run killed outright (SIGKILL, the OOM killer) left its helpers compiling
    every unit still unclaimed, for ~25 s, children of init."""
    run, helpers = _first_run_with_helpers(tmp_path)
    run.kill()
    run.communicate(timeout=30)
    for _ in range(40):
        if not [h for h in helpers if _alive(h)]:
            break
        time.sleep(0.05)
    assert not [h for h in helpers if _alive(h)]


@pytest.mark.slow
def test_manifest_lists_what_the_code_calls():
    """The recorder's check: each group's work run now lists the same kernels and
    signatures as kernels.json (a stale list fails here: re-record it)."""
    out = subprocess.run(
        [sys.executable, str(ROOT / "benchmarks" / "kernels.py")],
        capture_output=True, text=True, timeout=600,
    )  # fmt: skip
    assert out.returncode == 0, out.stdout + out.stderr
    assert "as the code calls them" in out.stdout


def test_manifest_installed_and_loaded():
    listed = kernels.manifest()
    assert listed, "kernels.json missing from the installed package"
    groups = {g for k in listed for g in k.groups}
    assert groups == {"generate", "tiles", "simulate", "shapes"}
    names = {(k.module, k.name) for k in listed if "generate" in k.groups}
    assert ("optdot.relax.penalty", "_penalty_kernel") in names
    traced = {(k.module, k.name) for k in listed if "simulate" in k.groups}
    assert ("optdot.optics.trace", "_trace_part") in traced
    doc = json.loads(kernels.MANIFEST.read_text())
    if not _recorded_with_this_numba():
        assert all(k.signature is None for k in listed)  # another numba: the list unused
        pytest.skip(STALE)
    assert all(k.signature is not None for k in listed)
    again = kernels.decode(doc, "0.0.0")  # another numba: the signatures are not used
    assert all(k.signature is None for k in again)
    assert [k.types for k in again] == [k.types for k in listed]


def test_helpers_import_this_optdot_wherever_the_command_runs(tmp_path, monkeypatch):
    """A command run in a folder holding another ``optdot`` (the checkout a package was
    installed from): its helpers compile this process's optdot, not that one (they would
    cache the other's kernels where the run never looks, and it would compile its own)."""
    decoy = tmp_path / "optdot"
    (decoy / "runtime").mkdir(parents=True)
    marker = tmp_path / "imported"
    (decoy / "__init__.py").write_text(f"open({str(marker)!r}, 'w').close()\n")
    (decoy / "runtime" / "__init__.py").write_text("")
    (decoy / "runtime" / "kernels.py").write_text("")
    monkeypatch.chdir(tmp_path)
    kernels._compile_together([[]], 2)  # a helper started, nothing to compile
    assert not marker.exists()
    home = Path(kernels.package_home())
    assert (home / "optdot" / "runtime" / "kernels.py").samefile(kernels.__file__)


def test_processes_allowed(monkeypatch):
    monkeypatch.setenv(kernels.PROCESSES_ENV, "1")
    assert kernels.processes_allowed() == 1
    monkeypatch.setenv(kernels.PROCESSES_ENV, "64")
    assert kernels.processes_allowed() == kernels.MAX_PROCESSES
    for bad in ("", "zero", "-2", "0", "1.5", "²", "٣"):
        monkeypatch.setenv(kernels.PROCESSES_ENV, bad)
        assert kernels.processes_allowed() == min(kernels.usable_cores(), kernels.MAX_PROCESSES)


HELPERS = """
import sys
from optdot.runtime import kernels
todo = kernels.cold("generate")
assert len(kernels.units(todo)) > 4, todo
assert kernels.warm("generate", processes=2) == len(todo)
assert kernels.cold("generate") == []
listed = kernels.manifest()
theirs = 0
for i in todo:  # a unit the helper compiled: loaded from the cache it wrote
    d = listed[i].dispatcher()
    if listed[i].depth == 0 and listed[i].signature not in d.overloads:
        d.compile(listed[i].signature)
        assert d.stats.cache_hits[listed[i].signature] == 1, listed[i]
        theirs += 1
assert theirs > 0
from optdot import load_job
from optdot.orchestration.pipeline import generate_to
generate_to(load_job(sys.argv[1]), sys.argv[2], tiles="off")
"""


@pytest.mark.slow
def test_a_cold_cache_compiled_by_helpers_gives_the_same_bytes(tmp_path):
    """An empty numba cache: the generate group's kernels compiled by this process and a
    helper, each the units it claimed; the helper's come from the cache it wrote; the
    pattern is the bytes of a run on the usual (warm) cache."""
    if not _recorded_with_this_numba():
        pytest.skip(STALE)
    cache = tmp_path / "cache"
    cache.mkdir()
    env = dict(os.environ, NUMBA_CACHE_DIR=str(cache))
    env.pop(kernels.PROCESSES_ENV, None)
    cold_out = tmp_path / "cold.npz"
    run = subprocess.run(
        [sys.executable, "-c", HELPERS, str(TINY), str(cold_out)],
        env=env, capture_output=True, text=True, timeout=600,
    )  # fmt: skip
    assert run.returncode == 0, run.stderr[-3000:]
    warm_out = tmp_path / "warm.npz"
    from optdot import load_job
    from optdot.orchestration.pipeline import generate_to

    generate_to(load_job(TINY), warm_out, tiles="off")
    assert cold_out.read_bytes() == warm_out.read_bytes()


class _Done:
    def __init__(self, value):
        self.value = value

    def done(self):
        return True

    def result(self):
        return self.value


class _Client:
    """A Dask client that runs each task at once, recording where it was sent."""

    def __init__(self, workers):
        self.workers = workers
        self.sent: list[tuple] = []

    def scheduler_info(self):
        return {"workers": {w: {} for w in self.workers}}

    def submit(self, fn, *args, workers=None, pure=True):
        self.sent.append((fn.__name__, workers))
        return _Done(fn(*args))


def test_a_tiled_first_run_compiles_on_every_worker(monkeypatch):
    from optdot.orchestration import tiled

    compiled: list[list[int]] = []

    def cold(group):
        return [0, 1, 2, 3] if group == "tiles" else []

    def units(indices):
        return [[0], [1, 3], [2]]

    def compile_kernels(members):
        compiled.append(members)
        return len(members)

    monkeypatch.setattr(kernels, "cold", cold)
    monkeypatch.setattr(kernels, "units", units)
    monkeypatch.setattr(kernels, "compile_kernels", compile_kernels)
    client = _Client(["tcp://b:2", "tcp://a:1", "tcp://c:3", "tcp://d:4"])
    tiled._compile_on_workers(client, embedded=True)
    # the cold kernels asked of one worker, then one task on each worker that has a unit
    assert client.sent == [
        ("cold", None),
        ("compile_claimed", ["tcp://a:1"]),
        ("compile_claimed", ["tcp://b:2"]),
        ("compile_claimed", ["tcp://c:3"]),
    ]
    assert compiled == [[0], [1, 3], [2]]  # each unit once: the claims folder is shared
    client = _Client(["tcp://a:1", "tcp://b:2"])
    tiled._compile_on_workers(client, embedded=False)  # workers may not share a folder
    assert client.sent == []


def test_generate_warms_its_kernels_first(monkeypatch, tiny_job):
    import dataclasses

    from optdot.orchestration import pipeline

    asked: list[str] = []
    monkeypatch.setattr(pipeline, "warm", lambda group, announce=None: asked.append(group))
    small = dataclasses.replace(
        tiny_job, optimize=dataclasses.replace(tiny_job.optimize, max_iter=5)
    )
    pipeline.generate(small)
    assert asked == ["generate"]
    md = dataclasses.replace(small, optimize=dataclasses.replace(small.optimize, method="md"))
    pipeline.generate(md)  # the MD baseline's kernels are not listed
    assert asked == ["generate"]
    from optdot.config.schema import load_job

    shaped = load_job(ROOT / "samples" / "ellipses" / "job.toml")
    shaped = dataclasses.replace(shaped, optimize=dataclasses.replace(shaped.optimize, max_iter=3))
    pipeline.generate(shaped)  # shaped dots: their own kernels too
    assert asked == ["generate", ("generate", "shapes")]


def test_simulate_and_design_warm_the_tracer_first(monkeypatch, tmp_path):
    """``simulate`` and ``design`` compile the tracer's listed kernels on all cores before
    they trace (the ``simulate`` group), as ``generate`` does its own."""
    from click.testing import CliRunner

    from optdot.cli import main, optics

    asked: list = []
    monkeypatch.setattr(optics, "warm", lambda group, announce=None: asked.append(group))
    job = ROOT / "samples" / "ellipses" / "job.toml"
    r = CliRunner().invoke(main, ["simulate", str(job), "--rays", "2000", "-q"])
    assert r.exit_code == 0, r.output
    assert asked == ["simulate"]
    r = CliRunner().invoke(
        main, ["design", str(job), "-o", str(tmp_path / "m.csv"), "--rays", "4000",
               "--iterations", "2", "-q"],
    )  # fmt: skip
    assert r.exit_code == 0, r.output
    assert asked == ["simulate", "simulate"]


def test_a_listed_signature_the_code_no_longer_takes_is_skipped(monkeypatch):
    from numba import types

    if not _recorded_with_this_numba():
        pytest.skip(STALE)
    good = next(k for k in kernels.manifest() if k.name == "_bounds")
    stale = kernels.Kernel(
        good.module, good.name, "(int64)", 0.1, ("generate",), "", 0, (types.int64,)
    )
    monkeypatch.setattr(kernels, "manifest", lambda: (stale, good))
    assert kernels.compile_kernels([0, 1]) == 1  # no error: the stale one is left


SETTLE = """
import os, sys
import numba, numpy as np

@numba.njit(parallel=True)
def first(x):
    s = 0.0
    for i in numba.prange(len(x)):
        s += x[i]
    return s

first(np.ones(8))  # numba's thread pool starts at its default size
os.environ["NUMBA_NUM_THREADS"] = "1"  # then a Dask nanny sets the variable
if sys.argv[1] == "settled":
    from optdot.runtime.cluster import single_threaded
    single_threaded()  # what a tiled run's worker does before its work

@numba.njit(parallel=True)
def second(x):  # a cold cache's compile re-reads the variable
    s = 0.0
    for i in numba.prange(len(x)):
        s += 2.0 * x[i]
    return s

print(second(np.ones(8)), numba.get_num_threads())
"""


@pytest.mark.slow  # over 1.5 s
def test_a_compile_after_the_pool_started_survives_a_changed_thread_variable(tmp_path):
    """The README's tiled example after a plain ``generate`` in one interpreter crashed a
    worker's first compile ("Cannot set NUMBA_NUM_THREADS to a different value once the
    threads have been launched"): NUMBA_NUM_THREADS changed after numba's pool started.
    Unsettled, the compile fails as it did; settled, it runs on one thread."""
    script = tmp_path / "settle.py"
    script.write_text(SETTLE)
    env = {k: v for k, v in os.environ.items() if k != "NUMBA_NUM_THREADS"}
    env["NUMBA_CACHE_DIR"] = str(tmp_path / "cache")
    run = [sys.executable, "-P", str(script)]
    raw = subprocess.run([*run, "raw"], capture_output=True, text=True, env=env)
    if (os.cpu_count() or 1) > 1:
        assert raw.returncode != 0 and "Cannot set NUMBA_NUM_THREADS" in raw.stderr
    got = subprocess.run([*run, "settled"], capture_output=True, text=True, env=env)
    assert got.returncode == 0, got.stderr
    assert got.stdout.split() == ["16.0", "1"]
