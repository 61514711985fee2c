"""compare's theoretical row planned in a process beside the calibrated rows (planning/compare.py): the plan crosses
the process boundary whole (its press model left out and put back), and the comparison's theoretical row is the plan
the press file's values give, planned in the other process."""
from __future__ import annotations

import dataclasses
import json
import math
import os

import numpy as np
import pytest

import planning.compare as compare
from planning.compare import Calibrated, evaluate_under, pack_plan, run_compare, unpack_plan
from planning.modes import keep_fastest, plan_in_mode, plan_modes
from planning.optimal import clear_solvers
from planning.planner import StrokeProblem, plan_stroke
from planning.settings import read_planning
from press_model.jobs import load_job
from press_model.model import PressModel
from press_model.params import apply_overrides
from press_model.press_data import load_press

CALIBRATED = {"eta_gear": 0.842, "mu_r": 0.012}


@pytest.fixture(scope="module")
def door():
    job = load_job("door-panel")
    # stop-at-top on the coarsest knots a job may state: one mode, a small problem (packing a plan, where compare plans
    # its rows and the modes planned apart against together do not depend on the knots)
    spec = dataclasses.replace(read_planning(job), mode="stop-at-top", grid_step=math.radians(5.0))
    return load_press(None), job, spec


@pytest.fixture(scope="module")
def planned(door):
    press, job, spec = door
    clear_solvers()  # as the other process plans: with no IPOPT solver built before (the rows are then the same bytes)
    sender = PressModel(press)
    return sender, plan_stroke(StrokeProblem.build(sender, job.process, spec))


def test_a_packed_plan_is_the_same_plan_on_the_receiving_model(door, planned):
    press, job, spec = door
    sender, plan = planned
    receiver = PressModel(press)
    got = unpack_plan(pack_plan(plan, sender), receiver)
    assert got.pd.pm is receiver and got.evaluation.pd.pm is receiver and got.stage is None
    assert (got.strokes_per_min, got.peak_torque, got.rms_torque, got.dwell) == (plan.strokes_per_min, plan.peak_torque, plan.rms_torque, plan.dwell)
    for a, b in ((got.profile.dt, plan.profile.dt), (got.evaluation.motor_right, plan.evaluation.motor_right), (got.pd.A_inv, plan.pd.A_inv)):
        np.testing.assert_array_equal(a, b)
    assert got.binding == plan.binding
    calibrated = PressModel(apply_overrides(press, CALIBRATED, "test"))
    assert evaluate_under(calibrated, got, job.process)[1:] == evaluate_under(calibrated, plan, job.process)[1:]


def test_a_plan_that_refers_to_another_press_model_is_not_packed(door, planned):
    press, job, spec = door
    _, plan = planned
    with pytest.raises(ValueError, match="other than the one it was planned on"):
        pack_plan(plan, PressModel(press))


def test_compare_plans_the_theoretical_row_in_another_process(door, planned, tmp_path, monkeypatch):
    press, job, spec = door
    planned_in = tmp_path / "pids.txt"

    def plan_and_say_where(problem, **kw):
        with open(planned_in, "a", encoding="utf-8") as fh:
            fh.write(f"{os.getpid()} {'theoretical' if problem.pm.press.parameter_values()['eta_gear'] != CALIBRATED['eta_gear'] else 'calibrated'}\n")
        return plan_in_mode(problem, **kw)

    monkeypatch.setattr(compare, "plan_in_mode", plan_and_say_where)
    rec = run_compare(press, job, spec, Calibrated(CALIBRATED), tmp_path / "cmp", verify=False)
    where = dict(reversed(line.split()) for line in planned_in.read_text().splitlines())
    assert where["calibrated"] == str(os.getpid()) and where["theoretical"] != str(os.getpid())
    # the row is the plan of the press file's values, as planned here
    _, alone = planned
    theoretical = rec["rows"][0]
    assert theoretical["plan"] == "theoretical" and theoretical["strokes_per_min"] == alone.strokes_per_min
    summary = json.loads((tmp_path / "cmp" / "theoretical" / "summary.json").read_text())
    assert summary["strokes_per_min"] == alone.strokes_per_min


def test_the_modes_planned_apart_give_the_plan_of_the_modes_planned_together(door, coarse_door_panel_auto):
    # reproduce plans the theoretical row's continuous mode in the comparing process, the others in its second process
    press, job, spec = door
    auto = dataclasses.replace(spec, mode="auto")
    pm = PressModel(press)
    # the modes planned together: the suite's plan (fixtures_suiteplan.py, test_planning_modes reads it too), plan_fastest
    # of this job on these knots from a clean IPOPT state, as planned here before
    together = coarse_door_panel_auto
    # as compare takes them: two modes planned and packed with their problem (plan_theoretical), continuous planned here
    # on the problem handed over (its knots, path dynamics and torques at rest not built again)
    receiver = PressModel(press)
    there, problem = unpack_plan(compare.plan_theoretical(pm, job, auto, modes=("stop-at-top", "pendulum")), receiver)
    assert problem.pm is receiver and problem.pd.pm is receiver and problem.rest
    clear_solvers()
    here = plan_modes(problem, names=("continuous",))
    parts = [here, there]
    apart = keep_fastest(auto, {**parts[0][0], **parts[1][0]}, {**parts[0][1], **parts[1][1]})
    assert apart.strokes_per_min == together.strokes_per_min and apart.spec.mode == together.spec.mode
    assert apart.modes == together.modes and list(apart.modes["modes"]) == list(together.modes["modes"])
