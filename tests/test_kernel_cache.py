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
    index = Path(first._cache._cache_file._index_path)
    damaged = index if part == "index" else next(index.parent.glob("*.nbc"))
    damaged.write_bytes(damaged.read_bytes()[:10])
    again = _kernel(src)
    assert again(1) == 2 and again.stats.cache_misses and not again.stats.cache_hits
    healed = _kernel(src)
    assert healed(1) == 2 and healed.stats.cache_hits and not healed.stats.cache_misses


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
