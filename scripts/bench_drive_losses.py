#!/usr/bin/env python
"""Benchmark: eta_gear from SYNTHETIC logs whose gear efficiency falls with load, with the press file's drive losses on.

The logs are made by `servo-press experiment` (calibration/synthetic/experiment.py) with the effect efficiency_drop_at_rated
(default 0.05: the efficiency 5 % lower at the motors' rated torque; calibration/synthetic/effects.py, applied to the log, never
through the model; --effect picks others, e.g. viscous_loss_of_rms=0.02, or none), on two runs: the cushion_test.toml job (11.4 strokes/min, 5,000 kN cushion) and a second run at
another speed and cushion force (cushion_validation.toml's motion, 13 strokes/min, with a 2,500 kN cushion). Per seed
a random truth of the job's six key parameters (uniform over the middle 80 % of each calibration range, numpy
default_rng(seed)); the noise seed of the two logs is seed and seed + 1. Each seed is calibrated three ways with the
job's method (default aco):

* ``paper``: the paper's Eq. 16 (losses off), the first log alone;
* ``paper-joint``: losses off, both logs jointly;
* ``losses-joint``: the reference press with [drive.losses] enabled, both logs jointly, the six key parameters plus
  k_load and c_drive calibrated.

Prints per run the relative error of eta_gear and psi, k_load and c_drive, and the summary: the largest |eta_gear
error| of each way (the issue's criterion: within 2 % with the losses on and two runs jointly). Intervals are skipped
(bootstrap_refits = 0): the criterion is on the estimate. Usage:
python scripts/bench_drive_losses.py [--seeds 3] [--seed0 7000] [--effect efficiency_drop_at_rated=0.05]
[--ways paper,paper-joint,losses-joint] [--method aco]
"""
import argparse
import dataclasses
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from calibration.synthetic.effects import LogEffects
from calibration.synthetic.experiment import ExperimentSettings, write_experiment
from calibration.identification.problem import CalibrationProblem
from calibration.identification.run import calibrate
from calibration.identification.settings import CalibrationSettings
from press_model.settings_fields import replaced
from press_model.jobs import load_job
from press_model.press_data import LOSS_SWITCH, load_press, read_press

LOSS_PARAMETERS = ("k_load", "c_drive")


def losses_on(press):
    """The press with [drive.losses] enabled at zero losses (nominal): k_load and c_drive become parameters."""
    raw = press.raw()
    raw["drive"]["losses"]["enabled"] = True
    return read_press(raw, f"{press.source} with {LOSS_SWITCH} = true")


def second_run(tmp: Path):
    """cushion_validation.toml's motion (another speed) with a 2,500 kN cushion (another load), as a job file."""
    import importlib.resources as ir
    text = ir.files("press_model.data").joinpath("cushion_validation.toml").read_text()
    old = "forces_N = [5.0e6, 5.0e6]"
    assert old in text, "cushion_validation.toml's cushion force line changed: update this benchmark"
    path = tmp / "second_run.toml"
    text = text.replace(old, "forces_N = [2.5e6, 2.5e6]").replace('name = "servo-cushion validation run, 5,000 kN', 'name = "second run, 2,500 kN')
    path.write_text(text)
    return load_job(path)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=3)
    ap.add_argument("--seed0", type=int, default=7000)
    ap.add_argument("--effect", action="append", default=None,
                    help="NAME=VALUE of calibration/synthetic/effects.py for the SYNTHETIC logs (repeatable; default efficiency_drop_at_rated=0.05; "
                         "'none' for a control run)")
    ap.add_argument("--ways", default="paper,paper-joint,losses-joint")
    ap.add_argument("--method", default=None)
    args = ap.parse_args()
    press, job = load_press(), load_job("cushion-test")
    tmp = Path(tempfile.mkdtemp(prefix="bench_drive_losses_"))
    job2 = second_run(tmp)
    lossy = losses_on(press)
    cs = CalibrationSettings.from_job(job)
    method = args.method or cs.default_method
    prob = CalibrationProblem.from_press(press, cs.parameters, cs.weight)
    names, span = prob.names, prob.high - prob.low
    items = args.effect or ["efficiency_drop_at_rated=0.05"]
    fx = LogEffects().with_args([e for e in items if e != "none"])
    print(f"SYNTHETIC logs: effects {fx.describe() or 'none (control)'}; runs: {job.name} and {job2.name}; "
          f"method {method}; seeds {args.seed0}..{args.seed0 + args.seeds - 1}", flush=True)
    worst = {w: 0.0 for w in args.ways.split(",")}
    for i in range(args.seeds):
        seed = args.seed0 + i
        rng = np.random.default_rng(seed)
        truth_v = prob.low + (0.1 + 0.8 * rng.random(len(names))) * span
        truth = {n: float(v) for n, v in zip(names, truth_v)}
        logs = []
        for k, jb in enumerate((job, job2)):
            log = tmp / f"seed{seed}_run{k}.csv"
            base = ExperimentSettings.from_job(jb)
            write_experiment(press, jb, truth, seed + k, log, settings=dataclasses.replace(base, effects=fx))
            logs.append(log)
        for way in worst:
            pr = lossy if way == "losses-joint" else press
            fit = names + (LOSS_PARAMETERS if way == "losses-joint" else ())
            more = [(logs[1], job2)] if way.endswith("joint") else []
            t0 = time.perf_counter()
            cal = calibrate(pr, job, logs[0], [method], seed, settings=replaced(CalibrationSettings.from_job(job), {"bootstrap.refits": 0, "parameters": fit}), progress=False, more_logs=more)
            dt = time.perf_counter() - t0
            x = dict(zip(fit, cal.best.x))
            rel = {n: (x[n] - truth[n]) / truth[n] for n in ("eta_gear", "psi")}
            worst[way] = max(worst[way], abs(rel["eta_gear"]))
            extra = ", ".join(f"{n} {x[n]:.4g}" for n in LOSS_PARAMETERS if n in x)
            corr = cal.uncertainty.correlation
            pairs = [(fit[a], fit[b], corr[a, b]) for a in range(len(fit)) for b in range(a + 1, len(fit)) if abs(corr[a, b]) > 0.9]
            print(f"{way:>13} seed {seed}: eta_gear {100 * rel['eta_gear']:+.2f} %, psi {100 * rel['psi']:+.2f} %"
                  f"{'; ' + extra if extra else ''}; RMSE {cal.after['rmse_Nm']:.0f} N m; |corr| > 0.9: "
                  f"{', '.join(f'{a}-{b} {c:+.2f}' for a, b, c in pairs) or 'none'}; {dt:.1f} s", flush=True)
    print("\nlargest |eta_gear error| over the seeds: " + "; ".join(f"{w} {100 * v:.2f} %" for w, v in worst.items())
          + " (criterion: losses-joint within 2 %)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
