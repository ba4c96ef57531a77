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


def _kernel_cache() -> None:
    """Where numba caches the kernels, read safely (:mod:`optdot.runtime.kernel_cache`),
    settled before numba loads."""
    from .runtime.kernel_cache import settle

    settle()


_kernel_cache()


def __getattr__(name: str):
    if name in _API:
        value = getattr(import_module(_API[name]), _ALIASES.get(name, name))
        globals()[name] = value
        return value
    raise AttributeError(f"module 'optdot' has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))
