"""Bad output paths (``--out``): nothing the user gave or made is overwritten, a run writes all of its files or none.

A file where a folder is wanted, a folder under a file, a name too long, an empty path, the current folder, a
folder holding other files or an input, a URDF or log another press (or a measurement) made: refused in one
line, and the folder is left as it was; an earlier result folder is replaced whole, and a run that fails late
leaves it untouched.
"""
from __future__ import annotations

import json
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest

from bad_input_helpers import LONG_NAME, cli, refused, write_log, flipped
from in_process import servo_press

pytestmark = pytest.mark.usefixtures("pyplot_imported")  # fixtures_suitecal.py: the figure workers start with matplotlib


@pytest.fixture
def a_file(work):
    path = work.root / "a_file"
    path.write_text("not a folder\n", encoding="utf-8")
    work.snap()
    return path


def test_simulate_out_is_an_existing_file(capsys, work, a_file):
    refused(cli(capsys, "simulate", "--step-deg", "10", "--out", a_file), str(a_file))
    work.unchanged()


def test_simulate_out_folder_under_a_file(capsys, work, a_file):
    refused(cli(capsys, "simulate", "--step-deg", "10", "--out", a_file / "sub"), str(a_file))
    work.unchanged()


def test_simulate_out_name_too_long(capsys, work):
    refused(cli(capsys, "simulate", "--step-deg", "10", "--out", work.root / LONG_NAME), LONG_NAME[:50])
    work.unchanged()


def test_urdf_out_under_a_file(capsys, work, a_file):
    refused(cli(capsys, "urdf", "--out", a_file / "x.urdf"), str(a_file))
    work.unchanged()


def test_urdf_out_name_with_xml_characters(capsys, work):
    out = work.out / 'a"b&c.urdf'
    code, _, err = cli(capsys, "urdf", "--out", out)
    if code == 0:
        ET.parse(out)
        import pinocchio as pin

        pin.buildModelFromUrdf(str(out))
    else:
        refused((code, "", err), "--out")
        work.unchanged()


def test_experiment_out_is_an_existing_folder(capsys, work):
    folder = work.root / "a_folder"
    folder.mkdir()
    work.snap()
    refused(cli(capsys, "experiment", "--out", folder), str(folder))
    work.unchanged()  # os.replace failed: the temp file must be gone, and no truth.json written either


def test_experiment_out_under_an_existing_file(capsys, work, a_file):
    """In this process: the exit code and line are main()'s (a refusal's in a real process: test_press_file_errors.py)."""
    refused(cli(capsys, "experiment", "--out", a_file / "log.csv"), str(a_file))
    work.unchanged()


def test_experiment_out_is_the_truth_file(capsys, work):
    truth = work.root / "truth.json"
    truth.write_text(json.dumps({"eta_gear": 0.9}), encoding="utf-8")
    work.snap()
    refused(cli(capsys, "experiment", "--truth", truth, "--out", truth), "is the input file", "inputs are never overwritten")
    work.unchanged()


@pytest.mark.parametrize("command", [["urdf"], ["experiment"], ["simulate", "--step-deg", "10"], ["sensitivity"]])
def test_out_empty_is_refused(capsys, work, command):
    refused(cli(capsys, *command, "--out", ""), "--out = ''", "is not valid")
    work.unchanged()


# the URDF
def test_urdf_without_out_writes_the_press_name_in_the_current_folder(work):
    tracked = Path(__file__).resolve().parents[1] / "urdf" / "eight_bar.urdf"
    before = tracked.read_bytes()
    r = servo_press("urdf", "--press", "crank-slider", cwd=work.root)  # in this process, in that folder (tests/in_process.py)
    code, err = r.returncode, r.stderr
    assert code == 0 and "Traceback" not in err, err
    assert tracked.read_bytes() == before  # the reference file in the repository is not touched
    made = sorted(p.name for p in work.root.iterdir())
    assert made == ["crank-slider_press_illustrative_0.5_m_stroke.loops.json", "crank-slider_press_illustrative_0.5_m_stroke.urdf"]


def test_urdf_refuses_to_replace_the_urdf_of_another_press(capsys, work):
    target = work.root / "press.urdf"
    assert cli(capsys, "urdf", "--out", target)[0] == 0  # the reference press
    work.snap()
    refused(cli(capsys, "urdf", "--press", "crank-slider", "--out", target),
            str(target), "exists and is the URDF of another press ('25,000 kN servo press", "choose another --out")
    work.unchanged()
    assert cli(capsys, "urdf", "--out", target)[0] == 0  # the same press: replaced
    work.unchanged()


def test_urdf_refuses_to_replace_a_file_it_did_not_write(capsys, work):
    target = work.root / "notes.urdf"
    target.write_text("my own notes\n", encoding="utf-8")
    work.snap()
    refused(cli(capsys, "urdf", "--out", target), "notes.urdf", "a file servo-press did not write")
    work.unchanged()


def test_experiment_refuses_to_replace_a_measured_log(capsys, work, log_lines):
    lines = [s for s in log_lines[0] if not s.startswith("#")]
    path = write_log(work, lines, "measured.csv")
    refused(cli(capsys, "experiment", "--out", path), "measured.csv", "is not a synthetic log of `servo-press experiment`")
    work.unchanged()


# output folders: all of a run's files or none, and what happens to old files
def test_rerun_replaces_the_folder_whole(capsys, work):
    assert cli(capsys, "simulate", "--step-deg", "10", "--playback", "--out", work.out)[0] == 0
    assert (work.out / "playback.csv").is_file()
    assert cli(capsys, "simulate", "--step-deg", "10", "--out", work.out)[0] == 0
    assert sorted(p.name for p in work.out.iterdir()) == [".servo-press-run.json", "cycle.csv", "cycle.png", "power.csv", "power.png", "summary.json"]  # no stale playback.csv
    assert sorted(p.name for p in work.root.iterdir()) == ["out"]  # no temporary sibling left


def test_a_run_that_fails_late_leaves_the_earlier_result_untouched(capsys, work, log_lines, eta_gear_only_job):
    """The earlier result is what is kept, whatever it holds: a calibration of the job reduced to eta_gear alone, no
    bootstrap (fixtures_suitecal.py) writes the same set of files as any other."""
    lines, h = log_lines
    good = write_log(work, lines, "good.csv")
    assert cli(capsys, "calibrate", "--log", good, "--method", "least-squares", "--job", eta_gear_only_job, "--out", work.out)[0] == 0
    work.snap()
    path = write_log(work, flipped(lines, h, -1.0))  # refused after the log is read, inside the run
    work.snap()
    refused(cli(capsys, "calibrate", "--log", path, "--out", work.out), "opposite sign")
    work.unchanged()


def test_out_folder_holding_other_files_is_refused(capsys, work):
    (work.root / "mine").mkdir()
    (work.root / "mine" / "notes.txt").write_text("keep me\n", encoding="utf-8")
    work.snap()
    refused(cli(capsys, "simulate", "--step-deg", "10", "--out", work.root / "mine"), "holding files that are not a servo-press result",
            "notes.txt", "choose a new or empty folder")
    work.unchanged()


def test_out_folder_holding_an_input_is_refused(capsys, work, log_lines):
    folder = work.root / "run"
    folder.mkdir()
    (folder / "summary.json").write_text('{"versions": {}}\n', encoding="utf-8")  # looks like an earlier result
    path = folder / "log.csv"
    path.write_text("\n".join(log_lines[0]) + "\n", encoding="utf-8")
    work.snap()
    refused(cli(capsys, "calibrate", "--log", path, "--out", folder), "holds the input file", "inputs are never overwritten")
    work.unchanged()


def test_out_current_folder_is_refused(work):
    r = servo_press("simulate", "--step-deg", "10", "--out", ".", cwd=work.root)  # in this process, in that folder
    refused((r.returncode, r.stdout, r.stderr), "--out .", "is the current folder")
    work.unchanged()


def test_out_under_missing_folders_leaves_none_behind(capsys, work):
    refused(cli(capsys, "simulate", "--spm", "0", "--out", work.root / "a" / "b" / "c"), "--spm")
    work.unchanged()
    refused(cli(capsys, "simulate", "--params", '{"m8": 1}', "--out", work.root / "a" / "b" / "c"), "m8")
    work.unchanged()


@pytest.mark.parametrize("command", ["plan", "compare"])
def test_a_refused_out_is_refused_before_the_figure_worker_forks(capsys, work, a_file, monkeypatch, command):
    """plan and compare fork their figure worker before planning (matplotlib's import beside the model's); a refused
    --out must not pay that fork (~1 s of CPU in a fresh process): the refusal comes first."""
    import planning.compare
    import planning.report

    def no_fork():
        raise AssertionError("the figure worker was forked before --out was checked")

    for module in (planning.report, planning.compare):
        monkeypatch.setattr(module, "figure_worker", no_fork)
    cal = work.root / "calibrated.json"
    cal.write_text(json.dumps({"parameters": {"m8": 32940.0}}), encoding="utf-8")
    args = ["--params", cal] if command == "plan" else ["--calibrated", cal]
    refused(cli(capsys, command, *args, "--out", a_file), str(a_file))
