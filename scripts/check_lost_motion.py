#!/usr/bin/env python
"""Check: is a small lost motion in the gear ever wrong without a warning, and what does its estimate cost the clean
logs' intervals? SYNTHETIC logs.

For each effect (scripts/bench_adequacy.py's EFFECTS: control, offset, delay, backlash_8, ...) and seed: a random truth
of the six key parameters (uniform over the middle 80 % of each calibration range, numpy default_rng(seed), as
scripts/bench_adequacy.py), the cushion test's synthetic log with that truth, noise seed and effect, then `calibrate`
as the command runs it (the job's method and bootstrap). Wrong and warned as in scripts/bench_adequacy.py.

Prints one JSON line per run (effect, seed, truth, estimate, per-parameter and joint half-widths as fractions of the
truth, warned, wrong, the recording estimate with its lost motion, seconds) and a summary per effect: runs wrong
without a warning, runs warned, the median half-widths. ``--out FILE`` also writes the lines there, so a run of
another version of the code on the same seeds can be set beside it (``--compare FILE``: ratio of the median
half-widths, this run over FILE's, per effect and parameter).
Usage: python scripts/check_lost_motion.py [--effects control,backlash_8] [--seed0 7100] [--seeds 8] [--out F] [--compare F]
"""
import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from bench_adequacy import EFFECTS
from calibration.identification.problem import CalibrationProblem
from calibration.identification.process_force import FORCE_WARNING
from calibration.identification.run import calibrate
from calibration.identification.settings import CalibrationSettings
from calibration.synthetic.experiment import ExperimentSettings, with_log_effects, write_experiment
from press_model.jobs import load_job
from press_model.press_data import load_press

LIMIT = 0.02  # eta_gear / psi off by more than this: wrong (scripts/bench_adequacy.py)


def run_one(press, job, cs, prob, base, eff, seed, tmp) -> dict:
    """One SYNTHETIC log of ``eff`` at ``seed``, calibrated; the record of the module docstring."""
    names, span = prob.names, prob.high - prob.low
    rng = np.random.default_rng(seed)
    truth_v = prob.low + (0.1 + 0.8 * rng.random(len(names))) * span
    truth = {n: float(v) for n, v in zip(names, truth_v)}
    log = tmp / f"{eff}_{seed}.csv"
    write_experiment(press, job, truth, seed, log, settings=with_log_effects(base, EFFECTS[eff]))
    t0 = time.perf_counter()
    cal = calibrate(press, job, log, [cs.default_method], seed, progress=False, settings=cs)
    dt = time.perf_counter() - t0
    b, x = cal.bootstrap, cal.best.x
    joint = bool(np.all((b.joint_low <= truth_v) & (truth_v <= b.joint_high)))
    rel = (x - truth_v) / truth_v
    big = [n for n, r in zip(names, rel) if n in ("eta_gear", "psi") and abs(r) > LIMIT]
    warned = (not cal.adequacy.adequate or any(a.noise_coloured for a in cal.adequacy_logs)
              or any(w.startswith(FORCE_WARNING) for w in cal.warnings))
    r = cal.recording
    rec = {} if r is None else {k: v for k, v in r.record().items() if k not in ("method",)}
    lash = {t.name: t for t in cal.adequacy.tests}.get("backlash")
    return {
        "effect": eff, "seed": seed, "synthetic": True, "truth": truth, "estimate": dict(zip(names, map(float, x))),
        "error": dict(zip(names, map(float, rel))),
        "half_width": dict(zip(names, map(float, (b.high - b.low) / 2.0 / truth_v))),
        "joint_half_width": dict(zip(names, map(float, (b.joint_high - b.joint_low) / 2.0 / truth_v))),
        "joint_misses": [n for n, lo, hi, t in zip(names, b.joint_low, b.joint_high, truth_v) if not lo <= t <= hi],
        "warned": bool(warned), "wrong": (not joint) or bool(big), "suspects": [t.name for t in cal.adequacy.suspects],
        "lost_motion_test_t": None if lash is None else float(lash.t), "recording": rec, "seconds": dt,
    }


def summary(rows: list[dict], names, base: dict | None = None) -> list[str]:
    """Lines per effect: runs, wrong without a warning, warned, median half-widths (and their ratio to ``base``)."""
    out = []
    for eff in dict.fromkeys(r["effect"] for r in rows):
        rs = [r for r in rows if r["effect"] == eff]
        silent = [r["seed"] for r in rs if r["wrong"] and not r["warned"]]
        warned = [r["seed"] for r in rs if r["warned"]]
        hw = {n: float(np.median([r["half_width"][n] for r in rs])) for n in names}
        jw = {n: float(np.median([r["joint_half_width"][n] for r in rs])) for n in names}
        secs = [r["seconds"] for r in rs]
        out.append(f"{eff}: {len(rs)} runs (seeds {min(r['seed'] for r in rs)}..{max(r['seed'] for r in rs)}); wrong without a "
                   f"warning {len(silent)} {silent}; warned {len(warned)} {warned}; calibrate {min(secs):.1f}-{max(secs):.1f} s")
        out.append("  median half-width % of truth: " + ", ".join(f"{n} {100 * hw[n]:.2f}" for n in names))
        out.append("  median joint half-width %:    " + ", ".join(f"{n} {100 * jw[n]:.2f}" for n in names))
        if base is not None and eff in base:
            bh, bj = base[eff]
            out.append("  ratio to --compare (per-parameter / joint): "
                       + ", ".join(f"{n} {hw[n] / bh[n]:.2f}/{jw[n] / bj[n]:.2f}" for n in names))
    return out


def medians(rows, names) -> dict:
    """effect -> (median half-widths, median joint half-widths) per parameter."""
    out = {}
    for eff in dict.fromkeys(r["effect"] for r in rows):
        rs = [r for r in rows if r["effect"] == eff]
        out[eff] = tuple({n: float(np.median([r[k][n] for r in rs])) for n in names} for k in ("half_width", "joint_half_width"))
    return out


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--effects", default="control,backlash_8")
    ap.add_argument("--seed0", type=int, default=7100)
    ap.add_argument("--seeds", type=int, default=8)
    ap.add_argument("--job", default="cushion-test")
    ap.add_argument("--out", default=None)
    ap.add_argument("--compare", default=None, help="JSON lines of another run on the same seeds")
    args = ap.parse_args()
    press, job = load_press(), load_job(args.job)
    cs = CalibrationSettings.from_job(job)
    prob = CalibrationProblem.from_press(press, cs.parameters, cs.weight)
    base = ExperimentSettings.from_job(job)
    tmp = Path(tempfile.mkdtemp(prefix="check_lost_motion_"))
    rows = []
    sink = open(args.out, "w") if args.out else None
    print(f"SYNTHETIC logs: job {job.name}; seeds {args.seed0}..{args.seed0 + args.seeds - 1}; effects {args.effects}", flush=True)
    for eff in args.effects.split(","):
        for seed in range(args.seed0, args.seed0 + args.seeds):
            rec = run_one(press, job, cs, prob, base, eff, seed, tmp)
            rows.append(rec)
            line = json.dumps(rec)
            print(line, flush=True)
            if sink:
                sink.write(line + "\n")
                sink.flush()
    other = None
    if args.compare:
        prev = [json.loads(s) for s in Path(args.compare).read_text().splitlines() if s.strip()]
        other = medians(prev, prob.names)
    print("\n" + "\n".join(summary(rows, prob.names, other)))
    return 0


if __name__ == "__main__":
    sys.exit(main())
