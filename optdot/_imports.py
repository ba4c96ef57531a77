"""Import hooks: the old flat module names, deprecated for one release, and the
``exporters/`` folder of a source checkout as ``optdot.exporters``.

Until version 0.2 optdot was one flat folder (``optdot.job``, ``optdot.generate``,
``optdot.neighbors``, ...). Those names still import, with an
:class:`OptdotDeprecationWarning` that says where each now lives; attributes are looked up
in the new modules. ``optdot.generate`` and ``optdot.qa`` were modules and are now
functions of the public API: their stand-ins can be called like the functions, so code
that imported the old module does not break the new name.

An installed optdot holds its exporters as the subpackage ``optdot.exporters``
(setuptools ``package-dir``). A source checkout keeps them in the top-level
``exporters/`` folder; the finder maps that folder to ``optdot.exporters`` so tests and
scripts run from a checkout see the same package names.
"""

from __future__ import annotations

import importlib
import importlib.abc
import importlib.machinery
import importlib.util
import sys
import types
import warnings
from pathlib import Path

#: Old module -> the modules its names moved to (looked up in this order).
LEGACY: dict[str, tuple[str, ...]] = {
    "optdot.job": ("optdot.config.schema", "optdot.config.job", "optdot.config.grids"),
    "optdot.generate": ("optdot.pipeline", "optdot.relax.optdot"),
    "optdot.density": ("optdot.geometry.density",),
    "optdot.domain": (
        "optdot.geometry.domain",
        "optdot.geometry.outline_io",
        "optdot.geometry.edges",
    ),
    "optdot.neighbors": (
        "optdot.spatial.cellgrid",
        "optdot.spatial.blocks",
        "optdot.spatial.verlet",
        "optdot.geometry.morton",
    ),
    "optdot.sobol": ("optdot.sampling.sobol",),
    "optdot.initial": ("optdot.sampling.initial",),
    "optdot.circles": ("optdot.relax.circles",),
    "optdot.formulation": ("optdot.relax.formulation",),
    "optdot.penalty": ("optdot.relax.penalty", "optdot.relax.terms"),
    "optdot.lbfgs": ("optdot.relax.lbfgs",),
    "optdot.md": ("optdot.relax.md",),
    "optdot.legalize": ("optdot.relax.legalize",),
    "optdot.qa": ("optdot.quality.gate", "optdot.quality.metrics"),
    "optdot.report": ("optdot.quality.report",),
    "optdot.atomic": ("optdot.io.atomic",),
    "optdot.memory": ("optdot.runtime.memory",),
    "optdot.progress": ("optdot.cli.progress",),
}

#: Old modules whose name is now a function of the public API.
CALLABLE = {"optdot.generate": "generate", "optdot.qa": "qa"}


class OptdotDeprecationWarning(FutureWarning):
    """An old optdot name still works but will go in the next release (shown by default)."""


class _LegacyModule(types.ModuleType):
    """A stand-in for an old module: attributes come from the new modules."""

    _targets: tuple[str, ...] = ()

    def __getattr__(self, name: str):
        if name.startswith("__"):
            raise AttributeError(name)
        for target in self._targets:
            mod = importlib.import_module(target)
            if hasattr(mod, name):
                return getattr(mod, name)
        raise AttributeError(f"module {self.__name__!r} has no attribute {name!r}")

    def __call__(self, *args, **kwargs):
        func = CALLABLE.get(self.__name__)
        if func is None:
            raise TypeError(f"module {self.__name__!r} is not callable")
        return getattr(importlib.import_module("optdot.pipeline"), func)(*args, **kwargs)


class _Finder(importlib.abc.MetaPathFinder, importlib.abc.Loader):
    """Finds the legacy names and, in a source checkout, ``optdot.exporters``."""

    def __init__(self, checkout_exporters: Path | None) -> None:
        self.checkout_exporters = checkout_exporters

    def find_spec(self, fullname, path, target=None):
        if fullname in LEGACY:
            return importlib.util.spec_from_loader(fullname, self)
        if self.checkout_exporters is not None and (
            fullname == "optdot.exporters" or fullname.startswith("optdot.exporters.")
        ):
            rel = fullname.split(".")[2:]
            base = self.checkout_exporters.joinpath(*rel)
            if base.is_dir():
                return importlib.util.spec_from_file_location(
                    fullname, base / "__init__.py", submodule_search_locations=[str(base)]
                )
            if base.with_suffix(".py").is_file():
                return importlib.util.spec_from_file_location(fullname, base.with_suffix(".py"))
        return None

    def create_module(self, spec):
        mod = _LegacyModule(spec.name)
        mod._targets = LEGACY[spec.name]
        return mod

    def exec_module(self, module) -> None:
        new = ", ".join(module._targets)
        hint = f" or `optdot.{CALLABLE[module.__name__]}`" if module.__name__ in CALLABLE else ""
        warnings.warn(
            f"{module.__name__} is deprecated and goes in the next release: import from "
            f"{new}{hint} (the public API is `from optdot import ...`)",
            OptdotDeprecationWarning,
            stacklevel=2,
        )


def install(package_dir: Path) -> None:
    """Put the finder on ``sys.meta_path`` once (last: real modules win)."""
    if any(isinstance(f, _Finder) for f in sys.meta_path):
        return
    installed = (package_dir / "exporters" / "__init__.py").is_file()
    checkout = package_dir.parent / "exporters"
    use = checkout if not installed and (checkout / "__init__.py").is_file() else None
    sys.meta_path.append(_Finder(use))
