"""Bad job files (``--job``): the reader :func:`press_model.jobs.load_job` and what the command line makes of it.

Each message names the field, the bad value and the fix; a job given as a press (and a press as a job) is named
as such; a job that does not fit the press is refused before anything is computed.
"""
from __future__ import annotations

import math

import pytest

from press_io.errors import PressDataError
from press_model.jobs import load_job, make_motion
from bad_input_helpers import LONG_NAME, DOOR_TEXT, DATA, cli, refused, write_log, check


MOTION_BLOCK = """[motion]
kind = "modulated"
strokes_per_min = 11.4
speed_depth = 0.4
slow_angle_deg = 125.0
"""


GOOD_JOB = """
[job]
name = "test job"

""" + MOTION_BLOCK + """
[process]
contact_height_m = 0.30
heights_m = [0.30, 0.0]
forces_N = [5.0e6, 5.0e6]
"""


JOB_CASES = [
    ("missing name", ('name = "test job"', ""), ["job.name = '<missing>'", "required; add 'name' under [job]"]),
    ("contact height 0", ("contact_height_m = 0.30", "contact_height_m = 0.0"), ["process.contact_height_m = 0.0", "must be > 0.0 (m)"]),
    ("one height", ("heights_m = [0.30, 0.0]", "heights_m = [0.30]"), ["process.heights_m = [0.3]", "at least two numbers"]),
    ("lengths differ", ("forces_N = [5.0e6, 5.0e6]", "forces_N = [5.0e6, 5.0e6, 1.0]"), ["process.forces_N = [", "as many entries as heights_m (2)"]),
    ("negative force", ("forces_N = [5.0e6, 5.0e6]", "forces_N = [5.0e6, -1.0]"), ["process.forces_N.1 = -1.0", "must be >= 0.0"]),
    ("height not a number", ("heights_m = [0.30, 0.0]", 'heights_m = [0.30, "low"]'), ["process.heights_m.1 = 'low'", "must be a finite number in m"]),
    ("repeated height", ("heights_m = [0.30, 0.0]", "heights_m = [0.30, 0.30]"), ["process.heights_m = [0.3, 0.3]", "must not repeat a height"]),
    ("motion kind", ('kind = "modulated"', 'kind = "jerky"'), ["motion.kind = 'jerky'", "must be one of 'constant', 'modulated'"]),
    ("speed depth 1", ("speed_depth = 0.4", "speed_depth = 1.0"), ["motion.speed_depth = 1.0", "must be >= 0.0 and < 1.0"]),
    ("strokes per minute 0", ("strokes_per_min = 11.4", "strokes_per_min = 0"), ["motion.strokes_per_min = 0", "must be > 0.0 (1/min)"]),
    ("motion not a table", ("[job]\n", "motion = 5\n[job]\n", MOTION_BLOCK, ""), ["motion = 5", "must be a table"]),
]


@pytest.mark.parametrize("edit, parts", [c[1:] for c in JOB_CASES], ids=[c[0] for c in JOB_CASES])
def test_job_file_errors(tmp_path, edit, parts):
    text = GOOD_JOB
    for old, new in zip(edit[::2], edit[1::2]):  # (old, new, old, new, ...) text replacements
        assert old in text
        text = text.replace(old, new)
    path = tmp_path / "job.toml"
    path.write_text(text, encoding="utf-8")
    with pytest.raises(PressDataError) as info:
        load_job(path)
    msg = str(info.value)
    assert msg.startswith(str(path))
    check(msg, *parts)


def test_good_job_loads(tmp_path):
    path = tmp_path / "job.toml"
    path.write_text(GOOD_JOB, encoding="utf-8")
    job = load_job(path)
    assert job.name == "test job" and job.process.contact_height == 0.3


def test_job_file_problems(tmp_path):
    with pytest.raises(PressDataError, match="--job = .*must be an existing TOML job file or one of cushion-test, cushion-validation, door-panel, no-load"):
        load_job(tmp_path / "nope.toml")
    bad = tmp_path / "bad.toml"
    bad.write_text("[job\nname = 1\n", encoding="utf-8")
    with pytest.raises(PressDataError, match="<file> = 'TOML' is not valid: is not valid TOML .*line"):
        load_job(bad)
    bad.write_bytes(b'[job]\nname = "\xff"\n')
    with pytest.raises(PressDataError, match="--job = .* must be a UTF-8 text file"):
        load_job(bad)


@pytest.mark.parametrize("spm", [0.0, -3.0, math.nan, math.inf])
def test_spm_override_must_be_positive(spm):
    table = {"kind": "constant", "strokes_per_min": 10.0}
    with pytest.raises(PressDataError) as info:
        make_motion(table, "job", spm)
    check(str(info.value), f"--spm = {spm!r}", "must be a positive number of strokes per minute")


def test_job_name_too_long(capsys, work):
    refused(cli(capsys, "experiment", "--job", LONG_NAME, "--out", work.out / "log.csv"), "--job")
    work.unchanged()


def test_press_file_given_as_job(capsys, work):
    refused(cli(capsys, "plan", "--job", DATA / "reference_press.toml", "--out", work.out),
            "--job = ", "is a press file (it has [press], no [job]): pass it as --press")
    work.unchanged()


def test_job_misspelled_required_key_is_named_as_the_misspelling(capsys, work):
    path = work.root / "job.toml"
    path.write_text(DOOR_TEXT.replace("opening_height_m = ", "opening_heigth_m = ", 1), encoding="utf-8")
    work.snap()
    refused(cli(capsys, "plan", "--job", path, "--out", work.out), "planning.transfer.opening_heigth_m = 0.7",
            "is not a known key of [planning.transfer] (misspelled? did you mean 'opening_height_m'?)")
    work.unchanged()


def test_calibrate_job_parameters_that_the_press_does_not_have(capsys, work, log_lines):
    path = write_log(work, log_lines[0])
    refused(cli(capsys, "calibrate", "--press", "crank-slider", "--log", path, "--out", work.out),
            "cushion_test.toml", "calibration.parameters = ['m8']", "give --parameters with names of this press")
    work.unchanged()


def test_experiment_job_truth_that_does_not_fit_the_press(capsys, work):
    refused(cli(capsys, "experiment", "--press", "crank-slider", "--out", work.out / "log.csv"),
            "cushion_test.toml> [experiment.truth]: J_gear = 60.6", "give --truth with values for this press")
    work.unchanged()


CUSHION_TEXT = (DATA / "cushion_test.toml").read_text(encoding="utf-8")


def job_with(work, text: str, old: str, new: str, name="job.toml"):
    assert old in text, old
    path = work.root / name
    path.write_text(text.replace(old, new, 1), encoding="utf-8")
    work.snap()
    return path


# A number beyond anything a press or its controller has: each used to run (a log of 1e300 N m noise, a plan with an
# endless dwell) or to end in a numpy traceback (2^63 strokes, a 1e300 Hz log, a 1e-300 deg model step); refused at
# the job file, naming the bound's key in run_limits.toml.
EXPERIMENT_CASES = [
    ("process_force_logged = true", "strokes = 9223372036854775807\nprocess_force_logged = true", "experiment.strokes = 9223372036854775807", "must be at most 1000,", "max_logged_strokes"),
    ("process_force_logged = true", "sample_rate_Hz = 1e300\nprocess_force_logged = true", "experiment.sample_rate_Hz = 1e+300", "must be at most 100000 Hz", "max_sample_rate_Hz"),
    ("process_force_logged = true", "noise_sigma_Nm = 1e300\nprocess_force_logged = true", "experiment.noise_sigma_Nm = 1e+300", "must be at most 1e+06 N m", "max_motor_torque_Nm"),
    ("process_force_logged = true", "contact_oscillation_Nm = 3e9\nprocess_force_logged = true", "experiment.contact_oscillation_Nm = 3000000000.0", "at most 1e+06 N m",
     "max_motor_torque_Nm"),
    ("process_force_logged = true", "model_step_deg = 1e-300\nprocess_force_logged = true", "experiment.model_step_deg = 1e-300", "must be at least 0.05 deg", "min_step_deg"),
    ("forces_N = [5.0e6, 5.0e6]", "forces_N = [5e300, 5e300]", "process.forces_N.0 = 5e+300", "must be at most 1e+09 N,", "max_process_force_N"),
    ("strokes_per_min = 11.4", "strokes_per_min = 1e300", "motion.strokes_per_min = 1e+300", "must be at most 3000 1/min", "max_strokes_per_min"),
    ("contact_height_m = 0.30", "contact_height_m = 1e300", "process.contact_height_m = 1e+300", "must be at most 100 m", "max_length_m"),
]


@pytest.mark.parametrize("old, new, shown, bound, key", EXPERIMENT_CASES, ids=[c[2].split(" = ")[0] for c in EXPERIMENT_CASES])
def test_experiment_refuses_a_number_beyond_any_press(capsys, work, old, new, shown, bound, key):
    path = job_with(work, CUSHION_TEXT, old, new)
    refused(cli(capsys, "experiment", "--job", path, "--out", work.root / "log.csv"), str(path), shown, bound,
            f"{key} in press_model/data/run_limits.toml", "check the unit and the exponent")
    work.unchanged()


@pytest.mark.parametrize("old, new, shown", [
    ("[design]", "[calibration.bootstrap]\nrefits = 9223372036854775807\n\n[design]", "calibration.bootstrap.refits = 9223372036854775807"),
    ("[design]", "[calibration.least_squares]\nstarts = 100000000\n\n[design]", "calibration.least_squares.starts = 100000000"),
], ids=["bootstrap refits", "least-squares starts"])
def test_calibrate_refuses_a_count_beyond_any_run(capsys, work, log_lines, old, new, shown):
    log = write_log(work, log_lines[0])
    path = job_with(work, CUSHION_TEXT, old, new)
    refused(cli(capsys, "calibrate", "--job", path, "--log", log, "--out", work.out), shown, "must be at most 1000000,",
            "max_count in press_model/data/run_limits.toml")
    work.unchanged()


PLAN_CASES = [
    ("time_s = 2.0", "time_s = 1e300", "planning.transfer.time_s = 1e+300", "must be at most 3600 s", "max_dwell_s"),
    ("\n[planning.transfer]", "sample_time_s = 1e-300\n[planning.transfer]", "planning.sample_time_s = 1e-300", "must be at least 5e-05 s", "min_sample_time_s"),
    ("\n[planning.transfer]", "controller_period_s = 1e-9\n[planning.transfer]", "planning.controller_period_s = 1e-09", "must be at least 5e-05 s",
     "min_sample_time_s"),
    ("[planning]", "[playback]\ntime_step_s = 1e-300\n\n[planning]", "playback.time_step_s = 1e-300", "must be at least 5e-05 s", "min_sample_time_s"),
    ("\n[planning.transfer]", "grid_step_deg = 1e-9\n[planning.transfer]", "planning.grid_step_deg = 1e-09", "must be at least 0.05 deg", "min_step_deg"),
    ("[planning]", "[planning.cam]\nmaster_step_deg = 1e-300\n\n[planning]", "planning.cam.master_step_deg = 1e-300", "must be at least 0.05 deg", "min_step_deg"),
    ("[planning]", "[planning.cam]\nisg_max_lines = 9223372036854775807\n\n[planning]", "planning.cam.isg_max_lines = 9223372036854775807", "must be at most 1000000,",
     "max_count"),
    ("[planning]", "[planning.solver]\noptimal_max_iterations = 9223372036854775807\n\n[planning]", "planning.solver.optimal_max_iterations = 9223372036854775807",
     "must be at most 1000000,", "max_count"),
    ("forces_N = [2.0e6, 6.0e6, 6.0e6]", "forces_N = [2.0e6, 6.0e300, 6.0e6]", "process.forces_N.1 = 6e+300", "must be at most 1e+09 N,",
     "max_process_force_N"),
]


@pytest.mark.parametrize("old, new, shown, bound, key", PLAN_CASES, ids=[c[2].split(" = ")[0] for c in PLAN_CASES])
def test_plan_refuses_a_number_beyond_any_press_or_controller(capsys, work, old, new, shown, bound, key):
    path = job_with(work, DOOR_TEXT, old, new)
    refused(cli(capsys, "plan", "--job", path, "--out", work.out), str(path), shown, bound, f"{key} in press_model/data/run_limits.toml")
    work.unchanged()


def test_simulate_refuses_a_stroke_rate_beyond_any_press(capsys, work):
    work.snap()
    refused(cli(capsys, "simulate", "--spm", "1e300", "--out", work.out), "--spm = 1e+300", "must be at most 3000 strokes per minute",
            "max_strokes_per_min")
    work.unchanged()


STOP_CASES = [
    ("[planning.hold]\nbottom_dwell_s = 0.5\nheight_above_bdc_m = 2.0\n", "planning.hold.height_above_bdc_m = 2.0",
     "must lie inside the stroke [0, "),
    ("[planning.pause]\ntime_s = 0.3\n", "planning.pause.height_m = 0.0", "must be > 0 with planning.pause.time_s > 0"),
    ("[planning.hold]\nbottom_dwell_s = 1e300\n", "planning.hold.bottom_dwell_s = 1e+300", "must be at most 3600 s"),
    ("[planning.hold]\nbottom_dwell_s = 0.5\nheight_above_bdc_m = 0.01\n\n[planning.pause]\ntime_s = 0.3\nheight_m = 0.01\n",
     "planning.pause.height_m = 0.01", "must differ from planning.hold.height_above_bdc_m"),
]


@pytest.mark.parametrize("table, shown, what", STOP_CASES, ids=[c[1].split(" = ")[0] for c in STOP_CASES])
def test_plan_refuses_a_stop_it_cannot_make(capsys, work, table, shown, what):
    """[planning.hold] and [planning.pause] (planning/hold.py): a height outside the stroke, a pause without its height, a
    time beyond any stop, a pause where the hold is: named with the value and what is valid, nothing written."""
    path = work.root / "job.toml"
    path.write_text(DOOR_TEXT + "\n" + table, encoding="utf-8")
    work.snap()
    refused(cli(capsys, "plan", "--job", path, "--out", work.out), str(path), shown, what)
    work.unchanged()
