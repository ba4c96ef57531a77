"""``python -m optdot``: the same command line as ``optdot``."""

from .cli import main

main(prog_name="optdot")
