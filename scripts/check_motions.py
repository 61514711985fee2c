#!/usr/bin/env python
"""Check: do clean SYNTHETIC logs of every shipped motion pass the adequacy test, alone and jointly?

Motions: the shipped jobs with a crank motion (press_model/data: cushion_test, cushion_validation, cushion_slow;
crank_slider_cushion on the crank-slider press; tests/data/cushion_test_fast.toml), the runs of a
`servo-press design-experiment` folder (--design DIR: its run_N/job.toml), and two-speed motions made here
(--two-speed RAMP_DEG ...: slow at 0.6 rad/s from 30 to 200 deg, fast at 2.0 rad/s elsewhere, raised-cosine changes
of speed over RAMP_DEG, by default 30 and 15 deg; not shipped, the kind of motion a fixed 24-harmonic speed fit called
NOT ADEQUATE, and with 15-degree ramps a Fourier fit of any length).
For each motion and seed: a random truth (uniform over the middle 80 % of each calibration range,
numpy default_rng(seed)), the motion's synthetic log with that truth and noise seed (the job's noise and die-contact
ringing; no [experiment.effects]), calibrated alone and jointly with the cushion test's log of the same truth (noise
seed + 500); each log as `servo-press experiment` writes it, the process force logged where the job has one
([experiment] process_force_logged); the [calibration] settings are the motion's job's, or cushion_test.toml's when it has none.

Prints each run (verdict, F, p, suspects, the crank motion's representation, whether each log has the force column, its
WARNING-level warnings) and the count of NOT ADEQUATE verdicts against what the job's adequacy level allows by chance
(level x runs), and of runs with any WARNING.
--channel-noise (or --effect NAME=VALUE): every log's angle and speed channels noisy (calibration/synthetic/effects.py).
Usage: python scripts/check_motions.py [--seeds 2] [--seed0 9100] [--design DIR] [--two-speed 30 15] [--refits 0]
       [--channel-noise] [--effect NAME=VALUE ...] [--no-shipped]
"""
import argparse
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

import calibration.synthetic.experiment as experiment
from calibration.synthetic.motions import TwoSpeedMotion
from calibration.identification.console import warning_lines
from calibration.identification.problem import CalibrationProblem
from calibration.identification.run import calibrate
from calibration.identification.speed_fit import crank_motion, describe
from calibration.identification.settings import CalibrationSettings
from press_model.settings_fields import replaced
from press_model.jobs import load_job
from press_model.press_data import load_press

ROOT = Path(__file__).resolve().parent.parent
# A real drive's angle and speed channels (--channel-noise), chosen before any run of this check: the crank angle
# from a motor resolver read at 12 bits (4096 counts per motor turn, the common resolver-to-digital resolution at a
# motor's full speed; a count is 0.0027 crank deg through u = 32) with converter noise of about one count, and the
# drive's speed estimate (the resolver's filtered derivative) with 1 rpm RMS of noise (0.1 % of the motor's 1,000 rpm).
CHANNEL_NOISE = ("angle_counts_per_motor_rev=4096", "angle_noise_deg=0.0027", "speed_noise_rpm=1")


def write_log(press, job, truth, seed, out, motion=None, effects=()):
    """The job's synthetic log (with ``motion`` instead of the job's when given, ``effects`` NAME=VALUE items of
    calibration/synthetic/effects.py in place of the job's [experiment.effects])."""
    made = experiment.make_motion
    if motion is not None:
        experiment.make_motion = lambda spec, source: motion
    try:
        experiment.write_experiment(press, job, truth, seed, out, settings=experiment.ExperimentSettings.from_job(job),
                                    effects=list(effects))
    finally:
        experiment.make_motion = made


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=2)
    ap.add_argument("--seed0", type=int, default=9100)
    ap.add_argument("--design", default=None, help="a design-experiment output folder: its runs too")
    ap.add_argument("--two-speed", type=float, nargs="*", default=[30.0, 15.0], metavar="RAMP_DEG",
                    help="the two-speed motion with these ramps (deg) too; none: leave it out")
    ap.add_argument("--refits", type=int, default=0, help="bootstrap refits (default 0: the verdict needs none)")
    ap.add_argument("--effect", action="append", default=[], metavar="NAME=VALUE",
                    help="an effect of calibration/synthetic/effects.py on every log (repeatable), e.g. the angle and "
                         "speed channels' noise: angle_counts_per_motor_rev, angle_noise_deg, speed_noise_rpm")
    ap.add_argument("--no-shipped", action="store_true", help="only the --design and --two-speed motions")
    ap.add_argument("--channel-noise", action="store_true",
                    help="both channels noisy at a real drive's levels: " + ", ".join(CHANNEL_NOISE))
    args = ap.parse_args()
    effects = (list(CHANNEL_NOISE) if args.channel_noise else []) + args.effect
    if effects:
        print(f"SYNTHETIC logs with the effects {', '.join(effects)}", flush=True)
    ref = load_press()
    base_job = load_job("cushion-test")
    motions = []
    if not args.no_shipped:
        motions += [(n, ref, load_job(n), None) for n in ("cushion-test", "cushion-validation")]
        motions.append(("cushion_slow", ref, load_job(str(ROOT / "press_model/data/cushion_slow.toml")), None))
        motions.append(("tests/data/cushion_test_fast.toml", ref, load_job(str(ROOT / "tests/data/cushion_test_fast.toml")), None))
        motions.append(("crank_slider_cushion", load_press("crank-slider"), load_job("crank-slider-cushion"), None))
    if args.design:
        motions += [(f"design {p.parent.name}", ref, load_job(str(p)), None) for p in sorted(Path(args.design).glob("run_*/job.toml"))]
    for ramp in args.two_speed:
        motions.append((f"two-speed ({ramp:g} deg ramps, SYNTHETIC motion)", ref, base_job, TwoSpeedMotion(0.6, 2.0, 30.0, 200.0, ramp)))
    tmp = Path(tempfile.mkdtemp(prefix="check_motions_"))
    alarms, loud, runs, level = [], [], 0, None
    for label, press, job, motion in motions:
        cal_job = job if "calibration" in job.raw else base_job
        cs = CalibrationSettings.from_job(cal_job)
        level = cs.adequacy.level
        prob = CalibrationProblem.from_press(press, cs.parameters, cs.weight)
        for i in range(args.seeds):
            seed = args.seed0 + i
            rng = np.random.default_rng(seed)
            truth_v = prob.low + (0.1 + 0.8 * rng.random(len(prob.names))) * (prob.high - prob.low)
            truth = {n: float(v) for n, v in zip(prob.names, truth_v)}
            log = tmp / f"{label.split(' deg')[0].replace('/', '_').replace(' ', '_').replace('(', '')}_{seed}.csv"
            write_log(press, job, truth, seed, log, motion, effects)
            fits = [("alone", ())]
            if press is ref:
                partner = tmp / f"partner_{seed}.csv"
                write_log(press, base_job, truth, seed + 500, partner, effects=effects)
                fits.append(("joint with cushion-test", ((partner, base_job),)))
            for how, more in fits:
                t0 = time.perf_counter()
                cal = calibrate(press, cal_job, log, [cs.default_method], seed, settings=replaced(cs, {"bootstrap.refits": args.refits}), progress=False, more_logs=more)
                elapsed = time.perf_counter() - t0
                a = cal.adequacy
                runs += 1
                if not a.adequate:
                    alarms.append(f"{label} seed {seed} {how}")
                warned = [w.split(":")[1].strip() for w in warning_lines(cal.warnings) if w.startswith("WARNING:")]
                if warned:
                    loud.append(f"{label} seed {seed} {how} ({', '.join(warned)})")
                sus = ", ".join(f"{t.name} t={t.t:.1f}" for t in a.suspects) or "none"
                print(f"{label} seed {seed} {how}: {'ADEQUATE' if a.adequate else 'NOT ADEQUATE'} F={a.lack_of_fit_ratio:.2f} "
                      f"p={a.p_value:.2g}; suspects: {sus}; speed: "
                      f"{' + '.join(describe(crank_motion(lg, cs)) for lg in cal.logs)}; force column "
                      f"{'+'.join('yes' if lg.stroke_force is not None else 'no' for lg in cal.logs)}; WARNINGs: "
                      f"{', '.join(warned) or 'none'}; {elapsed:.1f} s", flush=True)
    print(f"\n{runs} clean runs: {len(alarms)} NOT ADEQUATE ({'; '.join(alarms) or 'none'}); the adequacy level {level:g} "
          f"allows {level * runs:.2f} by chance; with a WARNING (not adequate, or the process force not logged): "
          f"{len(loud)} ({'; '.join(loud) or 'none'})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
