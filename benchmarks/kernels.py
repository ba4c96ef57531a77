"""The kernels each kind of work compiles, for a first run's compile in several processes
(:mod:`optdot.runtime.kernels`), and what a first run's compile takes.

    python benchmarks/kernels.py            # check optdot/runtime/kernels.json (exit 1: stale)
    python benchmarks/kernels.py --write    # record it again (cold caches: ~2 minutes)
    python benchmarks/kernels.py --time     # a cold led-sample generate, 1 process and all cores

Each group's work runs in a fresh process: ``generate`` the README's led sample in one
process (written to NPZ) and QA on it, ``tiles`` the tiny tiled job a cluster's workers
warm up with (one numba thread), ``simulate`` the ellipses sample's guide traced as its
map's coverage (the tracer is the same kernel for real dots and every stack), ``shapes``
the ellipses, prisms and hexagons samples in one process and QA on each. Then every
numba dispatcher of an optdot module lists its signatures. ``--write`` runs each on an
empty numba cache (``NUMBA_CACHE_DIR`` in a temporary folder) and times every compile
(numba's compile events; each compile's own time, without the functions compiled inside
it). A function compiled inside a kernel's compile (called from compiled code) is listed
in that kernel's unit; the check leaves them out: a run on a warm cache loads a kernel whole.
"""

from __future__ import annotations

import argparse
import base64
import json
import os
import pickle
import subprocess
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))  # _common, panels

ROOT = Path(__file__).resolve().parent.parent
LED = ROOT / "samples" / "led" / "job.toml"
ELLIPSES = ROOT / "samples" / "ellipses" / "job.toml"
#: The shaped samples whose runs make the ``shapes`` group (each kind's gap and terms).
SHAPED = ("ellipses", "prisms", "hexagons")
GROUPS = ("generate", "tiles", "simulate", "shapes")


def _work(group: str, folder: Path) -> None:
    """Run ``group``'s work in this process."""
    from optdot import load_job
    from optdot.io.patterns import load_pattern
    from optdot.orchestration.pipeline import generate_to, qa

    if group == "generate":
        job = load_job(LED)
        generate_to(job, folder / "led.npz", tiles="off")
        qa(load_pattern(folder / "led.npz", job.box), job)
    elif group == "shapes":
        for name in SHAPED:
            job = load_job(ROOT / "samples" / name / "job.toml")
            generate_to(job, folder / f"{name}.npz", tiles="off")
            qa(load_pattern(folder / f"{name}.npz", job.box), job)
    elif group == "simulate":
        from optdot.optics.simulate import simulate

        simulate(load_job(ELLIPSES).bench, 20_000)
    else:
        from optdot.orchestration.tiling.run import warm_up

        warm_up()


def _child(group: str, folder: Path, out: Path) -> None:
    """Run ``group``'s work, then write the signatures of every optdot dispatcher (and
    the seconds each compile took here) to ``out`` as JSON lines."""
    from numba.core import event
    from numba.core.dispatcher import Dispatcher

    seconds: dict[tuple, float] = {}  # each compile's own, without the compiles inside it
    depth: dict[tuple, int] = {}  # 0: called from Python; 1: compiled inside such; ...
    root: dict[tuple, tuple] = {}  # the kernel called from Python it was compiled for
    stack: list[list] = []  # [key, start, seconds of the compiles inside it]

    class Timer(event.Listener):
        def on_start(self, ev):
            key = self._key(ev)
            depth.setdefault(key, len(stack))
            root.setdefault(key, stack[0][0] if stack else key)
            stack.append([key, time.perf_counter(), 0.0])

        def on_end(self, ev):
            key, t0, inside = stack.pop()
            took = time.perf_counter() - t0
            seconds[key] = took - inside
            if stack:
                stack[-1][2] += took

        @staticmethod
        def _key(ev):
            d = ev.data["dispatcher"]
            return (id(d), tuple(map(str, ev.data["args"])))

    event.register("numba:compile", Timer())
    _work(group, folder)
    from optdot.runtime.kernels import signature_text

    listed = []
    for name, mod in sorted(sys.modules.items()):
        if not name.startswith("optdot"):
            continue
        for attr, d in sorted(vars(mod).items()):
            if isinstance(d, Dispatcher) and d.py_func.__module__ == name:
                listed += [(name, attr, d, sig) for sig in d.signatures]
    text = {(id(d), tuple(map(str, s))): f"{m}.{a}{signature_text(s)}" for m, a, d, s in listed}
    with open(out, "w") as fh:
        for name, attr, d, sig in listed:
            key = (id(d), tuple(map(str, sig)))
            entry = {
                "module": name,
                "name": attr,
                "types": signature_text(sig),
                "seconds": seconds.get(key, 0.0),
                "depth": depth.get(key, 0),
                "unit": text.get(root.get(key, key), text[key]),
                "signature": base64.b64encode(pickle.dumps(sig, protocol=4)).decode(),
            }
            fh.write(json.dumps(entry) + "\n")


def record(cold: bool) -> list:
    """Every group's kernels (:class:`optdot.runtime.kernels.Kernel`, signatures loaded),
    in module, name and signature order; timed on empty caches when ``cold``."""
    from optdot.runtime.kernels import Kernel

    found: dict[tuple, Kernel] = {}
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        for group in GROUPS:
            env = dict(os.environ, OPTDOT_COMPILE_PROCESSES="1")  # every compile timed here
            if cold:
                cache = folder / f"cache-{group}"
                cache.mkdir()
                env["NUMBA_CACHE_DIR"] = str(cache)
            if group == "tiles":
                env["NUMBA_NUM_THREADS"] = "1"
            out = folder / f"{group}.jsonl"
            args = [sys.executable, __file__, "--child", group, str(folder), str(out)]
            subprocess.run(args, env=env, check=True)
            for line in out.read_text().splitlines():
                e = json.loads(line)
                key = (e["module"], e["name"], e["types"])
                old = found.get(key)
                groups = tuple(sorted(set(old.groups if old else ()) | {group}))
                secs = max(e["seconds"], old.seconds if old else 0.0)
                unit, depth = (old.unit, old.depth) if old else (e["unit"], e["depth"])
                sig = pickle.loads(base64.b64decode(e["signature"]))
                found[key] = Kernel(*key, secs, groups, unit, depth, sig)
    return [found[k] for k in sorted(found)]


def check() -> int:
    """Compare :data:`optdot.runtime.kernels.MANIFEST` with what the code calls now."""
    from optdot.runtime.kernels import MANIFEST

    listed = {  # a run on a warm cache loads a kernel whole: its callees are not seen
        (e["module"], e["name"], e["types"], tuple(e["groups"]))
        for e in json.loads(MANIFEST.read_text())["kernels"]
        if not e["depth"]
    }
    now = {(k.module, k.name, k.types, k.groups) for k in record(cold=False)}
    for e in sorted(now - listed):
        print("not listed:", *e)
    for e in sorted(listed - now):
        print("listed, not called:", *e)
    if now != listed:
        print(f"{MANIFEST.name} is stale: python benchmarks/kernels.py --write")
        return 1
    print(f"{MANIFEST.name}: {len(now)} kernels, as the code calls them")
    return 0


def write() -> None:
    """Record :data:`optdot.runtime.kernels.MANIFEST` on empty caches."""
    import numba

    from optdot.runtime.kernels import MANIFEST, encode

    kernels = record(cold=True)
    MANIFEST.write_text(json.dumps(encode(kernels, numba.__version__), indent=1) + "\n")
    total = sum(k.seconds for k in kernels)
    print(f"{MANIFEST}: {len(kernels)} kernels, {total:.1f} s of compile as recorded")


def timed() -> None:
    """A cold led-sample generate, compiled in one process and then on all cores: dots,
    seconds, dots/s and the peak RSS of all its processes (helpers included)."""
    import numpy as np
    from _common import machine
    from panels import PEAK_SPLIT, optdot, run

    from optdot.runtime.kernels import PROCESSES_ENV

    print(machine())
    print("| compile | dots | s | dots/s | peak GiB, all processes (each) |")
    print("|---|---|---|---|---|")
    saved = dict(os.environ)
    try:
        for label, procs in (("1 process", "1"), ("all cores", None)):
            with tempfile.TemporaryDirectory() as tmp:
                os.environ["NUMBA_CACHE_DIR"] = tmp
                os.environ.pop(PROCESSES_ENV, None)
                if procs:
                    os.environ[PROCESSES_ENV] = procs
                out = Path(tmp) / "led.npz"
                secs, peak, code, err = run(optdot("generate", LED, "-o", out, "-q"))
                if code:
                    raise SystemExit(err)
                dots = len(np.load(out)["xy"])
                each = " + ".join(f"{g:.2f}" for g in PEAK_SPLIT)
                rate = f"{dots / secs:,.0f}"
                print(f"| {label} | {dots:,} | {secs:.1f} | {rate} | {peak:.2f} ({each}) |")
    finally:
        os.environ.clear()
        os.environ.update(saved)


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--write", action="store_true", help="record kernels.json again")
    p.add_argument("--time", action="store_true", help="time a cold generate")
    p.add_argument("--child", nargs=3, help=argparse.SUPPRESS)
    a = p.parse_args()
    if a.child:
        _child(a.child[0], Path(a.child[1]), Path(a.child[2]))
        return 0
    if a.time:
        timed()
        return 0
    if a.write:
        write()
        return 0
    return check()


if __name__ == "__main__":
    sys.exit(main())
