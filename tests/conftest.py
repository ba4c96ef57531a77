from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from hypothesis import settings

ROOT = Path(__file__).resolve().parents[1]
SAMPLES = ROOT / "samples"
# a checkout's kernels compile into a cache named by their sources (optdot/__init__.py:
# numba keys a cached kernel by its own file only, and a broken kernel could pass)


@pytest.fixture(scope="session", autouse=True)
def _kernels_compiled_on_all_cores():
    """On an empty kernel cache (a fresh install), the listed kernels of a run and of the
    tracer compiled first on all cores, as a first ``generate`` does
    (:func:`optdot.runtime.kernels.warm`); nothing when they are cached."""
    from optdot.runtime.kernels import warm

    warm(("generate", "simulate", "shapes"))


# the same examples every run (a property test that finds a case one day and not the
# next is not a gate); tests that set their own settings keep them
settings.register_profile("optdot", derandomize=True, database=None)
settings.load_profile("optdot")


def write_job(tmp: Path, grid: np.ndarray | str, **sections) -> Path:
    """Write a job + grid into ``tmp``; ``sections`` override/add TOML lines per section
    (a value of None removes that key)."""
    if isinstance(grid, str):
        (tmp / "density.csv").write_text(grid)
    else:
        np.savetxt(tmp / "density.csv", grid, delimiter=",", fmt="%.6g")
    base = {
        "domain": {"width": 2.0, "height": 1.5},
        "density": {"grid": '"density.csv"'},
        "dots": {"diameter": 0.046},
        "optimize": {"max_iter": 60, "seed": 3},
    }
    for k, v in sections.items():
        sec = base.setdefault(k, {})
        for kk, vv in v.items():
            if vv is None:  # None removes a default key
                sec.pop(kk, None)
            else:
                sec[kk] = vv
    lines = []
    for sec, kv in base.items():
        lines.append(f"[{sec}]")
        lines += [f"{k} = {v}" for k, v in kv.items()]
    path = tmp / "job.toml"
    path.write_text("\n".join(lines) + "\n")
    return path


@pytest.fixture(scope="session")
def tiny_job():
    from optdot.config.schema import load_job

    return load_job(SAMPLES / "tiny" / "job.toml")


@pytest.fixture(scope="session")
def tiny_pattern(tiny_job):
    from optdot.orchestration.pipeline import generate

    return generate(tiny_job)


def cli(*args):
    """``(exit code, stderr lines, stdout)`` of an ``optdot`` command run in-process, as a
    user sees them (an exception escaping the top-level handler fails the test)."""
    from click.testing import CliRunner

    from optdot.cli import main

    r = CliRunner().invoke(main, [str(a) for a in args])
    assert r.exception is None or isinstance(r.exception, SystemExit), r.exception
    return r.exit_code, r.stderr.strip().splitlines(), r.stdout


def optdot(*args, check: bool = False):
    """``python -P -m optdot *args`` in a child process, as a user runs it (signals, exit
    codes and stderr of the real process; ``-P``: the installed optdot, not the folder
    the tests run in): the ``CompletedProcess``; with ``check`` its exit code must be 0."""
    import subprocess
    import sys

    r = subprocess.run(
        [sys.executable, "-P", "-m", "optdot", *map(str, args)], capture_output=True, text=True
    )
    if check:
        assert r.returncode == 0, r.stderr
    return r


def one_error(args, code: int, *words: str) -> str:
    """Run ``optdot *args``: it must end with exit ``code`` and one line on stderr,
    ``optdot: error: ...`` holding each of ``words``; that line is returned."""
    rc, err, _ = cli(*args)
    assert rc == code, (rc, err)
    assert len(err) == 1, err
    assert err[0].startswith("optdot: error: "), err
    assert "Traceback" not in err[0]
    for w in words:
        assert w in err[0], (w, err[0])
    return err[0]


def graded_guide(
    tmp: Path,
    fill: tuple[float, float],
    dots: str,
    more: str = "",
    thickness: float = 0.4,
    optimize: str = "",
    guide: str = "",
    domain: str = "",
) -> Path:
    """A 10 x 8 mm guide ``thickness`` mm thick, lit by two LEDs 1 mm wide at x = 2.5 and
    7.5 mm on its bottom edge, its map graded along y from ``fill[0]`` to ``fill[1]`` (8 x
    10 cells): ``dots`` the ``[dots]`` lines, ``more`` whole sections after them (an
    ``[orientation]``), ``optimize``, ``guide`` and ``domain`` more keys of those
    sections. Written into ``tmp``; the job's path."""
    grid = np.repeat(np.linspace(fill[0], fill[1], 8)[:, None], 10, axis=1)
    np.savetxt(tmp / "grad.csv", grid, delimiter=",")
    text = f"""[domain]
width = 10.0
height = 8.0
{domain}
[density]
grid = "grad.csv"
[dots]
{dots}
{more}
[optimize]
seed = 1
{optimize}
[light_guide]
thickness = {thickness}
{guide}
[[light_guide.leds]]
edge = "bottom"
positions = [2.5, 7.5]
width = 1.0
"""
    (tmp / "job.toml").write_text(text)
    return tmp / "job.toml"


def bare_guide(w: float, h: float, t: float, n: float, dots: dict, y: float, width: float) -> dict:
    """The job (a raw dict) of a ``w`` x ``h`` x ``t`` mm guide of index ``n`` that the
    pvtrace comparisons trace: ``dots`` its ``[dots]``, no absorption, white dots,
    nothing under it, bare edges, one LED ``width`` mm wide at ``y`` on the left edge."""
    guide = {"thickness": t, "refractive_index": n, "absorption": 0.0, "dot_albedo": 1.0}
    guide |= {"reflector": 0.0, "edge_reflectance": 0.0}
    guide["leds"] = [{"edge": "left", "positions": [y], "width": width}]
    return {"domain": {"width": w, "height": h}, "dots": dots, "light_guide": guide}


def pvtrace_left_led(pv, world, y: float, width: float, thickness: float) -> None:
    """A Lambertian LED ``width`` mm wide centred at ``y`` on the left edge (``x = 0``) of
    a guide ``thickness`` mm thick, 0.1 um outside it: a node of pvtrace's ``world``
    (``pv``: :func:`load_pvtrace`'s module; draws from ``np.random``)."""

    def position():
        return (-1e-4, y + (np.random.uniform() - 0.5) * width, np.random.uniform() * thickness)

    def direction():
        u, v = np.random.uniform(), np.random.uniform()
        s = math.sqrt(u)
        return (math.sqrt(1 - u), s * math.cos(2 * math.pi * v), s * math.sin(2 * math.pi * v))

    pv.Node(name="led", light=pv.Light(position=position, direction=direction), parent=world)


def load_pvtrace():
    """The pvtrace module (an independent ray tracer the optics tests compare against),
    with the numpy aliases pvtrace 2.1 still uses (numpy 1.24 removed them) and its
    logging quiet."""
    import logging

    for name, typ in (("float", float), ("int", int), ("bool", bool)):
        if not hasattr(np, name):
            setattr(np, name, typ)
    try:
        import pvtrace
    except ImportError:  # a failure, not a skip: a comparison left out must not pass
        pytest.fail("pvtrace is not installed: pip install '.[validation]'", pytrace=False)

    logging.getLogger("pvtrace").setLevel(logging.WARNING)
    return pvtrace
