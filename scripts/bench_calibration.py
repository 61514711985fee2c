#!/usr/bin/env python
"""Benchmark: calibration on the SYNTHETIC reference experiment (seed 0, truth = the paper's Table 4).

1. Makes the synthetic drive log with `servo-press experiment` into a temporary folder.
2. Times `servo-press calibrate` with the default method end to end (target: at most 30 s on 2 cores).
3. Runs all three solvers on the same Eq. 28 objective and prints, side by side, the objective reached,
   model cycles, time and recovered parameters against the synthetic truth (read from the sidecar here,
   for scoring only: calibration never reads it), and which method wins (lowest Eq. 28).
Usage: python scripts/bench_calibration.py [--seed 0]
"""
import argparse
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from calibration.run import calibrate
from calibration.settings import METHODS, CalibrationSettings
from press_model.jobs import load_job
from press_model.press_data import load_press


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args()
    tmp = Path(tempfile.mkdtemp(prefix="bench_calibration_"))
    log = tmp / "cushion_log.csv"
    t0 = time.perf_counter()
    subprocess.run(["servo-press", "experiment", "--seed", str(args.seed), "--out", str(log)], check=True)
    t_exp = time.perf_counter() - t0
    t0 = time.perf_counter()
    subprocess.run(["servo-press", "calibrate", "--log", str(log), "--seed", str(args.seed), "--out", str(tmp / "cal")],
                   check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    t_cal = time.perf_counter() - t0
    rec = json.loads((tmp / "cal" / "calibrated.json").read_text())
    truth = json.loads(log.with_suffix(".truth.json").read_text())["truth"]

    press, job = load_press(), load_job("cushion-test")
    cs = CalibrationSettings.from_job(job)
    cal = calibrate(press, job, log, list(METHODS), args.seed, progress=False)
    names = cal.objective.problem.names
    print(f"SYNTHETIC log, seed {args.seed}, truth = {truth}")
    print(f"servo-press experiment: {t_exp:.1f} s;  servo-press calibrate (default method {cs.default_method}): {t_cal:.1f} s end to end (target 30 s)")
    print()
    print(f"{'method':<24}{'Eq. 28':>9}{'cycles':>8}{'time s':>8}  " + "".join(f"{n:>16}" for n in names))
    print(f"{'truth (synthetic)':<24}{'':>9}{'':>8}{'':>8}  " + "".join(f"{truth[n]:>16.5g}" for n in names))
    for r in cal.runs:
        print(f"{r.method:<24}{r.objective:>9.5f}{r.cycles:>8d}{r.time_s:>8.2f}  " + "".join(f"{x:>16.5g}" for x in r.x))
        print(f"{'  error vs truth':<24}{'':>9}{'':>8}{'':>8}  " + "".join(f"{100 * (x - truth[n]) / truth[n]:>15.2f}%" for n, x in zip(names, r.x)))
    win = min(cal.runs, key=lambda r: (r.objective, r.time_s))
    print(f"\nwinner (lowest Eq. 28): {win.method}; job file default_method: {cs.default_method}")
    m = rec["metrics"]
    print("\ndefault-method result (calibrated.json) beside the paper's figures (real press, real log):")
    print(f"  RMSE          {m['rmse_before_Nm']:8.1f} -> {m['rmse_after_Nm']:7.1f} N m   (paper 1366.9 -> 277.7)")
    print(f"  peak error    {m['peak_error_before_Nm']:+8.1f} -> {m['peak_error_after_Nm']:+7.1f} N m   (paper 3139.3 -> 856.3, -72.7 %)"
          f"; with the die-contact spike {m['peak_error_with_impact_before_Nm']:+.0f} -> {m['peak_error_with_impact_after_Nm']:+.0f} N m")
    print(f"  thermal error {100 * m['thermal_error_before']:+7.2f} % -> {100 * m['thermal_error_after']:+6.2f} %     (paper 7.6 % -> 1.4 %)")
    for n in names:
        lo, hi = rec["intervals"][n]
        x = rec["parameters"][n]
        inside = "inside" if lo <= truth[n] <= hi else "OUTSIDE"
        print(f"  {n:>9}: {x:.5g} [{lo:.5g}, {hi:.5g}]  truth {truth[n]:.5g} ({100 * (x - truth[n]) / truth[n]:+.2f} %, truth {inside} the interval)")
    for s in rec["identifiability"]:
        print(f"  - {s}")
    return 0 if win.method == cs.default_method else 1


if __name__ == "__main__":
    sys.exit(main())
