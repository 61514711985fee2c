"""Output folders and files through the real command line: nothing servo-press did not write is ever deleted.

A run folder holds ``.servo-press-run.json`` naming the command that wrote it and its files. A rerun of the same
command replaces its own earlier result whole; another command's folder (a monitor history, a synthetic fleet),
a file the user added, and a result folder without that record are refused before anything runs, and left byte
for byte as they were. A second run on the same ``--out`` while one runs is refused (a lock), so that two runs
never both report success with one result silently lost.
"""
from __future__ import annotations

import errno
import hashlib
import json
import os
import signal
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from servo_press.cli import main
from press_io.outputs import MARKER, claim, lock_path, output_folder

from bad_input_helpers import cli, refused  # noqa: E402 (tests/ is on sys.path, conftest.py)

pytestmark = pytest.mark.usefixtures("pyplot_imported")  # fixtures_suitecal.py: the figure workers start with matplotlib


def snapshot(root: Path) -> dict[str, bytes | None]:
    """Every file (its bytes), link (where it points) and folder (None) under ``root``, hidden ones included."""
    return {str(p.relative_to(root)): (f"-> {os.readlink(p)}" if p.is_symlink() else None if p.is_dir() else p.read_bytes())
            for p in root.rglob("*")}


def ok(result):
    code, _, err = result
    assert code == 0 and "Traceback" not in err, err


@pytest.fixture(scope="module")
def fleet_and_monitor(tmp_path_factory, eta_gear_only_job):
    """A SYNTHETIC fleet of two logs (`experiment --fleet 2`) and the monitor folder of one of them (in this process).
    The tests read the folders' records and files, not the calibration in them: the monitor calibrates with
    fixtures_suitecal.py's eta_gear_only_job (eta_gear alone, no bootstrap), the cheapest that writes every file."""
    root = tmp_path_factory.mktemp("fleet")
    assert main(["experiment", "--fleet", "2", "--out", str(root / "fleet")]) == 0
    logs = root / "one_log"
    logs.mkdir()
    shutil.copy(root / "fleet" / "log_000.csv", logs / "log_000.csv")
    assert main(["monitor", "--logs", str(logs), "--workers", "1", "--method", "least-squares", "--job", str(eta_gear_only_job),
                 "--out", str(root / "monitor")]) == 0
    return root


def test_a_run_folder_records_its_command_and_files(simulate_run):
    """The record of `simulate --step-deg 10 --out run` (fixtures_suitecal.py: run once for the suite, read only)."""
    rec = json.loads((simulate_run / MARKER).read_text())
    assert rec["command"] == "simulate" and [f["path"] for f in rec["files"]] == ["cycle.csv", "cycle.png", "power.csv", "power.png",
                                                                               "summary.json"]
    for f in rec["files"]:  # what a rerun checks before it deletes anything
        data = (simulate_run / f["path"]).read_bytes()
        assert f["bytes"] == len(data) and f["sha256"] == hashlib.sha256(data).hexdigest()
    assert rec["folders"] == []


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
def test_another_commands_folder_is_refused(capsys, fleet_and_monitor, tmp_path, argv, simulate_run):
    shutil.copytree(simulate_run, tmp_path / "sim", symlinks=True)  # a simulate result (fixtures_suitecal.py)
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




def test_two_concurrent_runs_one_result_each_or_refused(tmp_path):
    """Two real processes on one --out: each either finishes (and its result is the folder's, one after the
    other) or is refused with the lock's message; never both 'wrote' with one result lost."""
    exe = shutil.which("servo-press")
    cmd = [exe] if exe else [sys.executable, "-m", "servo_press.cli"]
    procs = [subprocess.Popen([*cmd, "simulate", "--step-deg", "10", "--spm", spm, "--out", str(tmp_path / "run")],
                              stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True) for spm in ("10", "12")]
    results = [(p.wait(timeout=300), *p.communicate()) for p in procs]
    for code, _, err in results:
        assert "Traceback" not in err and (code == 0 or "another servo-press run" in err), err
    assert any(code == 0 for code, _, _ in results)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["run"]


def test_a_failed_write_names_the_out_path_not_the_temporary_folder(capsys, tmp_path, monkeypatch):
    import press_io.outputs as outputs

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



# --- the record is not trusted as written: only files whose size and SHA-256 match it are replaced --------------
def _record(folder: Path, files, folders=None) -> None:
    rec = {"command": "simulate", "files": files, **({"folders": folders} if folders is not None else {})}
    (folder / MARKER).write_text(json.dumps(rec), encoding="utf-8")


@pytest.mark.parametrize("kind", ["names only, as an earlier version wrote", "a made-up size and hash"])
def test_a_hand_made_record_listing_a_users_file_does_not_get_it_deleted(capsys, tmp_path, kind):
    mine = tmp_path / "mine"
    mine.mkdir()
    (mine / "notes.txt").write_text("my measurements\n", encoding="utf-8")
    if kind.startswith("names"):
        _record(mine, ["notes.txt"])
        expected = ("without their sizes and SHA-256", "deletes none of them", "choose another --out")
    else:
        _record(mine, [{"path": "notes.txt", "bytes": 16, "sha256": "0" * 64}], [])
        expected = ("notes.txt was not written by servo-press or changed since", "move it out, or choose another --out")
    before = snapshot(tmp_path)
    refused(cli(capsys, "simulate", "--step-deg", "10", "--out", mine), *expected)
    assert snapshot(tmp_path) == before


def test_a_result_file_changed_since_its_run_is_refused_not_replaced(capsys, tmp_path, simulate_run):
    out = tmp_path / "run"
    shutil.copytree(simulate_run, out, symlinks=True)  # a simulate result (fixtures_suitecal.py)
    with open(out / "summary.json", "a", encoding="utf-8") as fh:
        fh.write("\n")  # the user's edit: one byte more
    before = snapshot(tmp_path)
    refused(cli(capsys, "simulate", "--step-deg", "10", "--out", out), "summary.json was not written by servo-press or changed since",
            "move it out, or choose another --out")
    assert snapshot(tmp_path) == before


def test_a_users_empty_folder_inside_a_result_is_refused_and_kept(capsys, tmp_path, simulate_run):
    out = tmp_path / "run"
    shutil.copytree(simulate_run, out, symlinks=True)  # a simulate result (fixtures_suitecal.py)
    (out / "mine").mkdir()
    before = snapshot(tmp_path)
    refused(cli(capsys, "simulate", "--step-deg", "10", "--out", out), "servo-press did not write there (mine/)")
    assert snapshot(tmp_path) == before


def test_a_results_own_subfolders_are_replaced_on_rerun(tmp_path):
    out = tmp_path / "run"
    for text in ("first", "second"):
        with output_folder(out, [], "simulate") as tmp:
            (tmp / "sub" / "deeper").mkdir(parents=True)
            (tmp / "sub" / "deeper" / "x.txt").write_text(text, encoding="utf-8")
    assert (out / "sub" / "deeper" / "x.txt").read_text(encoding="utf-8") == "second"
    assert json.loads((out / MARKER).read_text())["folders"] == ["sub", "sub/deeper"]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["run"]


# --- the lock beside --out is never a user's file ------------------------------------------------------------
def test_a_users_file_named_like_a_lock_beside_out_is_kept(capsys, tmp_path):
    (tmp_path / ".run.lock").write_text("my notes\n", encoding="utf-8")  # the name of the lock before it was made unmistakable
    ok(cli(capsys, "simulate", "--step-deg", "10", "--out", tmp_path / "run"))
    assert (tmp_path / ".run.lock").read_text(encoding="utf-8") == "my notes\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == [".run.lock", "run"]


def test_a_file_servo_press_did_not_make_at_the_locks_name_is_refused_and_kept(capsys, tmp_path):
    lock = lock_path(tmp_path / "run")
    lock.write_text("not a lock\n", encoding="utf-8")
    before = snapshot(tmp_path)
    refused(cli(capsys, "simulate", "--step-deg", "10", "--out", tmp_path / "run"), lock.name, "a file servo-press did not make",
            "move that file, or choose another --out")
    assert snapshot(tmp_path) == before


HOLD_AND_SLEEP = """
import sys, time
from press_io.outputs import output_folder
with output_folder(sys.argv[1], [], "simulate") as tmp:
    (tmp / "half.csv").write_text("a half-written result", encoding="utf-8")
    print("writing", flush=True)
    time.sleep(600)
"""


def _gone(pid: int) -> bool:
    """True once process ``pid`` has ended (a zombie counts: its parent may not reap it)."""
    try:
        return "\nState:\tZ" in Path(f"/proc/{pid}/status").read_text()
    except FileNotFoundError:
        return True


def _dead_pid() -> int:
    proc = subprocess.Popen([sys.executable, "-c", "pass"])
    proc.wait()
    return proc.pid


def test_a_killed_runs_lock_and_temporary_folder_do_not_outlive_it(capsys, tmp_path):
    """SIGKILL leaves the lock file (the system released the lock) and ``.run.tmp-<pid>``: the next run takes the lock
    and removes the folder, since its process is gone and it holds a servo-press record; a folder of the user's that
    merely has such a name stays."""
    proc = subprocess.Popen([sys.executable, "-c", HOLD_AND_SLEEP, str(tmp_path / "run")], stdout=subprocess.PIPE, text=True)
    try:
        assert proc.stdout.readline() == "writing\n"
    finally:
        proc.kill()
        proc.wait()
    left = tmp_path / f".run.tmp-{proc.pid}"
    assert (left / "half.csv").is_file()  # and the lock file, which the system no longer holds
    users = tmp_path / f".run.tmp-{_dead_pid()}"
    users.mkdir()
    (users / "keep.txt").write_text("mine\n", encoding="utf-8")
    ok(cli(capsys, "simulate", "--step-deg", "10", "--out", tmp_path / "run"))
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(["run", users.name])
    assert (users / "keep.txt").read_text(encoding="utf-8") == "mine\n"


# --- a link as --out -------------------------------------------------------------------------------------------
def test_a_linked_out_writes_the_folder_it_points_to_and_keeps_the_link(capsys, tmp_path):
    real = tmp_path / "disk" / "results"
    real.mkdir(parents=True)
    link = tmp_path / "run"
    link.symlink_to(real, target_is_directory=True)
    for spm in ("11.4", "12"):  # a first run into the empty folder, then a rerun replacing it
        ok(cli(capsys, "simulate", "--step-deg", "10", "--spm", spm, "--out", link))
    assert link.is_symlink() and os.readlink(link) == str(real)
    assert json.loads((real / "summary.json").read_text())["strokes_per_min"] == 12.0
    assert sorted(p.name for p in tmp_path.iterdir()) == ["disk", "run"] and sorted(p.name for p in real.parent.iterdir()) == ["results"]


def test_a_link_to_nothing_as_out_is_refused(capsys, tmp_path):
    (tmp_path / "run").symlink_to(tmp_path / "nowhere", target_is_directory=True)
    before = snapshot(tmp_path)
    refused(cli(capsys, "simulate", "--step-deg", "10", "--out", tmp_path / "run"), "is a symbolic link to", "which does not exist")
    assert snapshot(tmp_path) == before


def test_the_help_says_what_an_interrupted_run_leaves():
    from servo_press.cli import build_parser

    text = " ".join(build_parser().format_help().split())
    assert "written whole or not at all, also when Ctrl-C (exit 130) or SIGTERM (143) stops the run" in text
    assert "only while that is as the run wrote it; monitor resumes its folder instead" in text


def test_a_lock_left_half_made_by_a_killed_run_is_removed_and_a_users_file_kept(capsys, tmp_path):
    lock = lock_path(tmp_path / "run")
    half = lock.with_name(f"{lock.name}.{_dead_pid()}")  # a run killed between making its lock and naming it
    half.write_bytes(b"servo-press lock of process 1\n")
    mine = lock.with_name(f"{lock.name}.{_dead_pid()}")
    mine.write_text("mine\n", encoding="utf-8")
    ok(cli(capsys, "simulate", "--step-deg", "10", "--out", tmp_path / "run"))
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted([mine.name, "run"])


def test_a_linked_urdf_out_writes_the_file_it_points_to_and_keeps_the_link(capsys, tmp_path):
    real = tmp_path / "disk" / "press.urdf"
    real.parent.mkdir()
    link = tmp_path / "press.urdf"
    link.symlink_to(real)
    for _ in range(2):  # the first run makes the file, the second replaces it
        ok(cli(capsys, "urdf", "--out", link))
    assert link.is_symlink() and real.read_text(encoding="utf-8").lstrip().startswith("<?xml")


def test_ctrl_c_between_a_urdf_and_its_loop_file_writes_both_then_stops(tmp_path, monkeypatch):
    """The URDF and its loop file are one result: a Ctrl-C after the first is written is raised after the second
    (a new URDF beside an earlier press's loop file was left otherwise)."""
    import press_model.urdf as urdf
    from press_io.interrupts import Interrupted
    from press_model.press_data import load_press

    real = urdf.atomic_write_text

    def write_then_ctrl_c(path, text):
        real(path, text)
        if Path(path).suffix == ".urdf":
            os.kill(os.getpid(), signal.SIGINT)
            sum(range(100_000))  # Python work, where the signal's handler runs

    monkeypatch.setattr(urdf, "atomic_write_text", write_then_ctrl_c)
    with pytest.raises(Interrupted):
        urdf.write_urdf(load_press(), tmp_path / "press.urdf")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["press.loops.json", "press.urdf"]


def test_a_rerun_without_a_one_step_swap_replaces_the_folder_by_two_renames(tmp_path, monkeypatch):
    import press_io.outputs as outputs

    monkeypatch.setattr(outputs, "_exchange", lambda a, b: False)  # a system or file system without renameat2
    out = tmp_path / "run"
    for text in ("first", "second"):
        with output_folder(out, [], "simulate") as tmp:
            (tmp / "x.txt").write_text(text, encoding="utf-8")
    assert (out / "x.txt").read_text(encoding="utf-8") == "second"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["run"]  # no .run.old-<pid>, no temporary folder
