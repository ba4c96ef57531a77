"""The package's shape: the curated API, the deprecated old names, arrows only downstream,
and the QA gate inside the library's export()."""

from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import optdot
from optdot import Pattern, QAGateError

ROOT = Path(__file__).resolve().parents[1]

#: Stage -> stages it may import. The core never imports quality, exporters, pipeline or cli.
ALLOWED = {
    "errors": set(),
    "_imports": set(),
    "__main__": {"cli"},
    "files": {"runtime"},
    "runtime": {"errors"},
    "io": {"errors", "files", "pattern", "geometry", "runtime"},
    "geometry": {"errors", "files"},
    "config": {"errors", "files", "geometry", "runtime"},
    "sampling": {"errors", "geometry"},
    "spatial": set(),
    "relax": {"errors", "geometry", "spatial"},
    "stages": {"config", "errors", "geometry", "relax", "sampling"},
    "tiling": {"config", "errors", "geometry", "relax", "runtime", "spatial", "stages"},
    "pattern": {"geometry", "io", "_imports"},
    "quality": {"config", "errors", "files", "geometry", "pattern", "io", "runtime", "spatial"},
    "exporters": {"errors", "files", "geometry", "io", "pattern", "runtime"},
    "pipeline": {
        "io",
        "config",
        "errors",
        "geometry",
        "pattern",
        "quality",
        "relax",
        "runtime",
        "exporters",
        "stages",
        "tiling",
    },
    "cli": {"config", "errors", "exporters", "io", "pipeline", "quality", "runtime"},
}


def _stage_of(path: Path) -> str:
    rel = path.relative_to(ROOT)
    if rel.parts[0] == "exporters":
        return "exporters"
    return rel.parts[1].removesuffix(".py")


def _imports(path: Path) -> set[str]:
    """The optdot stages a module imports (absolute or relative)."""
    tree = ast.parse(path.read_text())
    pkg = path.relative_to(ROOT).with_suffix("").parts
    if pkg[0] == "exporters":
        pkg = ("optdot", *pkg)
    out = set()
    for node in ast.walk(tree):
        names = []
        if isinstance(node, ast.ImportFrom):
            if node.level:
                base = list(pkg[: len(pkg) - node.level])
                mod = ".".join(base + ([node.module] if node.module else []))
            else:
                mod = node.module or ""
            names = [mod] if node.module else [f"{mod}.{a.name}" for a in node.names]
        elif isinstance(node, ast.Import):
            names = [a.name for a in node.names]
        for n in names:
            parts = n.split(".")
            if parts[0] == "optdot" and len(parts) > 1:
                out.add(parts[1])
    return out


def test_arrows_only_downstream():
    files = [
        p
        for p in [*(ROOT / "optdot").rglob("*.py"), *(ROOT / "exporters").rglob("*.py")]
        if p.name != "__init__.py" or p.parent.name not in ("optdot",)
    ]
    bad = []
    for f in files:
        stage = _stage_of(f)
        for used in _imports(f) - {stage}:
            if used not in ALLOWED[stage]:
                bad.append(f"{f.relative_to(ROOT)} imports optdot.{used}")
    assert not bad, bad


def test_no_site_wide_exporters_package():
    import optdot.exporters

    assert optdot.exporters.FORMATS[0] == "gds"
    text = (ROOT / "pyproject.toml").read_text()
    assert '"optdot.exporters" = "exporters"' in text and '"exporters",' not in text


def test_curated_api_imports():
    for name in optdot.__all__:
        assert getattr(optdot, name) is not None, name
    assert issubclass(QAGateError, optdot.OptdotError) and QAGateError.exit_code == 1


def test_old_names_warn_and_still_work():
    code = (
        "import warnings\n"
        "warnings.simplefilter('error')\n"
        "try:\n"
        "    from optdot.job import load_job\n"
        "except FutureWarning as w:\n"
        "    print('WARNED', w)\n"
        "warnings.simplefilter('ignore')\n"
        "from optdot.job import load_job\n"
        "from optdot.generate import generate\n"
        "from optdot.pattern import save_pattern\n"
        "import optdot\n"
        f"job = load_job({str(ROOT / 'samples/tiny/job.toml')!r})\n"
        "p = optdot.generate(job)\n"
        "print('DOTS', p.n, generate is optdot.pipeline.generate)\n"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT, check=True
    ).stdout
    assert "WARNED optdot.job is deprecated" in out and "optdot.config" in out
    assert "DOTS 869 True" in out


def test_export_refuses_on_a_failed_gate_and_writes_nothing(tiny_job, tiny_pattern, tmp_path):
    bad_xy = tiny_pattern.xy.copy()
    bad_xy[1] = bad_xy[0] + [0.01, 0.0]  # a collision
    bad = Pattern(bad_xy, tiny_pattern.diameter, tiny_pattern.box)
    out = tmp_path / "m.gds"
    with pytest.raises(QAGateError, match="collisions"):
        optdot.export(bad, {"gds": out}, tiny_job)
    assert not out.exists()
    result = optdot.export(bad, {"gds": out}, tiny_job, force=True)
    assert not result.passed and out.stat().st_size > 0
    assert optdot.export(tiny_pattern, {"csv": tmp_path / "ok.csv"}, tiny_job).passed


def test_pattern_diameter_is_per_dot():
    p = Pattern(np.zeros((3, 2)) + [[0, 0], [1, 0], [2, 0]], 0.046, (0, 0, 3, 1))
    assert p.diameter.shape == (3,) and p.uniform_diameter == 0.046
    q = Pattern(p.xy, [0.03, 0.05, 0.04], p.box)
    assert q.uniform_diameter is None and q.nominal_diameter == 0.04
    with pytest.raises(ValueError):
        Pattern(p.xy, [0.03, 0.05], p.box)
