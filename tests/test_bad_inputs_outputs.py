"""Output folders and files through the real command line: nothing servo-press did not write is ever deleted.

A run folder holds ``.servo-press-run.json`` naming the command that wrote it and its files. A rerun of the same
command replaces its own earlier result whole; another command's folder (a monitor history, a synthetic fleet),
a file the user added, and a result folder without that record are refused before anything runs, and left byte
for byte as they were. A second run on the same ``--out`` while one runs is refused (a lock), so that two runs
never both report success with one result silently lost.
"""
from __future__ import annotations

import errno
import json
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from press_model.commands.cli import main
from press_model.outputs import MARKER, claim

from bad_input_helpers import cli, refused  # noqa: E402 (tests/ is on sys.path, conftest.py)


def snapshot(root: Path) -> dict[str, bytes | None]:
    """Every file (its bytes) and folder (None) under ``root``, hidden ones included."""
    return {str(p.relative_to(root)): (None if p.is_dir() else p.read_bytes()) for p in root.rglob("*")}


def ok(result):
    code, _, err = result
    assert code == 0 and "Traceback" not in err, err


@pytest.fixture(scope="module")
def fleet_and_monitor(tmp_path_factory):
    """A SYNTHETIC fleet of two logs (`experiment --fleet 2`) and the monitor folder of one of them (in this process)."""
    root = tmp_path_factory.mktemp("fleet")
    assert main(["experiment", "--fleet", "2", "--out", str(root / "fleet")]) == 0
    logs = root / "one_log"
    logs.mkdir()
    shutil.copy(root / "fleet" / "log_000.csv", logs / "log_000.csv")
    assert main(["monitor", "--logs", str(logs), "--workers", "1", "--method", "least-squares", "--out", str(root / "monitor")]) == 0
    return root


def test_a_run_folder_records_its_command_and_files(capsys, tmp_path):
    ok(cli(capsys, "simulate", "--step-deg", "10", "--out", tmp_path / "run"))
    rec = json.loads((tmp_path / "run" / MARKER).read_text())
    assert rec["command"] == "simulate" and rec["files"] == ["cycle.csv", "cycle.png", "power.csv", "power.png", "summary.json"]


def test_simulate_into_a_monitor_folder_is_refused_and_its_history_kept(capsys, fleet_and_monitor):
    mon = fleet_and_monitor / "monitor"
    before = snapshot(mon)
    assert any(name.startswith("logs/") for name in before)  # the per-log results a rerun resumes from
    refused(cli(capsys, "simulate", "--step-deg", "10", "--out", mon), "holds the result of `servo-press monitor`",
            "choose another --out")
    assert snapshot(mon) == before


@pytest.mark.parametrize("command", [["simulate", "--step-deg", "10"], ["experiment", "--fleet", "1"]])
def test_a_fleet_folder_with_a_log_the_user_added_is_refused(capsys, fleet_and_monitor, command):
    fleet = fleet_and_monitor / "fleet"
    added = fleet / "log_measured.csv"
    added.write_text("# a measured log the user put beside the synthetic ones\ntime_s,crank_angle_deg\n", encoding="utf-8")
    try:
        before = snapshot(fleet)
        line = refused(cli(capsys, *command, "--out", fleet), "--out")
        if command[0] == "simulate":
            assert "holds the result of `servo-press experiment --fleet`" in line
        else:
            assert "servo-press did not write there (log_measured.csv)" in line and "move them out" in line
        assert snapshot(fleet) == before
    finally:
        added.unlink()


def test_a_rerun_of_the_same_command_replaces_its_own_folder_whole(capsys, tmp_path):
    out = tmp_path / "fleet"
    ok(cli(capsys, "experiment", "--fleet", "2", "--out", out))
    ok(cli(capsys, "experiment", "--fleet", "1", "--seed", "3", "--out", out))
    assert sorted(p.name for p in out.iterdir()) == [MARKER, "fleet.json", "log_000.csv", "log_000.truth.json"]  # log_001: gone
    assert sorted(p.name for p in tmp_path.iterdir()) == ["fleet"]  # no temporary sibling, no lock file left


@pytest.mark.parametrize("argv", [["calibrate", "--log", "LOG"], ["monitor", "--logs", "LOGS"]])
def test_another_commands_folder_is_refused(capsys, fleet_and_monitor, tmp_path, argv):
    ok(cli(capsys, "simulate", "--step-deg", "10", "--out", tmp_path / "sim"))
    log = fleet_and_monitor / "fleet" / "log_000.csv"
    argv = [str(log) if a == "LOG" else str(log.parent) if a == "LOGS" else a for a in argv]
    before = snapshot(tmp_path)
    refused(cli(capsys, *argv, "--out", tmp_path / "sim"), "holds the result of `servo-press simulate`")
    assert snapshot(tmp_path) == before


def test_a_result_folder_without_the_record_is_refused(capsys, tmp_path):
    old = tmp_path / "old"  # what servo-press wrote before it recorded its files: it cannot tell them from the user's
    old.mkdir()
    (old / "summary.json").write_text('{"versions": {}}\n', encoding="utf-8")
    (old / "notes.txt").write_text("mine\n", encoding="utf-8")
    before = snapshot(tmp_path)
    refused(cli(capsys, "simulate", "--step-deg", "10", "--out", old), "earlier servo-press version", "did not record")
    assert snapshot(tmp_path) == before


def test_a_second_run_on_the_same_out_while_one_runs_is_refused(capsys, tmp_path):
    out = tmp_path / "run"
    with claim(out):  # what a first run holds from its start to its end
        refused(cli(capsys, "simulate", "--step-deg", "10", "--out", out), "another servo-press run", "is writing it now")
        refused(cli(capsys, "experiment", "--out", tmp_path / "run"), "another servo-press run")
    assert sorted(p.name for p in tmp_path.iterdir()) == []  # neither wrote anything; the lock is gone


def test_a_lock_file_left_by_a_killed_run_does_not_block(capsys, tmp_path):
    (tmp_path / ".run.lock").write_text("99999999\n", encoding="ascii")  # nobody holds it: the lock is the system's
    ok(cli(capsys, "simulate", "--step-deg", "10", "--out", tmp_path / "run"))
    assert sorted(p.name for p in tmp_path.iterdir()) == ["run"]


def test_two_concurrent_runs_one_result_each_or_refused(tmp_path):
    """Two real processes on one --out: each either finishes (and its result is the folder's, one after the
    other) or is refused with the lock's message; never both 'wrote' with one result lost."""
    exe = shutil.which("servo-press")
    cmd = [exe] if exe else [sys.executable, "-m", "press_model.commands.cli"]
    procs = [subprocess.Popen([*cmd, "simulate", "--step-deg", "10", "--spm", spm, "--out", str(tmp_path / "run")],
                              stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True) for spm in ("10", "12")]
    results = [(p.wait(timeout=300), *p.communicate()) for p in procs]
    for code, _, err in results:
        assert "Traceback" not in err and (code == 0 or "another servo-press run" in err), err
    assert any(code == 0 for code, _, _ in results)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["run"]


def test_a_failed_write_names_the_out_path_not_the_temporary_folder(capsys, tmp_path, monkeypatch):
    import press_model.outputs as outputs

    real = outputs.atomic_write

    def full_disk(path, write, suffix=""):
        if Path(path).name == "summary.json":
            raise OSError(errno.ENOSPC, "No space left on device", str(path))
        real(path, write, suffix)

    monkeypatch.setattr(outputs, "atomic_write", full_disk)
    line = refused(cli(capsys, "simulate", "--step-deg", "10", "--out", tmp_path / "run"), "No space left on device")
    assert str(tmp_path / "run" / "summary.json") in line and ".tmp-" not in line
    assert sorted(p.name for p in tmp_path.iterdir()) == []


def test_a_long_out_name_is_written(capsys, tmp_path):
    name = "y" * 250  # a valid name; its temporary sibling and lock must not exceed the system's 255
    ok(cli(capsys, "simulate", "--step-deg", "10", "--out", tmp_path / name))
    assert sorted(p.name for p in tmp_path.iterdir()) == [name]
