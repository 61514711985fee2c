#!/usr/bin/env python
"""Check: are SYNTHETIC cushion-test logs with a recording effect (by default a 2 ms torque-channel delay) corrected
and judged ADEQUATE?

For each seed: a random truth (uniform over the middle 80 % of each calibration range, numpy default_rng(seed)), the
job's synthetic log with that truth and noise seed and the effects given ([experiment.effects] NAME=VALUE of
calibration/synthetic/effects.py; by default channel_delay_s=0.002, one sample at 500 Hz), calibrated without the
bootstrap (the verdict and the recording estimate need none). Prints each run's verdict, F, suspects, the recording
estimate (delay, offset, lost motion, iterations, whether the log was corrected) and the errors of eta_gear and psi,
then the count of NOT ADEQUATE verdicts.
Usage: python scripts/check_recording.py [--seeds 32] [--seed0 9300] [--job cushion-test] [--effect NAME=VALUE ...]
"""
import argparse
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from calibration.identification.problem import CalibrationProblem
from calibration.identification.run import calibrate
from calibration.identification.settings import CalibrationSettings
from press_model.settings_fields import replaced
from calibration.synthetic.experiment import ExperimentSettings, with_log_effects, write_experiment
from press_model.jobs import load_job
from press_model.press_data import load_press


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=32)
    ap.add_argument("--seed0", type=int, default=9300)
    ap.add_argument("--job", default="cushion-test")
    ap.add_argument("--effect", action="append", default=None, metavar="NAME=VALUE",
                    help="an effect of calibration/synthetic/effects.py (repeatable); default channel_delay_s=0.002")
    args = ap.parse_args()
    effects = {k: float(v) for k, v in (e.split("=", 1) for e in (args.effect or ["channel_delay_s=0.002"]))}
    press, job = load_press(), load_job(args.job)
    cs = CalibrationSettings.from_job(job)
    prob = CalibrationProblem.from_press(press, cs.parameters, cs.weight)
    settings = with_log_effects(ExperimentSettings.from_job(job), effects)
    tmp = Path(tempfile.mkdtemp(prefix="check_recording_"))
    print(f"SYNTHETIC logs: job {job.name}, effects {effects}; seeds {args.seed0}..{args.seed0 + args.seeds - 1}", flush=True)
    alarms = []
    for seed in range(args.seed0, args.seed0 + args.seeds):
        rng = np.random.default_rng(seed)
        truth = prob.low + (0.1 + 0.8 * rng.random(len(prob.names))) * (prob.high - prob.low)
        log = tmp / f"log_{seed}.csv"
        write_experiment(press, job, {n: float(v) for n, v in zip(prob.names, truth)}, seed, log, settings=settings)
        t0 = time.perf_counter()
        cal = calibrate(press, job, log, [cs.default_method], seed, settings=replaced(cs, {"bootstrap.refits": 0}), progress=False)
        a, r = cal.adequacy, cal.recording
        if not a.adequate:
            alarms.append(str(seed))
        rel = 100.0 * (cal.best.x - truth) / truth
        sus = ", ".join(f"{t.name} t={t.t:.1f}" for t in a.suspects) or "none"
        rec = (f"delay {1e3 * r.channel_delay_s:+.2f} +- {1e3 * r.std[0]:.2f} ms, offset {r.angle_offset_deg:+.3f} deg"
               + ("" if r.lost_motion_deg is None else f", lost motion {r.lost_motion_deg:+.1f} motor deg")
               + f", {r.iterations} corrections{'' if r.corrected else ' (not corrected)'}") if r is not None else "off"
        print(f"seed {seed}: {'ADEQUATE' if a.adequate else 'NOT ADEQUATE'} F={a.lack_of_fit_ratio:.2f}; suspects: {sus}; "
              f"recording: {rec}; eta_gear {rel[prob.names.index('eta_gear')]:+.2f} %, psi {rel[prob.names.index('psi')]:+.2f} %; "
              f"{time.perf_counter() - t0:.1f} s", flush=True)
    print(f"\n{args.seeds} runs: {len(alarms)} NOT ADEQUATE ({', '.join(alarms) or 'none'}); the adequacy level "
          f"{cs.adequacy.level:g} allows {cs.adequacy.level * args.seeds:.2f} by chance")
    return 0


if __name__ == "__main__":
    sys.exit(main())
