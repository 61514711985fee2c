#!/usr/bin/env python
"""Benchmark: coverage of the calibration's 95 % intervals on SYNTHETIC logs with random truths.

For each log i (seed = --seed0 + i): a random truth of the six key parameters, uniform over the middle
80 % of each calibration range (drawn with numpy's default_rng(seed)); the synthetic servo-cushion log of
the job with that truth and that noise seed (`calibration.synthetic.experiment.write_experiment`); the calibration
with the job's default method and its intervals. Counts how often each parameter's interval holds the
truth: the reported interval (`intervals` of calibrated.json: the parametric bootstrap's basic interval
widened by the window shift and the recording correction's uncertainty, joined with the Jacobian interval on a
bound or under coloured noise, and widened by the job's [calibration.bootstrap.allowance] if it sets one; the
shipped job sets none), the basic interval alone, the plain percentile
interval of the same refits, and, as a second opinion, the Jacobian intervals (`intervals_jacobian`).
Target ~95 %. Prints each log's seed, truth and hits, then the coverage per parameter with a 95 % Wilson
interval for the count and a two-sided binomial test of it against the level (with 40 logs, coverage of 95 %
reads anywhere from about 83 to 99 %). Then, per parameter, the RMS of error / (half-width / 1.96) (about 1 for honest
intervals), and how many runs' joint region missed a truth without a warning (issue 32's criterion).

Two questions, two figures (calibrated.json `intervals_question`, `joint_region`): each per-parameter interval is
meant to hold its own truth in 95 % of logs (one parameter at a time: the per-parameter coverage above); the joint
region (`joint_region.box`) to hold all six truths at once in at least 95 % of logs: the share of logs whose joint
region holds every truth, beside the share whose six per-parameter intervals all hold (0.95^6 = 74 % if they were
independent and exact). No constant here or in the method is chosen to make either pass.

--fit-allowance prints, per parameter, the smallest widening of the basic interval (a fraction of the range,
on each side) that makes it hold the truth on ceil(level x logs) of these logs: how an earlier allowance was
fitted to the synthetic ringing (seeds 2000-2039). The shipped job has none; the window shift measured on each
log took its place. Kept to show what such a fit would call for, not to set one.

--force-noise F writes the logs' process_force_N with white noise of F times the force's peak per sample (default the
job's [experiment] process_force_noise_of_peak): the logged force's noise, which the intervals carry
(calibration/identification/force_noise.py), made large enough to matter.

Usage: python scripts/bench_coverage.py [--logs 40] [--seed0 1000] [--force-noise F] [--fit-allowance] [--dump DIR]
"""
import argparse
import dataclasses
import math
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from scipy import stats

from calibration.synthetic.experiment import ExperimentSettings, write_experiment
from calibration.identification.problem import CalibrationProblem
from calibration.identification.run import calibrate
from calibration.identification.settings import CalibrationSettings
from press_model.jobs import load_job
from press_model.press_data import load_press


def wilson(k: int, n: int, z: float = 1.96) -> tuple[float, float]:
    p = k / n
    c = (p + z * z / (2 * n)) / (1 + z * z / n)
    h = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / (1 + z * z / n)
    return c - h, c + h


def marks(h) -> str:
    return "".join("x" if v else "." for v in h)


def coverage_lines(hits: np.ndarray, joint: np.ndarray, names, level: float, label: str) -> list[str]:
    """The two figures for ``label`` runs: per parameter, how often its interval held the truth (hits (n, k) bool),
    with a Wilson interval and a two-sided binomial test against ``level`` (the runs are independent, so the count
    is binomial); and the share of runs whose joint region held every truth (joint (n,) bool), beside the share whose
    per-parameter intervals all held."""
    n, k = hits.shape
    out = [f"one parameter at a time ({label}: {n} runs; each interval should hold its truth in {100 * level:g} %, binomial check):"]
    for j, nm in enumerate(names):
        c = int(hits[:, j].sum())
        lo, hi = wilson(c, n)
        out.append(f"  {nm:>10} {c:>3} of {n} ({100 * c / n:5.1f} %, Wilson [{100 * lo:.0f}, {100 * hi:.0f}] %, binomial p = "
                   f"{stats.binomtest(c, n, level).pvalue:.2g})")
    c = int(hits.sum())
    out.append(f"  {'all':>10} {c:>3} of {hits.size} ({100 * c / hits.size:.1f} %; no binomial test: one run's six are not independent)")
    cj, ca = int(joint.sum()), int(hits.all(axis=1).sum())
    lo, hi = wilson(cj, n)
    out.append(f"all parameters at once: the joint region held every truth in {cj} of {n} runs ({100 * cj / n:.1f} %, Wilson "
               f"[{100 * lo:.0f}, {100 * hi:.0f}] %, target >= {100 * level:g} %, binomial p = {stats.binomtest(cj, n, level).pvalue:.2g}); "
               f"the per-parameter intervals all held in {ca} of {n} ({100 * ca / n:.1f} %; {100 * level ** k:.0f} % if independent and exact)")
    return out


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--logs", type=int, default=40)
    ap.add_argument("--seed0", type=int, default=1000)
    ap.add_argument("--job", default="cushion-test")
    ap.add_argument("--force-noise", type=float, default=None,
                    help="process_force_N noise per sample over the force's peak (default the job's [experiment])")
    ap.add_argument("--fit-allowance", action="store_true", help="print the allowance these logs call for (fit on seeds you do not report)")
    ap.add_argument("--dump", default=None, help="folder for each log and its raw results (<seed>.npz: truth, estimate, refits)")
    args = ap.parse_args()
    press, job = load_press(), load_job(args.job)
    cs = CalibrationSettings.from_job(job)
    st = ExperimentSettings.from_job(job)
    if args.force_noise is not None:
        st = dataclasses.replace(st, force_noise_of_peak=args.force_noise)
    prob = CalibrationProblem.from_press(press, cs.parameters, cs.weight)
    names, span = prob.names, prob.high - prob.low
    tmp = Path(args.dump) if args.dump else Path(tempfile.mkdtemp(prefix="bench_coverage_"))
    tmp.mkdir(parents=True, exist_ok=True)
    n, k = args.logs, len(names)
    hits = {c: np.zeros((n, k), dtype=bool) for c in ("reported", "basic", "percentile", "jacobian", "joint", "jacobian_joint")}
    width = np.zeros((n, k))
    err = np.zeros((n, k))
    z = np.zeros((n, k))  # error / (reported half-width / 1.96): about unit RMS for honest intervals
    warned = np.zeros(n, dtype=bool)
    need = np.zeros((n, k))  # widening of the basic interval that this log needs, fraction of the range
    print(f"SYNTHETIC logs: job {job.name}, method {cs.default_method}, {cs.bootstrap.refits} bootstrap refits, allowance "
          + ", ".join(f"{nm} {cs.bootstrap.allowance.get(nm, 0.0):g}" for nm in names)
          + f"; process_force_N noise {st.force_noise_of_peak:g} of its peak; truths uniform over the middle 80 % of each range; seeds {args.seed0}..{args.seed0 + n - 1}", flush=True)
    t_all, t_cal = time.perf_counter(), []
    for i in range(n):
        seed = args.seed0 + i
        rng = np.random.default_rng(seed)
        truth_v = prob.low + (0.1 + 0.8 * rng.random(k)) * span
        truth = {nm: float(v) for nm, v in zip(names, truth_v)}
        log = tmp / f"log_{seed}.csv"
        write_experiment(press, job, truth, seed, log, settings=st)
        t0 = time.perf_counter()
        cal = calibrate(press, job, log, [cs.default_method], seed, progress=False)
        t_cal.append(time.perf_counter() - t0)
        b, u = cal.bootstrap, cal.uncertainty
        for c, (lo, hi) in {"reported": (b.low, b.high), "basic": (b.low_basic, b.high_basic),
                            "percentile": (b.low_percentile, b.high_percentile), "jacobian": (u.low, u.high),
                            "joint": (b.joint_low, b.joint_high), "jacobian_joint": (u.joint_low, u.joint_high)}.items():
            hits[c][i] = (lo <= truth_v) & (truth_v <= hi)
        width[i] = (b.high - b.low) / span
        z[i] = (cal.best.x - truth_v) / ((b.high - b.low) / 2.0 / 1.96)
        warned[i] = bool(cal.warnings)
        err[i] = (cal.best.x - truth_v) / span
        need[i] = np.maximum(0.0, np.maximum(b.low_basic - truth_v, truth_v - b.high_basic)) / span
        if args.dump:
            np.savez(tmp / f"{seed}.npz", truth=truth_v, x_hat=cal.best.x, refits=b.estimates, low=b.low, high=b.high,
                     jac_low=u.low, jac_high=u.high, span=span, bound_low=prob.low, bound_high=prob.high)
        shift = (b.estimates.mean(axis=0) - cal.best.x) / span
        print(f"seed {seed}: truth " + ", ".join(f"{nm}={truth[nm]:.5g}" for nm in names)
              + f"; Eq. 28 {cal.best.objective:.5f}; hits: reported {marks(hits['reported'][i])}, basic {marks(hits['basic'][i])}, "
              f"percentile {marks(hits['percentile'][i])}, jacobian {marks(hits['jacobian'][i])}, joint region "
              f"{'holds all' if hits['joint'][i].all() else 'MISSES ' + marks(hits['joint'][i])}; error/range "
              + " ".join(f"{e:+.4f}" for e in err[i]) + "; bootstrap mean - estimate, /range " + " ".join(f"{s:+.4f}" for s in shift)
              + f"; {t_cal[-1]:.1f} s", flush=True)
    print(f"\ncoverage over {n} SYNTHETIC logs (seeds {args.seed0}..{args.seed0 + n - 1}), target {100 * cs.interval_level:g} %; "
          f"{time.perf_counter() - t_all:.0f} s in all, calibrate {np.median(t_cal):.1f} s median ({min(t_cal):.1f}-{max(t_cal):.1f} s)")
    print(f"{'parameter':>10} {'reported':>9} {'(Wilson 95 %)':>14} {'basic':>7} {'percentile':>10} {'jacobian':>9} "
          f"{'mean width/range':>17} {'bias/range':>11} {'rmse/range':>11}")
    for j, nm in enumerate(names):
        kr = int(hits["reported"][:, j].sum())
        lo, hi = wilson(kr, n)
        print(f"{nm:>10} {100 * kr / n:8.1f}% {f'[{100 * lo:.0f}, {100 * hi:.0f}] %':>14} "
              + " ".join(f"{100 * hits[c][:, j].mean():{w}.1f}%" for c, w in (("basic", 6), ("percentile", 9), ("jacobian", 8)))
              + f" {np.mean(width[:, j]):17.4f} {np.mean(err[:, j]):+11.5f} {np.sqrt(np.mean(err[:, j] ** 2)):11.5f}")
    kr = int(hits["reported"].sum())  # no Wilson interval: the six parameters of one log are not independent trials
    print(f"{'all':>10} {100 * kr / hits['reported'].size:8.1f}% {'':>14} "
          + " ".join(f"{100 * hits[c].mean():{w}.1f}%" for c, w in (("basic", 6), ("percentile", 9), ("jacobian", 8))))
    print()
    for line in coverage_lines(hits["reported"], hits["joint"].all(axis=1), names, cs.interval_level,
                               f"reported intervals, SYNTHETIC seeds {args.seed0}..{args.seed0 + n - 1}"):
        print(line)
    cj = int(hits["jacobian_joint"].all(axis=1).sum())
    print("RMS of error / (reported half-width / 1.96), about 1 for honest intervals: "
          + ", ".join(f"{nm} {v:.2f}" for nm, v in zip(names, np.sqrt(np.mean(z ** 2, axis=0)))))
    miss = ~hits["joint"].all(axis=1)
    print(f"joint region missed a truth in {int(miss.sum())} of {n} runs, {int((miss & ~warned).sum())} of them without a warning "
          f"({int(warned.sum())} runs warned)")
    print(f"second opinion: the Jacobian joint region (Sidak) held every truth in {cj} of {n} runs ({100 * cj / n:.1f} %)")
    if args.fit_allowance:
        m = math.ceil(cs.interval_level * n)  # the basic interval, so widened, holds the truth on m of the n logs
        fit = np.sort(need, axis=0)[m - 1]
        print(f"\nallowance fitted on these {n} logs (seeds {args.seed0}..{args.seed0 + n - 1}; the widening of the basic interval, "
              f"a fraction of the range on each side, that holds the truth on {m} of {n}):")
        for nm, a in zip(names, fit):
            print(f"{nm} = {math.ceil(a * 1000) / 1000:.3f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
