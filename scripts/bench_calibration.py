#!/usr/bin/env python
"""Benchmark: calibration on SYNTHETIC reference experiments (truth = the paper's Table 4, noise seeds given).

1. Times `servo-press calibrate` with the default method end to end (bootstrap and a --validate log included)
   --repeats times on the seed-0 log: target at most 30 s on 2 cores; prints min / median / max, and what the
   bootstrap costs (its own line in the command's output).
2. For each seed of --seeds: the synthetic log, all three solvers on the same Eq. 28, and per seed the ACO's
   Eq. 28 against the minimum found by any method (target: within 1 %, at most 5,500 model cycles), with the
   recovered parameters against the synthetic truth (read from the sidecar here, for scoring only:
   calibration never reads it).
Usage: python scripts/bench_calibration.py [--seeds 0,1,2,3,4] [--repeats 3]
"""
import argparse
import json
import re
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from calibration.identification.run import calibrate
from calibration.identification.settings import METHODS, CalibrationSettings
from press_model.settings_fields import replaced
from press_model.jobs import load_job
from press_model.press_data import load_press


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", default="0,1,2,3,4")
    ap.add_argument("--repeats", type=int, default=3)
    args = ap.parse_args()
    seeds = [int(s) for s in args.seeds.split(",")]
    tmp = Path(tempfile.mkdtemp(prefix="bench_calibration_"))
    press, job = load_press(), load_job("cushion-test")
    cs = CalibrationSettings.from_job(job)

    log0, val = tmp / "log_0.csv", tmp / "validation_1.csv"
    subprocess.run(["servo-press", "experiment", "--seed", "0", "--out", str(log0)], check=True, stdout=subprocess.DEVNULL)
    subprocess.run(["servo-press", "experiment", "--job", "cushion-validation", "--seed", "1", "--out", str(val)], check=True,
                   stdout=subprocess.DEVNULL)
    walls, boots = [], []
    for i in range(args.repeats):
        t0 = time.perf_counter()
        r = subprocess.run(["servo-press", "calibrate", "--log", str(log0), "--validate", str(val), "--out", str(tmp / f"cal{i}")],
                           check=True, capture_output=True, text=True)
        walls.append(time.perf_counter() - t0)
        m = re.search(r"model cycles, ([0-9.]+) s", r.stdout)
        boots.append(float(m.group(1)) if m else float("nan"))
    print(f"servo-press calibrate (default method {cs.default_method}, {cs.bootstrap.refits} bootstrap refits, --validate), "
          f"{args.repeats} runs on the SYNTHETIC seed-0 log: wall {min(walls):.1f} / {statistics.median(walls):.1f} / {max(walls):.1f} s "
          f"(min / median / max; target 30 s); bootstrap {min(boots):.1f} / {statistics.median(boots):.1f} / {max(boots):.1f} s")
    rec = json.loads((tmp / "cal0" / "calibrated.json").read_text())
    v = rec["validation"]
    print(f"  validation (another motion, not fitted): RMSE {v['rmse_before_Nm']:.1f} -> {v['rmse_after_Nm']:.1f} N m, peak error "
          f"{v['peak_error_before_Nm']:+.0f} -> {v['peak_error_after_Nm']:+.0f} N m, thermal error {100 * v['thermal_error_before']:+.2f} % "
          f"-> {100 * v['thermal_error_after']:+.2f} %")
    for w in rec["warnings"]:
        print(f"  warning: {w}")

    print(f"\nall methods on the same Eq. 28, SYNTHETIC logs with seeds {seeds} (truth: job's [experiment.truth])")
    gaps = []
    for seed in seeds:
        log = tmp / f"log_{seed}.csv"
        if not log.exists():
            subprocess.run(["servo-press", "experiment", "--seed", str(seed), "--out", str(log)], check=True, stdout=subprocess.DEVNULL)
        truth = json.loads(log.with_suffix(".truth.json").read_text())["truth"]
        cal = calibrate(press, job, log, list(METHODS), seed, settings=replaced(CalibrationSettings.from_job(job), {"bootstrap.refits": 0}), progress=False)
        names = cal.objective.problem.names
        low = min(r.objective for r in cal.runs)
        print(f"seed {seed}: minimum of all methods Eq. 28 = {low:.6f}")
        print(f"  {'method':<24}{'Eq. 28':>10}{'gap':>9}{'cycles':>8}{'time s':>8}  " + "".join(f"{n:>11}" for n in names))
        for r in cal.runs:
            print(f"  {r.method:<24}{r.objective:>10.6f}{100 * (r.objective - low) / low:>8.3f}%{r.cycles:>8d}{r.time_s:>8.2f}  "
                  + "".join(f"{100 * (x - truth[n]) / truth[n]:>+10.2f}%" for n, x in zip(names, r.x)))
            if r.method == "aco":
                gaps.append((seed, 100 * (r.objective - low) / low, r.cycles))
        print(f"  (parameter columns: error against the synthetic truth)")
    print("\nACO per seed: " + "; ".join(f"seed {s}: {g:.3f} % above the minimum, {c} cycles" for s, g, c in gaps))
    ok = all(g <= 1.0 and c <= 5500 for _, g, c in gaps)
    print(f"ACO within 1 % of the minimum of all methods in <= 5,500 cycles on every seed: {'yes' if ok else 'NO'}")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
