"""Up-front memory estimate, so a job too big for the machine is refused, not killed."""

from __future__ import annotations

import os

from ..errors import ResourceError

#: Bytes per dot besides the L-BFGS history (positions, gradients, radii, containers,
#: Verlet list, grid bins, temporaries). Calibrated on benchmarks/scaling.py: peak RSS
#: 210 MB at 10⁵ dots, 680 MB at 1.2·10⁶, 4,355 MB at 10⁷ (BENCHMARKS.md; estimates 293 MB,
#: 772 MB, 4,599 MB; MB = 2²⁰ bytes), so it stays an upper bound, 6 % over at 10⁷.
BYTES_PER_DOT = 360
#: Fixed overhead of the interpreter, numpy/scipy/numba, bytes.
BASE_BYTES = 250 * 2**20


def estimate_bytes(n_dots: int, memory: int = 6) -> int:
    """Peak memory estimate of generating ``n_dots`` with L-BFGS memory ``memory``, bytes."""
    # float32 (s, y) pairs: memory + 1 rows of 2 coordinates
    return BASE_BYTES + n_dots * (BYTES_PER_DOT + 2 * (memory + 1) * 2 * 4)


def available_bytes() -> int:
    """Memory available to this process now (Linux ``MemAvailable``), bytes."""
    try:
        with open("/proc/meminfo") as fh:
            for line in fh:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except OSError:
        pass
    return os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")


def check_memory(n_dots: int, memory: int = 6, where: str = "job") -> None:
    """Refuse a job whose estimate exceeds 90 % of the available memory.

    Raises:
        ResourceError: with the estimate and what is available.
    """
    need = estimate_bytes(n_dots, memory)
    have = available_bytes()
    if need > 0.9 * have:
        raise ResourceError(
            f"{where}: {n_dots:,} dots need about {need / 2**30:.1f} GiB but only "
            f"{have / 2**30:.1f} GiB is available; coarsen the map, enlarge the dots or "
            "split the panel"
        )


#: Bytes per dot of checking a pattern in memory (positions, diameters, k-d tree,
#: nearest neighbours, coverage deposits), an upper bound from benchmarks/qa_speed.py
#: (846 MB at 10⁶ dots).
QA_BYTES_PER_DOT = 600


def max_dots_read() -> int:
    """Most dots a reader may produce before QA would exhaust the available memory."""
    return max(int(0.8 * (available_bytes() - BASE_BYTES) / QA_BYTES_PER_DOT), 10**6)
