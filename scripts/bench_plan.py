#!/usr/bin/env python
"""Benchmark of planning (targets on 2 cores): one plan <= 3 s, `plan --verify` <= 6 s, `compare` with playback and
the robust row <= 20 s, continuous mode <= 3 s (the jerk-limited optimum, planning/optimal.py); from a calibration
(a SYNTHETIC log made and calibrated first, seed ``CAL_SEED``): `plan --params calibrated.json` (the robust default)
<= 5 s, `compare --calibrated calibrated.json` <= 20 s.

One plan and continuous mode are timed in-process (grid + path dynamics + toppra friction fixed point + the
jerk-limited optimum with its friction fixed point + re-check + thermal check); the robust plan in-process too
(17 members in the optimum's torque rows); `plan --verify` and `compare` as fresh `servo-press` processes (imports,
outputs and figures included). Each is run ``--repeat`` times; printed: min, median and max wall time, the least
CPU time (user + system; of a command, its process and the figure worker it forks), and the load average (the
machine may be shared: the minimum is the figure to compare, the spread says how loaded it was; the CPU time
moves less with the load than the wall time).
Usage: python scripts/bench_plan.py [--repeat 3] [--skip-cli]
"""
import argparse
import dataclasses
import json
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time

from planning.modes import plan_in_mode
from planning.planner import StrokeProblem
from planning.settings import read_planning
from press_model.jobs import load_job
from press_model.model import PressModel
from press_model.params import apply_overrides
from press_model.press_data import load_press

TABLE4 = {"eta_gear": 0.842, "psi": 1.06, "mu_r": 0.012, "m8": 32940, "J_gear": 60.6, "mu_s": 0.085}
# a box of calibrated.json's shape around Table 4 (for the robust row of compare)
INTERVALS = {"eta_gear": [0.83, 0.854], "psi": [1.04, 1.08], "mu_r": [0.010, 0.014], "m8": [32000.0, 33900.0],
             "J_gear": [58.0, 63.0], "mu_s": [0.07, 0.10]}
# a SYNTHETIC calibration to plan from (`experiment` then `calibrate`): seed and truth fixed, the truth in the middle of
# the six ranges; its all-corner check adds one corner to the robust plan (the re-solve after a cut is timed too)
CAL_SEED = 101
CAL_TRUTH = {"eta_gear": 0.88, "psi": 1.05, "mu_r": 0.02, "m8": 33500.0, "J_gear": 57.0, "mu_s": 0.08}
TARGETS = {"one plan": 3.0, "one plan, Table 4 parameters": 3.0, "continuous mode": 3.0, "plan --verify": 6.0,
           "compare with playback": 20.0, "compare with playback and robust row": 20.0,
           "robust plan from a SYNTHETIC calibration (in-process)": 5.0,
           "plan --params calibrated.json (robust default)": 5.0, "compare --calibrated calibrated.json": 20.0}


def report(label, walls, cpus=None, extra=""):
    cpu = f", CPU min {min(cpus):.2f} s" if cpus else ""
    print(f"{label}: min {min(walls):.2f} s, median {statistics.median(walls):.2f} s, max {max(walls):.2f} s "
          f"({len(walls)} runs{cpu}; target {TARGETS.get(label, float('nan')):g} s){extra}", flush=True)


def in_process(label, pm, job, spec, repeat):
    walls, cpus = [], []
    for _ in range(repeat):
        t0, c0 = time.perf_counter(), time.process_time()
        plan = plan_in_mode(StrokeProblem.build(pm, job.process, spec))
        walls.append(time.perf_counter() - t0)
        cpus.append(time.process_time() - c0)
    opt = plan.optimiser
    report(label, walls, cpus, f"; {plan.strokes_per_min:.3f} spm (stroke {plan.stroke_time:.4f} s, jerk-free bound "
                               f"{plan.jerk_free_stroke_time:.4f} s), {plan.friction_iterations} toppra re-solves, "
                               f"IPOPT iterations {opt.get('ipopt_iterations')}, {plan.recheck_rounds} re-check rounds")


def robust(label, pm, job, spec, repeat):
    from planning.robust import Box, plan_robust

    box = Box.from_calibration(pm.press, TABLE4, INTERVALS, "bench", "per-parameter intervals")
    walls, cpus = [], []
    for _ in range(repeat):
        t0, c0 = time.perf_counter(), time.process_time()
        res = plan_robust(pm, job.process, spec, box)
        walls.append(time.perf_counter() - t0)
        cpus.append(time.process_time() - c0)
    report(label, walls, cpus, f"; {res.plan.strokes_per_min:.3f} spm robust against {res.nominal.strokes_per_min:.3f} nominal, "
                               f"{len(res.members)} members, IPOPT iterations {res.plan.optimiser.get('ipopt_iterations')}")


def synthetic_calibration(tmp: str) -> str:
    """calibrated.json of a SYNTHETIC cushion-test log (``CAL_SEED``, ``CAL_TRUTH``), made and calibrated by the CLI."""
    log = os.path.join(tmp, "log.csv")
    for argv in (["experiment", "--seed", str(CAL_SEED), "--truth", json.dumps(CAL_TRUTH), "--out", log],
                 ["calibrate", "--log", log, "--out", os.path.join(tmp, "cal")]):
        res = subprocess.run(["servo-press", *argv], capture_output=True, text=True)
        if res.returncode:
            raise SystemExit(f"servo-press {' '.join(argv)} failed ({res.returncode}):\n{res.stderr}")
    return os.path.join(tmp, "cal", "calibrated.json")


def robust_from_calibration(label, job, spec, cal, repeat):
    """The robust plan `plan --params` makes (no nominal plan: its rate estimated), in-process."""
    from planning.robust import Box, plan_robust
    from press_model.params import joint_box_of, overrides_of, read_json

    press = load_press()
    doc = read_json(cal, press)
    pm = PressModel(apply_overrides(press, overrides_of(doc)))
    center, intervals, kind = joint_box_of(doc, required=True)
    box = Box.from_calibration(pm.press, center, intervals, cal, kind)
    walls, cpus = [], []
    for _ in range(repeat):
        t0, c0 = time.perf_counter(), time.process_time()
        res = plan_robust(pm, job.process, spec, box, plan_nominal=False)
        walls.append(time.perf_counter() - t0)
        cpus.append(time.process_time() - c0)
    report(label, walls, cpus, f"; {res.plan.strokes_per_min:.4f} spm (stroke {res.plan.stroke_time:.7f} s), {len(res.members)} members, "
                               f"{res.cuts} corner(s) added, per segment {res.per_segment}, IPOPT iterations "
                               f"{res.plan.optimiser.get('ipopt_iterations')}")


def _children_cpu() -> float:
    """User + system seconds of the finished child processes (theirs and their own children's, e.g. a figure worker)."""
    ru = resource.getrusage(resource.RUSAGE_CHILDREN)
    return ru.ru_utime + ru.ru_stime


def cli(label, argv, repeat):
    walls, cpus = [], []
    for _ in range(repeat):
        out = tempfile.mkdtemp(prefix="bench_plan_")
        t0, c0 = time.perf_counter(), _children_cpu()
        res = subprocess.run(["servo-press", *argv, "--out", os.path.join(out, "o")], capture_output=True, text=True)
        walls.append(time.perf_counter() - t0)
        cpus.append(_children_cpu() - c0)
        if res.returncode not in (0, 3):
            print(res.stderr, file=sys.stderr)
            raise SystemExit(f"servo-press {' '.join(argv)} failed with exit code {res.returncode}")
    verdict = next((ln for ln in res.stdout.splitlines() if ln.startswith("VERIFY")), "")
    phases = "; ".join(ln.split("] ", 1)[1] for ln in res.stderr.splitlines() if ln.startswith("["))
    report(label, walls, cpus, f"\n    last run's phases: {phases}\n    {verdict}")


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--skip-cli", action="store_true", help="only the in-process timings")
    args = ap.parse_args()
    print(f"load average at start: {os.getloadavg()[0]:.2f} (1 min) on {os.cpu_count()} cores", flush=True)
    press = load_press()
    pm = PressModel(press)
    job = load_job("door-panel")
    spec = read_planning(job)
    in_process("one plan", pm, job, spec, args.repeat)
    in_process("one plan, Table 4 parameters", PressModel(apply_overrides(press, TABLE4)), job, spec, args.repeat)
    in_process("continuous mode", pm, job, dataclasses.replace(spec, mode="continuous", dwell=0.0, transfer=None), args.repeat)  # the transfer window is a stop-at-top matter (continuous rotation cannot meet the door panel's)
    robust("robust plan over the Table 4 box (with its nominal plan)", PressModel(apply_overrides(press, TABLE4)), job, spec, args.repeat)
    synthetic = synthetic_calibration(tempfile.mkdtemp(prefix="bench_plan_synthetic_"))
    robust_from_calibration("robust plan from a SYNTHETIC calibration (in-process)", job, spec, synthetic, args.repeat)
    if not args.skip_cli:
        cli("plan --params calibrated.json (robust default)", ["plan", "--params", synthetic], args.repeat)
        cli("compare --calibrated calibrated.json", ["compare", "--calibrated", synthetic], args.repeat)
        tmp = tempfile.mkdtemp(prefix="bench_plan_cal_")
        cal = os.path.join(tmp, "calibrated.json")
        with open(cal, "w") as fh:
            json.dump({"parameters": TABLE4}, fh)
        cal_box = os.path.join(tmp, "calibrated_box.json")
        with open(cal_box, "w") as fh:
            json.dump({"parameters": TABLE4, "intervals": INTERVALS}, fh)
        cli("plan --verify", ["plan", "--verify"], args.repeat)
        cli("compare with playback", ["compare", "--calibrated", cal], args.repeat)
        cli("compare with playback and robust row", ["compare", "--calibrated", cal_box], args.repeat)
    print(f"load average at end: {os.getloadavg()[0]:.2f} (1 min)")


if __name__ == "__main__":
    main()
