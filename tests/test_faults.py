"""Faults while writing: a full disk or a file-size limit never leaves a wrong file.

Each case runs the real command in a child process under ``RLIMIT_FSIZE`` (Python ignores
SIGXFSZ, so a write past the limit fails with EFBIG, as on a full disk; gdstk's C writer
ignored such failures and left a truncated mask with exit 0)."""

from __future__ import annotations

import os
import stat
import subprocess
import sys

import pytest

from optdot import exporters
from optdot.errors import ExportError
from optdot.io.patterns import load_pattern

from .conftest import SAMPLES

TINY = SAMPLES / "tiny" / "job.toml"
FORMATS = ["gds", "oas", "dxf", "csv", "svg", "png"]


def optdot_limited(limit: int, *args) -> subprocess.CompletedProcess:
    code = (
        "import resource, sys\n"
        f"resource.setrlimit(resource.RLIMIT_FSIZE, ({limit}, {limit}))\n"
        "from optdot.cli import main\n"
        "sys.argv = ['optdot', *sys.argv[1:]]\n"
        "main()\n"
    )
    return subprocess.run(
        [sys.executable, "-P", "-c", code, *map(str, args)], capture_output=True, text=True
    )


@pytest.fixture(scope="module")
def tiny_csv(tmp_path_factory, tiny_pattern):
    d = tmp_path_factory.mktemp("faults")
    path = d / "dots.csv"
    exporters.write(tiny_pattern, "csv", path)
    return path


@pytest.mark.parametrize("fmt", FORMATS)
@pytest.mark.slow
def test_a_write_past_the_file_size_limit_keeps_the_old_file(tmp_path, tiny_csv, fmt):
    full = tmp_path / f"full.{fmt}"
    exporters.write(load_pattern(tiny_csv), fmt, full)
    size = full.stat().st_size
    out = tmp_path / f"v.{fmt}"
    out.write_bytes(b"OLD")
    os.chmod(out, 0o640)
    r = optdot_limited(size // 2, "export", tiny_csv, f"--{fmt}", out, "--job", TINY, "-q")
    assert r.returncode == 2, (r.returncode, r.stderr)
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(f"optdot: error: {out}:"), r.stderr
    assert "Traceback" not in r.stderr and "[GDSTK]" not in r.stderr
    assert out.read_bytes() == b"OLD"
    assert stat.S_IMODE(out.stat().st_mode) == 0o640
    assert sorted(p.name for p in tmp_path.iterdir()) == [f"full.{fmt}", f"v.{fmt}"]


@pytest.mark.slow  # over 2 s on 2 cores
def test_generate_under_a_file_size_limit_keeps_the_old_pattern(tmp_path):
    warm = tmp_path.parent / "warm.npz"  # kernels compiled and cached, unlimited: the
    optdot_limited(1 << 30, "generate", TINY, "-o", warm, "-q")  # limit hits the pattern
    out = tmp_path / "dots.npz"
    out.write_bytes(b"OLD")
    r = optdot_limited(2000, "generate", TINY, "-o", out, "-q")
    assert r.returncode == 2 and "cannot write" in r.stderr, r.stderr
    assert out.read_bytes() == b"OLD" and len(list(tmp_path.iterdir())) == 1


def test_a_replaced_file_keeps_its_permissions(tmp_path, tiny_csv):
    out = tmp_path / "m.gds"
    out.write_bytes(b"OLD")
    os.chmod(out, 0o600)
    exporters.write(load_pattern(tiny_csv), "gds", out)
    assert out.read_bytes()[:4] != b"OLD" and stat.S_IMODE(out.stat().st_mode) == 0o600
    new = tmp_path / "new.gds"
    exporters.write(load_pattern(tiny_csv), "gds", new)
    assert stat.S_IMODE(new.stat().st_mode) == 0o644


@pytest.mark.slow
def test_a_read_only_target_is_never_replaced(tmp_path, tiny_csv):
    """A mask whose write bits are off was protected on purpose (also for root, which
    os.access would let through): refused before the run, old bytes kept."""
    outs = {f: tmp_path / f"v.{f}" for f in ("gds", "dxf")}
    for p in outs.values():
        p.write_bytes(b"OLD")
    os.chmod(outs["dxf"], 0o444)
    r = optdot_limited(
        10**9, "export", tiny_csv, "--gds", outs["gds"], "--dxf", outs["dxf"], "--no-job"
    )
    assert r.returncode == 2 and "is read-only (mode 0444)" in r.stderr, r.stderr
    assert len(r.stderr.strip().splitlines()) == 1
    assert all(p.read_bytes() == b"OLD" for p in outs.values())
    with pytest.raises(ExportError, match="read-only"):
        exporters.write(load_pattern(tiny_csv), "dxf", outs["dxf"])
    assert sorted(p.name for p in tmp_path.iterdir()) == ["v.dxf", "v.gds"]


@pytest.mark.slow
@pytest.mark.parametrize("where", ["/sys/optdot-test.gds", "/proc/optdot-test.gds"])
def test_an_unwritable_place_is_one_line(tiny_csv, where):
    r = optdot_limited(10**9, "export", tiny_csv, "--gds", where, "--no-job")
    assert r.returncode == 2 and r.stderr.startswith(f"optdot: error: {where}"), r.stderr
    assert len(r.stderr.strip().splitlines()) == 1


def test_a_failed_output_replaces_none_of_the_set(tmp_path, tiny_csv):
    """--oas (small, written first) succeeds, --dxf (large) hits the limit: the OAS file
    must not be replaced either."""
    sizes = {}
    for fmt in ("oas", "dxf"):
        exporters.write(load_pattern(tiny_csv), fmt, tmp_path / f"full.{fmt}")
        sizes[fmt] = (tmp_path / f"full.{fmt}").stat().st_size
    assert sizes["oas"] * 2 < sizes["dxf"]
    outs = {f: tmp_path / f"v.{f}" for f in ("oas", "dxf")}
    for p in outs.values():
        p.write_bytes(b"OLD")
    limit = (sizes["oas"] + sizes["dxf"]) // 2
    r = optdot_limited(
        limit, "export", tiny_csv, "--oas", outs["oas"], "--dxf", outs["dxf"], "-q", "--no-job"
    )
    assert r.returncode == 2 and str(outs["dxf"]) in r.stderr, r.stderr
    assert all(p.read_bytes() == b"OLD" for p in outs.values())
    assert sorted(p.name for p in tmp_path.iterdir()) == ["full.dxf", "full.oas", "v.dxf", "v.oas"]


def test_an_interrupt_in_the_middle_of_a_set_replaces_nothing(tmp_path, tiny_pattern, monkeypatch):
    from optdot.io.atomic import transaction

    outs = {f: tmp_path / f"v.{f}" for f in ("gds", "csv", "svg")}
    for p in outs.values():
        p.write_bytes(b"OLD")
    real = exporters.write
    calls = []

    def write(pattern, fmt, path, opts=None):
        calls.append(fmt)
        if fmt == "svg":
            raise KeyboardInterrupt
        real(pattern, fmt, path, opts)

    monkeypatch.setattr(exporters, "write", write)
    with pytest.raises(KeyboardInterrupt), transaction():
        for fmt, path in outs.items():
            exporters.write(tiny_pattern, fmt, path)
    assert calls == ["gds", "csv", "svg"]
    assert all(p.read_bytes() == b"OLD" for p in outs.values())
    assert len(list(tmp_path.iterdir())) == 3
    with transaction(replace_masks=True):  # and a set that completes replaces all of them
        for fmt, path in outs.items():
            real(tiny_pattern, fmt, path)
    assert all(p.read_bytes() != b"OLD" for p in outs.values())


@pytest.mark.parametrize(
    "signame,delay",
    [
        ("SIGINT", 0.15),
        ("SIGTERM", 0.15),
        ("SIGINT", 0.3),
        ("SIGTERM", 0.6),
        ("SIGTERM", 1.2),
        ("SIGINT", 0.9),
    ],
)
@pytest.mark.slow
def test_a_signal_during_export_leaves_the_old_files(tmp_path, signame, delay):
    """At any point of the run (imports, numba's cache load, relaxation, writing): exit 130,
    one line, old files byte-identical, no temporary file left. With ``--overwrite``, a
    run that would replace them: without it a quiet machine's run refused the old masks
    (exit 2) about 1.6 s in, before the latest signal came."""
    import signal
    import time

    outs = {f: tmp_path / f"v.{f}" for f in ("gds", "oas", "dxf", "csv")}
    for p in outs.values():
        p.write_bytes(b"OLD")
    args = [sys.executable, "-P", "-m", "optdot", "export", SAMPLES / "led" / "job.toml", "-q"]
    for f, p in outs.items():
        args += [f"--{f}", p]
    args.append("--overwrite")
    proc = subprocess.Popen(list(map(str, args)), stderr=subprocess.PIPE, text=True)
    time.sleep(delay)
    proc.send_signal(getattr(signal, signame))
    err = proc.communicate(timeout=120)[1]
    assert proc.returncode == 130, err
    assert err.strip() == "optdot: interrupted"
    assert all(p.read_bytes() == b"OLD" for p in outs.values())
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(p.name for p in outs.values())
