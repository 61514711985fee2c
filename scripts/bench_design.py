"""Designed calibration runs against what calibration achieves on SYNTHETIC logs of them.

    python scripts/bench_design.py DESIGN_DIR [--press reference] [--seeds 1 2 3] [--joint]

DESIGN_DIR is the folder of `servo-press design-experiment`. For each seed, each run's job writes a SYNTHETIC log
(`servo-press experiment --job run_N/job.toml --seed S`, truth: the job's [experiment.truth]), which is calibrated
alone (`servo-press calibrate --job run_N/job.toml`) and, with --joint, all runs' logs together (`calibrate --log A
--job a --log B --job b`, the several-runs calibration). Printed per parameter: the predicted 95 % half-width
(prediction.json, the run alone or the design; they carry the uncertainty of the recording's delay and offset, as
calibrate's intervals do since they add the recording correction's in quadrature) and the achieved half-widths, both the linearised least-squares
intervals (`intervals_jacobian`) and the reported ones (`intervals`), their ratio
to the prediction (Eq. 28's estimate's, for the noise of the stroke-averaged curve: scripts/check_design_coverage.py
checks it over many seeds), and whether the reported interval holds the truth. Nothing here is fitted to the truth.
"""
from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time
from pathlib import Path


def run(cmd: list[str]) -> None:
    res = subprocess.run(cmd, capture_output=True, text=True)
    if res.returncode not in (0,):
        sys.stderr.write(res.stdout + res.stderr)
        raise SystemExit(f"failed: {' '.join(cmd)}")


def half_widths(rec: dict, key: str) -> dict:
    return {n: (b - a) / 2.0 for n, (a, b) in rec[key].items()}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("design", type=Path)
    ap.add_argument("--press", default=None)
    ap.add_argument("--seeds", type=int, nargs="+", default=[1, 2, 3])
    ap.add_argument("--joint", action="store_true", help="also calibrate all runs' logs together (needs the several-runs calibrate)")
    ap.add_argument("--work", type=Path, default=None, help="folder for the logs and calibrations (default: DESIGN_DIR/bench)")
    args = ap.parse_args()
    pred = json.loads((args.design / "prediction.json").read_text())
    runs = pred["design"]["runs"]
    names = pred["parameters"]
    work = args.work or args.design.parent / (args.design.name + "_bench")
    work.mkdir(parents=True, exist_ok=True)
    press = ["--press", args.press] if args.press else []
    rows = []
    for seed in args.seeds:
        logs = []
        for r in runs:
            job = str(args.design / r["folder"] / "job.toml")
            log = work / f"{r['folder']}_seed{seed}.csv"
            run(["servo-press", "experiment", *press, "--job", job, "--seed", str(seed), "--out", str(log)])
            logs.append((log, job))
            t0 = time.perf_counter()
            out = work / f"cal_{r['folder']}_seed{seed}"
            run(["servo-press", "calibrate", *press, "--job", job, "--log", str(log), "--out", str(out)])
            rows.append((f"{r['folder']} alone", seed, r["alone"]["half_widths"], json.loads((out / "calibrated.json").read_text()),
                         json.loads(log.with_suffix(".truth.json").read_text())["truth"], time.perf_counter() - t0))
        if args.joint:
            cmd = ["servo-press", "calibrate", *press]
            for log, job in logs:
                cmd += ["--log", str(log), "--job", job]
            out = work / f"cal_joint_seed{seed}"
            t0 = time.perf_counter()
            run(cmd + ["--out", str(out)])
            rows.append(("design (joint)", seed, pred["design"]["half_widths"], json.loads((out / "calibrated.json").read_text()),
                         json.loads(logs[0][0].with_suffix(".truth.json").read_text())["truth"], time.perf_counter() - t0))
    print("SYNTHETIC logs (experiment of each run's job; truth = the job's [experiment.truth]); seeds", args.seeds)
    print(f"{'fit':<16} {'seed':>4} {'parameter':>9} {'predicted':>11} {'jacobian':>11} {'ratio':>6} {'reported':>11} {'ratio':>6} {'holds truth':>11}")
    ratios_j, ratios_r = [], []
    for fit, seed, hp, rec, truth, dt in rows:
        hj, hr = half_widths(rec, "intervals_jacobian"), half_widths(rec, "intervals")
        for n in names:
            lo, hi = rec["intervals"][n]
            holds = lo <= truth[n] <= hi if n in truth else None
            ratios_j.append(hj[n] / hp[n])
            ratios_r.append(hr[n] / hp[n])
            print(f"{fit:<16} {seed:>4} {n:>9} {hp[n]:>11.4g} {hj[n]:>11.4g} {hj[n] / hp[n]:>6.2f} {hr[n]:>11.4g} {hr[n] / hp[n]:>6.2f} {str(holds):>11}")
        corr = rec["correlation_jacobian"]["matrix"]
        k = len(corr)
        worst = max(abs(corr[i][j]) for i in range(k) for j in range(k) if i != j)
        print(f"{fit:<16} {seed:>4} largest |correlation| (Jacobian) {worst:.2f}; calibrate took {dt:.1f} s")
    print(f"achieved / predicted half-width: Jacobian {min(ratios_j):.2f}..{max(ratios_j):.2f}, reported {min(ratios_r):.2f}..{max(ratios_r):.2f} "
          f"(within 2x: {all(0.5 <= r <= 2.0 for r in ratios_j)} / {all(0.5 <= r <= 2.0 for r in ratios_r)})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
