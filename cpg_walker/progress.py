"""A dependency-free progress bar for long work (learning, replays, sweeps), printed to stderr."""

from __future__ import annotations

import sys
import time


class Progress:
    """Call `update(done)` as work advances; prints at most ~10 times a second, and a final line."""

    def __init__(self, total: float, label: str, unit: str = "s", stream=None, enabled: bool = True):
        self.total = float(total)
        self.label = label
        self.unit = unit
        self.stream = stream if stream is not None else sys.stderr
        self.enabled = enabled
        self._start = time.perf_counter()
        self._last = 0.0
        self._tty = getattr(self.stream, "isatty", lambda: False)()
        self._final = False

    def update(self, done: float, extra: str = "") -> None:
        if not self.enabled:
            return
        now = time.perf_counter()
        if now - self._last < (0.1 if self._tty else 2.0) and done < self.total:
            return
        self._last = now
        self._final = done >= self.total
        frac = 0.0 if self.total <= 0 else min(1.0, done / self.total)
        bar = "#" * int(frac * 30)
        elapsed = now - self._start
        line = (
            f"{self.label} [{bar:<30}] {100 * frac:5.1f}% {done:.1f}/{self.total:.1f} {self.unit}"
            f" ({elapsed:.1f} s wall){' ' + extra if extra else ''}"
        )
        self.stream.write(("\r" + line) if self._tty else (line + "\n"))
        self.stream.flush()

    def close(self, extra: str = "") -> None:
        if not self.enabled:
            return
        if not self._final or extra:
            self._last = 0.0
            self.update(self.total, extra)
        if self._tty:
            self.stream.write("\n")
            self.stream.flush()
