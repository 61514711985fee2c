"""A pendulum plan robust over a calibration's region (planning/pendulum.py, plan_swing_robust): both swings, replayed per point on
the Pinocchio model at every corner of a small box (the backward swing as the real backward motion, the die empty),
keep the 10 % torque margin; and `mode = "auto"` records the robust pendulum with its strokes per minute."""
from __future__ import annotations

import dataclasses
import itertools
import json
import math
from importlib import resources

import numpy as np
import pytest

from planning.planner import planning_limit
from planning.robust import Box, plan_robust
from planning.settings import read_planning
from servo_press.cli import main
from press_model.dynamics import inverse_dynamics, slide_loads
from press_model.forces import NO_PROCESS
from press_model.jobs import load_job
from press_model.kinematics import state_at
from press_model.model import PressModel, Workspace
from press_model.motor import motor_torque
from press_model.press_data import load_press

# an inertial parameter (every corner), the gear inertia (enters the reversal) and the efficiency (monotone, one side per row)
WIDTHS = {"m8": 0.05, "J_gear": 0.05, "eta_gear": 0.05}  # relative half-widths of the box


@pytest.fixture(scope="module")
def setup():
    press = load_press(None)
    pm = PressModel(press)
    job = load_job("door-panel")
    spec = dataclasses.replace(read_planning(job), mode="pendulum", grid_step=math.radians(2.0))
    centre = press.parameter_values()
    box = Box(dict(centre), {n: (centre[n] * (1 - w), centre[n] * (1 + w)) for n, w in WIDTHS.items()}, {}, "test box")
    return press, pm, job, spec, box


def _played_peak(press, pm, job, swing, corner: dict, backward: bool) -> float:
    """Peak |T_m| (N m per motor) of a swing's profile at the box corner ``corner``, per point on the Pinocchio model
    (Eq. 16 at the sampled angle, speed and acceleration; the backward swing turning back with the die empty)."""
    pc = PressModel(press.with_overrides(corner, "test corner"), check_assembly=False)
    pc.assembly = pm.assembly
    ws = Workspace(pc)
    loads = slide_loads(pc, NO_PROCESS if backward else job.process)
    t = np.linspace(0.0, swing.stroke_time, 400)
    smp = swing.profile.sample(t, swing.grid.theta)
    peak = 0.0
    for th, sd, acc in zip(smp["theta"], smp["theta_dot"], smp["theta_ddot"]):
        sd = -sd if backward else sd  # the reversal's time runs back: the real crank speed is negative, its acceleration the same
        st = state_at(pc, ws, float(th), float(sd), float(acc))
        peak = max(peak, abs(float(motor_torque(pc.press.drive, inverse_dynamics(pc, ws, st, loads).crank_torque, sd, acc))))
    return peak


@pytest.fixture(scope="module")
def robust(setup):
    """`plan_robust` of the door panel in pendulum mode over the box."""
    press, pm, job, spec, box = setup
    return plan_robust(pm, job.process, spec, box, plan_nominal=False)


def test_robust_pendulum_keeps_the_torque_margin_at_every_corner_of_the_box(setup, robust):
    press, pm, job, spec, box = setup
    nominal = robust.nominal
    robust = robust.plan
    limit = planning_limit(pm, spec)
    names = sorted(box.bounds)
    peaks = {}
    for pick in itertools.product(*(box.bounds[n] for n in names)):
        corner = dict(zip(names, pick))
        for backward, swing in ((False, robust.forward), (True, robust.backward)):
            peaks[(pick, backward)] = _played_peak(press, pm, job, swing, corner, backward)
    worst = max(peaks.values())
    assert worst <= limit * 1.001, (worst, limit)  # per point between the knots: the planner's knot check to 0.1 %
    assert worst > 0.99 * limit  # the limit binds at the worst corner
    # the nominal plan, made for the centre alone, breaks the margin somewhere in the box: the robust one costs rate
    nominal_worst = max(_played_peak(press, pm, job, s, dict(zip(names, pick)), b)
                        for pick in itertools.product(*(box.bounds[n] for n in names))
                        for b, s in ((False, nominal.forward), (True, nominal.backward)))
    assert nominal_worst > limit * 1.002
    assert robust.strokes_per_min < nominal.strokes_per_min


def test_auto_mode_over_the_region_records_the_robust_pendulum_and_its_rate(setup, robust):
    press, pm, job, spec, box = setup
    res = plan_robust(pm, job.process, dataclasses.replace(spec, mode="auto"), box, plan_nominal=False)
    rec = res.plan.modes["modes"]["pendulum"]
    assert rec.get("supported") is not False and rec["keeps_every_limit"], rec
    assert rec["strokes_per_min"] == pytest.approx(robust.plan.strokes_per_min, rel=1e-6)
    assert res.plan.spec.mode == res.plan.modes["planned"]  # the mode kept, not "auto"
    s = robust.summary(pm.press.motor.peak_torque)
    assert s["corners_checked"] == 2 ** len(WIDTHS) and s["worst_corner_peak_torque_Nm"] <= planning_limit(pm, spec) * (1 + 1e-9)
    assert 0.0 < s["rate_cost_percent"] < 5.0


def test_plan_with_a_calibrated_region_plans_the_pendulum_robustly(tmp_path, setup):
    """`plan --params calibrated.json` (a joint region) of a pendulum job: planned robustly over the region, not refused;
    summary.json records the corners checked and the worst corner within the limit, and the gain over the robust
    stop-at-top plan."""
    press, pm, job, spec, box = setup
    values = press.parameter_values()
    region = {n: list(box.bounds[n]) for n in WIDTHS}
    cal = tmp_path / "calibrated.json"
    cal.write_text(json.dumps({"parameters": {n: values[n] for n in WIDTHS}, "intervals": region, "joint_region": {"box": region},
                               **press.identity()}), encoding="utf-8")
    text = resources.files("press_model.data").joinpath("door_panel.toml").read_text(encoding="utf-8")
    text = text.replace('# mode = "pendulum" plans', 'mode = "pendulum"\ngrid_step_deg = 2.0\n# plans', 1)
    job_path = tmp_path / "job.toml"
    job_path.write_text(text, encoding="utf-8")
    out = tmp_path / "plan"
    assert main(["plan", "--job", str(job_path), "--params", str(cal), "--out", str(out)]) == 0
    s = json.loads((out / "summary.json").read_text(encoding="utf-8"))
    assert s["mode"] == "pendulum" and s["robust"]["corners_checked"] == 2 ** len(WIDTHS)
    assert s["robust"]["worst_corner_peak_torque_Nm"] <= s["limits"]["peak_torque_limit_Nm"] * (1 + 1e-9)
    assert s["gain_over_stop_at_top"]["pendulum_strokes_per_min"] == pytest.approx(s["robust"]["strokes_per_min_robust"])
