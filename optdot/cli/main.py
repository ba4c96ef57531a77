"""The ``optdot`` command: the group (:mod:`optdot.cli.app`) with its commands registered
(:mod:`optdot.cli.make`: check, generate; :mod:`optdot.cli.tooling`: export, qa;
:mod:`optdot.cli.optics`: simulate, design)."""

from __future__ import annotations

from . import make, optics, tooling
from .app import EXIT_INTERNAL, main

__all__ = ["EXIT_INTERNAL", "main", "make", "optics", "tooling"]
