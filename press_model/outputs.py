"""Writing results: atomic CSV and JSON files that record what produced them."""
from __future__ import annotations

import csv
import io
import json
import math
import os
import platform
import tempfile
from importlib import metadata
from pathlib import Path
from typing import Callable

import numpy as np


def file_mode() -> int:
    """The mode a plainly created file gets (0666 less the umask): mkstemp's temp files are 0600, and a
    result renamed into place should be as readable as any other file the user writes."""
    umask = os.umask(0)
    os.umask(umask)
    return 0o666 & ~umask


def atomic_write(path: Path, write: Callable[[str], None], suffix: str = "") -> None:
    """Make ``path`` by ``write(temporary_path)`` in the same folder, then rename it into place, so that a
    reader never sees a half-written file and a failed write leaves nothing behind."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.stem}.", suffix=suffix, dir=path.parent)
    os.close(fd)
    try:
        os.chmod(tmp, file_mode())
        write(tmp)
        os.replace(tmp, path)
    finally:
        if os.path.exists(tmp):
            os.unlink(tmp)


def atomic_write_text(path: Path, text: str) -> None:
    """Write text (UTF-8, LF line ends) atomically; see :func:`atomic_write`."""
    atomic_write(path, lambda tmp: Path(tmp).write_text(text, encoding="utf-8", newline="\n"))


_PACKAGES = ("servo-press-twin", "pin", "numpy", "scipy", "SALib", "toppra", "matplotlib")


def versions() -> dict:
    """Versions of Python and of every package that shapes a result."""
    out = {"python": platform.python_version()}
    for name in _PACKAGES:
        try:
            out[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            out[name] = "not installed"
    return out


def _clean(obj):
    if isinstance(obj, dict):
        return {str(k): _clean(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_clean(v) for v in obj]
    if isinstance(obj, (np.floating, float)):
        v = float(obj)
        return v if math.isfinite(v) else None
    if isinstance(obj, np.integer):
        return int(obj)
    if isinstance(obj, np.ndarray):
        return _clean(obj.tolist())
    return obj


def write_json(path: Path, obj) -> None:
    """Write ``obj`` as indented, key-ordered JSON, atomically."""
    atomic_write_text(Path(path), json.dumps(_clean(obj), indent=2, sort_keys=False) + "\n")


def write_table(path: Path, columns: list[str], rows: list[dict], digits: int = 10) -> None:
    """Write rows (dicts keyed by ``columns``) as CSV with a header row, atomically; floats to ``digits`` digits."""
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(columns)
    for r in rows:
        w.writerow([f"{r[c]:.{digits}g}" if isinstance(r[c], (float, np.floating)) else r[c] for c in columns])
    atomic_write_text(Path(path), buf.getvalue())


def write_csv(path: Path, columns: dict[str, np.ndarray], digits: int = 10) -> None:
    """Write equal-length numeric columns with a header row, atomically (``digits`` significant digits)."""
    names = list(columns)
    data = np.column_stack([np.asarray(columns[n], dtype=float) for n in names])
    write_table(path, names, [dict(zip(names, map(float, row))) for row in data], digits)
