"""Progress of long runs on stderr: a bar redrawn in place on a terminal, one line per phase in a log file.

Wall times are printed, never written into output files (reruns must give identical files).
"""
from __future__ import annotations

import sys
import time
from contextlib import contextmanager


def progress(label: str, done: int, total: int, detail: str = "", width: int = 30) -> None:
    """Report ``done`` of ``total`` steps of the phase ``label``.

    On a terminal the bar is redrawn in place with ``\\r``; otherwise (stderr redirected to a file or a pipe) the
    ``\\r`` lines would pile up in the log, so only the phase's last call writes one line.
    """
    stream = sys.stderr
    tail = f"  {detail}" if detail else ""
    if _is_terminal(stream):
        frac = done / total if total else 1.0
        stream.write(f"\r  {label} [{'#' * int(frac * width):<{width}}] {done}/{total}{tail}   ")
        if done >= total:
            stream.write("\n")
    elif done >= total:
        stream.write(f"  {label}: {done}/{total}{tail}\n")
    else:
        return
    stream.flush()


def _is_terminal(stream) -> bool:
    try:
        return bool(stream.isatty())
    except (AttributeError, ValueError):  # a replaced or closed stream
        return False


BAR_WIDTH = 30


class Progress:
    """Phase lines ``[tag] name: 1.2 s`` and, when ``stream`` is a terminal, a bar for long loops.

    ``announce``: also a line ``[tag] name ...`` when a phase starts (for phases of many seconds); ``timings``: a
    dict that receives each finished phase's wall time (s) by name.
    """

    def __init__(self, tag: str, stream=None, enabled: bool = True, announce: bool = False, timings: dict | None = None):
        self.tag = tag
        self.stream = sys.stderr if stream is None else stream
        self.enabled = enabled
        self.announce = announce
        self.timings = timings

    @contextmanager
    def phase(self, name: str):
        if self.enabled and self.announce:
            print(f"[{self.tag}] {name} ...", file=self.stream, flush=True)
        t0 = time.perf_counter()
        yield
        dt = time.perf_counter() - t0
        if self.timings is not None:
            self.timings[name] = dt
        if self.enabled:
            print(f"[{self.tag}] {name}: {dt:.1f} s", file=self.stream, flush=True)

    def bar(self, name: str):
        """A callback ``f(fraction)`` drawing a ``\\r`` bar on a terminal; None (no callback) otherwise."""
        if not self.enabled or not _is_terminal(self.stream):
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
