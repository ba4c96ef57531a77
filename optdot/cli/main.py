"""The ``optdot`` command: the group (:mod:`optdot.cli.app`) with its commands registered
(:mod:`optdot.cli.make`: check, generate; :mod:`optdot.cli.gate`: export, qa)."""

from __future__ import annotations

from . import gate, make
from .app import EXIT_INTERNAL, main

__all__ = ["EXIT_INTERNAL", "gate", "main", "make"]
