"""The command line, ``optdot generate | export | qa``: parses, calls the pipeline, prints."""

from .main import main

__all__ = ["main"]
