"""The constant drag of [drive.losses] (``coulomb_drag_Nm``, press_model/motor.py): a torque of constant magnitude against
the motor's rotation, added by Eq. 16's one home, inverted exactly, the same on the batch path, in the planner's torque
bracket and rows, calibratable as a parameter and planned at its worst side like the other losses."""
import numpy as np
import pytest

from planning.robust import DRIVE_LOSS_FIELDS
from press_model import batch as BT
from press_model.cycle import simulate_cycle
from press_io.errors import PressDataError
from press_model.model import PressModel
from press_model.motor import (crank_input_torque, eq16, loss_coefficients, lossy_torque_rows, motor_torque,
                               torque_bracket_interval)
from press_model.press_data import read_press

DRAG = 250.0  # N m per motor


def with_drag(press, drag=DRAG, enabled=True, parameter=False):
    raw = press.raw()
    others = dict(load_loss_at_rated=0.04, viscous_Nms_per_rad=2.0) if enabled else {}
    raw["drive"]["losses"].update(enabled=enabled, coulomb_drag_Nm=drag, **others)
    if parameter:
        raw["parameters"]["d_drive"] = {"path": "drive.losses.coulomb_drag_Nm", "range": [0.0, 400.0], "unit": "N m",
                                        "requires": "drive.losses.enabled"}
    return read_press(raw, "test press")


@pytest.fixture(scope="module")
def dragged(press):
    return with_drag(press, parameter=True)


def test_the_drag_adds_its_size_against_the_rotation_and_nothing_at_rest(press, dragged):
    rng = np.random.default_rng(1)
    tau, td, tdd = rng.normal(0.0, 4e5, 500), rng.normal(0.0, 1.0, 500), rng.normal(0.0, 2.0, 500)
    td[::25] = 0.0
    without = with_drag(press, drag=0.0).drive
    extra = motor_torque(dragged.drive, tau, td, tdd) - motor_torque(without, tau, td, tdd)
    assert np.allclose(extra, DRAG * np.sign(td), rtol=0, atol=1e-9)
    assert np.array_equal(eq16(tau, td, tdd, 54.4, 0.9, 32.0, 2, True), eq16(tau, td, tdd, 54.4, 0.9, 32.0, 2, True, (0.0, 0.0, 0.0)))


def test_crank_input_torque_inverts_eq16_with_the_drag(dragged):
    rng = np.random.default_rng(2)
    tau, td = rng.normal(0.0, 4e5, 400), np.abs(rng.normal(0.0, 1.0, 400)) + 0.05
    tm = motor_torque(dragged.drive, tau, td, 0.0)
    assert np.allclose(crank_input_torque(dragged.drive, tm, td), tau, rtol=1e-12, atol=1e-9 * np.abs(tau).max())


def test_the_planners_bracket_interval_and_rows_hold_the_drag(dragged):
    d = dragged.drive
    w = np.array([0.3, 1.0, 1.7, 0.0])
    still = np.array([False, False, False, True])
    limit = 20000.0
    lo, hi = torque_bracket_interval(d, limit, w, still)
    for B, s in ((hi, 1.0), (lo, -1.0)):  # at the interval's ends Eq. 16 (the drag included) reaches the limit
        tm = np.array([motor_torque(d, b, ww, 0.0) for b, ww in zip(B, w)])
        assert np.allclose(tm, s * limit, rtol=1e-9)
    y = np.linspace(-8000.0, 8000.0, 9)
    mot, brk, _ = lossy_torque_rows(y, 1.0, loss_coefficients(d))
    B = y * d.motors * d.gear_ratio * d.efficiency  # y = B / (n u eta)
    tm = motor_torque(d, B, 1.0, 0.0)
    assert np.allclose(np.where(y >= 0, mot, brk), tm, rtol=1e-12, atol=1e-6)


def test_the_drag_is_a_parameter_on_both_paths_and_planned_at_its_worst_side(dragged, cushion):
    job, motion = cushion
    assert dragged.parameters["d_drive"].target.field == "coulomb_drag" and "coulomb_drag" in DRIVE_LOSS_FIELDS
    bm = BT.build_batch_model(dragged, motion, job.process, step_deg=12.0, pm=PressModel(dragged))
    x = bm.nominal.copy()
    x[bm.names.index("d_drive")] = 120.0
    t = BT.motor_torques(bm, x[None])[0]
    cyc = simulate_cycle(PressModel(dragged.with_overrides({"d_drive": 120.0})), motion, job.process, step_deg=12.0)
    assert np.max(np.abs(t - cyc.motor_torque)) < 1e-10 * np.max(np.abs(cyc.motor_torque))
    x[bm.names.index("d_drive")] = 0.0
    assert np.allclose(t - BT.motor_torques(bm, x[None])[0], 120.0)  # the crank turns forward: +d everywhere


def test_a_drag_of_an_option_that_is_off_or_beyond_the_rated_torque_is_refused(press):
    with pytest.raises(PressDataError, match=r"coulomb_drag_Nm.*option that is off"):
        with_drag(press, enabled=False)
    with pytest.raises(PressDataError, match=r"coulomb_drag_Nm"):
        with_drag(press, drag=press.motor.rated_torque)
