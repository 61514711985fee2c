"""The logged process force's own accuracy: carried into the intervals and the joint region, its scale tested against
the stated accuracy, warned about where the log shows it off; no warning on clean logs with the force logged."""
from __future__ import annotations

import dataclasses
import json
from importlib import resources
from types import SimpleNamespace

import pytest

from in_process import servo_press

from calibration.identification.adequacy import ScoreTest
from calibration.identification.force_accuracy import ACCURACY_WARNING, SCALE_TEST, scale_warning
from calibration.identification.process_force import ProcessForceSection

HIGH_SEED = 11  # the log whose force channel reads 3 % high; truth: the cushion test's [experiment.truth] (in the sidecar)


def _calibrate(log, out, *job):
    r = servo_press("calibrate", "--log", log, *job, "--out", out)
    assert r.returncode == 0, r.stderr
    return r, json.loads((out / "calibrated.json").read_text())


def _test(size: float, sd: float) -> ScoreTest:
    return ScoreTest(SCALE_TEST, "", abs(size) / sd, 0.05, size, sd, "% of the logged force", False)


def test_the_scales_test_warns_only_beyond_the_stated_accuracy_and_the_datas_own_error():
    st = ProcessForceSection()  # +-1.5 % (95 %)
    assert scale_warning([_test(-1.0, 0.5)], st) is None  # within the accuracy
    assert scale_warning([_test(-6.0, 2.1)], st).startswith(ACCURACY_WARNING)  # 2.6 combined standard errors off
    assert "reads high" in scale_warning([_test(-6.0, 2.1)], st)
    assert scale_warning([_test(-4.0, 2.1)], st) is None  # the data cannot tell 4 % from 0 this well
    assert scale_warning([], st) is None  # no logged force: no test


def test_a_clean_log_with_the_force_logged_carries_its_accuracy_without_a_warning(synthetic_log_calibrated):
    """`calibrate --log` of the seed-0 log (500 Hz, force logged), the shipped job: the suite's one run of it
    (conftest.py's synthetic_log_calibrated)."""
    out, stdout, stderr = synthetic_log_calibrated
    r, rec = SimpleNamespace(stdout=stdout, stderr=stderr), json.loads((out / "calibrated.json").read_text())
    assert "WARNING" not in r.stderr, r.stderr
    acc = rec["process_force"]["logged_force_accuracy"]
    assert acc["scale_accuracy"] == ProcessForceSection().logged_scale_accuracy
    # the logged force's scale moves eta_gear (per percent) and its accuracy widens the interval by what it moves
    assert abs(acc["per_percent_scale"]["eta_gear"]) > 1e-3 and acc["interval_sd"]["eta_gear"] > 0.0
    assert acc["moves_at_accuracy"]["eta_gear"] <= acc["warning_shift"]
    # the force column on time: no delay beyond its noise, and the force taken as logged (calibration/identification/force_delay.py)
    (delay,) = rec["process_force"]["logged_force_delay"]
    assert delay["interval_s"][0] <= 0.0 <= delay["interval_s"][1] and not delay["corrected"], delay
    assert "no force-channel delay beyond its noise" in r.stdout


def test_a_clean_log_at_250_hz_with_the_force_logged_gives_no_warning(tmp_path):
    """The job's bootstrap refits are left out (``refits = 0``): they give the intervals and their statements alone,
    never a warning line or the force accuracy's ``warned`` (both decided from the fit before the refits,
    calibration/identification/run.py), which are all this test reads. The ant colony is a smaller one (20 ants, 25
    iterations) polished as the job's: the warnings are read at the fit's minimum, which the colony only finds a start
    for; on this log both colonies end on the same estimate (every parameter to 5 digits, J_gear 60.4811 and 60.4814)
    with no warning and ``warned`` false, at ~0.65 of the CPU (1.4 against 2.2 s warm), so the assertions do not depend
    on the colony's size."""
    text = resources.files("press_model.data").joinpath("cushion_test.toml").read_text(encoding="utf-8")
    assert "\n[experiment]\n" in text and "[calibration.bootstrap]" not in text and "[calibration.aco]" not in text
    job = tmp_path / "cushion_250.toml"
    job.write_text(text.replace("\n[experiment]\n", "\n[experiment]\nsample_rate_Hz = 250.0\n", 1)
                   + "\n[calibration.bootstrap]\nrefits = 0\n\n[calibration.aco]\nants = 20\niterations = 25\n", encoding="utf-8")
    log = tmp_path / "log250.csv"
    assert servo_press("experiment", "--job", job, "--seed", 3, "--out", log).returncode == 0
    r, rec = _calibrate(log, tmp_path / "cal", "--job", job)
    assert "WARNING" not in r.stderr, r.stderr
    assert rec["process_force"]["logged_force_accuracy"]["warned"] is False


# SYNTHETIC truths of the six parameters (the others the press file's), and the seeds of the logs whose force channel
# reads 3 % high, chosen before any run of the test below
TRUTH_A = None  # the cushion test's [experiment.truth] (Table 4: eta_gear 0.842)
TRUTH_B = {"eta_gear": 0.86, "psi": 1.03, "mu_r": 0.010, "m8": 33500.0, "J_gear": 58.0, "mu_s": 0.075}
TRUTH_C = {"eta_gear": 0.82, "psi": 1.08, "mu_r": 0.014, "m8": 32400.0, "J_gear": 63.0, "mu_s": 0.095}
HIGH_LOGS = [(5101, TRUTH_A), (5102, TRUTH_A), (5103, TRUTH_B), (5104, TRUTH_B), (5105, TRUTH_C), (5106, TRUTH_C)]


@pytest.mark.parametrize("seed,truth", HIGH_LOGS)
def test_a_force_reading_3_percent_high_is_named_by_its_scale_or_eta_gear_stays_in_its_joint_region(tmp_path, seed, truth):
    """SYNTHETIC cushion-test logs (seeds 5101-5106; truths A: the job's, B, C above, two seeds each) whose force channel
    reads 3 % high (force_reading_scale = 1.03, the torque made with the true force), least squares: each is warned by
    the force's scale test (the warning names the channel reading high and the check against a load cell), or eta_gear's
    truth lies in its joint region. The stated accuracy's own warning (it alone moves eta_gear past warning_shift) does
    not count: it does not say this log's channel is off."""
    log = tmp_path / "high.csv"
    args = ("--truth", json.dumps(truth)) if truth is not None else ()
    assert servo_press("experiment", "--seed", seed, *args, "--effect", "force_reading_scale=1.03", "--out", log).returncode == 0
    eta = json.loads(log.with_suffix(".truth.json").read_text())["truth"]["eta_gear"]
    r, rec = _calibrate(log, tmp_path / "cal", "--method", "least-squares")
    low, high = rec["joint_region"]["box"]["eta_gear"]
    named = [w for w in r.stderr.splitlines() if w.startswith(f"WARNING: {ACCURACY_WARNING}: the log's torque asks")]
    assert (named and "reads high" in named[0] and "load cell" in named[0]) or low <= eta <= high, (r.stderr, low, high, eta)


def test_a_force_channel_reading_3_percent_high_is_warned_or_eta_gear_stays_in_its_joint_region(tmp_path):
    log = tmp_path / "high.csv"
    assert servo_press("experiment", "--seed", HIGH_SEED, "--effect", "force_reading_scale=1.03", "--out", log).returncode == 0
    truth = json.loads(log.with_suffix(".truth.json").read_text())["truth"]["eta_gear"]
    r, rec = _calibrate(log, tmp_path / "cal")
    low, high = rec["joint_region"]["box"]["eta_gear"]
    assert f"WARNING: {ACCURACY_WARNING}" in r.stderr or low <= truth <= high, (r.stderr, low, high, truth)


def test_the_job_set_force_is_a_second_reading_of_the_channels_scale():
    """The logged force over the job's set force (known to job_force_tolerance, 3 %, 95 %) joins the torque's score
    test, the two weighed by their variances: a score test short of the threshold alone is warned about with the force
    3 % above the job's, not with it on the job's; with the job's force taken as exact the ratio alone decides."""
    st = ProcessForceSection()
    assert scale_warning([_test(-2.0, 0.8)], st) is None  # 2 % high by the torque: 1.8 combined standard deviations
    assert scale_warning([_test(-2.0, 0.8)], st, ratio=1.0) is None  # the set force agrees with the channel
    warned = scale_warning([_test(-2.0, 0.8)], st, ratio=1.03)
    assert warned.startswith(ACCURACY_WARNING) and "reads high" in warned and "+3.0 % against the job's set force" in warned
    assert scale_warning([_test(+2.0, 0.8)], st, ratio=0.97) is not None  # low alike
    exact = dataclasses.replace(st, job_force_tolerance=0.0)
    assert scale_warning([_test(0.0, 0.8)], exact, ratio=1.03) is not None
    assert scale_warning([_test(-2.0, 0.8)], exact, ratio=1.01) is None
