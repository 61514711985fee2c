#!/usr/bin/env python
"""Benchmark: the forward dynamics (RK4 + Baumgarte, Pinocchio's constrained dynamics and the compiled friction fixed
point per evaluation) and the playbacks built on it, per CPU target.

Prints, per target: the CPU microseconds of one `forward_dynamics` call (median over 52 perturbed cushion-test states,
best of --repeat passes), the CPU seconds of one cushion-test turn played back as `simulate` does, and with
--door-panel of the shipped door-panel plan played back as `plan --verify` does (`planning.playback.play_back`; the
plan itself is not counted); best and median of --repeat, after one run that compiles or loads the compiled loops.
--against TREE: another checkout (a git worktree of an older commit) and this one in alternating pairs, each run a
fresh process of this script with PYTHONPATH at the tree (the script reads only functions both trees have).

Usage: python scripts/bench_forward.py [--repeat 3] [--cpu avx2,host] [--door-panel] [--against TREE [--pairs 3]]
"""
import argparse
import math
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
import cpu_targets  # noqa: E402 (scripts/ beside this file)


def cpu_seconds(fn, repeat):
    """(best, median) CPU seconds of ``repeat`` calls of ``fn``."""
    times = []
    for _ in range(repeat):
        t0 = time.process_time()
        fn()
        times.append(time.process_time() - t0)
    return min(times), statistics.median(times)


def per_call_us(repeat):
    """CPU us of one forward_dynamics call at 52 perturbed cushion-test states (best of ``repeat`` passes of 10 rounds)."""
    import numpy as np

    from press_model.dynamics import slide_loads
    from press_model.forward import ForwardModel, ForwardWorkspace, forward_dynamics
    from press_model.jobs import load_job
    from press_model.kinematics import state_at
    from press_model.model import PressModel, Workspace
    from press_model.press_data import load_press

    pm = PressModel(load_press())
    loads = slide_loads(pm, load_job("cushion-test").process)
    ws, rng = Workspace(pm), np.random.default_rng(3)
    states = []
    for deg in range(0, 360, 7):
        st = state_at(pm, ws, math.radians(deg), rng.uniform(0.3, 3.0), rng.uniform(-20, 20))
        states.append((st.q + rng.normal(0, 1e-6, len(st.q)), st.v, rng.uniform(-20000, 20000)))
    fm = ForwardModel(pm)
    fws = ForwardWorkspace(fm)

    def rounds():
        for _ in range(10):
            for q, v, tm in states:
                forward_dynamics(fm, fws, q, v, tm, loads)

    rounds()  # compiles or loads the compiled loops
    best, median = cpu_seconds(rounds, repeat)
    return best / (10 * len(states)) * 1e6, median / (10 * len(states)) * 1e6


def cushion_turn(repeat):
    from press_model.cycle import simulate_cycle
    from press_model.jobs import load_job, make_motion
    from press_model.model import PressModel
    from press_model.press_data import load_press
    from servo_press.simulate import playback

    pm = PressModel(load_press())
    job = load_job("cushion-test")
    motion = make_motion(job.motion, job.source)
    cycle = simulate_cycle(pm, motion, job.process)
    cols, _ = playback(pm, cycle, motion, job.process)  # compiles (or loads) the compiled loops: not counted
    return len(cols["time_s"]) - 1, cpu_seconds(lambda: playback(pm, cycle, motion, job.process), repeat)


def door_panel(repeat):
    from planning.planner import StrokeProblem, plan_stroke
    from planning.playback import play_back
    from planning.settings import read_planning
    from press_model.jobs import load_job
    from press_model.model import PressModel
    from press_model.press_data import load_press

    pm = PressModel(load_press())
    job = load_job("door-panel")
    spec = read_planning(job)
    plan = plan_stroke(StrokeProblem.build(pm, job.process, spec))
    cols, _ = play_back(pm, job, spec, plan)  # not counted
    return len(cols["time_s"]) - 1, cpu_seconds(lambda: play_back(pm, job, spec, plan), repeat)


def measure(args):
    us = per_call_us(args.repeat)
    print(f"forward_dynamics: {us[0]:.1f} us CPU per call best, {us[1]:.1f} median (52 cushion-test states)", flush=True)
    steps, (best, median) = cushion_turn(args.repeat)
    print(f"one cushion-test turn played back ({steps} RK4 steps): CPU best {best:.3f} s, median {median:.3f} s "
          f"({args.repeat} runs)", flush=True)
    if args.door_panel:
        steps, (best, median) = door_panel(args.repeat)
        print(f"the door-panel plan played back ({steps} RK4 steps): CPU best {best:.3f} s, median {median:.3f} s "
              f"({args.repeat} runs)", flush=True)


def against(args):
    """Alternating pairs: the other tree's run, then this checkout's, each a fresh process for one target."""
    trees = {"other": Path(args.against).resolve(), "this": Path(__file__).resolve().parent.parent}
    argv = [sys.executable, str(Path(__file__).resolve()), "--repeat", str(args.repeat), "--cpu", args.cpu]
    argv += ["--door-panel"] if args.door_panel else []
    for i in range(1, args.pairs + 1):
        for name, tree in trees.items():
            print(f"-- pair {i}, {name} ({tree}), load average {os.getloadavg()[0]:.1f}", flush=True)
            subprocess.run(argv, env={**os.environ, "PYTHONPATH": str(tree)}, check=True)


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--door-panel", action="store_true", help="also play back the shipped door-panel plan (planned first, ~15 s)")
    ap.add_argument("--against", metavar="TREE", help="another checkout: it and this one in alternating pairs")
    ap.add_argument("--pairs", type=int, default=3, help="pairs with --against (default 3)")
    cpu_targets.add_cpu_argument(ap)
    args = ap.parse_args()
    if args.against:
        return against(args)
    if cpu_targets.current() is None:
        sys.exit(cpu_targets.run_per_target(args.cpu))
    measure(args)


if __name__ == "__main__":
    main()
