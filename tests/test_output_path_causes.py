"""Output-path messages name the real folder and the real cause: a full disk says the disk is full (and which file it
was writing), a read-only folder names that folder (not the lock file servo-press makes beside --out), a run record cut
short is not taken for an earlier version's, and an --out inside another run's result folder is refused before it
makes that folder one its own command refuses to replace."""
from __future__ import annotations

import errno
import os
import shutil
from pathlib import Path

import pytest

from press_io.errors import os_error
from press_io.outputs import MARKER

from bad_input_helpers import cli, refused

pytestmark = pytest.mark.usefixtures("pyplot_imported")  # fixtures_suitecal.py: the figure workers start with matplotlib


def ok(result):
    code, _, err = result
    assert code == 0 and "Traceback" not in err, err


def test_a_full_disk_names_the_file_being_written_and_the_disk(capsys, tmp_path, monkeypatch):
    real = Path.write_text

    def full_disk(self, *args, **kwargs):  # as a write on a full disk fails: errno ENOSPC, no file name
        if self.name.startswith(".summary."):
            raise OSError(errno.ENOSPC, "No space left on device")
        return real(self, *args, **kwargs)

    monkeypatch.setattr(Path, "write_text", full_disk)
    line = refused(cli(capsys, "simulate", "--step-deg", "10", "--out", tmp_path / "run"), "No space left on device", "disk")
    assert str(tmp_path / "run" / "summary.json") in line and "<path>" not in line and "existing file" not in line, line
    assert sorted(p.name for p in tmp_path.iterdir()) == []


def test_a_read_only_folder_is_named_not_the_lock_file(capsys, tmp_path, monkeypatch):
    import press_io.outputs as outputs

    folder = tmp_path / "read_only"
    folder.mkdir()
    real = os.open

    def read_only(path, flags, *args, **kwargs):  # what a folder without write permission does (tests may run as root)
        if Path(path).parent == folder and flags & os.O_CREAT:
            raise PermissionError(errno.EACCES, "Permission denied", str(path))
        return real(path, flags, *args, **kwargs)

    monkeypatch.setattr(outputs.os, "open", read_only)
    line = refused(cli(capsys, "simulate", "--step-deg", "10", "--out", folder / "run"), f"{folder}: Permission denied",
                   "folder you can write")
    assert "lock" not in line and "existing file" not in line, line
    assert list(folder.iterdir()) == []


def test_os_error_without_a_path_says_what_was_written_not_a_placeholder():
    msg = str(os_error(OSError(errno.ENOSPC, "No space left on device")))
    assert "<path>" not in msg and msg.startswith("writing the output: No space left on device: ") and "full" in msg
    assert "existing file" in str(os_error(NotADirectoryError(errno.ENOTDIR, "Not a directory", "a/b")))
    assert "shorter" in str(os_error(OSError(errno.ENAMETOOLONG, "File name too long", "x" * 300)))


def test_a_run_record_cut_short_is_not_called_an_earlier_versions(capsys, tmp_path, simulate_run):
    out = tmp_path / "run"
    shutil.copytree(simulate_run, out, symlinks=True)  # a simulate result (fixtures_suitecal.py)
    record = out / MARKER
    record.write_bytes(record.read_bytes()[:40])  # cut short, as a full disk or a killed copy leaves it
    before = {p.name: p.read_bytes() for p in out.iterdir()}
    line = refused(cli(capsys, "simulate", "--step-deg", "10", "--out", out), MARKER, "cut short")
    assert "earlier servo-press version" not in line, line
    assert {p.name: p.read_bytes() for p in out.iterdir()} == before


@pytest.mark.parametrize("inner", ["inner", "a/b"])
def test_an_out_inside_another_runs_result_is_refused_and_that_result_stays_replaceable(capsys, tmp_path, inner, simulate_run):
    out = tmp_path / "run"
    shutil.copytree(simulate_run, out, symlinks=True)  # a simulate result (fixtures_suitecal.py)
    before = {p.name for p in out.iterdir()}
    refused(cli(capsys, "plan", "--job", "door-panel", "--out", out / inner), f"{out}, the result folder of `servo-press simulate`",
            "outside it")
    assert {p.name for p in out.iterdir()} == before
    ok(cli(capsys, "simulate", "--step-deg", "10", "--out", out))  # its own command still replaces it
