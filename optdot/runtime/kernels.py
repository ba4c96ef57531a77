"""A first run's compile, spread over processes.

numba compiles a kernel on its first call and caches it on disk; a run after that loads
it in milliseconds. A first run after an install therefore compiles every kernel it
calls before its work: ~55 s of the led sample's ~60 s on this machine's core, ~30 s of
a tiled panel's first run. numba compiles in Python, one kernel at a time in a process,
so the other cores wait.

This module compiles a command's kernels on a cold cache in several processes at once.
``kernels.json`` lists, for each group of work (``"generate"``: a one-process run and
its QA; ``"tiles"``: a tiled run's tasks; ``"simulate"``: the tracer; ``"shapes"``:
shaped dots' own), the kernels it
calls with their signatures (numba types, pickled) and what each took to compile. It is
recorded from real runs by ``python benchmarks/kernels.py --write`` and a test holds it
to what the code calls. :func:`warm` finds the group's kernels with no cache on disk and
compiles them, a unit at a time (a kernel with the functions it calls), the longest
first, in helper processes (``python -m optdot.runtime.kernels``) while the run waits,
answering a stop at once: each helper claims the next unit as it finishes one
(:func:`compile_claimed`), so the recorded times, which a process's own first compile
skews, only order the work. Each writes numba's cache; the run then loads every kernel.
The machine code is the same whoever compiled it, so the output's bytes are too. A tiled
run does the same on its workers.

Nothing here is needed for a correct run: a kernel the list misses, a signature that
changed, a helper that failed or another numba version (the list is then not used) all
leave the run compiling on first call, as without this module.
"""

from __future__ import annotations

import base64
import importlib
import json
import os
import pickle
import subprocess
import sys
import tempfile
import time
import zlib
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

from .kernel_cache import ROOT
from .stop import check_interrupt

#: The list of kernels (recorded by ``benchmarks/kernels.py --write``).
MANIFEST = Path(__file__).with_name("kernels.json")

#: Environment variable that sets the processes :func:`warm` may use (``1``: none but
#: the command's, which then compiles each kernel on its first call).
PROCESSES_ENV = "OPTDOT_COMPILE_PROCESSES"

#: Processes that compile at once, at most: each holds numba and LLVM (~0.3 GB), and
#: past four the largest unit (the penalty kernel's, 15-20 s) bounds the wait anyway.
MAX_PROCESSES = 4


@dataclass(frozen=True)
class Kernel:
    """One compiled specialization of a numba kernel.

    Attributes:
        module: the module that defines it, ``"optdot.relax.penalty"``.
        name: its name there, ``"_penalty_kernel"``.
        types: the signature as numba prints it (for people and the test).
        seconds: what compiling it took when the list was recorded, s (for dealing).
        groups: the work that calls it: ``"generate"``, ``"tiles"``.
        unit: the kernel called from Python (``"module.name(types)"``) whose compile
            compiled this one: a unit is compiled in one process.
        depth: 0 for a kernel called from Python, 1 for one it calls, ...: a unit is
            compiled deepest first, so that a caller in another process finds the
            functions it shares with this unit cached sooner.
        signature: the argument types (numba types), or None when not loaded.
    """

    module: str
    name: str
    types: str
    seconds: float
    groups: tuple[str, ...]
    unit: str = ""
    depth: int = 0
    signature: tuple | None = None

    def dispatcher(self):
        """The numba dispatcher (imports its module)."""
        return getattr(importlib.import_module(self.module), self.name)


def signature_text(signature: tuple) -> str:
    """A signature as text: ``"(array(float64, 2d, C), float64)"``."""
    return "(" + ", ".join(str(t) for t in signature) + ")"


def encode(kernels: list[Kernel], numba_version: str) -> dict:
    """The JSON document of :data:`MANIFEST` for ``kernels`` (each with its signature)."""
    blob = pickle.dumps([k.signature for k in kernels], protocol=4)
    return {
        "numba": numba_version,
        "kernels": [
            {
                "module": k.module,
                "name": k.name,
                "types": k.types,
                "seconds": round(k.seconds, 2),
                "groups": list(k.groups),
                "unit": k.unit,
                "depth": k.depth,
            }
            for k in kernels
        ],
        "signatures": base64.b64encode(zlib.compress(blob, 9)).decode("ascii"),
    }


def decode(doc: dict, numba_version: str) -> list[Kernel]:
    """The kernels of a :data:`MANIFEST` document; their signatures loaded only when it
    was recorded with this numba (``numba_version``), else None."""
    sigs: list = [None] * len(doc["kernels"])
    if doc.get("numba") == numba_version:
        sigs = pickle.loads(zlib.decompress(base64.b64decode(doc["signatures"])))
    return [
        Kernel(
            e["module"],
            e["name"],
            e["types"],
            float(e["seconds"]),
            tuple(e["groups"]),
            e["unit"],
            int(e["depth"]),
            s,
        )
        for e, s in zip(doc["kernels"], sigs, strict=True)
    ]


@lru_cache(maxsize=1)
def manifest() -> tuple[Kernel, ...]:
    """The kernels of :data:`MANIFEST` (none when it cannot be read)."""
    import numba

    try:
        return tuple(decode(json.loads(MANIFEST.read_text()), numba.__version__))
    except Exception:  # a list that cannot be read is one not used
        return ()


def cached(kernel: Kernel) -> bool:
    """Whether numba's cache on disk (in this process's cache folder) has a current index
    for ``kernel``'s function: one written by this numba from this source file (numba
    reads an index of an older install as empty). True when it cannot tell."""
    try:
        return bool(kernel.dispatcher()._cache._cache_file._load_index())
    except Exception:
        return True


def cold(group: str | tuple[str, ...]) -> list[int]:
    """Indices into :func:`manifest` of ``group``'s kernels (those of any of several
    groups) that numba has not cached."""
    groups = (group,) if isinstance(group, str) else group
    return [
        i
        for i, k in enumerate(manifest())
        if set(groups) & set(k.groups) and k.signature is not None and not cached(k)
    ]


def units(indices: list[int]) -> list[list[int]]:
    """``indices`` (into :func:`manifest`) by unit (:attr:`Kernel.unit`), units that share
    a function (two signatures of one kernel, or a kernel both call) joined into one, the
    units with the most compile time first (so the last to start are the shortest).

    One process compiles all of a function's signatures: numba numbers the cache files
    of a function's signatures from the index it read, so two processes writing two
    signatures of one function at once may each take the same file, and the index then
    names one signature's machine code for the other's (a run loading it fails: "can't
    unbox array")."""
    kernels = manifest()
    found: dict[str, list[int]] = {}
    for i in indices:
        found.setdefault(kernels[i].unit, []).append(i)
    groups: list[list[int]] = []
    owner: dict[str, int] = {}  # a function's group
    for members in found.values():
        names = {f"{kernels[i].module}.{kernels[i].name}" for i in members}
        joined = sorted({owner[n] for n in names if n in owner})
        merged = list(members)
        for g in reversed(joined):  # fold every group sharing a function into this one
            merged += groups[g]
            groups[g] = []
        groups.append(merged)
        for i in merged:
            owner[f"{kernels[i].module}.{kernels[i].name}"] = len(groups) - 1
    work = [sorted(g) for g in groups if g]
    return sorted(work, key=lambda m: (-sum(kernels[i].seconds for i in m), m))


def compile_kernels(indices: list[int]) -> int:
    """Compile (and cache) the kernels ``indices`` of :func:`manifest` in this process,
    the deepest first (:attr:`Kernel.depth`); returns how many compiled. One that does
    not compile (a list older than the code) is left to the run's first call."""
    kernels = manifest()
    done = 0
    for i in sorted(indices, key=lambda i: (-kernels[i].depth, i)):
        check_interrupt()
        try:
            kernels[i].dispatcher().compile(kernels[i].signature)
        except Exception:
            continue
        done += 1
    return done


def compile_claimed(work: list[list[int]], claims: str, parent: int | None = None) -> int:
    """Compile the units ``work`` (:func:`units`) that no other process has claimed in
    the folder ``claims``, in turn: a unit is claimed by creating the file of its number
    there (exclusively), so processes sharing the folder take the next unit as each
    finishes one, whatever the recorded times. With ``parent`` (a process id), stop
    before a unit once that process is gone. Returns the kernels compiled here."""
    done = 0
    for u, members in enumerate(work):
        if parent is not None and os.getppid() != parent:
            break  # the run that started this helper is gone
        try:
            os.close(os.open(os.path.join(claims, str(u)), os.O_CREAT | os.O_EXCL | os.O_WRONLY))
        except FileExistsError:
            continue
        done += compile_kernels(members)
    return done


def usable_cores() -> int:
    """CPUs this process may run on."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        return os.cpu_count() or 1


def processes_allowed() -> int:
    """Processes a first run's compile may use: :data:`PROCESSES_ENV` when it is a
    positive whole number, else the usable cores; at most :data:`MAX_PROCESSES`."""
    text = os.environ.get(PROCESSES_ENV, "").strip()
    whole = text.isascii() and text.isdigit()  # not "²", which isdigit() takes
    count = int(text) if whole and int(text) > 0 else usable_cores()
    return min(count, MAX_PROCESSES)


def warm(group: str | tuple[str, ...], processes: int | None = None, announce=None) -> int:
    """Compile ``group``'s uncached kernels (or several groups') in up to ``processes``
    helper processes at once (default :func:`processes_allowed`), telling
    ``announce`` (a callable taking one line) first. Returns the kernels now cached that
    were not; 0 when all were cached or one process would do it (the run then compiles
    them on first call, as it would).

    Raises:
        KeyboardInterrupt: a stop was asked for (the helpers are stopped first).
    """
    allowed = processes or processes_allowed()
    if allowed < 2:
        return 0
    todo = cold(group)
    work = units(todo)
    count = min(allowed, len(work))
    if count < 2:
        return 0
    if announce is not None:
        announce("compiling kernels (first run)")
    try:
        _compile_together(work, count)
    except OSError:  # no temporary folder, no process: the run compiles on first call
        pass
    return len(todo) - len(cold(group))


def package_home() -> str:
    """The folder holding the optdot package this process runs: a helper started there
    (``python -m`` puts the folder it starts in first on the import path) compiles this optdot's
    kernels into this optdot's cache. Started from a checkout's folder instead, as a
    command run in the checkout a package was installed from is, it would compile the
    checkout's modules into their own cache, and the run would compile its own again."""
    return str(ROOT)


def start_helper(work: list[list[int]], claims: str) -> subprocess.Popen:
    """A helper process compiling the units ``work`` not claimed in the folder ``claims``
    (:func:`compile_claimed`), started in :func:`package_home`, with nothing to read or
    print; it stops when this process is gone (:func:`main`)."""
    args = [sys.executable, "-m", __name__, claims, json.dumps(work), str(os.getpid())]
    quiet = subprocess.DEVNULL
    return subprocess.Popen(args, stdin=quiet, stdout=quiet, stderr=quiet, cwd=package_home())


def _compile_together(work: list[list[int]], count: int) -> None:
    """:func:`compile_claimed` in ``count`` helpers sharing a temporary claims folder,
    while this process only waits: it sees a stop asked for within 50 ms (compiling a
    unit itself, it saw one only between kernels: 9 s into the penalty kernel's). The
    helpers are stopped if this process stops, and stop if it dies."""
    with tempfile.TemporaryDirectory(prefix="optdot-compile-") as claims:
        helpers: list[subprocess.Popen] = []
        try:
            for _ in range(count):
                helpers.append(start_helper(work, claims))
            for p in helpers:
                while p.poll() is None:
                    check_interrupt()
                    time.sleep(0.05)
        finally:
            for p in helpers:
                if p.poll() is None:
                    p.kill()
                    p.wait()


def _die_with(parent: int) -> None:
    """End this helper when the process ``parent`` ends, even killed (Linux: the
    kernel's parent-death signal; elsewhere :func:`compile_claimed` looks between units)."""
    try:
        import ctypes

        libc = ctypes.CDLL(None, use_errno=True)
        libc.prctl(1, 9)  # PR_SET_PDEATHSIG, SIGKILL
    except (OSError, AttributeError):
        pass
    if os.getppid() != parent:  # gone before the signal was asked for
        sys.exit(0)


def main(argv: list[str]) -> int:
    """A helper: ``CLAIMS WORK PARENT``, :func:`compile_claimed` with the units ``WORK``
    (JSON) while the process ``PARENT`` lives."""
    parent = int(argv[2]) if len(argv) > 2 else None
    if parent is not None:
        _die_with(parent)
    compile_claimed(json.loads(argv[1]), argv[0], parent)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
