"""A point of `plan --pareto` whose plan fell back to toppra's jerk-free stroke (it breaks the jerk limit and is not
planned under the grid limit) is marked as not meeting its limit in pareto.csv and the summary, and the printed front
ends before it."""
from __future__ import annotations

import dataclasses
import math

from planning.energy import ParetoRow, _row
from planning.planner import StrokeProblem
from planning.power import PowerLimit
from planning.report import pareto_line, pareto_record
from planning.settings import read_planning
from press_model.jobs import load_job


def test_a_fallen_back_plan_is_never_within_its_limit(ref_model, door_panel_plan):
    """Even a limit far above what the stroke draws: a fallback breaks the jerk limit."""
    job = load_job("door-panel")
    fell = dataclasses.replace(door_panel_plan, optimiser={"status": "fallback", "fallback_reason": "IPOPT stopped"})
    row = _row(ref_model, job.process, fell, 1.0e9)
    assert row["grid_peak_W"] < 1.0e9 and row["within_limit"] == "NO" and row["optimiser"] == "fallback: IPOPT stopped"
    assert _row(ref_model, job.process, door_panel_plan, 1.0e9)["within_limit"] == "yes"


def test_a_pareto_row_at_an_unreachable_limit_is_marked_and_not_reported_as_met(ref_model, door_panel_plan):
    job = load_job("door-panel")
    spec = dataclasses.replace(read_planning(job), optimal_max_iterations=5)
    problem = StrokeProblem(ref_model, job.process, spec, door_panel_plan.grid, door_panel_plan.pd)
    free = _row(ref_model, job.process, door_panel_plan, 4.7e6)
    _, rec = ParetoRow(PowerLimit(), 0.05 * free["grid_peak_W"]).plan(problem, start=door_panel_plan.profile)
    row = rec["pareto_row"]
    assert row["within_limit"] == "NO"
    assert row["optimiser"].startswith(("fallback", "infeasible")) or row["grid_peak_W"] > row["grid_peak_limit_W"]
    summary = pareto_record([free, row])
    assert summary["within_limit"] == [True, False] and len(summary["not_met"]) == 1
    line = pareto_line(summary)
    # the front as printed ends at the free plan; the unreachable limit is named as NOT met with why
    assert f"to {free['grid_peak_limit_W'] / 1e6:.2f} MW ({free['strokes_per_min']:.3f} spm)" in line
    assert f"NOT met, the front ends there (down to {row['grid_peak_limit_W'] / 1e6:.2f} MW" in line
    assert not math.isnan(free["strokes_per_min"])
