"""The grid limit ([planning.power] grid_peak_limit_W) with the drive losses on ([drive.losses]: the grid rows take Eq. 16
with the losses, planning/optimal.GridRow.losses), a robust plan under it (planning/energy.py: held at every corner
of the calibration's region) and a robust plan's refusal of an energy target."""
from __future__ import annotations

import dataclasses
import itertools
import json
import math
import re
from importlib import resources

import numpy as np

from planning.energy import plan_energy
from planning.planner import StrokeProblem, plan_stroke
from planning.power import PowerLimit, grid_bound_coefficients
from planning.energy import plan_under_grid_limit
from planning.profile import sample_plan
from planning.settings import read_planning
from servo_press.cli import main
from press_model.dynamics import inverse_dynamics, slide_loads
from press_model.jobs import load_job
from press_model.kinematics import state_at
from press_model.model import PressModel, Workspace
from press_model.motor import motor_torque
from press_model.press_data import load_press

JOB = "door-panel"
LOSSES = {"load_loss_at_rated": 0.06, "viscous_Nms_per_rad": 4.0}  # the drive-loss tests' values


def _lossy_press(tmp_path):
    text = resources.files("press_model.data").joinpath("reference_press.toml").read_text(encoding="utf-8")
    text, n = re.subn(r"(?m)(^\[drive\.losses\][^\[]*?^)enabled = false", r"\1enabled = true", text)
    assert n == 1
    for key, value in LOSSES.items():
        text, n = re.subn(rf"(?m)^{key} = [^#\n]*", f"{key} = {value} ", text)
        assert n == 1
    path = tmp_path / "lossy_press.toml"
    path.write_text(text, encoding="utf-8")
    return load_press(str(path))


def test_grid_limited_plan_with_drive_losses_holds_the_limit_with_rows_that_match_its_written_profile(tmp_path, job):
    """On 2-degree knots (half the shipped grid's problem): the limit binding and held, and the rows' grid power within
    0.1 % of the written profile's, hold on any knots whose written profile stays close to its knots between them
    (measured: the re-check tightened the bound by 0.03 % there; on 5-degree knots by 0.105 %, the spline's gaps)."""
    press = _lossy_press(tmp_path)
    assert press.drive.has_losses
    pm, spec = PressModel(press), dataclasses.replace(read_planning(job), grid_step=math.radians(2.0))
    free = plan_stroke(StrokeProblem.build(pm, job.process, spec))
    _, en = plan_energy(pm, job.process, sample_plan(free, press.drive.gear_ratio))
    power = PowerLimit(grid_peak_limit_W=0.6 * en["grid_peak_W"])
    plan, rec = plan_under_grid_limit(StrokeProblem(pm, job.process, spec, free.grid, free.pd), power, start=free.profile)
    assert rec["held"] and rec["optimiser"] == "Solve_Succeeded"
    assert power.feedforward_limit_W * 0.999 < rec["grid_peak_W"] <= power.feedforward_limit_W  # binds and holds
    # the rows' grid power is the written profile's (losses included): the re-check tightened the bound by < 0.1 %
    # (rows without the losses put the written peak several % above their bound)
    assert rec["row_bounds_W"][-1] > 0.999 * rec["row_bounds_W"][0]
    assert plan.strokes_per_min < free.strokes_per_min and plan.peak_torque <= 0.9 * press.motor.peak_torque


def _calibration(tmp_path, names, widths: dict):
    """A calibrated.json at the reference press's values with a joint region of ``widths`` (SI, half-width per name)."""
    press = load_press(None)
    values = press.parameter_values()
    box = {n: [values[n] - widths[n], values[n] + widths[n]] for n in names}
    cal = tmp_path / "calibrated.json"
    cal.write_text(json.dumps({"parameters": {n: values[n] for n in names}, "intervals": box, "joint_region": {"box": box},
                               **press.identity()}), encoding="utf-8")
    return cal


def _job(tmp_path, extra: str, planning: str = ""):
    text = resources.files("press_model.data").joinpath("door_panel.toml").read_text(encoding="utf-8")
    if planning:
        text = text.replace("[planning]\n", f"[planning]\n{planning}\n", 1)
    job = tmp_path / "job.toml"
    job.write_text(text + f"\n[planning.power]\n{extra}\n", encoding="utf-8")
    return job


def test_a_robust_plan_with_an_energy_target_is_refused_saying_why(tmp_path, capsys):
    press = load_press(None)
    names = ("eta_gear", "psi", "mu_r", "m8", "J_gear", "mu_s")
    cal = _calibration(tmp_path, names, {n: 0.01 * (press.parameters[n].high - press.parameters[n].low) for n in names})
    job = _job(tmp_path, "target_strokes_per_min = 11.0")
    assert main(["plan", "--job", str(job), "--params", str(cal), "--out", str(tmp_path / "plan")]) == 2
    err = capsys.readouterr().err
    assert "planning.power.target_strokes_per_min" in err and "corners" in err and "--nominal" in err
    assert not (tmp_path / "plan").exists()


ROBUST_LIMIT = 2.8e6  # W: 60 % of the door panel's free grid peak (4.69 MW)
ROBUST_WIDTHS = {"eta_gear": 0.012, "m8": 950.0, "J_gear": 2.5}  # half-widths of the calibration's order (Table 4 box)


def test_robust_plan_with_a_grid_limit_holds_it_at_every_corner_on_the_per_point_model(tmp_path):
    """`plan --params` a calibration with a joint region and a job with a grid limit (5-degree knots, the coarsest
    a job may state: what is checked holds on any knots, and the written profile between wider gaps only tests it harder):
    planned, not refused; the centre's grid rows alone let a corner draw above the limit (the first plan's bound is
    tightened), and the written profile run at every corner of the region, per point on the Pinocchio model (the motor
    torque of Eq. 16 at profile.csv's angle, speed and acceleration, the grid power from it), keeps the limit."""
    cal = _calibration(tmp_path, tuple(ROBUST_WIDTHS), ROBUST_WIDTHS)
    job_path = _job(tmp_path, f"grid_peak_limit_W = {ROBUST_LIMIT}", "grid_step_deg = 5.0")
    out = tmp_path / "plan"
    assert main(["plan", "--job", str(job_path), "--params", str(cal), "--out", str(out)]) == 0
    summary = json.loads((out / "summary.json").read_text(encoding="utf-8"))
    rec = summary["grid_limit"]
    assert "robust" in summary and rec["held"] and rec["corners_checked"] == 8
    assert len(rec["row_bounds_W"]) >= 2 and rec["row_bounds_W"][-1] < rec["row_bounds_W"][0]  # the corners needed a tighter bound
    assert rec["worst_corner_grid_peak_W"] > rec["grid_peak_W"]
    # independently: the rows of profile.csv with the largest written grid power, per point at every corner
    press = load_press(None)
    pm = PressModel(press)
    cols = np.genfromtxt(out / "profile.csv", delimiter=",", names=True)
    a, b, c, k = grid_bound_coefficients(press.electrical, press.drive.motors)
    gear = press.drive.gear_ratio

    def grid_power(torque, crank_speed):
        w = gear * crank_speed
        return k * (torque * w + a * torque**2 + b * w + c * w**2)

    written = grid_power(cols["motor_torque_Nm"], cols["crank_speed_rad_s"])
    rows = np.argsort(-written)[:12]
    job = load_job(str(job_path))
    loads = slide_loads(pm, job.process)
    centre = {n: press.parameter_values()[n] for n in ROBUST_WIDTHS}
    peak = 0.0
    for pick in itertools.product(*((centre[n] - w, centre[n] + w) for n, w in ROBUST_WIDTHS.items())):
        pc = PressModel(press.with_overrides(dict(zip(ROBUST_WIDTHS, pick))), check_assembly=False)
        pc.assembly = pm.assembly
        ws = Workspace(pc)
        for r in rows:
            th, sd, acc = math.radians(cols["crank_angle_deg"][r]), float(cols["crank_speed_rad_s"][r]), float(cols["crank_accel_rad_s2"][r])
            st = state_at(pc, ws, th, sd, acc)
            T = float(motor_torque(pc.press.drive, inverse_dynamics(pc, ws, st, loads).crank_torque, sd, acc))
            peak = max(peak, float(grid_power(T, sd)))
    assert peak <= ROBUST_LIMIT
    assert peak > 0.99 * ROBUST_LIMIT  # the limit binds at the worst corner
