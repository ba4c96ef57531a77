"""Where numba caches optdot's compiled kernels, and reading that cache safely.

Settled when ``optdot`` is imported (:func:`settle`), before numba is:

- a source checkout's kernels compile into a cache of their own, named by the sources
  (:func:`checkout_cache`);
- where numba could cache nowhere (an install and a home both read-only: a container, a
  system-wide install run by an account without a home), into a temporary folder this
  process removes at exit (:func:`temporary_cache`): every run compiles, none fails;
- a cache entry numba cannot read back (a file cut short by a full disk, a killed copy)
  is read as no entry (:func:`tolerate_damaged_entries`): the kernel compiles again and
  its entry is written anew. numba raised the unpickling error, and every later run
  failed on it until the file was found and deleted.

Nothing here imports numba: ``import optdot`` stays cheap.
"""

from __future__ import annotations

import atexit
import hashlib
import os
import shutil
import sys
import tempfile
from pathlib import Path

#: Caches of compiled kernels kept for a checkout (the newest; older sources' removed).
KERNEL_CACHES = 3

#: The folder that holds the ``optdot`` package (a checkout's root, or site-packages).
ROOT = Path(__file__).resolve().parents[2]


def settle() -> None:
    """Choose the kernel cache and make reading it safe (see the module doc); a
    ``NUMBA_CACHE_DIR`` the user set is kept where it can be written (numba caches only
    there, and raised at import where it could not: every command failed)."""
    chosen = os.environ.get("NUMBA_CACHE_DIR", "")
    if chosen:
        if not writable(Path(chosen)):
            temporary_cache()
    elif not checkout_cache():
        if not writable(ROOT / "optdot" / "__pycache__") and not writable(numba_user_cache()):
            temporary_cache()
    tolerate_damaged_entries()


def _use(folder: str) -> None:
    """Point numba at ``folder``: read when numba is imported, and by workers."""
    os.environ["NUMBA_CACHE_DIR"] = folder
    if "numba" in sys.modules:  # imported already: its config, before any kernel is made
        sys.modules["numba"].config.CACHE_DIR = folder


def checkout_cache() -> bool:
    """Compile a source checkout's kernels into a numba cache of their own, named by the
    sources of every module that holds kernels; whether it did (False: not a checkout, or
    no writable cache home). numba keys a cached kernel by its own file only: a kernel that
    inlines another module's (the registry's dispatch of a kind's ``inside``, the tracer's
    of a face's ``meet``) would run the old code after that module is edited. An installed
    copy does not change (an upgrade rewrites every file), so it keeps numba's own cache."""
    if not ((ROOT / "pyproject.toml").is_file() and (ROOT / "exporters").is_dir()):
        return False
    digest = hashlib.sha256()
    for path in sorted(ROOT.glob("optdot/**/*.py")) + sorted(ROOT.glob("exporters/**/*.py")):
        text = path.read_bytes()
        if b"numba" in text:
            digest.update(path.relative_to(ROOT).as_posix().encode() + b"\0" + text)
    base = Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "optdot-kernels"
    here = base / digest.hexdigest()[:16]
    try:
        here.mkdir(parents=True, exist_ok=True)
        here.touch()  # the newest
        for old in sorted(base.iterdir(), key=lambda p: p.stat().st_mtime)[:-KERNEL_CACHES]:
            shutil.rmtree(old, ignore_errors=True)
    except OSError:  # no writable cache home: numba's own cache, as installed
        return False
    _use(str(here))
    return True


def numba_user_cache() -> Path:
    """The folder numba caches in when it cannot write beside a kernel's source (its
    user-wide cache: ``$XDG_CACHE_HOME/numba``, else ``~/.cache/numba``; an empty
    ``XDG_CACHE_HOME`` gives ``numba`` in the working folder, as numba reads it)."""
    home = os.getenv("XDG_CACHE_HOME", os.path.expanduser("~/.cache"))  # "" kept, as numba does
    return Path(home) / "numba"


def writable(folder: Path) -> bool:
    """Whether ``folder`` could be made and written in: its nearest existing ancestor is
    a folder this process may write in (``access(2)``, which sees a read-only mount)."""
    p = Path(os.path.abspath(folder))
    while not p.exists():
        if p.parent == p:
            return False
        p = p.parent
    return p.is_dir() and os.access(p, os.W_OK | os.X_OK)


#: The temporary kernel cache this process made, and the process (:func:`temporary_cache`).
_temporary: tuple[str, int] | None = None


def temporary_cache() -> str | None:
    """Cache kernels in a new temporary folder, removed when this process exits
    (:func:`discard_temporary`; the workers and helpers it starts share it); its path, or
    None when none can be made."""
    global _temporary
    try:
        folder = tempfile.mkdtemp(prefix="optdot-kernels-")
    except OSError:
        return None
    _temporary = (folder, os.getpid())
    atexit.register(discard_temporary)
    _use(folder)
    return folder


def discard_temporary() -> None:
    """Remove the temporary kernel cache this process made, if any (not in a forked
    child); called at exit, and before an exit that skips Python's (``os._exit``)."""
    global _temporary
    if _temporary is not None and _temporary[1] == os.getpid():
        shutil.rmtree(_temporary[0], ignore_errors=True)
        _temporary = None


def _tolerant(module) -> None:
    """Make numba's cache (the module ``numba.core.caching``) read an entry it cannot
    load as no entry. Read errors of the file system still raise, as numba's do."""
    index_file, cache = getattr(module, "IndexDataCacheFile", None), getattr(module, "Cache", None)
    if index_file is None or cache is None or getattr(cache, "_optdot_tolerant", False):
        return  # another numba: left as it is
    load_index, load_overload = index_file._load_index, cache._load_overload

    def _load_index(self):
        try:
            found = load_index(self)
        except OSError:
            raise
        except Exception:  # noqa: BLE001 - cut short, or not numba's: no entries
            return {}
        return found if isinstance(found, dict) else {}

    def _load_overload(self, sig, target_context):
        try:
            found = load_overload(self, sig, target_context)
        except OSError:
            raise
        except Exception:  # noqa: BLE001 - an entry that cannot be rebuilt: compile it
            return None
        # another signature's machine code under this one's name (two processes that
        # wrote a function's signatures at once, a file copied over): run, it could not
        # unbox its arguments (every later run failed), or read them wrongly
        args = getattr(getattr(found, "signature", None), "args", None)
        if found is not None and (args is None or tuple(args) != tuple(sig)):
            return None
        return found

    index_file._load_index, cache._load_overload = _load_index, _load_overload
    cache._optdot_tolerant = True


def tolerate_damaged_entries() -> None:
    """:func:`_tolerant` on numba's cache: now if numba is loaded, else as it loads (a
    finder that wraps ``numba.core.caching``'s loading)."""
    from importlib.abc import MetaPathFinder
    from importlib.machinery import PathFinder

    name = "numba.core.caching"
    if name in sys.modules:
        _tolerant(sys.modules[name])
        return

    class TolerantNumbaCache(MetaPathFinder):
        def find_spec(self, fullname, path=None, target=None):
            if fullname != name:
                return None
            spec = PathFinder.find_spec(fullname, path)
            loader = getattr(spec, "loader", None)
            if loader is None or not hasattr(loader, "exec_module"):
                return spec
            run = loader.exec_module

            def exec_module(module):
                run(module)
                _tolerant(module)

            loader.exec_module = exec_module
            return spec

    if not any(type(f).__name__ == "TolerantNumbaCache" for f in sys.meta_path):
        sys.meta_path.insert(0, TolerantNumbaCache())
