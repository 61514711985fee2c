#!/usr/bin/env python
"""Benchmark: the full Sobol run of Section 3 (N = 2048, 28 parameters: 61,440 model cycles, four responses).

Target (issues 11, 25): `servo-press sensitivity --n 2048` end to end (process start to the last file) in at
most 5 s wall on a 2-core machine, AVX2 as well as AVX-512 (``--cpu``: one process per CPU target, see
scripts/cpu_targets.py), the batch kernel at most 0.1 ms per 360-point cycle amortised (scripts/bench_batch.py). Runs the command ``--repeat`` times in fresh processes (imports included, as a
user sees it) and prints the minimum and the spread of the wall time, with the CPU time (user + system) of
each run (the command and the processes it forks: SALib's, the analysis'): on a shared machine the wall time
swings with the other load, the CPU time much less. Then one in-process run prints the phases (setup: the
model, the batch model and the first kernel call, and any wait for the design from the SALib process;
evaluation; analysis). Each line starts with its CPU target.
Usage: python scripts/bench_sensitivity.py [--cpu avx2,host] [--n 2048] [--repeat 3] [--job cushion-test] [--out DIR]
"""
import argparse
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import cpu_targets

TARGET_S = 5.0


def _end_to_end(args, out: Path) -> tuple[float, float]:
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    subprocess.run([sys.executable, "-m", "servo_press.cli", "sensitivity", "--n", str(args.n), "--job", args.job,
                    "--out", str(out)], check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    return wall, (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--n", type=int, default=2048)
    ap.add_argument("--repeat", type=int, default=3, help="end-to-end runs in fresh processes (default 3)")
    ap.add_argument("--job", default="cushion-test")
    ap.add_argument("--out", default=None)
    cpu_targets.add_cpu_argument(ap)
    args = ap.parse_args()
    if cpu_targets.current() is None:
        return cpu_targets.run_per_target(args.cpu)
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(args.out or tmp)
        runs = [_end_to_end(args, out) for _ in range(args.repeat)]
        walls = [w for w, _ in runs]
        print(f"[{cpu_targets.current()}] servo-press sensitivity --n {args.n} --job {args.job}, end to end, {args.repeat} runs: wall min {min(walls):.2f} s, "
              f"max {max(walls):.2f} s (target <= {TARGET_S:g} s); CPU (user + sys) {', '.join(f'{c:.2f}' for _, c in runs)} s; "
              f"load average before the last run {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores")

        from calibration.sensitivity.report import load_case, run_sensitivity
        from press_model.model import PressModel
        from press_model.press_data import load_press

        t0 = time.perf_counter()
        pm = PressModel(load_press())
        t_model = time.perf_counter() - t0
        rec = run_sensitivity(pm, args.n, 0, False, out, progress=False, case=load_case(args.job))
    t = rec["timing_s"]
    print(f"[{cpu_targets.current()}] in-process phases: press model {t_model:.2f} s, batch setup {t['setup']:.2f} s, evaluation {t['evaluation']:.2f} s "
          f"({t['evaluation'] / rec['model_cycles'] * 1e3:.4f} ms per cycle incl. COM fits, Eq. 16 and responses), "
          f"SALib analysis {t['analysis']:.2f} s; {rec['model_cycles']} model cycles; key parameters: {', '.join(rec['key_parameters'])}")


if __name__ == "__main__":
    sys.exit(main())
