"""The batch model moved to another process force or crank motion without a rebuild (press_model.batch.with_process,
with_motion) against a model built on the moved input: the torque differences the force-noise and crank-motion probes
take (calibration/identification/force_noise.py, motion_error.py) must be the same numbers."""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from calibration.identification.motion_error import _STEP, _Moved
from press_model.batch import build_batch_model, motion_terms, motor_torques, with_motion, with_process
from press_model.jobs import load_job, make_motion
from press_model.model import PressModel
from press_model.press_data import load_press

STEP_DEG = 5.0  # a coarse grid: the identities hold at every angle, and a 72-point model builds in a fifth of the time


@pytest.fixture(scope="module", params=["reference", "crank-slider"])
def case(request):
    """A press, its cushion test's motion and process force, the model built on them and a parameter set off nominal."""
    press = load_press(request.param)
    job = load_job("cushion-test" if request.param == "reference" else "crank-slider-cushion")
    pm = PressModel(press)
    motion = make_motion(job.motion, job.source)
    bm = build_batch_model(press, motion, job.process, step_deg=STEP_DEG, pm=pm)
    x = bm.nominal + 0.3 * (bm.high - bm.nominal)
    return press, pm, job.process, bm, x[None]


def _relative(a, b):
    return float(np.max(np.abs(a - b)) / np.max(np.abs(b)))


def test_a_moved_process_force_gives_the_torque_change_of_a_model_built_on_it(case):
    press, pm, process, bm, X = case
    delta = 1e-3 * max(process.forces)  # the force probe's step (force_noise.FORCE_PROBE of the peak)
    bumped = dataclasses.replace(process, forces=tuple(f + delta for f in process.forces))
    base = motor_torques(bm, X)[0]
    built = (motor_torques(build_batch_model(press, _Moved(bm, 0.0, 0.0), bumped, step_deg=STEP_DEG, pm=pm), X)[0] - base) / delta
    moved = (motor_torques(with_process(bm, process, bumped, pm), X)[0] - base) / delta
    assert np.max(np.abs(built)) > 0.0
    assert _relative(moved, built) < 1e-9


def test_a_moved_crank_motion_gives_the_torque_change_of_a_model_built_on_it(case):
    press, pm, process, bm, X = case
    terms = motion_terms(press, pm, STEP_DEG)
    dw = _STEP * float(np.max(np.abs(bm.theta_dot)))
    da = _STEP * max(float(np.max(np.abs(bm.theta_ddot))), float(np.max(np.abs(bm.theta_dot))) ** 2)
    base = motor_torques(bm, X)[0]
    for d_speed, d_accel, step in ((dw, 0.0, dw), (0.0, da, da)):
        built = build_batch_model(press, _Moved(bm, d_speed, d_accel), process, step_deg=STEP_DEG, pm=pm)
        moved = with_motion(bm, process, bm.theta_dot + d_speed, bm.theta_ddot + d_accel, terms)
        for name in ("theta_dot", "theta_ddot", "height_dot"):
            np.testing.assert_allclose(getattr(moved, name), getattr(built, name), rtol=1e-12, atol=1e-12)
        d_built = (motor_torques(built, X)[0] - base) / step
        d_moved = (motor_torques(moved, X)[0] - base) / step
        assert np.max(np.abs(d_built)) > 0.0
        assert _relative(d_moved, d_built) < 1e-9


def test_a_crank_speed_that_changes_sign_is_refused(case):
    press, pm, process, bm, X = case
    with pytest.raises(ValueError, match="changes sign"):
        with_motion(bm, process, -bm.theta_dot, bm.theta_ddot, motion_terms(press, pm, STEP_DEG))
