#!/usr/bin/env python
"""Check: are the estimates right on clean SYNTHETIC logs of the two-speed motion with sharp ramps when both the angle
and the speed channel are noisy, and does a wrong one warn?

For each seed: a random truth (uniform over the middle 80 % of each calibration range, numpy default_rng(seed)), the
cushion test's synthetic log with the two-speed motion of scripts/check_motions.py (0.6 and 2.0 rad/s, RAMP_DEG ramps)
and that truth and noise seed, both channels noisy as check_motions.py's --channel-noise, calibrated alone with the
job's bootstrap. A run is *wrong* when a truth lies outside its joint region or eta_gear / psi is off by more than
2 % (scripts/bench_adequacy.py); *warned* when calibrate printed a WARNING.
--clean-channels: exact angle and speed channels instead, for comparison.
Usage: python scripts/check_ramp_estimates.py [--seeds 6] [--seed0 9300] [--ramp 15] [--refits N] [--clean-channels]
"""
import argparse
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from calibration.identification.console import warning_lines
from calibration.identification.problem import CalibrationProblem
from calibration.identification.run import calibrate
from calibration.identification.settings import CalibrationSettings
from press_model.settings_fields import replaced
from calibration.synthetic.motions import TwoSpeedMotion
from press_model.jobs import load_job
from press_model.press_data import load_press

sys.path.insert(0, str(Path(__file__).resolve().parent))
from check_motions import CHANNEL_NOISE, write_log  # noqa: E402


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=6)
    ap.add_argument("--seed0", type=int, default=9300)
    ap.add_argument("--ramp", type=float, default=15.0)
    ap.add_argument("--refits", type=int, default=None, help="bootstrap refits (default: the job's)")
    ap.add_argument("--clean-channels", action="store_true", help="exact angle and speed channels (for comparison)")
    args = ap.parse_args()
    channels = () if args.clean_channels else CHANNEL_NOISE
    press, job = load_press(), load_job("cushion-test")
    cs = CalibrationSettings.from_job(job)
    prob = CalibrationProblem.from_press(press, cs.parameters, cs.weight)
    names = prob.names
    motion = TwoSpeedMotion(0.6, 2.0, 30.0, 200.0, args.ramp)
    tmp = Path(tempfile.mkdtemp(prefix="check_ramp_"))
    print(f"SYNTHETIC logs: two-speed motion, {args.ramp:g} deg ramps, channels {', '.join(channels) or 'exact'}; seeds "
          f"{args.seed0}..{args.seed0 + args.seeds - 1}", flush=True)
    silent, wrong_n, warned_n = [], 0, 0
    for seed in range(args.seed0, args.seed0 + args.seeds):
        rng = np.random.default_rng(seed)
        truth_v = prob.low + (0.1 + 0.8 * rng.random(len(names))) * (prob.high - prob.low)
        log = tmp / f"ramp_{seed}.csv"
        write_log(press, job, {n: float(v) for n, v in zip(names, truth_v)}, seed, log, motion, channels)
        t0 = time.perf_counter()
        cal = calibrate(press, job, log, [cs.default_method], seed, progress=False,
                        settings=cs if args.refits is None else replaced(cs, {"bootstrap.refits": args.refits}))
        b, a = cal.bootstrap, cal.adequacy
        joint = bool(np.all((b.joint_low <= truth_v) & (truth_v <= b.joint_high)))
        rel = (cal.best.x - truth_v) / truth_v
        big = [n for n, r in zip(names, rel) if n in ("eta_gear", "psi") and abs(r) > 0.02]
        wrong = (not joint) or bool(big)
        warned = [w.split(":")[1].strip() for w in warning_lines(cal.warnings) if w.startswith("WARNING:")]
        wrong_n += wrong
        warned_n += bool(warned)
        if wrong and not warned:
            silent.append(seed)
        out = [f"{n} {100 * r:+.2f} % ({100 * (b.joint_high[i] - b.joint_low[i]) / 2 / truth_v[i]:.1f} % joint half-width)"
               for i, (n, r) in enumerate(zip(names, rel))]
        print(f"seed {seed}: {'ADEQUATE' if a.adequate else 'NOT ADEQUATE'} F={a.lack_of_fit_ratio:.2f}; "
              f"joint region {'holds all' if joint else 'MISSES ' + ', '.join(n for i, n in enumerate(names) if not b.joint_low[i] <= truth_v[i] <= b.joint_high[i])}; "
              f"{'; '.join(out)}; {'WRONG' if wrong else 'right'}; WARNINGs: {', '.join(warned) or 'none'}; "
              f"{time.perf_counter() - t0:.1f} s", flush=True)
    print(f"\n{args.seeds} runs: {wrong_n} wrong, {warned_n} with a WARNING, wrong without a warning: {len(silent)} "
          f"({', '.join(map(str, silent)) or 'none'})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
