"""Work run beside the caller in a forked process (press_io.forked.beside): its result, its errors, its end."""
from __future__ import annotations

import os
import signal
import subprocess
import sys
import time

import pytest

from press_io.errors import PressDataError, ServoPressError
from press_io.forked import beside


def _needs_fork(b):
    if not b.forked:
        pytest.skip("this system cannot fork")


def test_the_result_comes_from_another_process():
    with beside(lambda: (os.getpid(), [1.5, "x"])) as b:
        _needs_fork(b)
        pid, value = b.result()
    assert pid != os.getpid() and value == [1.5, "x"]


def test_the_work_may_fork_processes_of_its_own():
    def nested():
        with beside(os.getpid) as inner:
            return os.getpid(), inner.result()

    with beside(nested) as b:
        _needs_fork(b)
        middle, inner = b.result()
    assert len({os.getpid(), middle, inner}) == 3


def test_a_user_error_arrives_with_its_message():
    def bad():
        raise PressDataError("job.toml", "design.runs", 0, "must be at least 1")  # its __init__ does not take its message

    with beside(bad) as b:
        _needs_fork(b)
        while not b.failed():
            time.sleep(0.01)
        with pytest.raises(ServoPressError) as err:
            b.result()
    assert str(err.value) == str(PressDataError("job.toml", "design.runs", 0, "must be at least 1"))


def test_a_crash_arrives_with_its_traceback():
    def crash():
        return 1 / 0

    with beside(crash) as b:
        _needs_fork(b)
        with pytest.raises(RuntimeError, match="ZeroDivisionError"):
            b.result()


def test_leaving_the_block_early_ends_the_process():
    with pytest.raises(KeyError):
        with beside(lambda: time.sleep(60)) as b:
            _needs_fork(b)
            raise KeyError("the caller's own step failed")
    assert not b._process.is_alive() and b._process.exitcode is not None


def test_without_fork_the_caller_does_the_work_when_it_asks_for_the_result(monkeypatch):
    import multiprocessing

    monkeypatch.setattr(multiprocessing, "get_all_start_methods", lambda: ["spawn"])
    calls = []
    with beside(lambda: calls.append(os.getpid()) or "done") as b:
        assert not b.forked and not b.running() and not calls  # nothing ran yet
        assert b.result() == "done"
    assert calls == [os.getpid()]


# a command that has forked both kinds of helper, printing their process ids, then waiting to be killed
FORKS_AND_WAITS = """
import os, sys, time
from press_io.forked import beside, warm_process

with warm_process(lambda: None) as pool, beside(lambda: time.sleep(600)) as b:
    if pool is None or not b.forked:
        print("no fork", flush=True)
        sys.exit(0)
    print(pool.submit(os.getpid).result(), b._process.pid, flush=True)
    time.sleep(600)
"""


def _gone(pid: int) -> bool:
    """True once process ``pid`` has ended (a zombie counts: its new parent may not reap it)."""
    try:
        return "\nState:\tZ" in open(f"/proc/{pid}/status", encoding="ascii").read()
    except FileNotFoundError:
        return True


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="the helpers end with their parent on Linux (prctl)")
def test_the_helpers_end_when_the_command_is_killed():
    """SIGKILL gives the command no chance to stop its helpers: they must end by themselves (they were left running,
    holding the command's pipes and its output lock)."""
    proc = subprocess.Popen([sys.executable, "-c", FORKS_AND_WAITS], stdout=subprocess.PIPE, text=True)
    try:
        line = proc.stdout.readline().split()
        if line == ["no", "fork"]:
            pytest.skip("this system cannot fork")
        helpers = [int(x) for x in line]
    finally:
        proc.kill()
        proc.wait()
    deadline = time.monotonic() + 60
    while not all(_gone(p) for p in helpers) and time.monotonic() < deadline:
        time.sleep(0.05)
    alive = [p for p in helpers if not _gone(p)]
    for p in alive:  # left by a failing check: end them here
        os.kill(p, signal.SIGKILL)
    assert not alive


def test_a_helper_whose_parent_is_gone_before_it_starts_ends_at_once():
    """The race the death signal cannot cover: the parent died between the fork and the request."""
    from press_io.forked import die_with_parent

    pid = os.fork()
    if pid == 0:  # the child: a parent id that is not its parent's
        try:
            die_with_parent(os.getppid() + 1)
        finally:
            os._exit(0)  # reached only if die_with_parent did not end the process
    _, status = os.waitpid(pid, 0)
    assert os.waitstatus_to_exitcode(status) == 128 + signal.SIGTERM
