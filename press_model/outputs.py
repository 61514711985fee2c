"""Writing results: atomic CSV and JSON files that record what produced them."""
from __future__ import annotations

import csv
import io
import json
import math
import platform
from importlib import metadata
from pathlib import Path

import numpy as np

from .urdf import atomic_write_text

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
