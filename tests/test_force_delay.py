"""The logged force channel's delay (calibration/identification/force_delay.py): timed at die contact against the torque
channel, with an interval that holds it, corrected in the log; a force on time reports none beyond its noise."""
from __future__ import annotations

import json

import numpy as np
import pytest

from in_process import servo_press

from calibration.identification.force_delay import beyond_noise, delay_estimate, force_lag, lag_of_rows, with_lag
from calibration.identification.inputs import read_log
from calibration.traces.drive_log import grid_rows

# SYNTHETIC truths (the six parameters; the others the press file's), chosen before any run of these tests
TRUTH_B = {"eta_gear": 0.86, "psi": 1.03, "mu_r": 0.010, "m8": 33500.0, "J_gear": 58.0, "mu_s": 0.075}
TRUTH_C = {"eta_gear": 0.82, "psi": 1.08, "mu_r": 0.014, "m8": 32400.0, "J_gear": 63.0, "mu_s": 0.095}


def _sampled_steps(delay_s: float, contacts: int, rng, dt: float = 0.002):
    """Torque and force sampled every ``dt`` s over ``contacts`` strokes of 5.26 s, each stepping at die contact (a
    random phase against the sample clock): the torque by 22 kN m on a slow ramp with 150 N m of noise, the force by
    5 MN with 25 kN of noise, ``delay_s`` later."""
    t = np.arange(0.0, 5.26 * contacts, dt)
    torque = 2000.0 * np.sin(2.0 * np.pi * t / 5.26) + rng.normal(0.0, 150.0, t.size)
    force = rng.normal(0.0, 25e3, t.size)
    for k in range(contacts):
        c = 5.26 * k + 1.0 + rng.uniform(0.0, dt)
        on = (t >= c) & (t < c + 2.0)
        torque[on] += 22e3
        force[(t >= c + delay_s) & (t < c + delay_s + 2.0)] += 5e6
    return t, torque, force


@pytest.mark.parametrize("delay_s", [0.0, 0.0073, 0.010, -0.0041])
def test_the_lag_of_a_sampled_step_is_found_within_its_interval(delay_s):
    """Steps of known delay on a sample clock, their phase random: the lag's 95 % interval holds the delay on at least
    93 % of 400 draws (a 95 % interval falls below that with probability 0.02), and a force on time is never
    corrected, one late always."""
    rng = np.random.default_rng(4711)
    held, corrected = 0, 0
    for _ in range(400):
        lag = force_lag(*_sampled_steps(delay_s, 3, rng))
        est = delay_estimate(lag, False, (0.0, 0.0, False), 0.95)
        held += est.low_s <= delay_s <= est.high_s
        corrected += beyond_noise(lag, 0.95)
        assert lag.contacts == 3 and abs(lag.lag_s - delay_s) <= lag.sample_s
    assert held >= 0.93 * 400, held
    assert corrected == (0 if delay_s == 0.0 else 400)


def test_no_step_in_the_torque_times_nothing():
    """A force that rises where the torque shows no step (no lever at the contact): no lag is claimed."""
    rng = np.random.default_rng(5)
    t, _, force = _sampled_steps(0.01, 3, rng)
    assert force_lag(t, rng.normal(0.0, 150.0, t.size), force) is None


def test_a_late_force_column_read_with_its_lag_is_gridded_as_the_force_on_time(tmp_path, press):
    """SYNTHETIC cushion-test logs of one seed (5301, the job's truth), the force column on time and 10 ms late: the
    late one's lag is timed, and gridded with it, its bin means are the on-time log's to within the channel's noise
    (the same samples, moved to the angles of their own times less 10 ms); gridded as logged, the bin at die contact
    differs by a share of the 5 MN step."""
    logs = {}
    for name, effect in (("on_time", ()), ("late", ("--effect", "force_channel_delay_s=0.01"))):
        logs[name] = tmp_path / f"{name}.csv"
        assert servo_press("experiment", "--seed", 5301, *effect, "--out", logs[name]).returncode == 0
    rows_on, rows_late = (read_log(logs[n], press) for n in ("on_time", "late"))
    lag = lag_of_rows(rows_late)
    assert beyond_noise(lag, 0.95) and abs(lag.lag_s - 0.010) <= lag.sample_s, lag
    assert not beyond_noise(lag_of_rows(rows_on), 0.95)

    def binned(rows):
        return grid_rows(rows, press.drive.gear_ratio, press.motor.rated_torque).force_binned

    on, late, fixed = binned(rows_on), binned(rows_late), binned(with_lag(rows_late, lag, 0.95))
    sigma = 25e3  # the experiment's force noise per sample (0.5 % of 5 MN); a bin holds several samples
    assert np.max(np.abs(fixed - on)) < 5.0 * sigma, np.max(np.abs(fixed - on))
    assert np.max(np.abs(late - on)) > 0.1 * 5e6


@pytest.mark.parametrize("seed,truth", [(5201, TRUTH_B), (5202, TRUTH_C)])
def test_a_force_column_10_ms_late_is_timed_corrected_and_eta_gear_held(tmp_path, seed, truth):
    """SYNTHETIC cushion-test log (seed 5201 truth B, 5202 truth C) whose force column is 10 ms late
    (force_channel_delay_s = 0.01): its delay's interval holds 10 ms, the force is read that much earlier, and eta_gear's
    truth lies in its joint region."""
    log = tmp_path / "late.csv"
    r = servo_press("experiment", "--seed", seed, "--truth", json.dumps(truth), "--effect", "force_channel_delay_s=0.01",
                    "--out", log)
    assert r.returncode == 0, r.stderr
    out = tmp_path / "cal"
    r = servo_press("calibrate", "--log", log, "--method", "least-squares", "--out", out)
    assert r.returncode == 0, r.stderr
    rec = json.loads((out / "calibrated.json").read_text())
    (delay,) = rec["process_force"]["logged_force_delay"]
    low, high = delay["interval_s"]
    assert low <= 0.010 <= high and delay["corrected"], delay
    assert "a force-channel delay of" in r.stdout
    lo, hi = rec["joint_region"]["box"]["eta_gear"]
    assert lo <= truth["eta_gear"] <= hi, (lo, hi, rec["parameters"]["eta_gear"])
