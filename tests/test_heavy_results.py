"""The suite's store of heavy results (tests/heavy_results.py): a result is made once for every process that asks for
it at the same time, read back as it was made, made again when its files were changed since, and kept apart for
other inputs."""
from __future__ import annotations

import multiprocessing
import os
import time

import pytest

from heavy_results import HeavyResults  # noqa: E402 (tests/ is on sys.path, conftest.py)


def _make(folder):
    """A result: one file, and a line per making in made.log beside the store's entries (who made it); it takes a
    moment, so that two processes asking at once overlap unless the lock keeps them apart."""
    time.sleep(0.3)
    (folder / "out.txt").write_text("made", encoding="utf-8")
    with open(folder.parents[1] / "made.log", "a", encoding="utf-8") as log:
        log.write(f"{os.getpid()}\n")
    return {"pid": os.getpid()}


def _made(root) -> int:
    return len((root / "made.log").read_text(encoding="utf-8").split())


def _ask(root, scratch, start, answers):
    start.wait(60)  # both ask at the same moment
    folder, value = HeavyResults(root, scratch).get("thing", _make)
    answers.put((str(folder), value, (folder / "out.txt").read_text(encoding="utf-8")))


def test_two_processes_asking_at_once_make_the_result_once(tmp_path):
    if "fork" not in multiprocessing.get_all_start_methods():
        pytest.skip("this system cannot fork")
    ctx = multiprocessing.get_context("fork")
    root = tmp_path / "store"
    root.mkdir()
    start, answers = ctx.Barrier(2), ctx.Queue()
    procs = [ctx.Process(target=_ask, args=(root, tmp_path / f"scratch{i}", start, answers)) for i in range(2)]
    for p in procs:
        p.start()
    got = [answers.get(timeout=120) for _ in procs]
    for p in procs:
        p.join(60)
    assert got[0] == got[1] and got[0][2] == "made"  # the same folder and value: the one the maker returned
    assert _made(root) == 1


def test_a_result_changed_since_it_was_made_is_made_again_and_other_inputs_get_their_own(tmp_path):
    root = tmp_path / "store"
    root.mkdir()
    folder, first = HeavyResults(root, tmp_path).get("thing", _make)
    assert HeavyResults(root, tmp_path).get("thing", _make) == (folder, first) and _made(root) == 1  # read back
    (folder / "out.txt").write_text("changed by a test", encoding="utf-8")
    again, _ = HeavyResults(root, tmp_path).get("thing", _make)
    assert again == folder and (again / "out.txt").read_text(encoding="utf-8") == "made" and _made(root) == 2
    other, _ = HeavyResults(root, tmp_path).get("thing", _make, "seed 1")
    assert other != folder and _made(root) == 3


def test_without_pytests_cache_each_process_makes_its_own(tmp_path):
    folder, _ = HeavyResults(None, tmp_path).get("thing", _make)
    assert folder.is_relative_to(tmp_path) and (folder / "out.txt").read_text(encoding="utf-8") == "made"
