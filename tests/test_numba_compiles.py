"""The suite's numba compile lock (tests/numba_compiles.py): two processes that compile one disk-cached function at
the same moment compile it once, the second loading the first one's machine code from the disk cache."""
from __future__ import annotations

import importlib.util
import multiprocessing
import sys

import pytest

SOURCE = "import numba\n\n\n@numba.njit(cache=True)\ndef f(x):\n    return 2.0 * x + 1.0\n"


def _compile_at_once(path, barrier, queue):
    spec = importlib.util.spec_from_file_location("compiled_twice", path)
    module = importlib.util.module_from_spec(spec)
    sys.modules["compiled_twice"] = module  # numba's cache finds the function's module by its name
    spec.loader.exec_module(module)
    barrier.wait(30)  # both processes ask numba for the compile together
    assert module.f(1.0) == 3.0
    queue.put((sum(module.f._cache_misses.values()), sum(module.f._cache_hits.values())))


def test_two_processes_compile_a_disk_cached_function_once(tmp_path):
    """Without the lock both processes miss the empty cache and compile (misses 1 and 1); with it one compiles and
    the other loads (misses 1 and 0, hits 0 and 1)."""
    if "fork" not in multiprocessing.get_all_start_methods():
        pytest.skip("this system cannot fork")
    path = tmp_path / "compiled_twice.py"  # numba caches its machine code beside it (__pycache__), empty now
    path.write_text(SOURCE, encoding="utf-8")
    ctx = multiprocessing.get_context("fork")  # the children inherit this process's numba, the lock installed
    barrier, queue = ctx.Barrier(2), ctx.Queue()
    procs = [ctx.Process(target=_compile_at_once, args=(path, barrier, queue)) for _ in range(2)]
    for p in procs:
        p.start()
    got = sorted(queue.get(timeout=120) for _ in procs)
    for p in procs:
        p.join(30)
    assert [p.exitcode for p in procs] == [0, 0]
    assert got == [(0, 1), (1, 0)], got
