#!/usr/bin/env python
"""Check: are the calibrated parameters biased on clean SYNTHETIC logs? Many seeds, one random truth each.

For each seed: a random truth of the job's calibrated parameters (uniform over the middle 80 % of each calibration
range, numpy default_rng(seed)), the job's synthetic log with that truth and noise seed (its white noise and
die-contact ringing: effects a real log carries that are no model error; no [experiment.effects]), then `calibrate`
as the command runs it (the job's method and bootstrap). With --perfect, also the same truth's log without noise
and ringing, where any error is the method's own.

Prints each run (error of each parameter against its truth, in % of the truth) and then, per parameter, the median
error over the runs beside the median half-width of the reported 95 % interval (in % of the truth): the criterion
is a median error within a tenth of that half-width, and eta_gear's within 0.1 %. A median near zero says the
estimator is unbiased; the per-run errors scatter by about half the half-width, so over N runs a median may
stray by about 1.25 x 0.5 x half-width / sqrt(N) by chance alone (about 0.18 x the half-width for 12 runs):
read a miss of the criterion against that.
Usage: python scripts/check_bias.py [--seeds 12] [--seed0 9000] [--job cushion-test] [--perfect] [--refits N]
"""
import argparse
import dataclasses
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from calibration.identification.problem import CalibrationProblem
from calibration.identification.run import calibrate
from calibration.identification.settings import CalibrationSettings
from calibration.synthetic.experiment import ExperimentSettings, write_experiment
from press_model.jobs import load_job
from press_model.press_data import load_press


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=12)
    ap.add_argument("--seed0", type=int, default=9000)
    ap.add_argument("--job", default="cushion-test")
    ap.add_argument("--perfect", action="store_true", help="also the noise- and ringing-free log of each truth")
    ap.add_argument("--refits", type=int, default=None, help="bootstrap refits (default: the job's; 0: Jacobian intervals)")
    args = ap.parse_args()
    press, job = load_press(), load_job(args.job)
    cs = CalibrationSettings.from_job(job)
    prob = CalibrationProblem.from_press(press, cs.parameters, cs.weight)
    names, span = prob.names, prob.high - prob.low
    base = ExperimentSettings.from_job(job)
    kinds = {"clean": base}
    if args.perfect:
        kinds["perfect"] = dataclasses.replace(base, noise_sigma=0.0, oscillation=0.0)
    tmp = Path(tempfile.mkdtemp(prefix="check_bias_"))
    seeds = list(range(args.seed0, args.seed0 + args.seeds))
    print(f"SYNTHETIC logs of job {job.name} (noise {base.noise_sigma:g} N m, ringing {base.oscillation:g} N m at "
          f"{base.frequency:g} Hz, decay {base.decay:g} s), method {cs.default_method}; seeds {seeds[0]}..{seeds[-1]}, "
          "truth uniform over the middle 80 % of each range", flush=True)
    errors = {k: [] for k in kinds}
    halves = {k: [] for k in kinds}
    for seed in seeds:
        rng = np.random.default_rng(seed)
        truth_v = prob.low + (0.1 + 0.8 * rng.random(len(names))) * span
        truth = {n: float(v) for n, v in zip(names, truth_v)}
        for kind, settings in kinds.items():
            log = tmp / f"{kind}_{seed}.csv"
            write_experiment(press, job, truth, seed, log, settings=settings)
            t0 = time.perf_counter()
            cal = calibrate(press, job, log, [cs.default_method], seed, progress=False, bootstrap_refits=args.refits)
            iv = cal.bootstrap if cal.bootstrap is not None else cal.uncertainty
            rel = 100.0 * (cal.best.x - truth_v) / truth_v
            half = 100.0 * (iv.high - iv.low) / 2.0 / truth_v
            errors[kind].append(rel)
            halves[kind].append(half)
            a = cal.adequacy
            print(f"{kind:>8} seed {seed}: {cal.log.strokes} strokes, {'ADEQUATE' if a.adequate else 'NOT ADEQUATE'} "
                  f"F={a.lack_of_fit_ratio:.2f}; " + ", ".join(f"{n} {r:+.2f} %" for n, r in zip(names, rel))
                  + f"; {time.perf_counter() - t0:.1f} s", flush=True)
    ok_all = True
    for kind in kinds:
        E, H = np.array(errors[kind]), np.array(halves[kind])
        med, hw = np.median(E, axis=0), np.median(H, axis=0)
        print(f"\n{kind} logs, {len(seeds)} seeds {seeds[0]}..{seeds[-1]}: median error against the truth, median half-width "
              "of the reported 95 % interval (both % of the truth), their ratio, and how many runs came out low")
        print("| parameter | median error [%] | median half-width [%] | error / half-width | runs low | criterion |")
        print("|---|---|---|---|---|---|")
        for j, n in enumerate(names):
            limit = 0.1 if n == "eta_gear" else 0.1 * hw[j]
            ok = abs(med[j]) <= limit if kind == "clean" else True
            ok_all &= bool(ok)
            crit = (f"{'met' if ok else 'MISSED'} (|median| <= {limit:.3g} %)" if kind == "clean" else "-")
            print(f"| {n} | {med[j]:+.3f} | {hw[j]:.3f} | {med[j] / hw[j]:+.2f} | {int(np.sum(E[:, j] < 0))}/{len(E)} | {crit} |")
    return 0 if ok_all else 1


if __name__ == "__main__":
    sys.exit(main())
