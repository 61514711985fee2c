#!/usr/bin/env python
"""How the door-panel job's transfer dwell was found: the dwell that makes the theoretical plan give 11.4 spm.

The reference page fixes the production rate of the plan made with the theoretical (nominal) parameters at
the paper's 11.4 strokes per minute; the dwell is what is left of 60 / 11.4 s after the time-optimal stroke.
The stroke depends on the dwell only through the thermal limit (the RMS includes the dwell), so the
fixed-point iteration dwell <- 60 / spm - stroke_time(dwell) is run until the dwell stops changing (it
takes one step when the thermal limit does not bind).

Usage:  python scripts/find_dwell.py [--job door-panel] [--press FILE] [--spm 11.4] [--digits 4]
Prints each iteration and the value (rounded to --digits decimals of a second) to write as
[planning] dwell_s in the job file, with the production rate that rounded value gives.
"""
from __future__ import annotations

import argparse
import sys

from planning.path_dynamics import build_path_dynamics
from planning.grid import planning_grid
from planning.modes import plan_in_mode
from planning.planner import StrokeProblem
from planning.settings import read_planning
from press_io.errors import ServoPressError
from press_model.jobs import load_job
from press_model.model import PressModel
from press_model.press_data import load_press


def find_dwell(pm, job, spec, spm: float, tol_s: float = 1e-9, max_iter: int = 50):
    """Dwell (s) with 60 / (stroke_time(dwell) + dwell) = spm, and the iterations [(dwell, stroke_time, thermal binding)]."""
    grid = planning_grid(pm, job.process, spec)
    pd = build_path_dynamics(pm, grid.theta, job.process, grid.contact_index)
    dwell, history = 0.0, []
    for _ in range(max_iter):
        plan = plan_in_mode(StrokeProblem(pm, job.process, spec, grid, pd), dwell=dwell)
        history.append((dwell, plan.stroke_time, plan.thermal_binding))
        new = 60.0 / spm - plan.stroke_time
        if new < 0:
            raise ServoPressError(f"the time-optimal stroke alone takes {plan.stroke_time:.4f} s, longer than 60/{spm:g} s: no dwell reaches {spm:g} spm")
        if abs(new - dwell) < tol_s:
            return new, history
        dwell = new
    raise ServoPressError(f"the dwell iteration did not settle in {max_iter} steps (last {history[-3:]})")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--job", default="door-panel")
    ap.add_argument("--press", default=None)
    ap.add_argument("--spm", type=float, default=11.4, help="target strokes per minute of the theoretical plan (default 11.4)")
    ap.add_argument("--digits", type=int, default=4, help="decimals of a second to record (default 4: 0.1 ms)")
    a = ap.parse_args(argv)
    try:
        job = load_job(a.job)
        spec = read_planning(job)
        pm = PressModel(load_press(a.press))
        dwell, history = find_dwell(pm, job, spec, a.spm)
        for k, (d, ts, th) in enumerate(history):
            print(f"iteration {k}: dwell {d:.9f} s -> stroke {ts:.9f} s, thermal limit {'binding' if th else 'not binding'}")
        rounded = round(dwell, a.digits)
        plan = plan_in_mode(StrokeProblem.build(pm, job.process, spec), dwell=rounded)
        print(f"dwell = {dwell:.9f} s; record dwell_s = {rounded:.{a.digits}f} -> {plan.strokes_per_min:.6f} spm "
              f"(stroke {plan.stroke_time:.6f} s, cycle RMS {plan.rms_torque:.1f} N m)")
    except ServoPressError as exc:
        print(f"find_dwell: error: {exc}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
