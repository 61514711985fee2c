#!/usr/bin/env python
"""Benchmark: the per-point Pinocchio path, microseconds of CPU per point of `state_at` (positions by Newton, velocities,
accelerations) and of `inverse_dynamics` (RNEA, reactions, the friction fixed point) on the cushion test's 0.25-deg grid
of the reference press (1,440 points, warm-started point to point as a synthetic log's torque table is).

Prints the best and the median of several passes, after one that compiles or loads the numba loops (not counted).
It reads only those two public functions, so the same script times an older tree: PYTHONPATH=OLD_TREE python
scripts/bench_point.py. Usage: python scripts/bench_point.py [--repeat 5] [--press reference|crank-slider|FILE]
"""
import argparse
import math
import statistics
import time


def main():
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--press", default=None)
    args = ap.parse_args()

    import numpy as np

    from press_model.dynamics import inverse_dynamics, slide_loads
    from press_model.jobs import load_job, make_motion
    from press_model.kinematics import state_at
    from press_model.model import PressModel, Workspace
    from press_model.press_data import load_press

    pm = PressModel(load_press(args.press))
    job = load_job("cushion-test")
    motion = make_motion(job.motion, job.source)
    theta = np.arange(1440) * (2.0 * math.pi / 1440)
    points = list(zip(theta.tolist(), motion.theta_dot(theta).tolist(), motion.theta_ddot(theta).tolist()))
    loads = slide_loads(pm, job.process)

    def kinematics():
        ws = Workspace(pm)
        return [state_at(pm, ws, *p) for p in points]

    states = kinematics()

    def dynamics():
        ws = Workspace(pm)
        return [inverse_dynamics(pm, ws, st, loads) for st in states]

    dynamics()
    for name, fn in (("state_at", kinematics), ("inverse_dynamics", dynamics)):
        times = []
        for _ in range(args.repeat):
            t0 = time.process_time()
            fn()
            times.append((time.process_time() - t0) / len(points) * 1e6)
        print(f"{name}: CPU best {min(times):.0f} us a point, median {statistics.median(times):.0f} us "
              f"({args.repeat} passes of {len(points)} points, {pm.press.name})", flush=True)


if __name__ == "__main__":
    main()
