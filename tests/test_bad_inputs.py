"""A catalogue of bad inputs, one test each, through the real command line (issue 6, item 3).

Every case runs ``press_model.commands.cli.main([...])`` as the ``servo-press`` script does (a few run the
installed ``servo-press`` in a subprocess, to see the real exit code and stderr), and checks what the user
sees: exit code 2, stderr one line ``servo-press: error: ...`` naming the field, the bad value and the fix
(argparse's usage errors too, pointing at the command's --help), no traceback, and nothing left behind that looks like a result:
the test's folder holds exactly the files it held before the run (no output, no half-written temp file).

The logs of the drive-log cases are lines of one synthetic log written by ``servo-press experiment``,
edited. The cases that the reader repairs (NaN rows, rows out of order, torque in kN m with
``--torque-unit kN*m``) run a full calibration with the fastest method and must say what they repaired.
"""
from __future__ import annotations

import json
import shutil
import subprocess
import sys
import xml.etree.ElementTree as ET
from importlib import resources
from pathlib import Path

import numpy as np
import pytest

from calibration.drive_log import read_drive_log
from press_model.commands.cli import main
from press_model.press_data import load_press

REF_TEXT = resources.files("press_model.data").joinpath("reference_press.toml").read_text(encoding="utf-8")
LONG_NAME = "x" * 300  # longer than any file name the system accepts (ENAMETOOLONG)
ERROR = "servo-press: error: "


# --- running the command line and checking what the user sees -----------------------------------------
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
    cmd = [exe] if exe else [sys.executable, "-m", "press_model.commands.cli"]
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


@pytest.fixture
def work(tmp_path):
    """A folder for one case: ``work.out`` is the output path, ``work.snap()`` records what exists before the run
    and ``work.unchanged()`` checks that the run added nothing (no output, no temp file) and changed no input."""

    class Work:
        root = tmp_path
        out = tmp_path / "out"

        def snap(self):
            self.before = files(tmp_path)
            self.bytes = {p: (tmp_path / p).read_bytes() for p in self.before if (tmp_path / p).is_file()}

        def unchanged(self):
            assert files(tmp_path) == self.before, sorted(files(tmp_path) - self.before)
            assert all((tmp_path / p).read_bytes() == b for p, b in self.bytes.items())

    w = Work()
    w.snap()
    return w


def edited_press(work, old: str, new: str, name="press.toml") -> Path:
    """The reference press file with one text edit, written into the case's folder."""
    assert old in REF_TEXT, old
    path = work.root / name
    path.write_text(REF_TEXT.replace(old, new, 1), encoding="utf-8")
    work.snap()
    return path


# --- the press file ----------------------------------------------------------------------------------------
def test_press_file_not_found(capsys, work):
    refused(cli(capsys, "simulate", "--press", work.root / "nope.toml", "--out", work.out),
            "nope.toml", "--press = ", "must be an existing TOML file or one of reference, crank-slider")
    work.unchanged()


def test_press_file_is_a_folder(capsys, work):
    refused(cli(capsys, "simulate", "--press", work.root, "--out", work.out), "--press = ", "must be an existing TOML file")
    work.unchanged()


def test_press_file_name_too_long(capsys, work):
    refused(cli(capsys, "simulate", "--press", work.root / LONG_NAME, "--out", work.out), "--press = ", "must be an existing TOML file")
    work.unchanged()


def test_press_file_not_utf8(capsys, work):
    path = work.root / "latin1.toml"
    path.write_bytes(REF_TEXT.replace("eight-bar", "acht-Gelenk \xe4").encode("latin-1"))
    work.snap()
    refused(cli(capsys, "simulate", "--press", path, "--out", work.out), "latin1.toml", "must be a UTF-8 text file", "at byte")
    work.unchanged()


def test_press_file_empty(capsys, work):
    path = work.root / "empty.toml"
    path.write_bytes(b"")
    work.snap()
    refused(cli(capsys, "simulate", "--press", path, "--out", work.out), "empty.toml", "press = '<missing>'", "required; add 'press'")
    work.unchanged()


def test_press_file_invalid_toml(capsys, work):
    path = edited_press(work, "mass_kg = 743.8", "mass_kg = 743.8 kg")
    refused(cli(capsys, "simulate", "--press", path, "--out", work.out), str(path), "is not valid TOML", "line", "fix the syntax")
    work.unchanged()


def test_press_file_missing_required_key(capsys, work):
    path = edited_press(work, "gear_ratio = 32.0\n", "")
    refused(cli(capsys, "simulate", "--press", path, "--out", work.out),
            str(path), "drive.gear_ratio = '<missing>'", "required; add 'gear_ratio' under [drive]")
    work.unchanged()


def test_press_file_misspelled_key(capsys, work):
    path = edited_press(work, 'label = "link 3"', 'lable = "link 3"')
    refused(cli(capsys, "simulate", "--press", path, "--out", work.out),
            "bodies.link3.lable = 'link 3'", "is not a known key of [bodies.link3] (misspelled? did you mean 'label'?)")
    work.unchanged()


def test_press_file_key_with_a_line_break_gives_one_line(capsys, work):
    path = edited_press(work, "[press]\n", '[press]\n"gear\\nratio" = 32.0\n')
    refused(cli(capsys, "simulate", "--press", path, "--out", work.out), "press.gear\\nratio = 32.0", "is not a known key")
    work.unchanged()


def test_press_file_negative_mass(capsys, work):
    path = edited_press(work, "mass_kg = 743.8", "mass_kg = -743.8")
    refused(cli(capsys, "simulate", "--press", path, "--out", work.out), "bodies.link3.mass_kg = -743.8", "must be > 0.0 (kg)")
    work.unchanged()


def test_press_file_efficiency_above_one(capsys, work):
    path = edited_press(work, "efficiency = 0.917", "efficiency = 1.2")
    refused(cli(capsys, "simulate", "--press", path, "--out", work.out), "drive.efficiency = 1.2", "must be > 0.0 and <= 1.0")
    work.unchanged()


def test_press_file_balance_coefficient_zero(capsys, work):
    path = edited_press(work, "coefficient = 1.15", "coefficient = 0.0")
    refused(cli(capsys, "simulate", "--press", path, "--out", work.out),
            "balance.coefficient = 0.0", "must be > 0 when cylinders > 0", "set cylinders = 0")
    work.unchanged()


def test_press_file_joint_naming_an_unknown_body(capsys, work):
    path = edited_press(work, 'connects = ["crank.A", "link6.A"]', 'connects = ["crank.A", "link9.A"]')
    refused(cli(capsys, "simulate", "--press", path, "--out", work.out),
            "joints.A.connects = 'link9.A'", "body must be 'frame' or one of crank, link3")
    work.unchanged()


def test_press_file_joint_naming_an_unknown_point(capsys, work):
    path = edited_press(work, 'connects = ["crank.A", "link6.A"]', 'connects = ["crank.Z", "link6.A"]')
    refused(cli(capsys, "simulate", "--press", path, "--out", work.out),
            "joints.A.connects = 'crank.Z'", "point must be one of O, A, B on body 'crank'")
    work.unchanged()


def test_press_file_linkage_that_cannot_assemble(capsys, work):
    # link 3 far too short: |BD| is about 1.55 m, link 3 (0.5 m) + DC (0.8 m) cannot reach
    path = edited_press(work, "points_m = { B = [0.0, 0.0], C = [1.369, 0.0] }", "points_m = { B = [0.0, 0.0], C = [0.5, 0.0] }")
    line = refused(cli(capsys, "simulate", "--press", path, "--out", work.out),
                   str(path), "the linkage does not assemble at crank angle", "the loop closed at joint C (link3.C to link4.C",
                   "Check the link lengths")
    assert " deg" in line.split("at crank angle", 1)[1][:12]
    work.unchanged()


def test_press_file_body_name_that_breaks_xml(capsys, work):
    path = edited_press(work, "[bodies.link3]", '[bodies."link<3>&"]')
    refused(cli(capsys, "urdf", "--press", path, "--out", work.out / "x.urdf"),
            "bodies.link<3>& = 'link<3>&'", "names must use only letters, digits, '_' or '-'")
    work.unchanged()


def test_press_name_with_a_double_dash_still_gives_well_formed_urdf(capsys, work):
    path = edited_press(work, 'name = "25,000 kN servo press, eight-bar linkage (reference)"', 'name = "press -- test <&> \\"x\\""')
    code, _, err = cli(capsys, "urdf", "--press", path, "--out", work.out / "x.urdf")
    assert code == 0, err
    ET.parse(work.out / "x.urdf")  # any XML tool (ROS, urdfdom's strict parsers) must read it


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


def test_press_file_absurd_com_distance_gives_one_line_subprocess(work):
    # the least-squares trilateration of link 4's COM overflows; its numpy warnings must not reach the user
    path = edited_press(work, "com = { distances_m = { E = 1.2425", "com = { distances_m = { E = 1e300")
    refused(servo_press("simulate", "--press", path, "--out", work.out),
            "bodies.link4.com.distances_m = {'E': 1e+300", "no centre of mass fits these distances")
    work.unchanged()


def test_press_file_absurd_coordinate_gives_one_line_subprocess(work):
    path = edited_press(work, "points_m = { O = [0.0, 0.0], A = [0.22, 0.0]", "points_m = { O = [0.0, 0.0], A = [1e300, 0.0]")
    refused(servo_press("simulate", "--press", path, "--out", work.out), "does not assemble")
    work.unchanged()


# --- --params ---------------------------------------------------------------------------------------------
def test_params_invalid_json(capsys, work):
    refused(cli(capsys, "simulate", "--params", '{"m8": 32940,}', "--out", work.out), "--params: <json>", "is not valid JSON")
    work.unchanged()


def test_params_file_not_an_object(capsys, work):
    path = work.root / "params.json"
    path.write_text("[32940, 0.9]", encoding="utf-8")
    work.snap()
    refused(cli(capsys, "simulate", "--params", path, "--out", work.out),
            str(path), "<top level> = 'list'", 'must be a JSON object such as {"m8": 32940}')
    work.unchanged()


def test_params_neither_json_nor_a_file(capsys, work):
    refused(cli(capsys, "simulate", "--params", "m8=32940", "--out", work.out),
            "--params = 'm8=32940'", "must be a JSON object such as", "or the path of a JSON file")
    work.unchanged()


def test_params_text_too_long_for_a_file_name(capsys, work):
    refused(cli(capsys, "simulate", "--params", "[" + ", ".join(["1.0"] * 100) + "]", "--out", work.out),
            "--params = '[1.0, 1.0", "...'", "must be a JSON object")
    work.unchanged()


def test_params_unknown_parameter(capsys, work):
    refused(cli(capsys, "simulate", "--params", '{"m99": 1}', "--out", work.out),
            "--params: m99 = 1", "is not a parameter of this press; known: J_gear, eta_gear")
    work.unchanged()


def test_params_value_outside_its_range(capsys, work):
    refused(cli(capsys, "simulate", "--params", '{"eta_gear": 1.5}', "--out", work.out),
            "--params: eta_gear = 1.5", "must lie in its range [0.7, 0.99]")
    work.unchanged()


def test_params_value_not_a_number(capsys, work):
    refused(cli(capsys, "simulate", "--params", '{"m8": "heavy"}', "--out", work.out), "--params: m8 = 'heavy'", "must be a finite number")
    work.unchanged()


def test_params_value_a_boolean(capsys, work):
    refused(cli(capsys, "simulate", "--params", '{"m8": true}', "--out", work.out), "--params: m8 = True", "must be a finite number")
    work.unchanged()


def test_params_value_nan(capsys, work):
    refused(cli(capsys, "simulate", "--params", '{"m8": NaN}', "--out", work.out), "--params: m8 = nan", "must lie in its range")
    work.unchanged()


# --- simulate ---------------------------------------------------------------------------------------------
@pytest.mark.parametrize("step", ["0", "nan", "-1", "7"])
def test_simulate_step_that_does_not_divide_the_turn(capsys, work, step):
    refused(cli(capsys, "simulate", "--step-deg", step, "--out", work.out),
            f"--step-deg: step = {float(step)!r}", "divide", "360")
    work.unchanged()


@pytest.mark.parametrize("spm", ["0", "-3", "inf"])
def test_simulate_strokes_per_minute_not_positive(capsys, work, spm):
    refused(cli(capsys, "simulate", "--spm", spm, "--out", work.out),
            f"--spm = {float(spm)!r}", "must be a positive number of strokes per minute")
    work.unchanged()


def test_simulate_strokes_per_minute_not_a_number(capsys, work):
    usage_error(cli(capsys, "simulate", "--spm", "fast", "--out", work.out), "argument --spm", "invalid float value: 'fast'")
    work.unchanged()


def test_simulate_unknown_load(capsys, work):
    usage_error(cli(capsys, "simulate", "--load", "bricks", "--out", work.out), "argument --load", "invalid choice: 'bricks'")
    work.unchanged()


# --- sensitivity --------------------------------------------------------------------------------------------
@pytest.mark.parametrize("n", ["1000", "0", "-4"])
def test_sensitivity_n_not_a_power_of_two(capsys, work, n):
    refused(cli(capsys, "sensitivity", "--n", n, "--out", work.out), f"--n: n = {n}", "must be a power of two (e.g. 1024, 2048, 4096)")
    work.unchanged()


def test_sensitivity_convergence_n_min_zero(capsys, work):
    refused(cli(capsys, "sensitivity", "--convergence", "--n-min", "0", "--out", work.out), "--n-min")
    work.unchanged()


def test_sensitivity_convergence_n_min_above_n_max(capsys, work):
    refused(cli(capsys, "sensitivity", "--convergence", "--n-min", "1024", "--n-max", "256", "--out", work.out), "--n-m")
    work.unchanged()


@pytest.mark.parametrize("command", [["sensitivity", "--n", "4"], ["experiment"]])
def test_negative_seed(capsys, work, command):
    out = work.out / "log.csv" if command[0] == "experiment" else work.out
    code, _, err = cli(capsys, *command, "--seed", "-1", "--out", out)
    assert code == 2 and "Traceback" not in err and "--seed" in err, err
    work.unchanged()


# --- drive logs (servo-press calibrate --log) -------------------------------------------------------------------
@pytest.fixture(scope="module")
def log_lines(tmp_path_factory):
    """The lines of a SYNTHETIC drive log written by ``servo-press experiment`` (seed 0), and its header index."""
    path = tmp_path_factory.mktemp("experiment") / "log.csv"
    assert main(["experiment", "--seed", "0", "--out", str(path)]) == 0
    lines = path.read_text(encoding="utf-8").splitlines()
    return lines, next(i for i, s in enumerate(lines) if s.startswith("time_s"))


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
    assert {p.name for p in out.iterdir()} == {"calibrated.json", "table4.csv", "table4.md", "figure5.png"}
    return json.loads((out / "calibrated.json").read_text(encoding="utf-8"))


def test_log_not_found(capsys, work):
    refused(cli(capsys, "calibrate", "--log", work.root / "nolog.csv", "--out", work.out),
            "nolog.csv", "must be an existing drive-log CSV file")
    work.unchanged()


def test_log_empty(capsys, work):
    path = write_log(work, [])
    refused(cli(capsys, "calibrate", "--log", path, "--out", work.out),
            "<file> = 'empty'", "must hold the header line 'time_s, crank_angle_deg, motor_speed_rpm, motor_torque_Nm'")
    work.unchanged()


def test_log_wrong_header_subprocess(work, log_lines):
    lines, h = log_lines
    path = write_log(work, lines[:h] + ["time, angle, speed, torque"] + lines[h + 1:])
    refused(servo_press("calibrate", "--log", path, "--out", work.out),
            f"header (line {h + 1}) = 'time, angle, speed, torque'", "missing time_s, crank_angle_deg",
            "unknown 'time', 'angle'", "torque per motor in N m")
    work.unchanged()


def test_log_nan_rows_are_dropped_with_a_warning(capsys, work, log_lines):
    lines, h = log_lines
    edited = list(lines)
    bad = [h + 101, h + 102, h + 2001, h + 3001]  # 0-based indices of data lines
    for i in bad[:3]:
        edited[i] = with_cell(edited[i], 3, "nan")
    edited[bad[3]] = with_cell(edited[bad[3]], 2, "")
    path = write_log(work, edited)
    result = cli(capsys, "calibrate", "--log", path, "--method", "least-squares", "--out", work.out)
    rec = calibrated(result, work.out)
    warning = (f"warning: Dropped 4 rows with an empty, NaN or infinite cell (line {', '.join(str(i + 1) for i in bad)}); "
               "the crank angles they held are treated as gaps.")
    assert warning in result[2]
    assert warning.removeprefix("warning: ") in rec["log"]["warnings"]


def test_log_torque_in_kilonewton_metres_is_refused(capsys, work, log_lines):
    lines, h = log_lines
    path = write_log(work, lines[:h + 1] + [with_cell(s, 3, f"{float(s.split(',')[3]) / 1e3:.6f}") for s in lines[h + 1:]])
    refused(cli(capsys, "calibrate", "--log", path, "--out", work.out),
            "motor_torque_Nm = 'max |torque|", "looks like kN m", "--torque-unit kN*m")
    work.unchanged()


def test_log_torque_in_kilonewton_metres_is_read_with_the_unit_given(capsys, work, log_lines):
    lines, h = log_lines
    path = write_log(work, lines[:h + 1] + [with_cell(s, 3, f"{float(s.split(',')[3]) / 1e3:.6f}") for s in lines[h + 1:]])
    original = write_log(work, lines, "original.csv")
    press = load_press()
    a = read_drive_log(original, press.drive.gear_ratio, press.motor.rated_torque)
    b = read_drive_log(path, press.drive.gear_ratio, press.motor.rated_torque, torque_unit="kN*m")
    np.testing.assert_allclose(b.torque, a.torque, rtol=1e-12, atol=1e-9)  # N m: the same log, in the other unit
    calibrated(cli(capsys, "calibrate", "--log", path, "--torque-unit", "kN*m", "--method", "least-squares", "--out", work.out), work.out)


def test_log_single_partial_stroke(capsys, work, log_lines):
    lines, h = log_lines
    path = write_log(work, lines[:h + 1 + 1500])  # 3 s of a 5.3 s stroke
    refused(cli(capsys, "calibrate", "--log", path, "--out", work.out),
            "crank_angle_deg = '", "the log covers only", "calibration needs at least one full turn (360 deg)")
    work.unchanged()


def test_log_duplicated_time_with_different_values(capsys, work, log_lines):
    lines, h = log_lines
    edited = list(lines)
    i = h + 1001
    edited[i + 1] = with_cell(edited[i + 1], 0, edited[i].split(",")[0])
    path = write_log(work, edited)
    refused(cli(capsys, "calibrate", "--log", path, "--out", work.out),
            f"lines {i + 1} and {i + 2} = 'time_s = {float(edited[i].split(',')[0])!r} twice'",
            "two rows with the same time must be identical", "remove the wrong row")
    work.unchanged()


def test_log_rows_out_of_time_order_are_sorted_with_a_warning(capsys, work, log_lines):
    lines, h = log_lines
    edited = list(lines)
    for i in (h + 1001, h + 5001):
        edited[i], edited[i + 1] = edited[i + 1], edited[i]
    path = write_log(work, edited)
    result = cli(capsys, "calibrate", "--log", path, "--method", "least-squares", "--out", work.out)
    rec = calibrated(result, work.out)
    warning = "Sorted the rows by time_s (2 were out of order); sorted, the crank angle turns forward."
    assert f"warning: {warning}" in result[2] and warning in rec["log"]["warnings"]


def test_log_gap_leaving_crank_angles_without_data(capsys, work, log_lines):
    lines, h = log_lines
    kept = [s for s in lines[h + 1:] if not 100.0 <= float(s.split(",")[1]) <= 110.0]  # the same gap in every stroke
    path = write_log(work, lines[:h + 1] + kept)
    refused(cli(capsys, "calibrate", "--log", path, "--out", work.out),
            "crank_angle_deg = 'no data at 100-110 deg'", "fall inside gaps in time in every turn")
    work.unchanged()


def test_log_speed_column_in_crank_rpm(capsys, work, log_lines):
    lines, h = log_lines
    path = write_log(work, lines[:h + 1] + [with_cell(s, 2, f"{float(s.split(',')[2]) / 32.0:.4f}") for s in lines[h + 1:]])
    refused(cli(capsys, "calibrate", "--log", path, "--out", work.out),
            "motor_speed_rpm = 'crank angle rate / (speed / gear_ratio) = 32", "holds crank rpm instead of motor rpm")
    work.unchanged()


def test_log_cell_that_is_not_a_number(capsys, work, log_lines):
    lines, h = log_lines
    edited = list(lines)
    edited[h + 11] = with_cell(edited[h + 11], 3, "1,234.5")
    path = write_log(work, edited)
    refused(cli(capsys, "calibrate", "--log", path, "--out", work.out),
            f"line {h + 12} = ", "must hold 4 comma-separated cells", "use '.' as the decimal point")
    work.unchanged()


# --- calibrate: the request ------------------------------------------------------------------------------------
def test_calibrate_parameters_list_too_long_for_a_file_name(capsys, work, log_lines):
    path = write_log(work, log_lines[0])
    refused(cli(capsys, "calibrate", "--log", path, "--parameters", "eta_gear,psi," + LONG_NAME, "--out", work.out), LONG_NAME[:50])
    work.unchanged()


def test_job_name_too_long(capsys, work):
    refused(cli(capsys, "experiment", "--job", LONG_NAME, "--out", work.out / "log.csv"), "--job")
    work.unchanged()


# --- experiment ---------------------------------------------------------------------------------------------------
def test_experiment_truth_outside_its_range(capsys, work):
    refused(cli(capsys, "experiment", "--truth", '{"eta_gear": 1.5}', "--out", work.out / "log.csv"),
            "truth: eta_gear = 1.5", "must lie in its range [0.7, 0.99]")
    work.unchanged()


def test_experiment_truth_naming_an_unknown_parameter(capsys, work):
    refused(cli(capsys, "experiment", "--truth", '{"eta_gearbox": 0.9}', "--out", work.out / "log.csv"),
            "truth: eta_gearbox = 0.9", "is not a parameter of this press; known: J_gear, eta_gear")
    work.unchanged()


def test_experiment_truth_not_json(capsys, work):
    refused(cli(capsys, "experiment", "--truth", "{eta_gear: 0.9}", "--out", work.out / "log.csv"), "<json>", "is not valid JSON")
    work.unchanged()


# --- output paths ---------------------------------------------------------------------------------------------------

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


def test_experiment_out_is_an_existing_folder(capsys, work):
    folder = work.root / "a_folder"
    folder.mkdir()
    work.snap()
    refused(cli(capsys, "experiment", "--out", folder), str(folder))
    work.unchanged()  # os.replace failed: the temp file must be gone, and no truth.json written either


def test_out_is_an_existing_file_subprocess(work, a_file):
    refused(servo_press("experiment", "--out", a_file / "log.csv"), str(a_file))
    work.unchanged()


def test_experiment_out_is_the_truth_file(capsys, work):
    truth = work.root / "truth.json"
    truth.write_text(json.dumps({"eta_gear": 0.9}), encoding="utf-8")
    work.snap()
    refused(cli(capsys, "experiment", "--truth", truth, "--out", truth), "is the input file", "inputs are never overwritten")
    work.unchanged()


def test_missing_out_is_a_usage_error(capsys, work):
    usage_error(cli(capsys, "simulate"), "the following arguments are required: --out")
    work.unchanged()


def test_unknown_command_is_a_usage_error(capsys, work):
    usage_error(cli(capsys, "simulat", "--out", work.out), "invalid choice: 'simulat'")
    work.unchanged()

