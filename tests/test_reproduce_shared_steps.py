"""reproduce's steps shared by two processes (servo_press/reproduce.py, SharedSteps): each step runs once, a
handed step's result reaches the parent while the second process still works, and a second process that fails
before handing it over raises its error instead of leaving the parent waiting."""
from __future__ import annotations

import multiprocessing
import os

import pytest

from servo_press.reproduce import SharedSteps, _Handed
from press_io.forked import beside

NAMES = ("plan", "design", "sobol a", "sobol b")


def _needs_fork(b):
    if not b.forked:
        pytest.skip("this system cannot fork")


def _take_all(shared: SharedSteps) -> list[str]:
    taken = []
    while (name := shared.take()) is not None:
        taken.append(name)
    return taken


def test_two_processes_take_every_step_once():
    shared = SharedSteps(NAMES)
    assert shared.claim("sobol a")  # taken out of order by the process that needs it
    assert not shared.claim("sobol a")
    with beside(lambda: _take_all(shared)) as b:
        _needs_fork(b)
        here = _take_all(shared)
        there = b.result()
    assert sorted(here + there) == sorted(n for n in NAMES if n != "sobol a")


def test_a_handed_result_reaches_the_parent_while_the_second_process_still_works():
    shared = SharedSteps(NAMES, handed=("plan",))
    ctx = multiprocessing.get_context("fork")
    taken, received = ctx.Event(), ctx.Event()

    def second():
        assert shared.take() == "plan"
        taken.set()
        shared.hand("plan", {"from": os.getpid(), "data": bytes(range(256)) * 4096})  # 1 MB: more than a pipe holds
        return received.wait(60)  # ends only once the parent has the result: it was handed over, not returned

    with beside(second) as b:
        _needs_fork(b)
        assert taken.wait(60)
        value = _Handed(shared, "plan", b, lambda: pytest.fail("the step was planned twice")).result()
        received.set()
        assert b.result() is True
    assert value["from"] != os.getpid() and value["data"] == bytes(range(256)) * 4096


def test_a_step_nobody_took_runs_in_the_process_that_needs_it():
    shared = SharedSteps(NAMES, handed=("plan",))
    with beside(lambda: None) as b:
        assert _Handed(shared, "plan", b, lambda: ("here", os.getpid())).result() == ("here", os.getpid())
        b.result()
    assert "plan" not in _take_all(shared)


def test_a_second_process_that_fails_before_handing_over_raises_its_error():
    shared = SharedSteps(NAMES, handed=("plan",))

    taken = multiprocessing.get_context("fork").Event()

    def second():
        shared.take()
        taken.set()
        raise ZeroDivisionError("the plan failed")

    with beside(second) as b:
        _needs_fork(b)
        assert taken.wait(60)
        with pytest.raises(RuntimeError, match="the plan failed"):
            _Handed(shared, "plan", b, lambda: pytest.fail("the step was planned twice")).result()
