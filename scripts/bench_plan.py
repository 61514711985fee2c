#!/usr/bin/env python
"""Benchmark: one door-panel plan (grid + path dynamics + toppra friction fixed point + re-check + thermal check).

Prints seconds per plan (best and median of several runs; target <= 2 s), the split between the per-knot
precomputation (Pinocchio kinematics and RNEA at every knot) and the planning loops, the number of
toppra re-solves, and the same for continuous mode and for the calibrated parameters (paper Table 4).
Usage: python scripts/bench_plan.py [--repeat 5]
"""
import argparse
import dataclasses
import statistics
import time

from planning.path_dynamics import build_path_dynamics
from planning.planner import plan_stroke, planning_grid
from press_model.jobs import load_job, read_planning
from press_model.model import PressModel
from press_model.params import apply_overrides
from press_model.press_data import load_press

TABLE4 = {"eta_gear": 0.842, "psi": 1.06, "mu_r": 0.012, "m8": 32940, "J_gear": 60.6, "mu_s": 0.085}


def bench(label, pm, job, spec, repeat):
    whole, pre, loops = [], [], []
    for _ in range(repeat):
        t0 = time.perf_counter()
        grid = planning_grid(pm, job.process, spec)
        pd = build_path_dynamics(pm, grid.theta, job.process, grid.contact_index)
        t1 = time.perf_counter()
        plan = plan_stroke(pm, job.process, spec, pd=pd, grid=grid)
        t2 = time.perf_counter()
        whole.append(t2 - t0)
        pre.append(t1 - t0)
        loops.append(t2 - t1)
    print(f"{label}: one plan best {min(whole):.3f} s, median {statistics.median(whole):.3f} s ({repeat} runs; "
          f"precompute {min(pre):.3f} s for {pd.n} knots, planning loops {min(loops):.3f} s, "
          f"{plan.friction_iterations} toppra re-solves); {plan.strokes_per_min:.3f} spm")


def main():
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--repeat", type=int, default=5)
    args = ap.parse_args()
    t0 = time.perf_counter()
    press = load_press()
    pm = PressModel(press)
    print(f"press model build incl. full-turn assembly check (not part of a plan): {time.perf_counter() - t0:.3f} s")
    job = load_job("door-panel")
    spec = read_planning(job)
    bench("stop-at-top, nominal", pm, job, spec, args.repeat)
    bench("stop-at-top, Table 4 parameters", PressModel(apply_overrides(press, TABLE4)), job, spec, args.repeat)
    bench("continuous, nominal", pm, job, dataclasses.replace(spec, mode="continuous", dwell=0.0), args.repeat)


if __name__ == "__main__":
    main()
