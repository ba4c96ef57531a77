"""The README's Python blocks run as a user pastes them: in a Python started at the
checkout's root (where the checkout's ``optdot/`` folder shadows the installed package),
each block alone, and all of them one after the other in one interpreter, as a notebook
runs them."""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / "README.md"


def python_blocks() -> list[str]:
    """The README's fenced ``python`` blocks, in order."""
    return re.findall(r"```python\n(.*?)```", README.read_text(), flags=re.S)


def _checkout(tmp: Path) -> Path:
    """A folder that looks like the checkout's root to a Python started there (its
    ``optdot``, ``exporters`` and ``samples``), whose outputs land in ``tmp``."""
    tmp.mkdir(parents=True, exist_ok=True)
    for name in ("optdot", "exporters", "samples"):
        (tmp / name).symlink_to(ROOT / name)
    return tmp


def _paste(code: str, where: Path) -> subprocess.CompletedProcess:
    """``code`` run by ``python -c`` in ``where``: the folder first on ``sys.path`` and
    ``__main__`` without a file, as an interactive interpreter or a notebook has it."""
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    return subprocess.run(
        [sys.executable, "-c", code], cwd=where, capture_output=True, text=True, env=env
    )


def test_the_readme_has_the_blocks_this_file_runs():
    blocks = python_blocks()
    assert len(blocks) >= 2
    assert any("generate_to" in b for b in blocks)


@pytest.mark.slow
def test_each_readme_block_runs_alone_at_the_checkout_root(tmp_path):
    """Each block alone in a fresh interpreter at the checkout's root: the first failed
    with ``ImportError: cannot import name 'exporters' from 'optdot'``."""
    for k, code in enumerate(python_blocks()):
        r = _paste(code, _checkout(tmp_path / f"b{k}"))
        assert r.returncode == 0, (k, r.stderr[-3000:])


@pytest.mark.slow
def test_all_readme_blocks_run_in_one_interpreter(tmp_path):
    """Every block, in order, in one interpreter: a plain ``generate`` starts numba's
    threads before the tiled example starts its workers (the tiled example crashed)."""
    code = "\n".join(python_blocks())
    r = _paste(code, _checkout(tmp_path))
    assert r.returncode == 0, r.stderr[-3000:]
    assert (tmp_path / "led.gds").exists() and (tmp_path / "led.parquet").is_dir()
    assert r.stdout.strip().splitlines()[-1] in ("PASS", "PASS WITH WARNINGS")


def _figures_script():
    import importlib.util

    path = ROOT / "benchmarks" / "readme_figures.py"
    spec = importlib.util.spec_from_file_location("readme_figures", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_every_marked_figure_is_one_the_script_makes():
    """The README marks each walk-through figure once, and the script makes each."""
    script = _figures_script()
    text = README.read_text()
    shown = {m.group(1): m.group(2) for m in script.MARK.finditer(text)}
    assert set(shown) == set(script.FIGURES)
    assert script.differences(text, shown) == []
    assert script.differences(text, {**shown, "lgp.u9": "0.5 ± 0.1"}) == [
        f"lgp.u9: the README says {shown['lgp.u9']!r}, the walk-through gives '0.5 ± 0.1'"
    ]


@pytest.mark.slow
def test_the_readme_s_figures_are_today_s_outputs():
    """Every walk-through figure the README quotes (lgp's 9-point was 0.941 where the
    run gave 0.939, minled's range 0.858–1.110 where it gave 0.901–1.159) is what the
    walk-through prints today: ``python benchmarks/readme_figures.py --check``."""
    r = subprocess.run(
        [sys.executable, str(ROOT / "benchmarks" / "readme_figures.py"), "--check"],
        capture_output=True, text=True, cwd=ROOT,
    )  # fmt: skip
    assert r.returncode == 0, r.stdout + r.stderr[-2000:]
