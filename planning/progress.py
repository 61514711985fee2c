"""Progress of long planning commands on stderr: one line per phase, and a ``\\r`` bar only on a terminal.

Wall times are printed, never written into output files (reruns must give identical files).
"""
from __future__ import annotations

import sys
import time
from contextlib import contextmanager

BAR_WIDTH = 30


class Progress:
    """Phase lines ``[tag] name: 1.2 s`` and, when ``stream`` is a terminal, a bar for long loops."""

    def __init__(self, tag: str, stream=None, enabled: bool = True):
        self.tag = tag
        self.stream = sys.stderr if stream is None else stream
        self.enabled = enabled

    @contextmanager
    def phase(self, name: str):
        t0 = time.perf_counter()
        yield
        if self.enabled:
            print(f"[{self.tag}] {name}: {time.perf_counter() - t0:.1f} s", file=self.stream, flush=True)

    def bar(self, name: str):
        """A callback ``f(fraction)`` drawing a ``\\r`` bar on a terminal; None (no callback) otherwise."""
        isatty = getattr(self.stream, "isatty", None)
        if not self.enabled or isatty is None or not isatty():
            return None
        last = [-1]

        def draw(fraction: float) -> None:
            k = int(max(0.0, min(1.0, fraction)) * 100)
            if k == last[0]:
                return
            last[0] = k
            filled = BAR_WIDTH * k // 100
            end = "\n" if k >= 100 else ""
            print(f"\r[{self.tag}] {name} [{'#' * filled}{' ' * (BAR_WIDTH - filled)}] {k:3d} %", end=end, file=self.stream, flush=True)

        return draw
