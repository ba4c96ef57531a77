"""A one-line progress bar on stderr that stays quiet when stderr is not a terminal.

It names each stage as it starts (``throwing darts``, ``relaxing``, ``guarantee pass``,
``writing``), draws the relaxation's iterations, and, when a stage shows no progress for
:data:`SLOW_START` seconds (numba compiles the kernels the first time they run, ~30 s;
afterwards they come from its cache), says so instead of leaving a blank terminal.
"""

from __future__ import annotations

import sys
import threading
import time
from typing import TextIO

#: Seconds without news after which the bar explains a slow start.
SLOW_START = 2.0


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
        self._lock = threading.Lock()
        self._timer: threading.Timer | None = None
        self._stage = ""
        self._iteration = 0

    def stage(self, name: str) -> None:
        """A stage starts: end the previous one's line (the relaxation's with the
        iteration it stopped at) and name this one."""
        if not self.enabled:
            return
        self._cancel()
        with self._lock:
            if self._stage == "relaxing" and self._iteration:
                self._write(
                    f"\r{self.label}: relaxed, stopped at iteration {self._iteration} "
                    f"of {self.total}  {time.perf_counter() - self.t0:.1f} s"
                )
                self.stream.write("\n")
            elif self._drawn:
                self.stream.write("\n")
            self._stage, self._iteration = name, 0
            self._write(f"\r{self.label}: {name}...  {time.perf_counter() - self.t0:.1f} s ")
        self._timer = threading.Timer(SLOW_START, self._slow, args=(name,))
        self._timer.daemon = True
        self._timer.start()

    def _slow(self, name: str) -> None:
        with self._lock:
            if self._stage == name and self._iteration == 0:
                self._write(
                    f"\r{self.label}: {name}... (compiling kernels: first run only, "
                    f"cached afterwards)  {time.perf_counter() - self.t0:.1f} s "
                )

    def _cancel(self) -> None:
        if self._timer is not None:
            self._timer.cancel()
            self._timer = None

    def _write(self, text: str) -> None:
        self.stream.write(text)
        self.stream.flush()
        self._drawn = True

    def __call__(self, iteration: int, penalty: float) -> None:
        if not self.enabled:
            return
        self._iteration = iteration
        now = time.perf_counter()
        if now - self._last < 0.1 and iteration < self.total:
            return
        self._last = now
        width = 24
        done = int(width * min(iteration / max(self.total, 1), 1.0))
        bar = "#" * done + "." * (width - done)
        with self._lock:
            self._write(
                f"\r{self.label} [{bar}] iter {iteration}/{self.total}  "
                f"penalty {penalty:.4g} mm²  {now - self.t0:.1f} s "
            )

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
        self._cancel()
        if self._drawn:
            self.stream.write("\n")
            self.stream.flush()
            self._drawn = False
