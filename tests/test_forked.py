"""Work run beside the caller in a forked process (press_model.forked.beside): its result, its errors, its end."""
from __future__ import annotations

import os
import time

import pytest

from press_model.errors import PressDataError, ServoPressError
from press_model.forked import beside


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
