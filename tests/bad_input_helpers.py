"""Shared helpers of the bad-input tests (test_*_errors.py): run the command line and check what the user sees
(exit code 2, one stderr line ``servo-press: error: ...``, no traceback, nothing left behind), edit the reference
press, and the fixed settings of the property-based (hypothesis) readers' tests."""
from __future__ import annotations

import copy
import json
import shutil
import subprocess
import sys
import tomllib
from importlib import resources
from pathlib import Path

import pytest
from hypothesis import HealthCheck

import in_process
from servo_press.cli import main
from press_io.errors import PressDataError
from press_model.press_data import read_press


REF_TEXT = resources.files("press_model.data").joinpath("reference_press.toml").read_text(encoding="utf-8")
REF = tomllib.loads(REF_TEXT)
LONG_NAME = "x" * 300  # longer than any file name the system accepts (ENAMETOOLONG)
ERROR = "servo-press: error: "
FIXED = dict(deadline=None, derandomize=True, suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])
DOOR_TEXT = resources.files("press_model.data").joinpath("door_panel.toml").read_text(encoding="utf-8")
DATA = Path(resources.files("press_model.data").joinpath("reference_press.toml")).parent


def cli(capsys, *argv):
    """(exit code, stdout, stderr) of ``servo-press argv`` run in this process."""
    try:
        code = main([str(a) for a in argv])
    except SystemExit as exc:  # argparse refuses with usage and exit 2
        code = exc.code
    out, err = capsys.readouterr()
    return code, out, err


def servo_press(*argv, cwd=None):
    """The installed ``servo-press`` script in a subprocess: the real exit code and stderr."""
    exe = shutil.which("servo-press")
    cmd = [exe] if exe else [sys.executable, "-m", "servo_press.cli"]
    proc = subprocess.run([*cmd, *map(str, argv)], capture_output=True, text=True, timeout=300, cwd=cwd)
    return proc.returncode, proc.stdout, proc.stderr


def files(root: Path) -> set[str]:
    """Every file and folder under ``root`` (hidden temp files included), relative."""
    return {str(p.relative_to(root)) for p in root.rglob("*")}


def refused(result, *parts: str) -> str:
    """Check a refusal: exit 2, one stderr line 'servo-press: error: ...' holding ``parts``, no traceback."""
    code, _, err = result
    assert "Traceback" not in err, err
    assert code == 2, (code, err)
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(ERROR), err
    for p in parts:
        assert p in lines[0], f"{p!r} not in: {lines[0]}"
    return lines[0]


def usage_error(result, *parts: str) -> str:
    """Check an argparse refusal: the same one-line format as every other error (README), pointing at --help."""
    line = refused(result, *parts)
    assert "--help'" in line, line
    return line


def edited_press(work, old: str, new: str, name="press.toml") -> Path:
    """The reference press file with one text edit, written into the case's folder."""
    assert old in REF_TEXT, old
    path = work.root / name
    path.write_text(REF_TEXT.replace(old, new, 1), encoding="utf-8")
    work.snap()
    return path


def write_log(work, lines, name="log.csv") -> Path:
    path = work.root / name
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    work.snap()
    return path


def with_cell(line: str, column: int, text: str) -> str:
    cells = line.split(",")
    cells[column] = text
    return ",".join(cells)


def calibrated(result, out: Path) -> dict:
    """Check a calibration that ran: exit 0, no traceback, every output written, no temp file left."""
    code, stdout, err = result
    assert code == 0 and "Traceback" not in err, err
    assert "least-squares" in stdout and "RMSE" in stdout
    assert {p.name for p in out.iterdir()} == {".servo-press-run.json", "calibrated.json", "table4.csv", "table4.md", "figure5.png"}
    return json.loads((out / "calibrated.json").read_text(encoding="utf-8"))


def flipped(lines, h, factor):
    return lines[:h + 1] + [with_cell(s, 3, f"{float(s.split(',')[3]) * factor:.6f}") for s in lines[h + 1:]]


def ref() -> dict:
    return copy.deepcopy(REF)


def walk(raw, dotted):
    """The table holding the dotted key and its last part; a table the file leaves to its defaults is added empty."""
    keys = dotted.split(".")
    cur = raw
    for k in keys[:-1]:
        cur = cur.setdefault(k, {})
    return cur, keys[-1]


def setp(dotted, value):
    def mutate(raw):
        cur, k = walk(raw, dotted)
        cur[k] = value
    return mutate


def delp(*dotted):
    def mutate(raw):
        for d in dotted:
            cur, k = walk(raw, d)
            del cur[k]
    return mutate


def both(*mutations):
    def mutate(raw):
        for m in mutations:
            m(raw)
    return mutate


def message_of(mutate) -> str:
    raw = ref()
    mutate(raw)
    with pytest.raises(PressDataError) as info:
        read_press(raw, "test")
    return str(info.value)


def check(msg: str, *parts: str):
    for p in parts:
        assert p in msg, f"{p!r} not in message: {msg}"


def run_cli(*args):
    """``servo-press args`` in this process (tests/in_process.py): returncode, stdout, stderr as a subprocess gives them.
    The real process's exit code and stderr are checked by :func:`servo_press` (the tests named ..._subprocess)."""
    return in_process.servo_press(*args)


def assert_clean_error(proc, *parts):
    assert proc.returncode != 0
    assert "Traceback" not in proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("servo-press: error: "), proc.stderr
    check(lines[0], *parts)
