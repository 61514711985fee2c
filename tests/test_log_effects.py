"""SYNTHETIC log effects of calibration/synthetic/effects.py: each one does to the log's channels what it says, checked against
the plain log made with the same seed (an independent statement of each effect), and the sidecar records it."""
import dataclasses
import json
import math

import numpy as np
import pytest

from calibration.synthetic.effects import LogEffects, ar1_noise
from calibration.synthetic.experiment import ExperimentSettings, synthetic_log, truth_path, write_experiment
from press_io.errors import PressDataError
from press_model.jobs import load_job
from press_model.press_data import load_press


@pytest.fixture(scope="module")
def setup():
    press, job = load_press(), load_job("cushion-test")
    s = dataclasses.replace(ExperimentSettings.from_job(job), strokes=1, model_step=math.radians(1.0))
    return press, job, s


def make(setup, noise=0.0, ring=0.0, **fx):
    press, job, s = setup
    s = dataclasses.replace(s, noise_sigma=noise, oscillation=ring, effects=LogEffects(**fx))
    return synthetic_log(press, job, {}, 5, s)["columns"]


@pytest.fixture(scope="module")
def plain(setup, one_stroke_plain_log):
    """``make(setup)``: the log without an effect, made once for the tests here and test_drag_and_backlash_suspects'
    (fixtures_suiteident.py). Read only."""
    from fixtures_suiteident import one_stroke_settings

    assert dataclasses.replace(setup[2], noise_sigma=0.0, oscillation=0.0, effects=LogEffects()) == one_stroke_settings(setup[1])
    return one_stroke_plain_log


def test_channel_delay_shifts_the_torque_channel_by_whole_samples(setup, plain):
    """4 ms at 500 Hz is two samples: the delayed log's torque is the plain torque two rows earlier."""
    c = make(setup, channel_delay_s=0.004)
    assert np.allclose(c["motor_torque_Nm"][2:], plain["motor_torque_Nm"][:-2], rtol=0, atol=1e-9)
    assert np.array_equal(c["crank_angle_deg"], plain["crank_angle_deg"])


def test_force_channel_delay_shifts_only_the_force_column_by_whole_samples(setup, plain):
    """10 ms at 500 Hz is five samples: the late force column is the plain one five rows earlier (its noise off); the
    torque and angle channels are the plain log's."""
    press, job, s = setup
    quiet = dataclasses.replace(s, noise_sigma=0.0, oscillation=0.0, force_noise_of_peak=0.0)
    c0 = synthetic_log(press, job, {}, 5, quiet)["columns"]
    c = synthetic_log(press, job, {}, 5, dataclasses.replace(quiet, effects=LogEffects(force_channel_delay_s=0.01)))["columns"]
    assert np.allclose(c["process_force_N"][5:], c0["process_force_N"][:-5], rtol=0, atol=1e-6 * np.max(np.abs(c0["process_force_N"])))
    assert not np.allclose(c["process_force_N"], c0["process_force_N"])
    assert np.array_equal(c["motor_torque_Nm"], c0["motor_torque_Nm"]) and np.array_equal(c["crank_angle_deg"], c0["crank_angle_deg"])


def test_encoder_offset_moves_only_the_angle_channel(setup, plain):
    c = make(setup, angle_offset_deg=0.5)
    assert np.allclose(c["crank_angle_deg"] - plain["crank_angle_deg"], 0.5)
    assert np.array_equal(c["motor_torque_Nm"], plain["motor_torque_Nm"])


def test_channel_noises_round_the_angle_to_motor_encoder_counts_and_add_their_noise(setup, plain):
    """A 4096-count motor encoder through u: every logged angle is a whole count of 360 / (4096 u) crank deg, within
    half a count of the plain angle; the angle and speed noises have their RMS; the torque is untouched."""
    u = setup[0].drive.gear_ratio
    count = 360.0 / (4096 * u)
    q = make(setup, angle_counts_per_motor_rev=4096)
    assert np.allclose(q["crank_angle_deg"] / count, np.round(q["crank_angle_deg"] / count), rtol=0, atol=1e-6)
    assert np.max(np.abs(q["crank_angle_deg"] - plain["crank_angle_deg"])) <= 0.5 * count + 1e-9
    c = make(setup, angle_noise_deg=0.01, speed_noise_rpm=2.0)
    assert np.std(c["crank_angle_deg"] - plain["crank_angle_deg"]) == pytest.approx(0.01, rel=0.1)
    assert np.std(c["motor_speed_rpm"] - plain["motor_speed_rpm"]) == pytest.approx(2.0, rel=0.1)
    assert np.array_equal(c["motor_torque_Nm"], plain["motor_torque_Nm"])


def test_load_dependent_efficiency_raises_driving_torque_and_lowers_braking_torque(setup, plain):
    press = setup[0]
    c = make(setup, efficiency_drop_at_rated=0.05)
    T, Te = plain["motor_torque_Nm"], c["motor_torque_Nm"]
    f = 1.0 - 0.05 * np.abs(T) / press.motor.rated_torque
    drive, brake = T > 0, T < 0
    assert drive.any() and brake.any()
    assert np.allclose(Te[drive] * f[drive], T[drive]) and np.allclose(Te[brake], T[brake] * f[brake])


def test_viscous_loss_is_proportional_to_motor_speed_with_the_asked_rms(setup, plain):
    c = make(setup, viscous_loss_of_rms=0.02)
    extra = c["motor_torque_Nm"] - plain["motor_torque_Nm"]
    speed = plain["motor_speed_rpm"] * 2 * math.pi / 60
    ratio = extra / speed
    assert np.ptp(ratio) < 1e-9 * abs(ratio.mean())
    rms = lambda x: math.sqrt(float(np.mean(x ** 2)))
    assert abs(rms(extra) / rms(plain["motor_torque_Nm"]) - 0.02) < 1e-3  # sized on the same samples


def test_ripple_has_its_order_per_motor_turn_and_amplitude(setup, plain):
    press = setup[0]
    c = make(setup, ripple_of_rms=0.03, ripple_order=6)
    extra = c["motor_torque_Nm"] - plain["motor_torque_Nm"]
    rms = math.sqrt(float(np.mean(plain["motor_torque_Nm"] ** 2)))
    motor_angle = np.unwrap(np.radians(plain["crank_angle_deg"])) * press.drive.gear_ratio
    X = np.column_stack([np.sin(6 * motor_angle), np.cos(6 * motor_angle)])
    coef, *_ = np.linalg.lstsq(X, extra, rcond=None)
    assert abs(np.hypot(*coef) - 0.03 * rms) < 1e-6 * rms
    assert np.max(np.abs(extra - X @ coef)) < 1e-6 * rms


def test_ar1_noise_keeps_sigma_and_has_its_lag_one_correlation():
    w = np.random.default_rng(1).normal(0, 150.0, 200_000)
    e = ar1_noise(w, 0.97)
    assert abs(e.std() / 150.0 - 1) < 0.03
    assert abs(np.corrcoef(e[1:], e[:-1])[0, 1] - 0.97) < 0.003
    assert e[0] == w[0]


def test_sidecar_and_header_record_the_effects(setup, tmp_path):
    press, job, s = setup
    out = tmp_path / "log.csv"
    prov = write_experiment(press, job, {}, 3, out, settings=dataclasses.replace(s, effects=LogEffects(channel_delay_s=0.004)))
    side = json.loads(truth_path(out).read_text())
    assert side["effects"]["log_effects"]["channel_delay_s"]["value"] == 0.004 and prov["synthetic"]
    head = out.read_text().splitlines()[:5]
    assert any("SYNTHETIC log effects" in h and "channel_delay_s = 0.004 s" in h for h in head)


def test_bad_effects_are_refused_in_one_line():
    with pytest.raises(PressDataError, match="channel_dealy_s"):
        LogEffects().with_args(["channel_dealy_s=0.004"])
    with pytest.raises(PressDataError, match="noise_ar1_rho"):
        LogEffects().with_args(["noise_ar1_rho=1.5"])
    with pytest.raises(PressDataError, match="unknown|known effects"):
        LogEffects.from_mapping({"delay": 0.1}, "job.toml")
