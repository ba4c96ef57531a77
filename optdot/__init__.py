"""optdot: non-overlapping random dot patterns for light guides and diffuser films, their
masks, and QA before tooling.

The public API (everything else is internal and may change)::

    from optdot import load_job, generate, qa, export, load_pattern, save_pattern, Pattern

    job = load_job("samples/led/job.toml")      # validated, frozen Job
    pattern = generate(job)                      # Pattern: xy [n, 2] mm, diameter [n] mm
    result = qa(pattern, job)                    # QAResult: .passed, .checks, .metrics
    export(pattern, {"gds": "led.gds"}, job)     # QA gate first; raises QAGateError

The pipeline, as the folders show it: ``config`` (job) → ``geometry`` (panel, map) →
``sampling`` (initial dots) → ``spatial`` (pair search) → ``relax`` (penalty, L-BFGS,
MD baseline, guarantee pass) → :class:`Pattern` → ``quality`` (metrics, gate, report) and
``exporters`` (masks, files); ``pipeline`` ties the stages, ``cli`` parses and prints.
"""

from __future__ import annotations

from importlib import import_module

from .errors import (
    ExportError,
    GeometryError,
    GuaranteeError,
    JobError,
    OptdotError,
    PatternFileError,
    QAGateError,
    ResourceError,
)

#: Public name -> the module that defines it (imported on first use: ``import optdot``
#: stays cheap, and the command line loads only what a command needs).
_API = {
    "load_job": "optdot.config.schema",
    "Job": "optdot.config.job",
    "generate": "optdot.orchestration.pipeline",
    "qa": "optdot.orchestration.pipeline",
    "export": "optdot.orchestration.pipeline",
    "Pattern": "optdot.pattern",
    "load_pattern": "optdot.io.patterns",
    "save_pattern": "optdot.io.patterns",
    "read_pattern": "optdot.exporters.readback",
    "QAResult": "optdot.quality.gate",
    "ExportOptions": "optdot.exporters.options",
}
_ALIASES = {"read_pattern": "read_any"}

__all__ = [
    *_API,
    "OptdotError",
    "JobError",
    "GeometryError",
    "PatternFileError",
    "ExportError",
    "ResourceError",
    "GuaranteeError",
    "QAGateError",
]


def _checkout_exporters() -> None:
    """Make ``optdot.exporters`` importable when this is a source checkout's ``optdot/``
    (Python started at the checkout's root imports this folder before the installed
    package): the installed package maps the top-level ``exporters/`` folder in as
    ``optdot.exporters`` (pyproject.toml's ``package-dir``); here a finder does the same,
    for that one name. Installed, ``optdot/exporters`` exists and nothing is added."""
    import sys
    from importlib.abc import MetaPathFinder
    from importlib.util import spec_from_file_location
    from pathlib import Path

    here = Path(__file__).resolve().parent
    top = here.parent / "exporters"
    if (here / "exporters").is_dir() or not (top / "__init__.py").is_file():
        return

    class CheckoutExporters(MetaPathFinder):
        def find_spec(self, name, path=None, target=None):
            if name != "optdot.exporters":
                return None
            return spec_from_file_location(
                name, top / "__init__.py", submodule_search_locations=[str(top)]
            )

    if not any(type(f).__name__ == "CheckoutExporters" for f in sys.meta_path):
        sys.meta_path.append(CheckoutExporters())


_checkout_exporters()

#: Caches of compiled kernels kept for a checkout (the newest; older sources' removed).
KERNEL_CACHES = 3


def _checkout_kernel_cache() -> None:
    """Compile a source checkout's kernels into a numba cache of their own, named by the
    sources of every module that holds kernels (unless ``NUMBA_CACHE_DIR`` is set). numba
    keys a cached kernel by its own file only: a kernel that inlines another module's
    (the registry's dispatch of a kind's ``inside``, the tracer's of a face's ``meet``)
    would run the old code after that module is edited. An installed copy does not
    change (an upgrade rewrites every file), so it keeps numba's own cache."""
    import hashlib
    import os
    import shutil
    import sys
    from pathlib import Path

    root = Path(__file__).resolve().parent.parent
    checkout = (root / "pyproject.toml").is_file() and (root / "exporters").is_dir()
    if "NUMBA_CACHE_DIR" in os.environ or not checkout:
        return
    digest = hashlib.sha256()
    for path in sorted(root.glob("optdot/**/*.py")) + sorted(root.glob("exporters/**/*.py")):
        text = path.read_bytes()
        if b"numba" in text:
            digest.update(path.relative_to(root).as_posix().encode() + b"\0" + text)
    base = Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "optdot-kernels"
    here = base / digest.hexdigest()[:16]
    try:
        here.mkdir(parents=True, exist_ok=True)
        here.touch()  # the newest
        for old in sorted(base.iterdir(), key=lambda p: p.stat().st_mtime)[:-KERNEL_CACHES]:
            shutil.rmtree(old, ignore_errors=True)
    except OSError:  # no writable cache home: numba's own cache, as installed
        return
    os.environ["NUMBA_CACHE_DIR"] = str(here)  # read when numba is imported, and by workers
    if "numba" in sys.modules:  # imported already: its config, before any kernel is made
        sys.modules["numba"].config.CACHE_DIR = str(here)


_checkout_kernel_cache()


def __getattr__(name: str):
    if name in _API:
        value = getattr(import_module(_API[name]), _ALIASES.get(name, name))
        globals()[name] = value
        return value
    raise AttributeError(f"module 'optdot' has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))
