"""The ``optdot`` command: the group (:mod:`optdot.cli.app`) with its commands registered
(:mod:`optdot.cli.make`: check, generate; :mod:`optdot.cli.gate`: export, qa;
:mod:`optdot.cli.optics`: simulate, design)."""

from __future__ import annotations

from . import gate, make, optics
from .app import EXIT_INTERNAL, main

__all__ = ["EXIT_INTERNAL", "gate", "main", "make", "optics"]
