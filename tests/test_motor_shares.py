"""Each motor's own torque channel: read as its own, its share of the total estimated with its interval, recorded by
calibrate, and the plan holding the heaviest motor (not the motors' mean) to the torque margin on the true press."""
from __future__ import annotations

import importlib.util
import json
from pathlib import Path

import numpy as np
import pytest

from in_process import servo_press

from calibration.traces.drive_log import read_log_rows
from calibration.traces.motor_shares import estimate_shares, shares_of_rows
from press_io.errors import PressDataError
from press_model.jobs import load_job
from press_model.press_data import load_press
from planning.settings import motor_sharing

SEED = 7  # the twin-drive log's seed; its truth is the cushion test's [experiment.truth] (the job's own), in the sidecar
SHARE = 0.53  # motor 1's share of the total torque in that log (motor 2: 0.47)
MARGIN = 0.90  # the plan's torque margin: the heavier motor within 0.9 T_max on the true press


@pytest.fixture(scope="module")
def twin_log(twin_drive_log):
    """A SYNTHETIC twin-drive log (`servo-press experiment --effect motor1_share=0.53`, seed 7): its path, the suite's
    one copy (fixtures_suiteident.py, which test_tonnage reads too)."""
    from fixtures_suiteident import TWIN_SEED, TWIN_SHARE

    assert (TWIN_SEED, TWIN_SHARE) == (SEED, SHARE)
    return twin_drive_log


def _check_chain():
    spec = importlib.util.spec_from_file_location("check_chain", Path(__file__).resolve().parents[1] / "scripts" / "check_chain.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_a_log_with_one_torque_column_per_motor_is_read_as_each_motor_and_their_mean(twin_log):
    rows = read_log_rows(twin_log)
    assert rows.motor_channels == ("motor_torque_Nm_1", "motor_torque_Nm_2")
    # the torque per motor is the channels' mean, every row
    assert np.allclose(rows.data[:, 3], rows.motor_torques.mean(axis=1), rtol=0, atol=1e-9)
    # motor 1 carries 53 % of the total: its channel is 2 x 0.53 = 1.06 times the mean where the torque is large
    big = np.abs(rows.data[:, 3]) > 0.5 * np.max(np.abs(rows.data[:, 3]))
    assert np.median(rows.motor_torques[big, 0] / rows.data[big, 3]) == pytest.approx(2 * SHARE, abs=0.01)


def test_a_trace_with_one_torque_channel_per_motor_keeps_each_channel_through_its_map(twin_log, tmp_path):
    from calibration.traces.channel_map import load_channel_map
    from calibration.traces.trace_log import read_trace_rows
    from trace_writers import write_plain_csv

    rows = read_log_rows(twin_log)
    press = load_press()
    trace = tmp_path / "trace.csv"
    write_plain_csv(trace, ["SYNTHETIC twin-drive trace"], {"Time": rows.data[:, 0], "fCrankAngle": rows.data[:, 1],
                                                            "Drive1_ActVelo": rows.data[:, 2], "Drive1_ActTorque": rows.motor_torques[:, 0],
                                                            "Drive2_ActTorque": rows.motor_torques[:, 1]}, sep=",", decimal=".")
    cmap = tmp_path / "map.toml"
    cmap.write_text(f'press = "{press.name}"\n[channels]\ncrank_angle_deg = {{ name = "fCrankAngle", unit = "deg" }}\n'
                    'motor_speed_rpm = { name = "Drive1_ActVelo", unit = "rpm", side = "motor" }\n'
                    'motor_torque_Nm = [{ name = "Drive1_ActTorque", unit = "N*m" }, { name = "Drive2_ActTorque", unit = "N*m" }]\n'
                    'time_s = { name = "Time", unit = "s" }\n', encoding="utf-8")
    mapped = read_trace_rows(trace, load_channel_map(cmap), press)
    assert mapped.motor_channels == ("Drive1_ActTorque", "Drive2_ActTorque")
    assert np.allclose(mapped.motor_torques, rows.motor_torques, rtol=0, atol=1e-9)
    assert np.allclose(shares_of_rows(mapped).shares, shares_of_rows(rows).shares, rtol=0, atol=1e-12)


def test_the_shares_of_a_twin_drive_log_hold_the_truth_in_their_interval(twin_log):
    s = shares_of_rows(read_log_rows(twin_log))
    assert s.low[0] <= SHARE <= s.high[0] and s.low[1] <= 1 - SHARE <= s.high[1]
    assert s.shares.sum() == pytest.approx(1.0)
    assert s.heaviest[0] == 0 and s.torque_factor == pytest.approx(2 * SHARE, abs=2e-3)
    assert not s.sign_differs  # the log's share is the same driving and braking


def test_a_share_that_depends_on_the_torques_sign_is_found_and_bounds_the_heaviest_motor():
    rng = np.random.default_rng(3)
    angle = np.arange(0.0, 5 * 360.0, 0.5)  # five turns, 720 samples each
    total = 20000.0 * np.sin(np.radians(angle)) + 3000.0
    s1 = np.where(total > 0, 0.56, 0.50)  # motor 1 carries more while driving
    T = np.column_stack([s1 * total, (1 - s1) * total]) + rng.normal(0.0, 100.0, (angle.size, 2))
    s = estimate_shares(angle, T, ("a", "b"))
    assert s.sign_differs
    assert s.by_sign["driving"][0] == pytest.approx(0.56, abs=0.005) and s.by_sign["braking"][0] == pytest.approx(0.50, abs=0.005)
    # the heaviest motor's bound is its driving share (over the driving samples, or a driving sector's), not the mean 0.53
    assert s.heaviest[0] == 0 and s.heaviest[1] >= 0.56 - 0.005 and s.torque_factor >= 2 * (0.56 - 0.005)
    even = estimate_shares(angle, np.column_stack([0.5 * total, 0.5 * total]) + rng.normal(0.0, 100.0, (angle.size, 2)), ("a", "b"))
    assert not even.sign_differs and not even.sectors[2].any()
    assert even.torque_factor == pytest.approx(1.0, abs=0.01)


def test_a_share_that_depends_on_the_crank_angle_is_found_where_the_torque_peaks():
    rng = np.random.default_rng(5)
    angle = np.arange(0.0, 5 * 360.0, 0.5)
    total = 20000.0 * np.sin(np.radians(angle)) + 3000.0  # its peak at 90 deg
    s1 = np.where((np.mod(angle, 360.0) >= 60.0) & (np.mod(angle, 360.0) < 120.0), 0.58, 0.52)
    T = np.column_stack([s1 * total, (1 - s1) * total]) + rng.normal(0.0, 100.0, (angle.size, 2))
    s = estimate_shares(angle, T, ("a", "b"))
    bounds, per, differs, loaded = s.sectors
    at = [list(map(tuple, bounds)).index(b) for b in ((60.0, 90.0), (90.0, 120.0))]
    assert differs[at].all() and loaded[at].all()  # apart from the turn's own share (0.54), where the torque peaks
    assert per[at, 0] == pytest.approx([0.58, 0.58], abs=0.003)
    assert np.delete(per[:, 0], at) == pytest.approx(np.full(10, 0.52), abs=0.01)  # the rest of the turn
    assert s.heaviest[0] == 0 and s.heaviest[2] in ("60-90 deg", "90-120 deg") and s.torque_factor >= 2 * 0.577


def test_a_press_file_states_the_shares_and_a_wrong_count_is_refused(tmp_path):
    import press_model.data

    text = (Path(press_model.data.__file__).parent / "reference_press.toml").read_text()
    ok = tmp_path / "shares.toml"
    ok.write_text(text.replace("[motor]", "[motor]\nload_shares = [0.45, 0.55]", 1))
    sharing = motor_sharing(load_press(str(ok)))
    assert sharing.motor == 2 and sharing.factor == pytest.approx(1.1)
    bad = tmp_path / "three.toml"
    bad.write_text(text.replace("[motor]", "[motor]\nload_shares = [0.3, 0.3, 0.4]", 1))
    with pytest.raises(PressDataError, match=r"load_shares.*one share per motor"):
        load_press(str(bad))


def test_a_twin_drive_calibration_plans_the_heavier_motor_within_the_margin_on_the_true_press(twin_log, tmp_path):
    cal = servo_press("calibrate", "--log", twin_log, "--out", tmp_path / "cal")
    assert cal.returncode == 0, cal.stderr
    assert "do not share the load evenly" in cal.stderr  # 6 points apart, past the press file's 3
    rec = json.loads((tmp_path / "cal" / "calibrated.json").read_text())["motor_shares"]
    assert rec["heaviest"]["motor"] == 1
    plan = servo_press("plan", "--job", "door-panel", "--params", tmp_path / "cal" / "calibrated.json", "--out", tmp_path / "plan")
    assert plan.returncode == 0, plan.stderr
    assert "limiting motor: motor 1" in plan.stdout
    # the oracle: the TRUE press's torque per motor along profile.csv (an independent per-point model, scripts/check_chain.py),
    # motor 1 carrying its true 53 %
    truth = json.loads(twin_log.with_suffix(".truth.json").read_text())["truth"]
    press = load_press()
    mean_peak = _check_chain().true_peak(press, truth, load_job("door-panel"), tmp_path / "plan" / "profile.csv", "clean", 0.0)
    heavier = press.drive.motors * SHARE * mean_peak / press.motor.peak_torque
    assert 0.5 < heavier <= MARGIN, heavier
