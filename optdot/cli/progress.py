"""A one-line progress bar on stderr that stays quiet when stderr is not a terminal."""

from __future__ import annotations

import sys
import time
from typing import TextIO


class ProgressBar:
    """Callable ``(iteration, penalty)`` that redraws one line at most 10 times a second.

    Args:
        total: the iteration limit.
        label: text before the numbers.
        stream: where to draw (default stderr).
        enabled: force on/off; default: only when ``stream`` is a terminal.
    """

    def __init__(
        self,
        total: int,
        label: str = "relax",
        stream: TextIO | None = None,
        enabled: bool | None = None,
    ) -> None:
        self.total = total
        self.label = label
        self.stream = stream or sys.stderr
        self.enabled = self.stream.isatty() if enabled is None else enabled
        self.t0 = time.perf_counter()
        self._last = 0.0
        self._drawn = False

    def __call__(self, iteration: int, penalty: float) -> None:
        if not self.enabled:
            return
        now = time.perf_counter()
        if now - self._last < 0.1 and iteration < self.total:
            return
        self._last = now
        width = 24
        done = int(width * min(iteration / max(self.total, 1), 1.0))
        bar = "#" * done + "." * (width - done)
        self.stream.write(
            f"\r{self.label} [{bar}] iter {iteration}/{self.total}  "
            f"penalty {penalty:.4g} mm²  {now - self.t0:.1f} s "
        )
        self.stream.flush()
        self._drawn = True

    def line(self, fraction: float, text: str) -> None:
        """Draw a fraction done (0..1) and a line of text (tiled runs: tiles and ETA)."""
        if not self.enabled:
            return
        now = time.perf_counter()
        if now - self._last < 0.1 and fraction < 1.0:
            return
        self._last = now
        width = 24
        done = int(width * min(max(fraction, 0.0), 1.0))
        bar = "#" * done + "." * (width - done)
        self.stream.write(f"\r{self.label} [{bar}] {text}  {now - self.t0:.1f} s ")
        self.stream.flush()
        self._drawn = True

    def close(self) -> None:
        """End the line if anything was drawn."""
        if self._drawn:
            self.stream.write("\n")
            self.stream.flush()
