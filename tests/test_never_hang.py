"""Never hang, never exhaust the machine, one line for every bad input.

Each case here hung, filled the memory, printed tracebacks or ended in an internal error
(exit 70) before the fix.
"""

from __future__ import annotations

import contextlib
import json
import os
import signal
import socket
import stat
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest

from optdot.errors import ClusterError
from optdot.runtime.cluster import connect, scheduler_address

from .conftest import SAMPLES, one_error

TINY = SAMPLES / "tiny" / "job.toml"
LED = SAMPLES / "led" / "job.toml"


@pytest.mark.parametrize(
    "address, words",
    [
        ("not a url", "missing port"),
        ("inproc://x", "inproc"),
        ("tcp://host", "missing port"),
        ("garbage:::", "invalid address"),
    ],
)
def test_a_scheduler_address_that_is_not_one_is_one_line(tmp_path, address, words):
    one_error(
        ["generate", TINY, "-o", tmp_path / "d.parquet", "--tiles", "on", "--scheduler", address],
        4,
        "not a Dask scheduler address",
        words,
    )


def test_a_garbage_scheduler_in_the_environment_is_named(monkeypatch):
    monkeypatch.setenv("DASK_SCHEDULER_ADDRESS", "garbage:::")
    with pytest.raises(ClusterError, match="DASK_SCHEDULER_ADDRESS 'garbage:::'"):
        scheduler_address(None)
    assert scheduler_address("tcp://10.0.0.1:8786") == "tcp://10.0.0.1:8786"


@contextlib.contextmanager
def _server(banner: bytes):
    """A TCP server on a free loopback port that accepts every connection and says
    ``banner`` (nothing when empty): its address."""
    server = socket.socket()
    server.bind(("127.0.0.1", 0))
    server.listen(8)
    server.settimeout(0.2)
    held, stop = [], threading.Event()

    def accept():
        while not stop.is_set():
            try:
                c = server.accept()[0]
                held.append(c)
                if banner:
                    c.sendall(banner)
            except OSError:
                pass

    t = threading.Thread(target=accept, daemon=True)
    t.start()
    try:
        yield f"tcp://127.0.0.1:{server.getsockname()[1]}"
    finally:
        stop.set()
        t.join(2)
        for c in held:
            c.close()
        server.close()


@pytest.mark.slow
def test_a_silent_scheduler_is_given_up_on_in_bounded_time():
    with _server(b"") as address:
        t0 = time.monotonic()
        with pytest.raises(ClusterError, match="did not answer|cannot reach"):
            with connect(address, timeout=1.0):
                pass
        assert time.monotonic() - t0 < 15  # the 10 s connect timeout never applied before


@pytest.mark.parametrize(
    "banner",
    [
        b"SSH-2.0-OpenSSH_9.6\r\n",
        b"HTTP/1.1 400 Bad\r\n\r\n",
        (6 << 30).to_bytes(8, "little") + bytes(1 << 16),  # a 6 GiB frame Dask would allocate
    ],
)
def test_a_server_that_speaks_first_is_not_taken_for_a_scheduler(tmp_path, banner):
    """An SSH or HTTP server at the scheduler's address: its banner read as a frame
    length made Dask ask for exabytes ("out of memory", exit 2); now the cluster's error,
    exit 4, naming the address."""
    with _server(banner) as address:
        one_error(
            [
                "generate",
                TINY,
                "-o",
                tmp_path / "d.parquet",
                "--tiles",
                "on",
                "--scheduler",
                address,
            ],
            4,
            address,
            "does not answer as a Dask scheduler",
        )
    assert list(tmp_path.iterdir()) == []  # no staging directory left with nothing in it


@pytest.mark.slow  # over 2 s on 2 cores
def test_the_embedded_cluster_is_private_loopback_tls_and_cleans_its_scratch():
    from distributed import Client

    before = {k: os.environ.get(k) for k in ("NUMBA_NUM_THREADS", "OMP_NUM_THREADS")}
    with connect(workers=1) as cluster:
        # the workers run numba on one thread, the command's own environment is untouched
        # (Dask's pre-spawn-environ would set it, and numba here then refuses to compile)
        def numba_threads():
            import numba

            return numba.config.NUMBA_NUM_THREADS

        assert set(cluster.client.run(numba_threads).values()) == {1}
        assert {k: os.environ.get(k) for k in before} == before
        addr = cluster.client.scheduler.address
        assert addr.startswith("tls://127.0.0.1:"), addr
        assert "127.0.0.1" in cluster.dashboard
        info = cluster.client.scheduler_info()["workers"]
        assert all(w.startswith("tls://127.0.0.1:") for w in info)
        dirs = cluster.client.run(lambda dask_worker: dask_worker.local_directory)
        scratch = Path(next(iter(dirs.values())))
        top = next(p for p in scratch.parents if p.name.startswith("optdot-dask-"))
        assert stat.S_IMODE(top.stat().st_mode) == 0o700
        with pytest.raises((OSError, TimeoutError)):  # no certificate: no way in
            Client(addr.replace("tls://", "tcp://"), timeout="2s")
    assert not top.exists()


def test_options_that_are_not_finite_numbers_are_usage_errors(tmp_path):
    for opt in ("--tile-size", "--worker-memory"):
        one_error(
            ["generate", TINY, "-o", tmp_path / "d.parquet", "--tiles", "on", opt, "nan"],
            2,
            opt,
            "not a finite number",
        )
    pattern = tmp_path / "p.csv"
    pattern.write_text("x_mm,y_mm,diameter_mm\n1,1,0.046\n")
    for opt in ("--psf", "--distance", "--collision", "--close"):
        one_error(["qa", pattern, opt, "inf"], 2, opt)


def test_toml_nested_too_deep_and_a_huge_job_are_one_line(tmp_path):
    deep = tmp_path / "deep.toml"
    deep.write_text("a = " + "[" * 5000 + "]" * 5000 + "\n")
    one_error(["generate", deep, "-o", tmp_path / "o.csv"], 2, "nested too deep")
    huge = tmp_path / "huge.toml"
    huge.write_text('name = "' + "x" * (3 << 20) + '"\n')
    err = one_error(["generate", huge, "-o", tmp_path / "o.csv"], 2, "job file is")
    assert len(err) < 300  # no 3 MB value echoed
    assert "1.0 MB this reader accepts" in err and "memory" not in err  # a cap, not the RAM


def test_a_device_or_fifo_as_an_input_is_refused_before_reading(tmp_path):
    text = TINY.read_text().replace('"density.csv"', '"/dev/zero"')
    (tmp_path / "j.toml").write_text(text)
    one_error(["generate", tmp_path / "j.toml", "-o", tmp_path / "o.csv"], 2, "character device")
    fifo = tmp_path / "p.csv"
    os.mkfifo(fifo)  # reading it would block forever
    one_error(["qa", fifo], 2, "FIFO")
    one_error(["export", fifo, "--gds", tmp_path / "m.gds"], 2, "FIFO")


def test_piled_up_dots_are_refused_before_qa_lists_their_pairs(tmp_path):
    rows = "x_mm,y_mm,diameter_mm\n" + "1.0,1.0,0.046\n" * 20_000
    (tmp_path / "dup.csv").write_text(rows)
    t0 = time.monotonic()
    one_error(["qa", tmp_path / "dup.csv"], 2, "199,990,000 pairs", "not a dot pattern")
    assert time.monotonic() - t0 < 30


def test_an_npz_bomb_is_refused_from_its_headers(tmp_path):
    import io
    import zipfile

    fmt = np.lib.format
    with zipfile.ZipFile(tmp_path / "bomb.npz", "w", zipfile.ZIP_DEFLATED) as zf:
        for name, arr in (("box", np.array([0, 0, 3, 2.0])), ("diameter", np.array(0.046))):
            b = io.BytesIO()
            np.save(b, arr)
            zf.writestr(name + ".npy", b.getvalue())
        with zf.open("xy.npy", "w", force_zip64=True) as fh:
            fmt.write_array_header_1_0(
                fh, {"descr": "<f8", "fortran_order": False, "shape": (10**10, 2)}
            )
            fh.write(bytes(1 << 20))
    assert (tmp_path / "bomb.npz").stat().st_size < 100_000
    one_error(["qa", tmp_path / "bomb.npz"], 2, "declare", "GiB")


def test_png_exif_orientation_is_applied_and_turned_tiffs_are_refused(tmp_path):
    from PIL import Image

    from optdot.config.images import load_image
    from optdot.errors import JobError

    a = np.zeros((20, 30), np.uint8)
    a[:5, :10] = 200  # bright block at the stored image's top left
    ex = Image.Exif()
    ex[0x0112] = 6  # "turn 90 degrees clockwise to display"
    Image.fromarray(a).save(tmp_path / "m.png", exif=ex)
    g = load_image(tmp_path / "m.png", (0.0, 0.4))
    assert g.shape == (30, 20)
    bright = np.argwhere(g[::-1] > 0.1)  # back to top-down rows for the check
    assert bright[:, 0].max() == 9 and bright[:, 1].min() == 15  # now at the top right
    Image.fromarray(a).save(tmp_path / "m.tif", exif=ex)
    with pytest.raises(JobError, match="orientation tag 6"):
        load_image(tmp_path / "m.tif", (0.0, 0.4))


def test_an_image_too_large_for_the_memory_is_refused_with_the_estimate(tmp_path, monkeypatch):
    from PIL import Image

    import optdot.config.images as images
    from optdot.errors import ResourceError

    Image.fromarray(np.zeros((400, 500), np.uint8)).save(tmp_path / "m.png")
    monkeypatch.setattr(images, "available_bytes", lambda: 1_000_000)
    with pytest.raises(ResourceError, match="500 x 400 pixels need about"):
        images.load_image(tmp_path / "m.png", (0.0, 0.4))


def _start_tiled(tmp_path, out: str, env=None) -> subprocess.Popen:
    return subprocess.Popen(
        [
            sys.executable,
            "-P",
            "-m",
            "optdot",
            "generate",
            str(LED),
            "-o",
            str(tmp_path / out),
            "--tiles",
            "on",
            "--tile-size",
            "8",
            "--workers",
            "2",
        ],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        start_new_session=True,  # its own process group, as a terminal gives it
        env={**os.environ, **(env or {})},
    )


def _workers_of(proc: subprocess.Popen, timeout: float = 60) -> list[int]:
    """PIDs of the Dask worker processes under ``proc`` once they run tiles (after the
    cluster announced itself on stderr, and a second more)."""
    import psutil

    line = proc.stderr.readline()
    assert line.startswith("local cluster:"), line
    time.sleep(1.0)
    t0 = time.monotonic()
    while time.monotonic() - t0 < timeout:
        kids = [
            k
            for k in psutil.Process(proc.pid).children(recursive=True)
            if "spawn_main" in " ".join(k.cmdline())  # not the resource tracker
        ]
        busy = [k.pid for k in kids if k.cpu_percent(0.2) > 20]
        if len(kids) >= 2 and busy:
            return busy
        time.sleep(0.3)
    raise AssertionError("no worker started")


@pytest.mark.parametrize("cache", ["warm", "cold"])
@pytest.mark.slow
def test_ctrl_c_on_a_tiled_run_is_one_line_and_keeps_nothing(tmp_path, cache):
    # cold: the workers compile the kernels first (a minute), the Ctrl-C lands in that wait
    env = {"NUMBA_CACHE_DIR": str(tmp_path / "numba")} if cache == "cold" else None
    proc = _start_tiled(tmp_path, "d.parquet", env)
    _workers_of(proc)
    os.killpg(proc.pid, signal.SIGINT)  # what a terminal's Ctrl-C does
    out, err = proc.communicate(timeout=60)
    assert proc.returncode == 130, err
    assert err.strip().splitlines()[-1:] == ["optdot: interrupted"], err
    assert "Traceback" not in err and "Error" not in err, err
    assert not (tmp_path / "d.parquet").exists()


@pytest.mark.slow
def test_a_frozen_worker_is_dropped_and_its_tiles_retried(tmp_path):
    ref = _start_tiled(tmp_path, "ref.parquet")
    assert ref.wait(timeout=180) == 0, ref.stderr.read()
    env = {"DASK_DISTRIBUTED__SCHEDULER__WORKER_TTL": "5s"}
    proc = _start_tiled(tmp_path, "d.parquet", env)
    try:
        frozen = _workers_of(proc)[0]  # one that is running a tile
        os.kill(frozen, signal.SIGSTOP)
        try:
            out, err = proc.communicate(timeout=150)
        finally:
            try:
                os.kill(frozen, signal.SIGCONT)
                os.kill(frozen, signal.SIGKILL)
            except ProcessLookupError:
                pass
    finally:
        if proc.poll() is None:  # a run that hung is not left running (nor its workers)
            os.killpg(proc.pid, signal.SIGKILL)
    assert proc.returncode == 0, err
    assert "Traceback" not in err and "Error" not in err, err  # no worker tracebacks
    a = json.loads((tmp_path / "ref.parquet" / "_manifest.json").read_text())
    b = json.loads((tmp_path / "d.parquet" / "_manifest.json").read_text())
    assert [p["sha256"] for p in a["parts"]] == [p["sha256"] for p in b["parts"]]


def test_impossible_jobs_are_refused_before_any_work(tmp_path):
    import shutil

    shutil.copy(SAMPLES / "tiny" / "density.csv", tmp_path / "density.csv")
    base = '[domain]\nwidth = 3.0\nheight = 2.0\n[density]\ngrid = "{grid}"\n[dots]\n'
    base += "diameter = 0.046\n"
    (tmp_path / "gap.toml").write_text(base.format(grid="density.csv") + "[optimize]\ngap = 5.0\n")
    t0 = time.monotonic()
    one_error(["generate", tmp_path / "gap.toml", "-o", tmp_path / "o.csv"], 2, "at most 6.6")
    np.savetxt(tmp_path / "dense.csv", np.full((4, 6), 0.82), delimiter=",")
    (tmp_path / "dense.toml").write_text(base.format(grid="dense.csv"))
    one_error(["generate", tmp_path / "dense.toml", "-o", tmp_path / "o.csv"], 2, "0.8")
    assert time.monotonic() - t0 < 10  # refused up front, not after the optimisation
    np.savetxt(tmp_path / "ok.csv", np.full((4, 6), 0.78), delimiter=",")
    (tmp_path / "ok.toml").write_text(base.format(grid="ok.csv"))
    from optdot.config.schema import load_job
    from optdot.orchestration.preflight import _check_fill

    _check_fill(load_job(tmp_path / "ok.toml"), "ok")  # the guarantee holds at 0.78


def test_too_many_workers_for_the_memory_are_refused_before_spawning(tmp_path):
    import psutil

    before = len(psutil.Process().children(recursive=True))
    t0 = time.monotonic()
    one_error(
        ["generate", TINY, "-o", tmp_path / "d.parquet", "--tiles", "on", "--workers", "1024"],
        2,
        "1024 local workers",
    )
    assert time.monotonic() - t0 < 10
    assert len(psutil.Process().children(recursive=True)) == before


def test_a_histogram_over_a_range_too_narrow_for_numpy_still_has_its_bins():
    from optdot.quality.summary import _histogram

    values = np.array([3e9, 3e9 + 1e-6, 3e9])  # numpy: "Too many bins for data range"
    with pytest.raises(ValueError):
        np.histogram(values, bins=100)
    counts, edges = _histogram(values)
    assert counts.sum() == 3 and len(edges) == 101 and np.all(np.diff(edges) > 0)
    counts, edges = _histogram(np.array([46.0, 60.0, 50.0]))
    assert counts.sum() == 3 and edges[0] == 46.0 and edges[-1] == 60.0


def test_a_huge_value_is_not_echoed_whole(tmp_path):
    import shutil

    shutil.copy(SAMPLES / "tiny" / "density.csv", tmp_path / "density.csv")
    big = "w" * 500_000
    (tmp_path / "j.toml").write_text(
        f'[domain]\nwidth = "{big}"\nheight = 2.0\n[density]\ngrid = "density.csv"\n'
        "[dots]\ndiameter = 0.046\n"
    )
    err = one_error(["generate", tmp_path / "j.toml", "-o", tmp_path / "o.csv"], 2, "width")
    assert len(err) < 700 and " ... " in err


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM])
@pytest.mark.slow
def test_a_long_simulation_stops_at_the_next_batch(tmp_path, sig):
    """``simulate --rays 1e10`` then Ctrl-C or SIGTERM: it kept tracing every ray (days);
    now it stops at the next batch of rays, exit 130, and writes nothing."""
    np.savetxt(tmp_path / "map.csv", np.full((20, 30), 0.2), delimiter=",")
    text = (SAMPLES / "lgp" / "job.toml").read_text()
    (tmp_path / "job.toml").write_text(
        text.replace("[dots]", '[density]\ngrid = "map.csv"\n\n[dots]')
    )
    proc = subprocess.Popen(
        [sys.executable, "-P", "-m", "optdot", "simulate", str(tmp_path / "job.toml"),
         "--rays", str(10**10), "--json", str(tmp_path / "s.json")],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
    )  # fmt: skip
    time.sleep(4)  # imports, the kernels from the cache, the first batches
    assert proc.poll() is None
    t = time.monotonic()
    proc.send_signal(sig)
    out, err = proc.communicate(timeout=60)
    assert proc.returncode == 130, err
    assert time.monotonic() - t < 30
    assert err.strip().splitlines()[-1:] == ["optdot: interrupted"], err
    assert not (tmp_path / "s.json").exists()


def test_a_signal_after_the_command_ended_keeps_its_exit_code():
    """SIGTERM in the last moments of a command whose outputs are complete ended the
    process by the signal's default action (exit 143); after it ends, a signal exits 0,
    and after a failure it is ignored (the failure's code stands)."""
    from optdot.cli.app import user_errors
    from optdot.errors import JobError

    before = signal.getsignal(signal.SIGTERM)
    try:
        signal.signal(signal.SIGTERM, signal.SIG_DFL)
        assert user_errors(lambda: "made")() == "made"
        handler = signal.getsignal(signal.SIGTERM)
        assert callable(handler)
        with pytest.raises(SystemExit) as e:
            handler(signal.SIGTERM, None)
        assert e.value.code == 0
        signal.signal(signal.SIGTERM, signal.SIG_DFL)

        def fails():
            raise JobError("bad")

        with pytest.raises(SystemExit) as e:
            user_errors(fails)()
        assert e.value.code == 2
        assert signal.getsignal(signal.SIGTERM) == signal.SIG_IGN
    finally:
        signal.signal(signal.SIGTERM, before)


LATE_SIGNAL = """
import os, signal, sys, time

class LateTerm:
    # torn down with __main__, after Python reset its signal handlers: a SIGTERM as late
    # as a signal can come
    def __del__(self):
        os.kill(os.getpid(), signal.SIGTERM)
        time.sleep(0.2)

late = LateTerm()
sys.argv = ["optdot", *sys.argv[1:]]
from optdot.console import run
run()
"""


@pytest.mark.slow  # over 1.5 s
def test_a_sigterm_while_the_interpreter_shuts_down_keeps_the_command_s_code(tmp_path):
    """A SIGTERM as the interpreter shuts down (after Python reset its handlers) killed
    the process by the default action, exit 143 (design after writing its outputs,
    export after its refusal line); the command's own code stands: 0 for a check that
    passed, 2 for a refusal."""
    import subprocess
    import sys

    from .conftest import SAMPLES

    script = tmp_path / "late.py"
    script.write_text(LATE_SIGNAL)
    ok = subprocess.run(
        [sys.executable, "-P", str(script), "check", SAMPLES / "tiny" / "job.toml"],
        capture_output=True, text=True,
    )  # fmt: skip
    assert ok.returncode == 0, (ok.returncode, ok.stderr)
    bad = subprocess.run(
        [sys.executable, "-P", str(script), "check", tmp_path / "missing.toml"],
        capture_output=True, text=True,
    )  # fmt: skip
    assert bad.returncode == 2, (bad.returncode, bad.stderr)
