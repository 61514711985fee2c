"""The logged process force's own accuracy: carried into the intervals and the joint region, its scale tested against
the stated accuracy, warned about where the log shows it off; no warning on clean logs with the force logged."""
from __future__ import annotations

import json
from importlib import resources

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


def test_a_clean_log_with_the_force_logged_carries_its_accuracy_without_a_warning(synthetic_log, tmp_path):
    r, rec = _calibrate(synthetic_log, tmp_path / "cal")  # seed 0, 500 Hz, force logged
    assert "WARNING" not in r.stderr, r.stderr
    acc = rec["process_force"]["logged_force_accuracy"]
    assert acc["scale_accuracy"] == ProcessForceSection().logged_scale_accuracy
    # the logged force's scale moves eta_gear (per percent) and its accuracy widens the interval by what it moves
    assert abs(acc["per_percent_scale"]["eta_gear"]) > 1e-3 and acc["interval_sd"]["eta_gear"] > 0.0
    assert acc["moves_at_accuracy"]["eta_gear"] <= acc["warning_shift"]


def test_a_clean_log_at_250_hz_with_the_force_logged_gives_no_warning(tmp_path):
    text = resources.files("press_model.data").joinpath("cushion_test.toml").read_text(encoding="utf-8")
    assert "\n[experiment]\n" in text
    job = tmp_path / "cushion_250.toml"
    job.write_text(text.replace("\n[experiment]\n", "\n[experiment]\nsample_rate_Hz = 250.0\n", 1), encoding="utf-8")
    log = tmp_path / "log250.csv"
    assert servo_press("experiment", "--job", job, "--seed", 3, "--out", log).returncode == 0
    r, rec = _calibrate(log, tmp_path / "cal", "--job", job)
    assert "WARNING" not in r.stderr, r.stderr
    assert rec["process_force"]["logged_force_accuracy"]["warned"] is False


def test_a_force_channel_reading_3_percent_high_is_warned_or_eta_gear_stays_in_its_joint_region(tmp_path):
    log = tmp_path / "high.csv"
    assert servo_press("experiment", "--seed", HIGH_SEED, "--effect", "force_reading_scale=1.03", "--out", log).returncode == 0
    truth = json.loads(log.with_suffix(".truth.json").read_text())["truth"]["eta_gear"]
    r, rec = _calibrate(log, tmp_path / "cal")
    low, high = rec["joint_region"]["box"]["eta_gear"]
    assert f"WARNING: {ACCURACY_WARNING}" in r.stderr or low <= truth <= high, (r.stderr, low, high, truth)
