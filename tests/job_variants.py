"""Shipped jobs changed for a test (tests/ is on sys.path, conftest.py): each written to a file under the test's
``tmp_path`` and read back as a user's job file is."""
from __future__ import annotations

from importlib import resources

from press_model.jobs import load_job


def continuous_door_panel(tmp_path, extra: str = "", name: str = "continuous.toml"):
    """The shipped door panel in continuous mode (no dwell, its [planning.transfer] table taken out) with the TOML text
    ``extra`` appended; returns the job read from ``tmp_path / name``."""
    text = resources.files("press_model.data").joinpath("door_panel.toml").read_text(encoding="utf-8")
    start = text.index("\n[planning.transfer]\n")
    end = text.find("\n[", start + 1)
    text = text[:start + 1] + (text[end + 1:] if end >= 0 else "")
    text = text.replace("[planning]\n", '[planning]\nmode = "continuous"\ndwell_s = 0\n', 1)
    path = tmp_path / name
    path.write_text(text + "\n" + extra, encoding="utf-8")
    return load_job(path)
