"""Heavy results (a command's output folder, the synthetic log, `reproduce --quick`) computed once for the whole
suite: a store under pytest's cache directory, keyed on the content of everything a result depends on, shared by the
xdist workers through one fcntl lock per result (the first worker to ask computes, the other waits and reads) and
kept for the next run while that content is unchanged (and its files as they were made).

The key is the sha256 of the packages' sources and shipped data, the file that defines the computation (a test
module or conftest.py), this file, the result's name and inputs, and the versions of Python and the numerical
libraries: a change to any of them computes the result again, so a stored result is never older than the code that
made it. Stored results are read only; a test that changes one works on a copy (shutil.copytree)."""
from __future__ import annotations

import contextlib
import functools
import hashlib
import inspect
import os
import pickle
import re
import shutil
import sys
from importlib import metadata
from pathlib import Path
from typing import Any, Callable

ROOT = Path(__file__).resolve().parent.parent
# everything the packages read or run: their sources, the shipped press and job files, the URDF, the dependencies
SOURCES = ("press_io", "press_model", "calibration", "planning", "servo_press", "urdf")
LIBRARIES = ("numpy", "scipy", "pin", "casadi", "toppra", "numba", "SALib", "matplotlib", "dask")
RESULT = "result"  # an entry's folder the computation writes into, nothing else in it
# beside it, written last, the value and the digest of the folder's files: an entry without it is a computation that
# was killed, one whose files differ from the digest was changed by a test; either is made again
DONE = "value.pickle"


@functools.lru_cache(maxsize=None)
def _file_digest(path: Path) -> bytes:
    return hashlib.sha256(path.read_bytes()).digest()


@functools.lru_cache(maxsize=None)
def code_digest() -> str:
    """sha256 (hex) of the packages' files (compiled files and caches left out) and the libraries' versions."""
    h = hashlib.sha256(sys.version.encode())
    for lib in LIBRARIES:
        with contextlib.suppress(metadata.PackageNotFoundError):
            h.update(f"{lib}={metadata.version(lib)}".encode())
    for name in SOURCES:
        top = ROOT / name
        files = [top] if top.is_file() else sorted(p for p in top.rglob("*") if p.is_file()
                                                   and "__pycache__" not in p.parts and p.suffix not in (".pyc", ".nbi", ".nbc"))
        for p in files:
            h.update(p.relative_to(ROOT).as_posix().encode())
            h.update(_file_digest(p))
    return h.hexdigest()


def folder_digest(folder: Path) -> str:
    """sha256 (hex) of every file, link and folder under ``folder``: relative paths, bytes, a link's target."""
    h = hashlib.sha256()
    for p in sorted(folder.rglob("*")):
        h.update(p.relative_to(folder).as_posix().encode() + b"\0")
        h.update(os.readlink(p).encode() if p.is_symlink() else p.read_bytes() if p.is_file() else b"/")
    return h.hexdigest()


def _stored(entry: Path) -> tuple[Any] | None:
    """(the value,) of a stored entry whose files are as they were made, else None."""
    try:
        stored = pickle.loads((entry / DONE).read_bytes())
    except FileNotFoundError:
        return None
    return (stored["value"],) if folder_digest(entry / RESULT) == stored["files"] else None


class HeavyResults:
    """The store: ``root`` under pytest's cache directory, shared by every worker and kept between runs; None (pytest
    run with ``-p no:cacheprovider``, or no fcntl) computes each result once in this process, in ``scratch``."""

    def __init__(self, root: Path | None, scratch: Path):
        try:
            import fcntl  # noqa: F401  (POSIX: the lock that lets one worker compute while the other waits)
        except ImportError:
            root = None
        self.root, self.scratch = root, scratch
        self._here: dict[str, tuple[Path, Any]] = {}

    def key(self, name: str, make: Callable, inputs: tuple) -> str:
        """The entry's folder name: ``name`` and 16 hex digits of the sha256 of everything the result depends on."""
        h = hashlib.sha256(code_digest().encode())
        for f in (Path(__file__), Path(inspect.getsourcefile(make))):
            h.update(_file_digest(f.resolve()))
        h.update(repr((name, inputs)).encode())
        return f"{name}-{h.hexdigest()[:16]}"

    def _drop_others(self, name: str, key: str) -> None:
        """Removes the entries of ``name`` made under other code (the store keeps one of each result)."""
        for old in self.root.glob(f"{name}-*"):
            if old.name != key and re.fullmatch(re.escape(name) + r"-[0-9a-f]{16}", old.name):
                shutil.rmtree(old, ignore_errors=True)  # its lock file stays: a worker may be waiting on it

    def get(self, name: str, make: Callable[[Path], Any], *inputs) -> tuple[Path, Any]:
        """(the folder, the value) of ``make(folder)``, which writes its files into the empty folder it is
        given and returns a picklable value: computed by the first worker that asks, read by every other. ``inputs``
        (their repr) name what the result depends on beside the code."""
        key = self.key(name, make, inputs)
        if key in self._here:
            return self._here[key]
        if self.root is None:
            folder = self.scratch / key / RESULT
            folder.mkdir(parents=True)
            self._here[key] = folder, make(folder)
            return self._here[key]
        import fcntl

        entry = self.root / key
        with open(self.root / f"{key}.lock", "a+b") as lock:
            fcntl.flock(lock, fcntl.LOCK_EX)  # released when the file is closed, by a killed worker too
            stored = _stored(entry)
            if stored is None:  # never made, killed half way, or changed since (a test that wrote into it)
                shutil.rmtree(entry, ignore_errors=True)
                (entry / RESULT).mkdir(parents=True)
                try:
                    stored = (make(entry / RESULT),)
                    tmp = entry / f".{DONE}.{os.getpid()}"
                    tmp.write_bytes(pickle.dumps({"value": stored[0], "files": folder_digest(entry / RESULT)}))
                    tmp.replace(entry / DONE)
                    self._drop_others(name, key)
                except BaseException:
                    shutil.rmtree(entry, ignore_errors=True)
                    raise
            value = stored[0]
        self._here[key] = entry / RESULT, value
        return self._here[key]
