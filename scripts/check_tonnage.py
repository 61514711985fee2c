#!/usr/bin/env python
"""Check: the virtual tonnage against the force a SYNTHETIC cushion test logged, on logs the calibration did not see.

The calibration is made as the command makes it on the experiment's seed-0 log (the shipped cushion test: 3 strokes at
500 Hz, the force logged with its noise, a 3,000 N m ringing at die contact). For each of --seeds further seeds (the same
truth, the paper's Table 4; new noise) and, with --effect NAME=VALUE, a SYNTHETIC effect of a real log (as `servo-press
experiment --effect`), the log's force is estimated from its torque alone (monitoring/tonnage.py) and compared with the
logged force (its own bin means, which carry the cushion channel's noise: the difference is judged against both
uncertainties together). Printed per log: the observable points, the share of them whose difference lies within the
combined 95 % interval, each complete stroke's peak (running median, both curves alike) against the logged one.
--figure writes the first log's estimate, interval and logged force over the crank angle, the points not observable
shaded.
--press and --job run it on another press and its cushion job (e.g. --press crank-slider --job crank-slider-cushion);
where the job's peak zone is not observable on that press (monitoring/strokes.py peak_seen) no peak is compared.
Usage: python scripts/check_tonnage.py [--seeds 5] [--seed0 1] [--press FILE] [--job FILE] [--effect NAME=VALUE ...]
       [--figure tonnage.png]
"""
import argparse
import contextlib
import io
import json
import math
import tempfile
from pathlib import Path

import numpy as np


def _cli(*argv):
    from servo_press.cli import main

    with contextlib.redirect_stdout(io.StringIO()) as out:
        code = main([str(a) for a in argv])
    if code != 0:
        raise SystemExit(f"servo-press {' '.join(map(str, argv))} failed ({code}): {out.getvalue()}")


def figure(log, lt, path: Path) -> None:
    from press_model.plots import save, subplots, tight_layout

    deg = np.degrees(lt.fmap.theta)
    logged = np.asarray(log.stroke_force_binned, float)[lt.rows[0]]
    est = lt.est
    fig, ax = subplots(figsize=(9, 4))
    ax.fill_between(deg, est.low[0] / 1e3, est.high[0] / 1e3, color="C0", alpha=0.25, lw=0, label="95 % interval")
    ax.plot(deg, est.force[0] / 1e3, color="C0", lw=1, label="virtual tonnage (from the torque)")
    ax.plot(deg, logged / 1e3, color="k", lw=0.8, ls="--", label="logged force (SYNTHETIC, with its noise)")
    for a, b in _runs(~est.observable):
        ax.axvspan(deg[a], deg[b], color="0.85", lw=0, zorder=0)
    ax.set_ylim(-0.5 * lt.fmap.job_force / 1e3, 1.5 * lt.fmap.job_force / 1e3)
    ax.set_xlabel("crank angle (deg); grey: force not observable (dead centre, contact transient)")
    ax.set_ylabel("force on the slide (kN)")
    ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8)
    tight_layout(fig)
    save(fig, path)


def _runs(mask):
    idx = np.flatnonzero(mask)
    if not idx.size:
        return []
    cuts = np.flatnonzero(np.diff(idx) > 1)
    starts, ends = np.r_[idx[0], idx[cuts + 1]], np.r_[idx[cuts], idx[-1]]
    return list(zip(starts, ends))


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[1])
    ap.add_argument("--seeds", type=int, default=5)
    ap.add_argument("--seed0", type=int, default=1)
    ap.add_argument("--press", default=None, help="press file or built-in name (default: the reference press)")
    ap.add_argument("--job", default="cushion-test", help="its cushion job (default: cushion-test)")
    ap.add_argument("--effect", action="append", default=[], metavar="NAME=VALUE")
    ap.add_argument("--figure", default=None, metavar="PNG")
    args = ap.parse_args()
    from calibration.traces.drive_log import read_drive_log
    from monitoring.rules import load_rules
    from monitoring.strokes import log_tonnage, peak_seen, peak_zone
    from monitoring.tonnage import Z95, running_median
    from press_model.jobs import load_job
    from press_model.model import PressModel
    from press_model.press_data import load_press

    press, job, rules = load_press(args.press), load_job(args.job), load_rules()
    where = ["--job", args.job] + (["--press", args.press] if args.press else [])
    pm = PressModel(press)
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        _cli("experiment", *where, "--seed", 0, "--out", tmp / "seed0.csv")
        _cli("calibrate", *where, "--log", tmp / "seed0.csv", "--out", tmp / "cal")
        cal = json.loads((tmp / "cal" / "calibrated.json").read_text(encoding="utf-8"))
        box = {k: tuple(v) for k, v in cal["joint_region"]["box"].items()}
        worst_cover, worst_peak, compared = 1.0, 0.0, 0
        for seed in range(args.seed0, args.seed0 + args.seeds):
            path = tmp / f"log{seed}.csv"
            _cli("experiment", *where, "--seed", seed, *sum((["--effect", e] for e in args.effect), []), "--out", path)
            log = read_drive_log(path, press.drive.gear_ratio, press.motor.rated_torque)
            lt = log_tonnage(press, job, cal["parameters"], box, log, rules, pm=pm)
            logged = np.asarray(log.stroke_force_binned, float)[lt.rows]
            noise = math.sqrt(np.nanmean(np.nanvar(logged, axis=0, ddof=1)))
            ok = lt.est.observable[None, :] & np.isfinite(logged)
            cover = float((np.abs(lt.est.force - logged) <= np.hypot(lt.est.half_width, Z95 * noise))[ok].mean())
            k = rules.tonnage.peak_median_points
            peak = np.nanmax(np.where(lt.est.observable, running_median(lt.est.force, k), np.nan), axis=1)
            truth = np.nanmax(np.where(lt.est.observable, running_median(logged, k), np.nan), axis=1)
            err = peak / truth - 1.0
            if not peak_seen(peak_zone(lt.fmap, job, rules), lt.est.observable, rules):
                err = np.full_like(err, np.nan)  # the largest observable force is not the stroke's peak: nothing to compare
            compared += int(np.isfinite(err).sum())
            worst_cover, worst_peak = min(worst_cover, cover), max(worst_peak, float(np.nanmax(np.abs(err), initial=0.0)))
            print(f"seed {seed}: {int(lt.est.observable.sum())} of {lt.est.observable.size} points observable; within the "
                  f"95 % interval {100 * cover:.1f} %; peaks {', '.join(f'{p / 1e3:.0f}' for p in peak)} kN against "
                  f"{', '.join(f'{t / 1e3:.0f}' for t in truth)} kN ({', '.join(f'{100 * e:+.2f} %' for e in err)}; nan: the peak not observable)", flush=True)
            if args.figure and seed == args.seed0:
                figure(log, lt, Path(args.figure))
        peaks = f"peak {100 * worst_peak:.2f} % off (target <= 2 %)" if compared else "no peak observable, none compared"
        print(f"worst: {100 * worst_cover:.1f} % within (target >= 95 %), {peaks}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
