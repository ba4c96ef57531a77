"""Where the compiled kernels are cached, and a damaged cache (optdot.runtime.kernel_cache)."""

from __future__ import annotations

import importlib.util
import os
import tempfile
from pathlib import Path

import numba
import pytest

from optdot.runtime import kernel_cache

KERNEL = "import numba\n\n@numba.njit(cache=True)\ndef f(x):\n    return x + 1\n"


def _entries(f) -> tuple[Path, list[Path]]:
    """A dispatcher's cache index and its machine-code files (one a signature)."""
    index = Path(f._cache._cache_file._index_path)
    return index, sorted(index.parent.glob(index.name.replace(".nbi", ".*.nbc")))


def _kernel(src: Path):
    """A fresh copy of the kernel module ``src`` (a new dispatcher, the same cache file)."""
    spec = importlib.util.spec_from_file_location("optdot_damaged_kernel", src)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module.f


@pytest.mark.parametrize("part", ["index", "machine code"])
def test_a_damaged_cache_entry_is_compiled_again(tmp_path, monkeypatch, part):
    """A kernel's cache entry cut short (a full disk, a killed copy) is read as none: the
    kernel compiles again and its entry is written anew. numba raised an unpickling
    error, and every later run failed on it until the file was found and deleted."""
    monkeypatch.setattr(numba.config, "CACHE_DIR", str(tmp_path / "cache"))
    src = tmp_path / "optdot_damaged_kernel.py"
    src.write_text(KERNEL)
    first = _kernel(src)
    assert first(1) == 2 and first.stats.cache_misses
    index, code = _entries(first)
    damaged = index if part == "index" else code[0]
    damaged.write_bytes(damaged.read_bytes()[:10])
    again = _kernel(src)
    assert again(1) == 2 and again.stats.cache_misses and not again.stats.cache_hits
    healed = _kernel(src)
    assert healed(1) == 2 and healed.stats.cache_hits and not healed.stats.cache_misses


def test_another_signatures_machine_code_is_compiled_again(tmp_path, monkeypatch):
    """Two signatures' machine code swapped (two processes writing a function's
    signatures at once number them alike: :func:`optdot.runtime.kernels.units`): the run
    loaded one for the other ("can't unbox array", every later run); now it compiles."""
    monkeypatch.setattr(numba.config, "CACHE_DIR", str(tmp_path / "cache"))
    src = tmp_path / "optdot_damaged_kernel.py"
    src.write_text(KERNEL)
    first = _kernel(src)
    assert first(1) == 2 and first(1.5) == 2.5
    _, (one, two) = _entries(first)
    a, b = one.read_bytes(), two.read_bytes()
    one.write_bytes(b)
    two.write_bytes(a)
    again = _kernel(src)
    assert again(1) == 2 and again(1.5) == 2.5
    assert sum(again.stats.cache_misses.values()) == 2 and not again.stats.cache_hits


def test_an_index_of_another_shape_is_no_index(tmp_path, monkeypatch):
    """An index numba reads without an error but that holds no table (a list where its
    entries' table stands): every run failed in numba's writing of a new entry."""
    import pickle

    monkeypatch.setattr(numba.config, "CACHE_DIR", str(tmp_path / "cache"))
    src = tmp_path / "optdot_damaged_kernel.py"
    src.write_text(KERNEL)
    first = _kernel(src)
    assert first(1) == 2
    index, _ = _entries(first)
    with open(index, "rb") as fh:
        version = pickle.load(fh)
        stamp, overloads = pickle.loads(fh.read())
    index.write_bytes(pickle.dumps(version) + pickle.dumps((stamp, list(overloads.values()))))
    again = _kernel(src)
    assert again(1) == 2 and again.stats.cache_misses
    assert _kernel(src)(1) == 2


def test_a_folder_is_writable_where_its_nearest_existing_folder_is(tmp_path):
    assert kernel_cache.writable(tmp_path / "a" / "b")
    (tmp_path / "file").write_text("")
    assert not kernel_cache.writable(tmp_path / "file" / "b")  # under a file: never a folder


def test_with_no_writable_cache_the_kernels_compile_into_a_temporary_folder(monkeypatch):
    """An install and a home both read-only (a container, a system-wide install run by an
    account without a home): numba raised at import, and every command (``--version``
    too) ended in a traceback. Now the kernels compile into a folder removed at exit."""
    monkeypatch.delenv("NUMBA_CACHE_DIR", raising=False)
    monkeypatch.setattr(numba.config, "CACHE_DIR", numba.config.CACHE_DIR)  # put back after
    monkeypatch.setattr(kernel_cache, "checkout_cache", lambda: False)
    monkeypatch.setattr(kernel_cache, "writable", lambda folder: False)
    at_exit: list = []
    monkeypatch.setattr(kernel_cache.atexit, "register", at_exit.append)
    kernel_cache.settle()
    folder = Path(os.environ["NUMBA_CACHE_DIR"])
    assert folder.is_dir() and folder.parent == Path(tempfile.gettempdir())
    assert numba.config.CACHE_DIR == str(folder)
    at_exit[0]()
    assert not folder.exists()


def test_a_writable_cache_is_left_to_numba(monkeypatch):
    monkeypatch.delenv("NUMBA_CACHE_DIR", raising=False)
    monkeypatch.setattr(kernel_cache, "checkout_cache", lambda: False)
    monkeypatch.setattr(kernel_cache, "writable", lambda folder: "__pycache__" in str(folder))
    kernel_cache.settle()
    assert "NUMBA_CACHE_DIR" not in os.environ


def test_a_cache_folder_set_where_nothing_can_be_written_is_replaced(tmp_path, monkeypatch):
    """``NUMBA_CACHE_DIR`` set to a folder that cannot be written (a container's
    ``ENV NUMBA_CACHE_DIR=/cache`` with no volume there): numba raised at import on every
    command; now the kernels compile into a temporary folder."""
    (tmp_path / "file").write_text("")
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path / "file" / "cache"))
    monkeypatch.setattr(numba.config, "CACHE_DIR", numba.config.CACHE_DIR)
    monkeypatch.setattr(kernel_cache.atexit, "register", lambda f: None)
    monkeypatch.setattr(kernel_cache, "_temporary", None)
    kernel_cache.settle()
    folder = Path(os.environ["NUMBA_CACHE_DIR"])
    assert folder.is_dir() and folder.name.startswith("optdot-kernels-")
    kernel_cache.discard_temporary()
    assert not folder.exists()


def test_an_empty_xdg_cache_home_is_read_as_numba_reads_it(monkeypatch):
    monkeypatch.setenv("XDG_CACHE_HOME", "")
    assert kernel_cache.numba_user_cache() == Path("numba")  # the working folder's
    monkeypatch.delenv("XDG_CACHE_HOME")
    assert kernel_cache.numba_user_cache() == Path.home() / ".cache" / "numba"


def test_an_exit_before_the_command_loads_removes_the_temporary_cache(tmp_path):
    """The temporary kernel cache was left in the temporary folder by the two exits
    that skip Python's clean-up: a stop while the modules load, a command line that
    cannot load."""
    import subprocess
    import sys

    (tmp_path / "file").write_text("")
    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path / "file" / "x"), TMPDIR=str(tmp_path))
    code = "import sys; sys.modules['optdot.cli'] = None; from optdot.console import run; run()"
    r = subprocess.run([sys.executable, "-P", "-c", code], env=env, capture_output=True)
    assert r.returncode == 70, r.stderr
    assert not list(tmp_path.glob("optdot-kernels-*"))
