"""Progress of long runs on stderr: a bar redrawn in place on a terminal, one line per phase in a log file."""
from __future__ import annotations

import sys


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
