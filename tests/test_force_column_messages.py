"""Messages about a drive log's process force column (process_force_N) name that column and what is wrong with it: a
column in kN, one absurd cell, a constant, a force twice the job's, a noisy channel, a column named twice or under
another name. Each case runs ``servo-press calibrate`` on the SYNTHETIC log of ``servo-press experiment`` (seed 0, the
cushion-test job: 5,000 kN over the last 300 mm, logged with 0.5 % noise), its force column edited; those that fit read
the warnings alone and fit without the bootstrap's refits, which give the intervals and never a warning (conftest.py's
no_bootstrap_job)."""
from __future__ import annotations

import numpy as np

from calibration.identification.run import trust_warnings
from calibration.traces.drive_log import read_drive_log
from press_model.press_data import load_press

from bad_input_helpers import calibrated, cli, refused, write_log

FORCE = 4  # the column of process_force_N in the experiment's log


def with_force(lines, h, edit, header=None):
    """The log with ``edit(row index, force in N)`` -> the new cell text, for every data row."""
    rows = []
    for k, s in enumerate(lines[h + 1:]):
        cells = s.split(",")
        cells[FORCE] = edit(k, float(cells[FORCE]))
        rows.append(",".join(cells))
    return lines[:h] + [header or lines[h]] + rows


def no_model_blame(line):
    assert "another run or die height" not in line and "motor_torque_Nm" not in line and "RuntimeWarning" not in line, line


def test_force_column_in_kilonewtons_is_named_with_the_factor(capsys, work, log_lines):
    path = write_log(work, with_force(*log_lines, lambda k, f: f"{f / 1e3:.6f}"))
    line = refused(cli(capsys, "calibrate", "--log", path, "--method", "least-squares", "--out", work.out),
                   "process_force_N = \"logged / job's peak force = 0.001", "looks like kN", "multiply it by 1000")
    no_model_blame(line)
    work.unchanged()


def test_one_absurd_force_cell_is_named_by_its_line(capsys, work, log_lines):
    lines, h = log_lines
    path = write_log(work, with_force(lines, h, lambda k, f: "1e308" if k == 3000 else f"{f:.3f}"))
    line = refused(cli(capsys, "calibrate", "--log", path, "--method", "least-squares", "--out", work.out),
                   f"line {h + 3002}, column process_force_N = 1e+308", "max_process_force_N")
    no_model_blame(line)
    work.unchanged()


def test_a_constant_force_column_is_blamed_on_itself_not_the_torque(capsys, work, log_lines):
    path = write_log(work, with_force(*log_lines, lambda k, f: "5000000"))
    line = refused(cli(capsys, "calibrate", "--log", path, "--method", "least-squares", "--out", work.out),
                   "process_force_N = '5e+06 N where the job has no force'", "offset or a constant")
    no_model_blame(line)
    work.unchanged()


def test_a_force_twice_the_jobs_is_warned_with_its_ratio_and_the_advice_names_the_logged_force(capsys, work, log_lines, no_bootstrap_job):
    path = write_log(work, with_force(*log_lines, lambda k, f: f"{2.0 * f:.3f}"))
    rec = calibrated(cli(capsys, "calibrate", "--log", path, "--job", no_bootstrap_job, "--method", "least-squares", "--out", work.out),
                     work.out)
    ratio = [w for w in rec["warnings"] if "2.000 times the job's [process] forces_N" in w]
    assert ratio and "force channel's scale or unit" in ratio[0], rec["warnings"]
    bound = [w for w in rec["warnings"] if "ended on a bound" in w]
    assert all("the logged process force (process_force_N" in w for w in bound), bound


def test_the_bound_warning_names_the_force_the_model_took():
    class Problem:
        names, low, high = ("eta_gear",), np.array([0.8]), np.array([0.9])

    at_bound = np.array([0.9])
    assert "the job's process force before" in trust_warnings(Problem, at_bound)[0]
    assert "the logged process force (process_force_N" in trust_warnings(Problem, at_bound, 1, 1)[0]
    assert "the job's process force and the logged one" in trust_warnings(Problem, at_bound, 1, 2)[0]


def test_a_noisy_force_channel_is_named(capsys, work, log_lines, no_bootstrap_job):
    rng = np.random.default_rng(1)
    path = write_log(work, with_force(*log_lines, lambda k, f: f"{f + rng.normal(0.0, 2e6):.3f}"))
    rec = calibrated(cli(capsys, "calibrate", "--log", path, "--job", no_bootstrap_job, "--method", "least-squares", "--out", work.out),
                     work.out)
    noisy = [w for w in rec["warnings"] if w.startswith("the force channel (process_force_N) is noisy")]
    assert noisy and " N per sample" in noisy[0], rec["warnings"]
    sigma = float(noisy[0].split("noisy: ")[1].split(" N per sample")[0])
    assert 1.6e6 < sigma < 2.4e6, sigma  # the noise added: 2e6 N per sample


def test_the_clean_force_column_gets_none_of_these_warnings(clean_log_calibrated):
    """The unedited log's fit (`calibrate --job` no_bootstrap_job `--method least-squares`), run once for the suite
    (fixtures_suitecal.py: test_bad_inputs_calibration reads it too)."""
    out, result = clean_log_calibrated
    rec = calibrated(result, out)
    assert not [w for w in rec["warnings"] if "process_force_N" in w], rec["warnings"]


def test_a_force_column_named_twice_is_not_called_unknown(capsys, work, log_lines):
    lines, h = log_lines
    path = write_log(work, lines[:h] + [lines[h] + ",process_force_N"] + [s + "," + s.split(",")[FORCE] for s in lines[h + 1:]])
    line = refused(cli(capsys, "calibrate", "--log", path, "--out", work.out), "'process_force_N' named twice")
    assert "unknown" not in line, line
    work.unchanged()


def test_a_force_column_in_another_unit_is_ignored_naming_process_force_n(work, log_lines):
    lines, h = log_lines
    path = write_log(work, with_force(lines, h, lambda k, f: f"{f / 1e3:.6f}", lines[h].replace("process_force_N", "process_force_kN")))
    press = load_press()
    log = read_drive_log(path, press.drive.gear_ratio, press.motor.rated_torque)
    ignored = [w for w in log.warnings if "process_force_kN" in w]
    assert ignored and "rename 'process_force_kN' to process_force_N, converted to N" in ignored[0], log.warnings
