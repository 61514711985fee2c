"""numba where it is installed: plain-Python loops over scalars, compiled on first use and cached on disk, one process
compiling at a time."""
from __future__ import annotations

import contextlib
import functools
import sys
from pathlib import Path


@functools.cache
def compiled(fn):
    """``fn`` compiled by numba (numpy's error model, machine code cached on disk), or None without numba.

    Compiled on the first call for a function, so that a command that never needs it does not pay numba's
    import (~0.2 s) or the cache load; ``fn`` itself stays callable as plain Python. Its compiles hold a lock
    file in numba's cache folder (:func:`one_compile_at_a_time`).
    """
    try:
        import numba
    except ImportError:  # pragma: no cover
        return None
    from .gesv import register_compiled

    register_compiled()  # the functions that solve call gesv.solve_columns
    return one_compile_at_a_time(numba.njit(error_model="numpy", cache=True)(fn))


@contextlib.contextmanager
def compile_lock(path: Path | None, what: str | None = None):
    """Context holding an exclusive lock on the file ``path`` (None, or a system without ``fcntl``: no lock); ``what``:
    the code compiled, named on stderr while this process waits (None: it waits silently).

    Around a compile with numba's disk cache: when several processes start on an empty cache at once (the suite's two
    xdist workers, ``reproduce``'s two processes), the first compiles and saves while the others wait here, then find
    the machine code in numba's cache and load it, instead of each compiling the same code (the friction kernel: ~15-20 s
    of CPU each). The lock goes with the process that holds it, so a crashed compile never blocks the next."""
    try:
        import fcntl
    except ImportError:  # pragma: no cover (not POSIX)
        fcntl = None
    handle = None
    if path is not None and fcntl is not None:
        try:
            handle = open(path, "a+b")  # noqa: SIM115 (held for the context)
        except OSError:  # a read-only cache folder: compile without waiting
            handle = None
    if handle is None:
        yield
        return
    try:
        try:
            fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            if what is not None:  # the friction kernel's wait (~15-20 s); a small function's passes unremarked
                print(f"waiting for another process compiling {what} (it then loads from the cache) ...", file=sys.stderr,
                      flush=True)
            fcntl.flock(handle, fcntl.LOCK_EX)
        yield
    finally:
        handle.close()  # releases the lock


@contextlib.contextmanager
def compiling(path: Path | None, what: str | None = None):
    """Context for a numba compile or cache load: numba's global compiler lock, then :func:`compile_lock` on ``path``
    (``what`` as there). numba's own nested compiles take its lock first, so every compile here takes the two in that
    order: one order for the two locks in a process."""
    from numba.core.compiler_lock import global_compiler_lock

    with global_compiler_lock, compile_lock(path, what):
        yield


def one_compile_at_a_time(dispatcher):
    """``dispatcher`` (a numba function with ``cache=True``), its compiles (or loads from numba's disk cache) made under
    :func:`compile_lock` on a file beside its cache; returned as it was where numba keeps no cache path for it.

    numba calls ``dispatcher.compile`` for a new signature only, so calls of a compiled one pay nothing."""
    try:
        lock = Path(dispatcher._cache._cache_path) / f"{dispatcher.py_func.__module__}.{dispatcher.py_func.__qualname__}.lock"
    except AttributeError:  # numba's internals moved: compile as numba does
        return dispatcher
    compile_ = dispatcher.compile

    def compile_locked(sig):
        with compiling(lock):
            return compile_(sig)

    dispatcher.compile = compile_locked
    return dispatcher
