"""The size of a synthetic drive log (`servo-press experiment`): its memory grows with its samples, not with samples
times strokes (a table of every sample's time since every die contact took 23.5 GB at 760 strokes), and a stroke count
`calibrate` cannot use (one stroke) is refused where it is set, not after the log is written."""
from __future__ import annotations

import dataclasses
import math
import tracemalloc

import numpy as np

from calibration.synthetic.experiment import ExperimentSettings, synthetic_log
from press_model.jobs import load_job
from press_model.press_data import load_press

from bad_input_helpers import DATA, cli, refused


def _peak_bytes_per_sample(strokes: int) -> float:
    press, job = load_press(), load_job("cushion-test")
    s = dataclasses.replace(ExperimentSettings.from_job(job), strokes=strokes, model_step=math.radians(1.0))
    synthetic_log(press, job, {}, 0, dataclasses.replace(s, strokes=2))  # the torque table's one-off cost, not counted
    tracemalloc.start()
    try:
        c = synthetic_log(press, job, {}, 0, s)["columns"]
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    return peak / c["time_s"].size


def test_experiment_memory_per_sample_does_not_grow_with_the_strokes():
    """Five columns of float64 are 40 bytes a sample and the model's intermediate arrays a few times that; the table of
    times since each contact added 8 bytes x (strokes + 3) a sample (772 bytes a sample at 40 strokes)."""
    few, many = _peak_bytes_per_sample(5), _peak_bytes_per_sample(40)
    assert many < 250.0, many
    assert many < 1.5 * few, (few, many)


def test_ringing_is_timed_from_the_latest_die_contact(press):
    """The ringing starts at each die contact and decays from there: the logged torque with ringing minus without it is
    A exp(-t'/tau) sin(2 pi f t'), t' the time since the latest contact (motion.time at the contact angle each turn)."""
    from press_model.jobs import make_motion
    from press_model.kinematics import force_step_angles
    from press_model.model import PressModel

    job = load_job("cushion-test")
    s = dataclasses.replace(ExperimentSettings.from_job(job), strokes=3, model_step=math.radians(1.0), noise_sigma=0.0)
    ring = synthetic_log(press, job, {}, 0, s)["columns"]
    plain = synthetic_log(press, job, {}, 0, dataclasses.replace(s, oscillation=0.0))["columns"]
    motion = make_motion(job.motion, job.source)
    contact = force_step_angles(PressModel(press), job.process)[0]
    t = ring["time_s"]
    contacts = [motion.time(contact + 2.0 * math.pi * k) for k in range(-1, 5)]
    since = np.array([min((x - c for c in contacts if c <= x), default=np.inf) for x in t])
    want = np.where(np.isfinite(since), s.oscillation * np.exp(-np.where(np.isfinite(since), since, 0.0) / s.decay)
                    * np.sin(2.0 * math.pi * s.frequency * np.where(np.isfinite(since), since, 0.0)), 0.0)
    np.testing.assert_allclose(ring["motor_torque_Nm"] - plain["motor_torque_Nm"], want, rtol=0, atol=1e-6)


def test_experiment_of_one_stroke_is_refused_before_writing_a_log_calibrate_refuses(capsys, work):
    job = work.root / "one.toml"
    job.write_text((DATA / "cushion_test.toml").read_text(encoding="utf-8").replace("[experiment]\n", "[experiment]\nstrokes = 1\n", 1),
                   encoding="utf-8")
    work.snap()
    refused(cli(capsys, "experiment", "--job", job, "--out", work.root / "log.csv"),
            "experiment.strokes = 1", "at least 2", "calibrate")
    work.unchanged()
