#!/usr/bin/env python
"""Check: is a calibration whose log has no process-force column ever wrong without a warning? SYNTHETIC logs.

For each effect (clean, as the experiment writes it: the force logged with the job's noise; clean without the force
column; the cushion's true force 4 % above or below the job's, not logged (the column dropped: [experiment]
process_force_logged = false); the same logged with 1 % noise) and seed: a random truth of the six key parameters (uniform over the middle 80 % of each calibration range,
numpy default_rng(seed), as scripts/bench_adequacy.py), the cushion test's synthetic log with that truth, noise seed
and effect (calibration/synthetic: the true force is made by the generator, never through the model being
calibrated), calibrated as the command runs it (the job's method, bootstrap and [calibration.process_force]), alone
and jointly with a log of the validation motion of the same truth and the same cushion force (noise seed + 500;
--partner validation: the shipped cushion-validation job's motion; --partner two-speed: the SYNTHETIC two-speed motion
of calibration/synthetic/motions.py, 30-degree ramps).

A run is *wrong* when a truth lies outside its joint region or eta_gear or psi is off by more than 2 %; it is *warned*
when `calibrate` warned at WARNING level: MODEL NOT ADEQUATE (any suspect, the process force scale's score test
among them), coloured noise, or PROCESS FORCE NOT LOGGED (the job's force tolerance moves eta_gear or psi by more than
[calibration.process_force] warning_shift). Printed per run: the errors, whether the joint region holds every truth,
the force-scale score test (t, p against its Bonferroni share of the adequacy level; the test is the adequacy
module's, at its nominal rate: no threshold here), the verdict and the warnings; then the score test's t on clean
against force-off logs, and the count of runs wrong without a warning and of clean runs that warned (and why).
--tolerance sets job_force_tolerance for every run (default: the job's).
Usage: python scripts/check_force_scale.py [--seeds 3] [--seed0 7000] [--effects ...] [--partner validation|two-speed|none]
"""
import argparse
import dataclasses
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

import calibration.synthetic.experiment as experiment
from calibration.identification.problem import CalibrationProblem
from calibration.identification.process_force import FORCE_WARNING
from calibration.identification.run import calibrate
from calibration.identification.settings import CalibrationSettings
from calibration.synthetic.motions import TwoSpeedMotion
from press_model.jobs import load_job
from press_model.press_data import load_press

OFF = {"process_force_logged": False}  # the experiment logs the force by default ([experiment] process_force_logged)
EFFECTS = {
    "clean": {},  # as `servo-press experiment` writes it: the force logged with the job's noise
    "clean unlogged": OFF,
    "force +4 %": {"cushion_force_scale": 1.04, **OFF},
    "force -4 %": {"cushion_force_scale": 0.96, **OFF},
    "force +4 % logged": {"cushion_force_scale": 1.04, "process_force_logged": 1.0, "process_force_noise_of_peak": 0.01},
    "force -4 % logged": {"cushion_force_scale": 0.96, "process_force_logged": 1.0, "process_force_noise_of_peak": 0.01},
}
LIMIT = 0.02  # eta_gear / psi off by more than this: wrong (the criterion of scripts/bench_adequacy.py)


def write_log(press, job, truth, seed, out, effects, motion=None):
    """The job's SYNTHETIC log with ``effects`` (and ``motion`` instead of the job's when given)."""
    made = experiment.make_motion
    if motion is not None:
        experiment.make_motion = lambda spec, source: motion
    try:
        st = experiment.with_log_effects(experiment.ExperimentSettings.from_job(job), effects)
        experiment.write_experiment(press, job, truth, seed, out, settings=st)
    finally:
        experiment.make_motion = made


def run(press, job, cs, prob, eff, seed, partner, tmp):
    """One run: (row dict) as the module docstring says."""
    names = prob.names
    rng = np.random.default_rng(seed)
    truth_v = prob.low + (0.1 + 0.8 * rng.random(len(names))) * (prob.high - prob.low)
    truth = {n: float(v) for n, v in zip(names, truth_v)}
    log = tmp / f"{eff.replace(' ', '_').replace('%', 'pc')}_{seed}.csv"
    write_log(press, job, truth, seed, log, EFFECTS[eff])
    more = ()
    if partner is not None:
        p_job, p_motion = partner
        other = log.with_name(log.stem + "_partner.csv")
        write_log(press, p_job, truth, seed + 500, other, EFFECTS[eff], p_motion)
        more = ((other, p_job),)
    t0 = time.perf_counter()
    cal = calibrate(press, job, log, [cs.default_method], seed, progress=False, more_logs=more, settings=cs)
    dt = time.perf_counter() - t0
    b = cal.bootstrap if cal.bootstrap is not None else cal.uncertainty
    joint = bool(np.all((b.joint_low <= truth_v) & (truth_v <= b.joint_high)))
    rel = (cal.best.x - truth_v) / truth_v
    big = [n for n, r in zip(names, rel) if n in ("eta_gear", "psi") and abs(r) > LIMIT]
    force_warned = any(w.startswith(FORCE_WARNING) for w in cal.warnings)
    inadequate = any(not a.adequate for a in cal.adequacy_logs)
    coloured = any(a.noise_coloured for a in cal.adequacy_logs)
    tests = [t for a in cal.adequacy_logs for t in a.tests if t.name == "process_force_scale"]
    ft = max(tests, key=lambda t: t.t) if tests else None
    alpha = cal.adequacy.level / len(cal.adequacy_logs) / (1 + len(cal.adequacy.tests))  # the test's Bonferroni share
    sens = (cal.process_force or {}).get("sensitivity")
    mc = sens["multiple_correlation_with_the_parameters"] if sens else float("nan")
    return {"eta": 100 * rel[names.index("eta_gear")], "psi": 100 * rel[names.index("psi")], "joint": joint,
            "wrong": (not joint) or bool(big), "warned": force_warned or inadequate or coloured,
            "force_warned": force_warned, "inadequate": inadequate, "coloured": coloured,
            "suspects": [t.name for a in cal.adequacy_logs for t in a.suspects],
            "t": ft.t if ft else float("nan"), "p": ft.p_value if ft else float("nan"), "sig": bool(ft and ft.significant),
            "size": ft.size if ft else float("nan"), "alpha": alpha, "mc": mc, "F": cal.adequacy.lack_of_fit_ratio, "s": dt}


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=3)
    ap.add_argument("--seed0", type=int, default=7000)
    ap.add_argument("--effects", default=",".join(EFFECTS), help="comma-separated, of: " + ", ".join(EFFECTS).replace("%", "%%"))
    ap.add_argument("--partner", default="validation", choices=("validation", "two-speed", "none"),
                    help="the second log of the joint fits")
    ap.add_argument("--tolerance", type=float, default=None, help="job_force_tolerance of every run (default: the job's)")
    args = ap.parse_args()
    press, job = load_press(), load_job("cushion-test")
    cs = CalibrationSettings.from_job(job)
    if args.tolerance is not None:
        cs = dataclasses.replace(cs, process_force=dataclasses.replace(cs.process_force, job_force_tolerance=args.tolerance))
    prob = CalibrationProblem.from_press(press, cs.parameters, cs.weight)
    fits = [("alone", None)]
    if args.partner == "validation":
        fits.append(("joint with cushion-validation", (load_job("cushion-validation"), None)))
    elif args.partner == "two-speed":
        fits.append(("joint with two-speed", (job, TwoSpeedMotion(0.6, 2.0, 30.0, 200.0, 30.0))))
    tmp = Path(tempfile.mkdtemp(prefix="check_force_scale_"))
    print(f"SYNTHETIC logs: job {job.name}; seeds {args.seed0}..{args.seed0 + args.seeds - 1}; truths uniform over the middle "
          f"80 % of each range (default_rng(seed)); job_force_tolerance {cs.process_force.job_force_tolerance:g}, warning_shift "
          f"{cs.process_force.warning_shift:g}; adequacy level {cs.adequacy.level:g}", flush=True)
    print("| effect | fit | seed | eta_gear error | psi error | truth in joint region | force score t (p) | force multiple "
          "correlation | F | warned | wrong |")
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    rows = []
    for eff in args.effects.split(","):
        for how, partner in fits:
            for i in range(args.seeds):
                seed = args.seed0 + i
                r = run(press, job, cs, prob, eff, seed, partner, tmp)
                rows.append((eff, how, seed, r))
                why = [w for w, on in (("FORCE NOT LOGGED", r["force_warned"]), ("NOT ADEQUATE: " + ", ".join(r["suspects"] or ["none"]),
                                                                                  r["inadequate"]), ("coloured noise", r["coloured"])) if on]
                tt = f"{r['t']:.2f} ({r['p']:.2g}{', significant' if r['sig'] else ''})" if np.isfinite(r["t"]) else "- (force logged)"
                print(f"| {eff} | {how} | {seed} | {r['eta']:+.2f} % | {r['psi']:+.2f} % | {'yes' if r['joint'] else 'NO'} | {tt} | "
                      f"{r['mc']:.3f} | {r['F']:.2f} | {'; '.join(why) or 'no'} | {'WRONG' if r['wrong'] else 'right'}"
                      f"{' WITHOUT WARNING' if r['wrong'] and not r['warned'] else ''} | ({r['s']:.1f} s)", flush=True)
    silent = [f"{e} {h} seed {s}" for e, h, s, r in rows if r["wrong"] and not r["warned"]]
    print(f"\n{len(rows)} runs: wrong without a warning (a truth outside its joint region, or eta_gear / psi off by more than "
          f"{100 * LIMIT:g} %): {len(silent)} ({'; '.join(silent) or 'none'})")
    for name in ("clean", "clean unlogged"):
        clean = [(h, s, r) for e, h, s, r in rows if e == name]
        if clean:
            print(f"{name} runs that warned: {sum(r['warned'] for _, _, r in clean)} of {len(clean)} (PROCESS FORCE NOT LOGGED "
                  f"in {sum(r['force_warned'] for _, _, r in clean)}, NOT ADEQUATE in {sum(r['inadequate'] for _, _, r in clean)})")
    for e in dict.fromkeys(e for e, *_ in rows):
        ts = [r["t"] for ee, _, _, r in rows if ee == e and np.isfinite(r["t"])]
        if ts:
            sig = sum(r["sig"] for ee, _, _, r in rows if ee == e)
            print(f"  force-scale score test, {e}: t {min(ts):.2f} .. {max(ts):.2f}, significant in {sig} of {len(ts)} "
                  f"(at each fit's Bonferroni share of the adequacy level: {rows[0][3]['alpha']:.2g} alone)")
        logged = [r for ee, _, _, r in rows if ee == e and not np.isfinite(r["t"])]
        if logged:
            print(f"  {e}: eta_gear {min(r['eta'] for r in logged):+.2f} .. {max(r['eta'] for r in logged):+.2f} % off its truth")
    return 0


if __name__ == "__main__":
    sys.exit(main())
