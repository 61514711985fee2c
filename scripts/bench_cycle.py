#!/usr/bin/env python
"""Benchmark: one 360-point cushion-test cycle with friction (kinematics + inverse dynamics + fixed point).

Prints the model build time, the per-cycle time (best and median of several runs) and the mean
friction iterations per point. Usage: python scripts/bench_cycle.py [--repeat 7]
"""
import argparse
import statistics
import time

from press_model.cycle import simulate_cycle
from press_model.jobs import load_job, make_motion
from press_model.model import PressModel
from press_model.press_data import load_press


def main():
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--repeat", type=int, default=7)
    args = ap.parse_args()
    t0 = time.perf_counter()
    pm = PressModel(load_press())
    build = time.perf_counter() - t0
    job = load_job("cushion-test")
    motion = make_motion(job.motion, job.source)
    times = []
    for _ in range(args.repeat):
        t0 = time.perf_counter()
        cycle = simulate_cycle(pm, motion, job.process)
        times.append(time.perf_counter() - t0)
    print(f"model build incl. full-turn assembly check: {build:.3f} s")
    print(f"one 360-point cycle with friction: best {min(times) * 1e3:.1f} ms, median {statistics.median(times) * 1e3:.1f} ms "
          f"({args.repeat} runs), {min(times) / 360 * 1e6:.0f} us per point")
    print(f"friction fixed point: mean {cycle.iterations.mean():.1f}, max {cycle.iterations.max()} iterations per point")


if __name__ == "__main__":
    main()
