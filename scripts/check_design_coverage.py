"""Do the design's predicted intervals come true? Achieved against predicted half-widths, and coverage, on SYNTHETIC logs.

    python scripts/check_design_coverage.py [--seeds 20] [--runs 2] [--press reference] [--job cushion-test]
                                            [--noise-sigma 150] [--noise-ar1 0.0] [--no-ringing]
                                            [--no-force-column] [--force-noise F] [--work DIR]

The workflow of a real press, all on SYNTHETIC logs (seed and truth labelled in each log's sidecar):
1. a first calibration: the job's own run (the single cushion test) logged by `experiment` (seed 0) and calibrated;
   its calibrated.json is written to WORK;
2. the design: `design-experiment --calibrated WORK/first/calibrated.json` (the noise level and AR(1) inflation of
   that calibration, not the job's keys; the playback is left out);
3. for each seed 1..N: every designed run logged by `experiment` with the same noise (the job's [experiment]
   noise, or --noise-sigma / --noise-ar1 for both the first log and the runs; the cushion's force logged as the job's
   [experiment] says, or --no-force-column for none, with --force-noise times its peak as the force channel's noise
   per sample) and calibrated jointly, as
   `calibrate --log run1.csv --job run_1/job.toml --log run2.csv --job run_2/job.toml` does.
The truth is the job's [experiment.truth] throughout; nothing is fitted to it. WORK (default out/check_design_coverage)
holds the logs, the first calibration and the runs' jobs; a rerun replaces them (the logs only if they are SYNTHETIC).

Printed per parameter: the predicted 95 % half-width (prediction.json's design), the achieved reported half-widths
(calibrate's `intervals`) as median and range of their ratio to the prediction, the Jacobian intervals' median
ratio, the estimates' own spread (t x their standard deviation over the seeds, what an interval should be), and
how many of the seeds' reported intervals hold the truth (95 % of N expected; a binomial two-sided p-value).
"""
from __future__ import annotations

import argparse
import dataclasses
import sys
import time
from pathlib import Path

import numpy as np
from scipy import stats

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from press_model.jobs import load_job  # noqa: E402
from press_io.outputs import write_json  # noqa: E402
from press_model.press_data import load_press  # noqa: E402

from calibration.design.noise import noise_from_calibrated  # noqa: E402
from calibration.design.report import design_experiment, run_job  # noqa: E402
from calibration.identification.record import result_record  # noqa: E402
from calibration.identification.run import calibrate  # noqa: E402
from calibration.synthetic.experiment import ExperimentSettings, experiment_truth, write_experiment  # noqa: E402


@dataclasses.dataclass(frozen=True)
class SeedResult:
    seed: int
    x: np.ndarray  # estimates, SI
    reported: np.ndarray  # (k, 2) calibrate's intervals
    jacobian: np.ndarray  # (k, 2) intervals_jacobian
    seconds: float


def experiment_settings(job, args) -> ExperimentSettings:
    """The job's [experiment] with the command line's noise and ringing."""
    st = ExperimentSettings.from_job(job)
    if args.noise_sigma is not None:
        st = dataclasses.replace(st, noise_sigma=args.noise_sigma)
    if args.noise_ar1:
        st = dataclasses.replace(st, effects=dataclasses.replace(st.effects, noise_ar1_rho=args.noise_ar1))
    if args.no_ringing:
        st = dataclasses.replace(st, oscillation=0.0)
    if args.no_force_column:
        st = dataclasses.replace(st, force_logged=False)
    if args.force_noise is not None:
        st = dataclasses.replace(st, force_noise_of_peak=args.force_noise)
    return st


def first_calibration(press, job, args, work: Path) -> Path:
    """Step 1: the job's own run logged (seed 0) and calibrated; returns the path of its calibrated.json."""
    log = work / "first" / "cushion_test_seed0.csv"
    write_experiment(press, job, experiment_truth(press, job, None), 0, log, settings=experiment_settings(job, args))
    cal = calibrate(press, job, log, ["aco"], 0, progress=False)
    out = work / "first" / "calibrated.json"
    write_json(out, result_record(cal, press, job, 0))
    return out


def joint_calibration(press, jobs, truth, seed: int, args, work: Path) -> SeedResult:
    """Step 3 for one seed: every designed run logged with ``seed`` and all calibrated together."""
    logs = []
    for i, jb in enumerate(jobs):
        log = work / "logs" / f"run_{i + 1}_seed{seed}.csv"
        write_experiment(press, jb, truth, seed, log, settings=experiment_settings(jb, args))
        logs.append(log)
    t0 = time.perf_counter()
    cal = calibrate(press, jobs[0], logs[0], ["aco"], seed, progress=False, more_logs=list(zip(logs[1:], jobs[1:])))
    dt = time.perf_counter() - t0
    rec = result_record(cal, press, jobs[0], seed)
    names = list(rec["parameters"])
    return SeedResult(seed, np.array([rec["parameters"][n] for n in names]), np.array([rec["intervals"][n] for n in names]),
                      np.array([rec["intervals_jacobian"][n] for n in names]), dt)


def table(names, predicted: np.ndarray, truth: np.ndarray, results: list[SeedResult], level: float) -> list[str]:
    """The printed table (module docstring); the last line says whether the targets hold."""
    X = np.array([r.x for r in results])
    hr = np.array([(r.reported[:, 1] - r.reported[:, 0]) / 2.0 for r in results]) / predicted
    hj = np.array([(r.jacobian[:, 1] - r.jacobian[:, 0]) / 2.0 for r in results]) / predicted
    holds = np.array([(r.reported[:, 0] <= truth) & (truth <= r.reported[:, 1]) for r in results])
    n = len(results)
    t = float(stats.t.ppf(0.5 + level / 2.0, max(n - 1, 1)))
    spread = t * X.std(axis=0, ddof=1) / predicted if n > 1 else np.full(len(names), np.nan)
    bias = (np.median(X, axis=0) - truth) / predicted
    lines = [f"{'parameter':>9} {'predicted':>10} {'reported/pred':>22} {'jacobian/pred':>13} {'spread/pred':>11} "
             f"{'median err/pred':>15} {'holds truth':>11} {'p':>6}"]
    ok = True
    for j, name in enumerate(names):
        k = int(holds[:, j].sum())
        p = float(stats.binomtest(k, n, level).pvalue)
        med = float(np.median(hr[:, j]))
        ok &= 0.67 <= med <= 1.5 and p >= 0.01
        lines.append(f"{name:>9} {predicted[j]:>10.4g} {med:>6.2f} ({hr[:, j].min():.2f}..{hr[:, j].max():.2f}) "
                     f"{float(np.median(hj[:, j])):>13.2f} {spread[j]:>11.2f} {bias[j]:>+15.2f} {k:>7}/{n:<3} {p:>6.2g}")
    lines.append(f"all at once (every reported interval holds its truth): {int(holds.all(axis=1).sum())}/{n}; "
                 f"calibrate took {np.median([r.seconds for r in results]):.1f} s per seed (median)")
    scatter_ok = bool(np.all((spread >= 0.67) & (spread <= 1.5)))
    lines.append(f"the estimates' scatter against the prediction (spread/pred in [0.67, 1.5] for every parameter): "
                 f"{'MET' if scatter_ok else 'NOT MET'}")
    lines.append(f"targets (median reported/predicted in [0.67, 1.5], coverage consistent with {100 * level:g} % at p >= 0.01): "
                 f"{'MET' if ok else 'NOT MET'}")
    return lines


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=20, help="seeds 1..N of the designed runs' logs (default 20)")
    ap.add_argument("--runs", type=int, default=None, help="runs of the design (default the job's [design] runs)")
    ap.add_argument("--press", default="reference", help="press file or built-in name (default reference)")
    ap.add_argument("--job", default="cushion-test", help="job whose own run is the first calibration's (default cushion-test)")
    ap.add_argument("--noise-sigma", type=float, default=None, help="per-sample white noise, N m (default the job's [experiment])")
    ap.add_argument("--noise-ar1", type=float, default=0.0, help="per-sample AR(1) lag-one correlation of the noise (default 0)")
    ap.add_argument("--no-ringing", action="store_true", help="no die-contact ringing in the logs (default: the job's)")
    ap.add_argument("--no-force-column", action="store_true",
                    help="logs without process_force_N (default: the job's [experiment] process_force_logged)")
    ap.add_argument("--force-noise", type=float, default=None,
                    help="process_force_N noise per sample over the force's peak (default the job's [experiment])")
    ap.add_argument("--work", type=Path, default=Path("out/check_design_coverage"),
                    help="folder of the logs and calibrations (default out/check_design_coverage)")
    args = ap.parse_args()
    press, job = load_press(args.press), load_job(args.job)
    args.work.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    calibrated = first_calibration(press, job, args, args.work)
    noise = noise_from_calibrated(calibrated, press)
    design = design_experiment(press, job, runs=args.runs, noise=noise)
    run_jobs = []
    for i, rc in enumerate(design.result.runs):
        path = args.work / "design" / f"run_{i + 1}" / "job.toml"
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(run_job(design, i + 1, rc))
        run_jobs.append(load_job(str(path)))
    names = design.problem.names
    truth_d = experiment_truth(press, job, None)
    truth = np.array([truth_d[n] for n in names])
    predicted = design.prediction.half_width
    write_json(args.work / "prediction.json", {"design": design.prediction.record(), "runs": [rc.run.record() for rc in design.result.runs]})
    print(f"SYNTHETIC logs; press {press.name}; job {job.source}; first calibration {calibrated}: noise "
          f"{noise.describe()}; design of {len(run_jobs)} runs in {time.perf_counter() - t0:.0f} s")
    results = []
    for seed in range(1, args.seeds + 1):
        results.append(joint_calibration(press, run_jobs, truth_d, seed, args, args.work))
        sys.stderr.write(f"  seed {seed}: {results[-1].seconds:.1f} s\n")
    print("\n".join(table(names, predicted, truth, results, design.calibration.interval_level)))
    return 0


if __name__ == "__main__":
    sys.exit(main())
