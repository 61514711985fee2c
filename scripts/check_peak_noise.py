#!/usr/bin/env python
"""Check: do the intervals carry the measured peak's noise on clean SYNTHETIC logs with a small |Y_PR,0|?

For each seed: a random truth of the job's calibrated parameters (uniform over the middle 80 % of each calibration
range, numpy default_rng(seed), as scripts/check_bias.py and scripts/bench_coverage.py draw it). Only the seeds whose
theoretical peak error is within ``--within`` times the peak noise of the note (calibration/identification/peak_noise.py)
on a first, cheap look (the truth's model peak against the theoretical one on one log's grid, 23 N m for the noise)
are logged and calibrated as `calibrate` runs them (the job's method and bootstrap); the runs where the note did
not fire are left out of the figures.

Prints each run (hits of the reported intervals, of the Jacobian intervals with and without the peak's move
(interval_widening.peak_move_sd, taken back out in quadrature), and of the joint region), then per parameter how
often each held the truth and the root mean square of error / (half-width / 1.96), about 1 for honest intervals.

Usage: python scripts/check_peak_noise.py [--seed0 2000] [--seeds 300] [--within 12] [--max-logs 12]
"""
import argparse
import sys
import tempfile
from pathlib import Path

import numpy as np
from scipy import stats

from calibration.identification.inputs import read_log
from calibration.identification.problem import CalibrationProblem
from calibration.identification.run import calibrate, log_problem
from calibration.identification.settings import CalibrationSettings
from calibration.synthetic.experiment import ExperimentSettings, write_experiment
from press_model.jobs import load_job
from press_model.model import PressModel
from press_model.press_data import load_press


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seed0", type=int, default=2000)
    ap.add_argument("--seeds", type=int, default=300, help="seeds looked at (cheaply) for a small |Y_PR,0|")
    ap.add_argument("--within", type=float, default=12.0, help="first look: keep seeds whose peak error is within this many "
                    "times 23 N m (a little above the note's 10, so that the log's own noise decides)")
    ap.add_argument("--max-logs", type=int, default=12)
    ap.add_argument("--job", default="cushion-test")
    args = ap.parse_args()
    press, job = load_press(), load_job(args.job)
    cs = CalibrationSettings.from_job(job)
    prob = CalibrationProblem.from_press(press, cs.parameters, cs.weight)
    names, span = prob.names, prob.high - prob.low
    tmp = Path(tempfile.mkdtemp(prefix="check_peak_noise_"))
    pm = PressModel(press)
    # the first look: every seed's truth on the grid of the job's seed-0 log
    first = tmp / "first.csv"
    write_experiment(press, job, ExperimentSettings.from_job(job).truth, 0, first)
    o = log_problem(press, job, cs, prob, read_log(first, press), pm).objective
    seeds = np.arange(args.seed0, args.seed0 + args.seeds)
    truths = np.array([prob.low + (0.1 + 0.8 * np.random.default_rng(s).random(len(names))) * span for s in seeds])
    peaks = np.abs(o.torques(np.vstack([prob.theoretical[None], truths]))[:, o.peak_points]).max(axis=1)
    keep = np.abs(peaks[1:] - peaks[0]) < args.within * 23.0
    print(f"SYNTHETIC logs: job {job.name}, seeds {seeds[0]}..{seeds[-1]}, {int(keep.sum())} with a small |Y_PR,0| at first look; "
          f"calibrating up to {args.max_logs} on which the note fires", flush=True)
    rows = []
    for seed, tv in zip(seeds[keep], truths[keep]):
        if len(rows) >= args.max_logs:
            break
        log = tmp / f"log_{seed}.csv"
        write_experiment(press, job, dict(zip(names, tv)), int(seed), log)
        cal = calibrate(press, job, log, [cs.default_method], int(seed), progress=False)
        if not cal.notes:
            continue
        x, b, u = cal.best.x, cal.bootstrap, cal.uncertainty
        q = float(stats.norm.ppf(0.5 + cs.interval_level / 2.0))  # the quantile run.py widens the Jacobian intervals with
        hw_j = (u.high - u.low) / 2.0
        hw_0 = np.sqrt(np.maximum(hw_j ** 2 - (q * cal.peak_move) ** 2, 0.0))  # the move taken back out
        err = x - tv
        rows.append({"hit": (b.low <= tv) & (tv <= b.high), "jac": (u.low <= tv) & (tv <= u.high), "jac0": np.abs(err) <= hw_0,
                     "joint": bool(np.all((b.joint_low <= tv) & (tv <= b.joint_high))),
                     "z": err / ((b.high - b.low) / 2.0 / 1.96), "zj": err / (hw_j / 1.96), "zj0": err / (hw_0 / 1.96)})
        r = rows[-1]
        print(f"seed {seed}: |Y_PR,0| {abs(cal.objective.pr0):.4f}; reported {''.join('x' if h else '.' for h in r['hit'])}, "
              f"Jacobian {''.join('x' if h else '.' for h in r['jac'])} (without the peak's move "
              f"{''.join('x' if h else '.' for h in r['jac0'])}), joint region {'holds all' if r['joint'] else 'MISSES'}", flush=True)
    if not rows:
        print("no log with the note")
        return 1
    n = len(rows)
    print(f"\n{n} SYNTHETIC logs with the note; per parameter: held by reported / Jacobian / Jacobian without the move; "
          "RMS of error / (half-width / 1.96) of the same three")
    for j, nm in enumerate(names):
        held = [sum(r[k][j] for r in rows) for k in ("hit", "jac", "jac0")]
        rms = [float(np.sqrt(np.mean([r[k][j] ** 2 for r in rows]))) for k in ("z", "zj", "zj0")]
        print(f"  {nm:>9}: {held[0]}/{n} {held[1]}/{n} {held[2]}/{n}; RMS {rms[0]:.2f} {rms[1]:.2f} {rms[2]:.2f}")
    print(f"  joint region holds every truth on {sum(r['joint'] for r in rows)} of {n}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
