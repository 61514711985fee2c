"""The packages' Python files, read and parsed once a test process (tests/ is on sys.path, conftest.py), for the tests
that scan the code: the floors and the parameter counts (test_layout.py), Eq. 16's switch (test_motor.py), the torque
margin (test_torque_limits.py). A parse of every package file costs ~0.8 s of CPU; each scan parsed them all again."""
from __future__ import annotations

import ast
import functools
from pathlib import Path


@functools.lru_cache(maxsize=None)
def source(path: Path) -> str:
    """The text of the file ``path`` (the suite does not edit the packages while it runs)."""
    return path.read_text(encoding="utf-8")


@functools.lru_cache(maxsize=None)
def tree(path: Path) -> ast.Module:
    """The parsed file ``path``, shared by every scan of this process: read it, never change it."""
    return ast.parse(source(path), filename=str(path))
