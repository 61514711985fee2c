"""The grid limit ([planning.power] grid_peak_limit_W) with the drive losses on ([drive.losses]: the grid rows take Eq. 16
with the losses, planning/optimal.GridRow.losses) and a robust plan's refusal of it (its corners' grid power is not
among its rows)."""
from __future__ import annotations

import json
import re
from importlib import resources

import pytest

from planning.energy import plan_energy
from planning.planner import plan_stroke
from planning.power import PowerLimit
from planning.power_plan import plan_under_grid_limit
from planning.profile import sample_plan
from planning.settings import read_planning
from press_model.commands.cli import main
from press_model.model import PressModel
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
    press = _lossy_press(tmp_path)
    assert press.drive.has_losses
    pm, spec = PressModel(press), read_planning(job)
    free = plan_stroke(pm, job.process, spec)
    _, en = plan_energy(pm, job.process, sample_plan(free, press.drive.gear_ratio))
    power = PowerLimit(grid_peak_limit_W=0.6 * en["grid_peak_W"])
    plan, rec = plan_under_grid_limit(pm, job.process, spec, power, pd=free.pd, grid=free.grid, start=free.profile)
    assert rec["held"] and rec["optimiser"] == "Solve_Succeeded"
    assert power.feedforward_limit_W * 0.999 < rec["grid_peak_W"] <= power.feedforward_limit_W  # binds and holds
    # the rows' grid power is the written profile's (losses included): the re-check tightened the bound by < 0.1 %
    # (rows without the losses put the written peak several % above their bound)
    assert rec["row_bounds_W"][-1] > 0.999 * rec["row_bounds_W"][0]
    assert plan.strokes_per_min < free.strokes_per_min and plan.peak_torque <= 0.9 * press.motor.peak_torque


@pytest.mark.parametrize("key, value", [("grid_peak_limit_W", 3.0e6), ("target_strokes_per_min", 11.0)])
def test_a_robust_plan_with_a_grid_limit_or_an_energy_target_is_refused_saying_why(tmp_path, capsys, key, value):
    press = load_press(None)
    values = press.parameter_values()
    names = ("eta_gear", "psi", "mu_r", "m8", "J_gear", "mu_s")
    box = {n: [values[n] - 0.01 * (press.parameters[n].high - press.parameters[n].low),
               values[n] + 0.01 * (press.parameters[n].high - press.parameters[n].low)] for n in names}
    cal = tmp_path / "calibrated.json"
    cal.write_text(json.dumps({"parameters": {n: values[n] for n in names}, "intervals": box, "joint_region": {"box": box},
                               **press.identity()}), encoding="utf-8")
    text = resources.files("press_model.data").joinpath("door_panel.toml").read_text(encoding="utf-8")
    job = tmp_path / "job.toml"
    job.write_text(text + f"\n[planning.power]\n{key} = {value}\n", encoding="utf-8")
    assert main(["plan", "--job", str(job), "--params", str(cal), "--out", str(tmp_path / "plan")]) == 2
    err = capsys.readouterr().err
    assert f"planning.power.{key}" in err and "corners" in err and "--nominal" in err
    assert not (tmp_path / "plan").exists()
