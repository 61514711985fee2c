"""The door panel's stroke under the grid limit by both formulations on refined knots: the jerk-limited stage
(planning/optimal.py with its grid rows) and toppra with the grid power as its own constraint (planning/power.py),
the jerk limit lifted in both (the time optimum under the grid limit is the quantity compared), on the shipped knots and
on knots graded toward the stroke's rest ends (planning/grid.graded_ends), then the shipped jerk-limited plan under the
same limit on the same knots. Prints one line per grid: knots, both stroke times and their difference (%), wall times.

    python scripts/grid_limit_convergence.py [--grids 1:0,1:3,1:6,1:9,1:12,0.5:0,0.5:12,0.25:14] [--fraction 0.6]

Each grid is STEP_DEG:LEVELS (uniform step in degrees, end segments halved LEVELS times). The figures it printed are in
docs/validation.md ("Planning within the supply")."""
from __future__ import annotations

import argparse
import dataclasses
import math
import time

import numpy as np

from planning.energy import plan_energy
from planning.grid import graded_ends, planning_grid
from planning.path_dynamics import build_path_dynamics
from planning.planner import GRID_BACKOFF, StrokeProblem, plan_stroke, planning_limit
from planning.power import PowerLimit
from planning.power import toppra_under_grid_limit
from planning.profile import sample_plan
from planning.settings import read_planning
from press_model.jobs import load_job
from press_model.model import PressModel
from press_model.press_data import load_press

FREE_JERK = 1.0e5  # rad/s^3: too high to bind, the stage then solves the jerk-free problem toppra solves


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--grids", default="1:0,1:3,1:6,1:9,1:12,0.5:0,0.5:12,0.25:14")
    ap.add_argument("--fraction", type=float, default=0.6, help="the grid limit as a share of the free plan's grid peak")
    ap.add_argument("--shipped-jerk", default="1:0,1:9,0.5:12", help="grids for the shipped jerk-limited plan under the limit")
    args = ap.parse_args()
    pm, job = PressModel(load_press()), load_job("door-panel")
    spec = read_planning(job)
    free = plan_stroke(StrokeProblem.build(pm, job.process, spec))
    _, en = plan_energy(pm, job.process, sample_plan(free, pm.press.drive.gear_ratio))
    limit = args.fraction * en["grid_peak_W"]
    print(f"free plan: stroke {free.stroke_time:.5f} s, grid peak {en['grid_peak_W'] / 1e6:.4f} MW; limit {limit / 1e6:.4f} MW")
    lifted = dataclasses.replace(spec, crank_jerk=FREE_JERK)

    def knots(item: str):
        step, levels = item.split(":")
        g = planning_grid(pm, job.process, dataclasses.replace(spec, grid_step=math.radians(float(step))))
        g = graded_ends(g, int(levels)) if int(levels) else g
        return g, build_path_dynamics(pm, g.theta, job.process, g.contact_index)

    print("step_deg:levels  knots  stage_s  toppra_s  difference_%  stage_wall_s  toppra_wall_s")
    for item in args.grids.split(","):
        g, pd = knots(item)
        still = np.zeros(pd.n, bool)
        still[0] = still[-1] = True
        t0 = time.perf_counter()
        stage = plan_stroke(StrokeProblem(pm, job.process, lifted, g, pd), power=PowerLimit(grid_peak_limit_W=limit))
        t1 = time.perf_counter()
        second = toppra_under_grid_limit(pm, g, pd, lifted, planning_limit(pm, lifted), limit * (1.0 - GRID_BACKOFF), still)
        t2 = time.perf_counter()
        print(f"{item:>8}  {pd.n:5d}  {stage.stroke_time:.5f}  {second.stroke_time:.5f}  "
              f"{100.0 * (stage.stroke_time / second.stroke_time - 1.0):+.3f}  {t1 - t0:.1f}  {t2 - t1:.1f}  {stage.optimiser.get('status')}",
              flush=True)
    for item in args.shipped_jerk.split(","):
        g, pd = knots(item)
        plan = plan_stroke(StrokeProblem(pm, job.process, spec, g, pd), power=PowerLimit(grid_peak_limit_W=limit))
        print(f"shipped jerk limit {spec.crank_jerk:g} rad/s^3, {item}: stroke {plan.stroke_time:.5f} s", flush=True)


if __name__ == "__main__":
    main()
