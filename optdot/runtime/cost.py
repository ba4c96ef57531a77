"""What a run will cost before it starts: seconds, peak memory, disk.

Rates are this project's measurements on its reference machine (2 cores, 24 GiB;
BENCHMARKS.md), so an estimate is an order of magnitude for another machine, scaled by
its cores where the work spreads over them:

- one process: ~50,000 dots/s at 200 L-BFGS iterations (10⁵..10⁷ dots), plus ~1 s to
  start (imports, numba's cache);
- tiled: ~45,000 dots/s per worker (notebook 9.1M dots in 104 s and monitor 27.4M in 242 s
  on 2 workers), plus ~8 s to start the cluster and compile on it;
- memory: :func:`optdot.runtime.memory.estimate_bytes` per process (one process), or per
  worker for its largest tile plus ~0.5 GiB for the command, scheduler and results held;
- disk: bytes per dot of each format (:data:`optdot.formats.FORMATS`);
- shaped dots: :data:`SHAPED_TIME` times the time and :data:`SHAPED_MEMORY` times the
  memory of discs of the same count (of a process, or of a tiled worker).
"""

from __future__ import annotations

from dataclasses import dataclass, field

from ..formats import FORMATS
from .memory import estimate_bytes

#: Dots per second of one process at 200 iterations (2 cores).
SINGLE_DOTS_PER_S = 50_000
#: Dots per second of each tiled worker (one core).
TILED_DOTS_PER_S_PER_WORKER = 45_000
#: Seconds before the first iteration: one process; an embedded cluster.
SINGLE_START_S, TILED_START_S = 1.0, 8.0
#: Memory of the command, scheduler and tiles held while a tiled run writes, bytes.
TILED_BASE_BYTES = 512 * 2**20
#: Shaped dots against discs of the same count, one process (BENCHMARKS.md, at
#: 10⁶ dots: ellipses 2.5-3.0x the time and 1.4x the memory, prisms 2.8-3.2x and 1.5x).
SHAPED_TIME, SHAPED_MEMORY = 3.0, 1.5


@dataclass(frozen=True)
class Cost:
    """An estimate of a run.

    Attributes:
        seconds: wall time, s. peak_bytes: memory of all its processes, bytes.
        disk_bytes: per output format, bytes.
    """

    seconds: float
    peak_bytes: int
    disk_bytes: dict[str, int] = field(default_factory=dict)


def estimate_cost(
    n_dots: int,
    iterations: int,
    lbfgs_memory: int,
    tile_dots: int | None = None,
    workers: int = 1,
    formats: tuple[str, ...] = ("parquet", "gds", "oas", "dxf"),
    shaped: bool = False,
) -> Cost:
    """Estimate a run of ``n_dots`` at ``iterations`` (time scales with them from the
    measured 200), in one process (``tile_dots`` None) or tiled on ``workers`` workers
    with tiles of at most ``tile_dots`` dots; ``shaped``: of shaped dots."""
    work = n_dots * max(iterations, 1) / 200.0 * (SHAPED_TIME if shaped else 1.0)
    grow = SHAPED_MEMORY if shaped else 1.0
    if tile_dots is None:
        seconds = SINGLE_START_S + work / SINGLE_DOTS_PER_S
        peak = estimate_bytes(n_dots, lbfgs_memory) * grow
    else:
        seconds = TILED_START_S + work / (TILED_DOTS_PER_S_PER_WORKER * max(workers, 1))
        peak = TILED_BASE_BYTES + workers * estimate_bytes(tile_dots, lbfgs_memory) * grow
    per_dot = {
        f: FORMATS[f].shaped_bytes_per_dot if shaped else FORMATS[f].bytes_per_dot
        for f in formats
        if f in FORMATS
    }
    disk = {f: b * n_dots for f, b in per_dot.items() if b is not None}
    return Cost(seconds, int(peak), disk)
