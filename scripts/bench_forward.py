#!/usr/bin/env python
"""Benchmark: the forward-dynamics playback of one cushion-test turn (`simulate`'s and the planners' playback: RK4 +
Baumgarte, Pinocchio's constrained dynamics and the compiled friction fixed point per evaluation), per CPU target.

Prints, per target, the CPU seconds of one playback (best and median of several, after one that compiles or loads
the friction loop) and the RK4 steps. Usage: python scripts/bench_forward.py [--repeat 3] [--cpu avx2,host]
"""
import argparse
import statistics
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
import cpu_targets  # noqa: E402 (scripts/ beside this file)


def main():
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--repeat", type=int, default=3)
    cpu_targets.add_cpu_argument(ap)
    args = ap.parse_args()
    if cpu_targets.current() is None:
        sys.exit(cpu_targets.run_per_target(args.cpu))

    from press_model.cycle import simulate_cycle
    from press_model.jobs import load_job, make_motion
    from press_model.model import PressModel
    from press_model.press_data import load_press
    from servo_press.simulate import playback

    pm = PressModel(load_press())
    job = load_job("cushion-test")
    motion = make_motion(job.motion, job.source)
    cycle = simulate_cycle(pm, motion, job.process)
    cols, _ = playback(pm, cycle, motion, job.process)  # compiles (or loads) the friction loop: not counted
    times = []
    for _ in range(args.repeat):
        t0 = time.process_time()
        playback(pm, cycle, motion, job.process)
        times.append(time.process_time() - t0)
    print(f"one cushion-test turn played back ({len(cols['time_s']) - 1} RK4 steps): CPU best {min(times):.2f} s, "
          f"median {statistics.median(times):.2f} s ({args.repeat} runs)", flush=True)


if __name__ == "__main__":
    main()
