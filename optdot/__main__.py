"""``python -m optdot``: the same command line as ``optdot``."""

from .console import run

run()
