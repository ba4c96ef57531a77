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
