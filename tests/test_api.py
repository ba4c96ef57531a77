"""The package's shape: the curated API, arrows only downstream, no import cycle (lazy
imports included), the installed package holding every module, and the QA gate inside
the library's export()."""

from __future__ import annotations

import ast
import re
from pathlib import Path

import numpy as np
import pytest

import optdot
from optdot import Pattern, QAGateError

ROOT = Path(__file__).resolve().parents[1]

#: Stage -> stages it may import. The core never imports quality, exporters, pipeline or cli.
ALLOWED = {
    "errors": set(),
    "formats": set(),
    "figures": set(),
    "__main__": {"console"},
    "console": {"cli", "runtime"},
    "files": {"runtime"},
    "runtime": {"errors", "formats"},
    "io": {"errors", "files", "formats", "pattern", "geometry", "runtime"},
    "geometry": {"errors", "files"},
    "printing": {"geometry"},
    "config": {"errors", "files", "geometry", "printing", "runtime"},
    "sampling": {"errors", "geometry"},
    "spatial": set(),
    "relax": {"errors", "geometry", "spatial"},
    "stages": {"config", "errors", "geometry", "relax", "sampling", "spatial"},
    "pattern": {"geometry"},
    "quality": {
        "config",
        "errors",
        "figures",
        "files",
        "geometry",
        "pattern",
        "printing",
        "io",
        "runtime",
        "spatial",
    },
    "exporters": {
        "errors",
        "files",
        "formats",
        "geometry",
        "io",
        "pattern",
        "printing",
        "runtime",
    },
    "testing": {"relax"},
    "orchestration": {
        "config",
        "errors",
        "exporters",
        "files",
        "formats",
        "geometry",
        "io",
        "pattern",
        "printing",
        "quality",
        "relax",
        "runtime",
        "spatial",
        "stages",
    },
    "optics": {
        "config",
        "errors",
        "figures",
        "files",
        "geometry",
        "io",
        "pattern",
        "printing",
        "runtime",
    },
    "cli": {
        "config",
        "errors",
        "exporters",
        "figures",
        "formats",
        "io",
        "optics",
        "orchestration",
        "quality",
        "runtime",
    },
}


def _stage_of(path: Path) -> str:
    rel = path.relative_to(ROOT)
    if rel.parts[0] == "exporters":
        return "exporters"
    return rel.parts[1].removesuffix(".py")


def _modules_imported(path: Path) -> set[str]:
    """The optdot modules a module imports, at the top or inside a function (absolute or
    relative; ``from pkg import name`` counts as ``pkg.name``, a module or not)."""
    tree = ast.parse(path.read_text())
    pkg = path.relative_to(ROOT).with_suffix("").parts
    if pkg[0] == "exporters":
        pkg = ("optdot", *pkg)
    if pkg[-1] == "__init__":
        pkg = (*pkg[:-1], "_")  # a package's relative imports start at the package
    out = set()
    for node in ast.walk(tree):
        names = []
        if isinstance(node, ast.ImportFrom):
            if node.level:
                base = list(pkg[: len(pkg) - node.level])
                mod = ".".join(base + ([node.module] if node.module else []))
            else:
                mod = node.module or ""
            names = [mod] + [f"{mod}.{a.name}" for a in node.names]
        elif isinstance(node, ast.Import):
            names = [a.name for a in node.names]
        out |= {n for n in names if n.split(".")[0] == "optdot"}
    return out


def _imports(path: Path) -> set[str]:
    """The optdot stages a module imports (absolute or relative)."""
    return {n.split(".")[1] for n in _modules_imported(path) if n.count(".")}


def _module_files() -> dict[str, Path]:
    """``{dotted module name: file}`` of every module of the package (exporters as
    ``optdot.exporters``)."""
    out = {}
    for base, prefix in (
        (ROOT / "optdot", ("optdot",)),
        (ROOT / "exporters", ("optdot", "exporters")),
    ):
        for f in base.rglob("*.py"):
            rel = f.relative_to(base).with_suffix("").parts
            if rel[-1] == "__init__":
                rel = rel[:-1]
            out[".".join((*prefix, *rel))] = f
    return out


@pytest.mark.slow
def test_no_import_cycle_lazy_imports_included():
    """No module reaches itself through imports, counting imports inside functions too
    (a lazy import hides a cycle from Python, not from the design)."""
    files = _module_files()
    graph = {}
    for name, f in files.items():
        deps = set()
        for m in _modules_imported(f):
            while m and m not in files:  # `from pkg import name`: the module is pkg
                m = m.rpartition(".")[0]
            # a package's __init__ re-exporting its modules is not an arrow back
            if m and m != name and not name.startswith(m + "."):
                deps.add(m)
        graph[name] = deps
    cycles, state = [], {}

    def visit(n, path):
        state[n] = 1
        for d in sorted(graph[n]):
            if state.get(d) == 1:
                cycles.append(path[path.index(d) :] + [d])
            elif d not in state:
                visit(d, [*path, d])
        state[n] = 2

    for n in sorted(graph):
        if n not in state:
            visit(n, [n])
    assert not cycles, cycles


def test_the_installed_package_holds_every_module_of_the_checkout():
    """Tests import the installed optdot (pytest --import-mode=importlib; CI installs
    it from its own files): a module or subpackage missing from pyproject's package
    list would be missing here."""
    import importlib.util

    assert (ROOT / "optdot" / "__init__.py").is_file()
    where = Path(optdot.__file__).resolve().parent
    missing = []
    for name in _module_files():
        spec = importlib.util.find_spec(name)
        if spec is None:
            missing.append(name)
    assert not missing, (where, missing)
    packages = {n for n, f in _module_files().items() if f.name == "__init__.py"}
    text = (ROOT / "pyproject.toml").read_text()
    listed = set(re.findall(r'^\s+"(optdot[\w.]*)",$', text, re.M))
    assert listed == packages, listed ^ packages


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


def test_no_module_name_twice():
    """Each module's file name says which one it is: none repeats in another folder."""
    names: dict[str, list[str]] = {}
    for f in sorted(ROOT.glob("optdot/**/*.py")) + sorted(ROOT.glob("exporters/**/*.py")):
        if f.name != "__init__.py" and "__pycache__" not in f.parts:
            names.setdefault(f.name, []).append(str(f.relative_to(ROOT)))
    assert not {k: v for k, v in names.items() if len(v) > 1}


#: Where a job may be taken whole: the commands, the orchestration of one process and of
#: tiles (where a job becomes the stages' values), and the job's own sections.
TAKE_THE_JOB = ("cli/", "config/", "orchestration/")


@pytest.mark.slow
def test_below_the_orchestration_functions_take_values_not_the_job():
    """The stages take the run's :class:`~optdot.stages.StageSettings`, the optics a
    :class:`~optdot.config.bench.Bench`, QA and the writers their records: a function
    with a ``job`` parameter anywhere else threads the job where a value would do."""
    import ast

    bad = []
    for f in [*(ROOT / "optdot").rglob("*.py"), *(ROOT / "exporters").rglob("*.py")]:
        rel = f.relative_to(ROOT / "optdot" if "optdot" in f.parts else ROOT).as_posix()
        if rel.startswith(TAKE_THE_JOB):
            continue
        for node in ast.walk(ast.parse(f.read_text())):
            if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef):
                args = node.args.posonlyargs + node.args.args + node.args.kwonlyargs
                if any(a.arg == "job" for a in args):
                    bad.append(f"{rel}:{node.lineno} {node.name}")
    assert not bad, bad


def test_the_ray_s_life_and_the_commands_stay_short():
    """A ray's life (``_trace_rays``: born, stepped, the face decides) stays at most 80
    lines, what a face does living in its own kernel; a command takes at most 8
    parameters, the rest one options record."""
    long = []
    for f in [ROOT / "optdot/optics/trace.py", *sorted((ROOT / "optdot/cli").glob("*.py"))]:
        for node in ast.walk(ast.parse(f.read_text())):
            if not isinstance(node, ast.FunctionDef):
                continue
            if node.name == "_trace_rays" and node.end_lineno - node.lineno + 1 > 80:
                long.append(f"{node.name}: {node.end_lineno - node.lineno + 1} lines")
            command = any("command" in ast.unparse(d) for d in node.decorator_list)
            count = len(node.args.args) + len(node.args.kwonlyargs)
            if command and count > 8:
                long.append(f"{f.name} {node.name}: {count} parameters")
    assert not long, long


@pytest.mark.parametrize(
    ("section", "key", "value", "said"),
    [
        ("optimize", "max_iter", "1.5", "optimize.max_iter = 1.5 must be"),
        ("optimize", "method", "3", "optimize.method = 3 must be"),
        ("qa", "max_collisions", "0.5", "qa.max_collisions = 0.5 must be"),
        ("qa", "view", "1", "qa.view = 1 must be"),
        ("optimize", "maxiter", "5", "unknown key 'optimize.maxiter'"),
    ],
)
def test_a_record_s_section_takes_its_fields_types(tmp_path, section, key, value, said):
    """``[optimize]`` and ``[qa]`` keys are their records' fields (declared once): an
    integer field refuses a fraction, a text field a number, a key no field has is
    unknown; a float field takes an integer."""
    from optdot.config.schema import load_job
    from optdot.errors import JobError

    from .conftest import write_job

    grid = np.full((3, 4), 0.3)
    with pytest.raises(JobError) as e:
        load_job(write_job(tmp_path, grid, **{section: {key: value}}))
    assert said in str(e.value), str(e.value)
    job = load_job(write_job(tmp_path, grid, optimize={"gap": 0, "skin": 1}, qa={"smoothing": 2}))
    assert job.optimize.gap == 0.0 and isinstance(job.optimize.skin, float)
