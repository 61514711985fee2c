"""The limits declared once (planning/limits.py): each limit's toppra face and its IPOPT face state the same bound, taken
from the press file and the job, and holding the limits over a region changes nothing but the members they hold for."""
import dataclasses

import numpy as np
import pytest

from planning.evaluation import Member
from planning.limits import Limits, Region, ToppraPoint


@pytest.fixture(scope="module")
def stage(door_panel_plan):
    """The shipped plan's jerk-limited stage: its limits and the collocation problem it solved."""
    assert door_panel_plan.stage is not None and door_panel_plan.stage.problem is not None
    return door_panel_plan.stage


def test_each_limit_yields_its_toppra_constraints_and_toppra_knows_no_jerk_rms_or_grid(stage, door_panel_plan):
    limits = stage.limits
    names = [item.name for item in limits.items]
    assert names == ["motor_torque", "motor_speed", "forming_slide_speed", "crank_jerk", "thermal_rms"]  # no grid limit in the job
    pd = door_panel_plan.pd
    zero = [(np.zeros(pd.n), np.zeros(pd.n))] * len(stage.members)
    level = door_panel_plan.torque_level
    cons = limits.toppra(ToppraPoint(stage.members, level, zero))
    assert [c.name for c in cons] == ["motor_torque", "motor_speed", "forming_slide_speed"]
    *_, F, h, _, _ = cons[0].compute_constraint_params(None, limits.theta)
    assert np.all(h == level)  # the torque rows' bound is the level they are built for


def test_speed_and_window_bounds_agree_between_toppra_and_the_collocation(stage, door_panel_plan):
    """Both faces against the press file's motor speed over the gear ratio and the job's forming speed over |dH/dtheta|."""
    press, spec, pd = door_panel_plan.pd.pm.press, door_panel_plan.spec, door_panel_plan.pd
    limits, problem = stage.limits, stage.problem
    w_max = press.motor.max_speed / press.drive.gear_ratio
    cons = limits.toppra(ToppraPoint(stage.members, door_panel_plan.torque_level, [(np.zeros(pd.n), np.zeros(pd.n))] * len(stage.members)))
    x_speed = cons[1].compute_constraint_params(None, limits.theta)[-1][:, 1]
    moving = ~limits.standstill
    assert np.allclose(x_speed[moving], w_max**2, rtol=1e-12)
    assert np.allclose(problem.speed_ub[np.isfinite(problem.speed_ub)] * problem.w_ref, w_max, rtol=1e-12)  # the collocation's rows
    x_win = cons[2].compute_constraint_params(None, limits.theta)[-1][:, 1]
    win = door_panel_plan.grid.in_window & (np.abs(pd.dh) > 0)
    assert win.any() and np.allclose(x_win[win], (spec.forming_speed / np.abs(pd.dh[win])) ** 2, rtol=1e-12)
    assert np.all(x_win[~win] > 1e11)  # no limit outside the window


def test_over_a_region_changes_only_the_members_held_for(stage, door_panel_plan):
    limits = stage.limits
    pd, press = door_panel_plan.pd, door_panel_plan.pd.pm.press
    region = Region([Member(pd, press.drive, press.friction), Member(pd, dataclasses.replace(press.drive, efficiency=0.8), press.friction)],
                    worst_case=[("motoring", [0, 1])])
    held = limits.over(region)
    assert held.region is region
    assert all(getattr(held, f.name) is getattr(limits, f.name) for f in dataclasses.fields(Limits) if f.name != "region")
    assert [i.name for i in held.items] == [i.name for i in limits.items]
    assert held.region.worst(limits.theta, limits.standstill).groups == [("motoring", [0, 1])]
