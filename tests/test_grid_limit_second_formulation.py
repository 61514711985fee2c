"""The jerk-limited stage's grid rows (planning/optimal.GridRow, Eq. 16's smooth form at knots and checks) against a
second formulation of the same limit: toppra with the grid power as its own constraint object (planning/power.py:
an exact torque bound at each speed, its tangent re-taken at the solution; toppra's discretisation).

Compared where the two solve the same problem: the door panel as a continuous stroke (no rest at the ends, where the
stage's cubic from standstill and toppra's constant acceleration differ by design) with a jerk limit too high to bind,
at 60 % of the free plan's grid peak; and the shipped stop-at-top door panel at 60 % of its own free grid peak with the
jerk limit lifted in both, on knots graded toward the rest ends (planning/grid.graded_ends), where both have converged.
The door panel's plan with its jerk limit has toppra's stroke under the same grid limit as a lower bound (on 5-degree
knots: a bound on any knots)."""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from planning.evaluation import Member, evaluate_members
from planning.energy import plan_energy
from planning.grid import graded_ends
from planning.path_dynamics import build_path_dynamics
from planning.planner import StrokeProblem, GRID_BACKOFF, plan_stroke, planning_limit
from planning.power import PowerLimit, grid_bound_coefficients
from planning.power import toppra_under_grid_limit
from planning.profile import sample_plan
from planning.settings import read_planning

JOB = "door-panel"
FREE_JERK = 1.0e5  # rad/s^3, 300 x the job's: the stage then solves the jerk-free problem toppra solves
AGREE = 0.005  # the issue's bound on the two stroke times' relative difference
GRADED_LEVELS = 9  # the end segments halved this often: 0.002 degree at the rest ends
COST_AGREE = 0.05  # the stroke time the limit adds, relative: a grid row 5 % off in power moves it by ~10 %


def _toppra_grid_peak(pm, pd, prof) -> float:
    """The largest grid power (W) at the knots of toppra's profile, both sides, on the full model."""
    press = pm.press
    ev = evaluate_members(pm, [Member(pd, press.drive, press.friction)], prof)[0]
    a, b, c, k = grid_bound_coefficients(press.electrical, press.drive.motors)
    w = press.drive.gear_ratio * np.asarray(prof.sd)
    return max(float(np.max(k * (t * w + a * t * t + b * w + c * w * w))) for t in (ev.motor_right, ev.motor_left))


@pytest.fixture(scope="module")
def continuous(ref_model, job):
    spec = dataclasses.replace(read_planning(job), mode="continuous", crank_jerk=FREE_JERK, transfer=None)  # the transfer is a stop-at-top matter
    free = plan_stroke(StrokeProblem.build(ref_model, job.process, spec))
    _, en = plan_energy(ref_model, job.process, sample_plan(free, ref_model.press.drive.gear_ratio))
    return spec, free, 0.6 * en["grid_peak_W"]


def test_grid_limited_optimum_agrees_with_toppra_under_its_own_grid_power_constraint(ref_model, job, continuous):
    spec, free, limit = continuous
    stage = plan_stroke(StrokeProblem(ref_model, job.process, spec, free.grid, free.pd), power=PowerLimit(grid_peak_limit_W=limit))
    assert stage.optimiser["status"] == "Solve_Succeeded"
    rows_limit = limit * (1.0 - GRID_BACKOFF)  # what the stage's rows hold
    second = toppra_under_grid_limit(ref_model, free.grid, free.pd, spec, planning_limit(ref_model, spec), rows_limit,
                                     np.zeros(free.pd.n, bool))
    assert _toppra_grid_peak(ref_model, free.pd, second) <= rows_limit * (1.0 + 1e-6)
    assert second.stroke_time > free.jerk_free_stroke_time * 1.002  # the limit binds in the second formulation too
    assert stage.stroke_time == pytest.approx(second.stroke_time, rel=AGREE)
    # sharper: what the limit costs each formulation against its own free stroke (measured: 16.18 and 16.20 ms)
    cost_stage, cost_second = stage.stroke_time - free.stroke_time, second.stroke_time - free.jerk_free_stroke_time
    assert cost_stage == pytest.approx(cost_second, rel=COST_AGREE)


@pytest.fixture(scope="module")
def shipped(ref_model, job, door_panel_plan):
    """The shipped door panel (stop-at-top, jerk limit as shipped), its free plan and 60 % of that plan's grid peak (W)."""
    spec = read_planning(job)
    free = door_panel_plan  # conftest.py: planned once a session
    _, en = plan_energy(ref_model, job.process, sample_plan(free, ref_model.press.drive.gear_ratio))
    return spec, free, 0.6 * en["grid_peak_W"]


def _rest_ends(n: int) -> np.ndarray:
    still = np.zeros(n, bool)
    still[0] = still[-1] = True
    return still


@pytest.fixture(scope="module")
def coarse(ref_model, job, coarse_door_panel_plan):
    """``shipped`` on 5-degree knots (the coarsest a job may state), its free plan the suite's (fixtures_suiteplan.py)."""
    free = coarse_door_panel_plan
    _, en = plan_energy(ref_model, job.process, sample_plan(free, ref_model.press.drive.gear_ratio))
    return free.spec, free, 0.6 * en["grid_peak_W"]


def test_toppra_under_the_grid_limit_bounds_the_jerk_limited_plan_from_below(ref_model, job, coarse):
    """On 5-degree knots: toppra's jerk-free optimum under the grid limit is below the jerk-limited one on the same knots
    (the jerk limit's own cost, 0.117 s on the shipped knots) and above the free jerk-free stroke (the limit binds) on
    any knots."""
    spec, free, limit = coarse
    assert spec == dataclasses.replace(read_planning(job), grid_step=np.radians(5.0))
    bound = toppra_under_grid_limit(ref_model, free.grid, free.pd, spec, planning_limit(ref_model, spec), limit,
                                    _rest_ends(free.pd.n))
    limited = plan_stroke(StrokeProblem(ref_model, job.process, spec, free.grid, free.pd), power=PowerLimit(grid_peak_limit_W=limit))
    assert bound.stroke_time > free.jerk_free_stroke_time  # the grid limit costs the jerk-free stroke time as well
    assert bound.stroke_time < limited.stroke_time


def test_stop_at_top_door_panel_under_the_grid_limit_agrees_with_toppra_on_knots_graded_toward_the_rest_ends(ref_model, job, shipped):
    """The shipped stop-at-top door panel at 60 % of its free grid peak, the jerk limit lifted in both formulations: on
    the shipped 1-degree knots the stage's cubic from standstill and toppra's constant acceleration differ by 1.7 % (the
    first and last segments); with those halved 9 times both have converged there (docs/validation.md's study: they meet
    within 0.07 % on every graded grid from 1 to 0.25 degree) and must agree to the issue's 0.5 %. The shipped plan with
    its jerk limit takes longer under the same limit (the jerk limit's own cost, measured 0.117 s)."""
    spec, free, limit = shipped
    lifted = dataclasses.replace(spec, crank_jerk=FREE_JERK)
    grid = graded_ends(free.grid, GRADED_LEVELS)
    pd = build_path_dynamics(ref_model, grid.theta, job.process, grid.contact_index)
    stage = plan_stroke(StrokeProblem(ref_model, job.process, lifted, grid, pd), power=PowerLimit(grid_peak_limit_W=limit))
    assert stage.optimiser["status"] == "Solve_Succeeded"
    rows_limit = limit * (1.0 - GRID_BACKOFF)
    second = toppra_under_grid_limit(ref_model, grid, pd, lifted, planning_limit(ref_model, lifted), rows_limit, _rest_ends(pd.n))
    assert _toppra_grid_peak(ref_model, pd, second) <= rows_limit * (1.0 + 1e-6)
    assert second.stroke_time > stage.jerk_free_stroke_time * 1.002  # the limit binds in the second formulation
    assert stage.stroke_time == pytest.approx(second.stroke_time, rel=AGREE)
    shipped_limited = plan_stroke(StrokeProblem(ref_model, job.process, spec, grid, pd), power=PowerLimit(grid_peak_limit_W=limit))
    assert shipped_limited.stroke_time > stage.stroke_time + 0.05  # the jerk limit's extra time under the grid limit
