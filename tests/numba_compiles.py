"""One numba compile per function for the whole suite, not one per xdist worker (a pytest plugin: conftest.py's
``pytest_plugins``).

A function numba caches on disk (``cache=True``, and the generated friction kernel of press_model/batch_kernel.py) is
compiled by the first process that calls it and loaded from the disk cache by every later one. On an empty cache (a
fresh clone, a changed kernel) the two workers start with modules that call the same functions at once, and each
compiled them: the friction kernel of each loop structure twice, ~25 s of CPU each time, and the smaller kernels
(trilateration, forward dynamics) too. Here each worker compiles such a function under a file lock keyed on it: the
worker that comes second waits, and numba's compile then finds the first one's machine code in the disk cache and
loads it (numba looks there before it compiles). Different functions are still compiled side by side, and a function
without a disk cache is not locked (the second worker would compile it anyway, only later).

Within a process numba compiles one function at a time (its global compiler lock, taken here before the file lock);
a function's compile that compiles another takes that one's lock too, and takes its own again freely. A lock held
longer than :data:`WAIT_S` (a worker stopped in a debugger) is waited for no longer: the compile goes on without it.
"""
from __future__ import annotations

import contextlib
import functools
import hashlib
import os
import tempfile
import time
from pathlib import Path

WAIT_S = 600.0  # longer than any compile of the suite (the friction kernel: ~25 s of CPU, ~100 s on a loaded machine)
_HELD: set[str] = set()  # the keys this process holds (a compile that compiles the same function again)


def _key(dispatcher) -> str:
    func = dispatcher.py_func
    where = f"{getattr(func, '__module__', '')}:{func.__qualname__}:{getattr(func.__code__, 'co_filename', '')}"
    return hashlib.sha256(where.encode()).hexdigest()[:24]


@contextlib.contextmanager
def _file_lock(key: str, folder: Path):
    """Hold the lock ``key`` among processes (fcntl), for at most WAIT_S of waiting; reentrant within this process."""
    import fcntl

    if key in _HELD:
        yield
        return
    try:
        folder.mkdir(parents=True, exist_ok=True)
        fh = open(folder / f"{key}.lock", "a+b")  # noqa: SIM115 (closed below: the lock goes with it)
    except OSError:  # no writable folder: compile without the lock, as every worker did
        yield
        return
    with fh:
        deadline = time.monotonic() + WAIT_S
        while True:
            try:
                fcntl.flock(fh, fcntl.LOCK_EX | fcntl.LOCK_NB)
                break
            except BlockingIOError:
                if time.monotonic() > deadline:
                    break  # not held: the compile goes on without it
                time.sleep(0.05)
        _HELD.add(key)
        try:
            yield
        finally:
            _HELD.discard(key)  # the lock goes with the file's closing


def install(folder: Path) -> None:
    """Wrap numba's Dispatcher.compile in this process so that a disk-cached function is compiled under its lock in
    ``folder``."""
    try:
        import fcntl  # noqa: F401  (POSIX only: elsewhere every worker compiles for itself, as before)

        from numba.core.caching import NullCache
        from numba.core.compiler_lock import global_compiler_lock
        from numba.core.dispatcher import Dispatcher
    except ImportError:  # pragma: no cover
        return
    if getattr(Dispatcher.compile, "_suite_locked", False):
        return
    compile_ = Dispatcher.compile

    @functools.wraps(compile_)
    def compile(self, sig):
        if isinstance(getattr(self, "_cache", None), NullCache):
            return compile_(self, sig)
        with global_compiler_lock, _file_lock(_key(self), folder):
            return compile_(self, sig)

    compile._suite_locked = True
    Dispatcher.compile = compile


def pytest_configure(config):
    if not hasattr(config, "workerinput") and getattr(config.option, "numprocesses", None):
        return  # the xdist controller compiles nothing: its workers install it
    # the folder every worker of this run and of any other run on the machine sees: a lock is a lock on a function of
    # a given source file, whichever run compiles it
    install(Path(tempfile.gettempdir()) / f"servo-press-twin-compile-locks-{os.getuid() if hasattr(os, 'getuid') else 0}")
