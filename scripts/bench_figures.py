#!/usr/bin/env python
"""Benchmark: drawing and saving figures, in-process: `plan`'s torque, speed and power figures from a plan's output
folder and a four-panel Sobol figure (fixed indices; its axes placed by a tight layout), each made and saved as PNG.

Prints, per figure, the CPU seconds of one figure made and saved (median and best of several, after one that loads the
fonts). Usage: python scripts/bench_figures.py PLAN_DIR [--repeat 5], PLAN_DIR a `servo-press plan --out PLAN_DIR`
folder (profile.csv, power.csv, summary.json). With PYTHONPATH set to another checkout it times that checkout's code.
"""
import argparse
import csv
import json
import statistics
import tempfile
import time
from pathlib import Path

import numpy as np


def columns(path: Path) -> dict:
    """The CSV file's columns as float arrays, by header."""
    with path.open(encoding="utf-8") as f:
        rows = list(csv.reader(f))
    return {h: np.array([float(r[i]) for r in rows[1:]]) for i, h in enumerate(rows[0])}


def main():
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("plan_dir", type=Path)
    ap.add_argument("--repeat", type=int, default=5)
    args = ap.parse_args()

    from calibration.sensitivity.sobol import Indices, figure as sobol_figure
    from planning.figures import speed_figure, torque_figure
    from press_model.plots import power_figure, save
    from press_model.press_data import load_press
    from press_model.torque_limits import TorqueLimits

    profile, power = columns(args.plan_dir / "profile.csv"), columns(args.plan_dir / "power.csv")
    rms = json.loads((args.plan_dir / "summary.json").read_text(encoding="utf-8")).get("rms_torque_Nm", 0.0)
    motor = load_press(None).motor
    limits = TorqueLimits(motor.peak_torque, 0.9)
    rng = np.random.default_rng(0)
    names = ("eta_gear", "mu_r", "m8", "psi", "J_gear", "mu_s")
    indices = [Indices(r, names, rng.random(6), 0.1 * rng.random(6), rng.random(6), 0.1 * rng.random(6))
               for r in ("Y_RMSE", "Y_PR", "Y_TL", "Y_Work")]
    t = profile["time_s"]
    makers = {
        "torque": lambda: torque_figure([("motor torque", t, profile["motor_torque_Nm"], rms)], limits, motor.rated_torque, "torque"),
        "speed": lambda: speed_figure([("plan", t, profile["crank_speed_rad_s"], profile["crank_accel_rad_s2"])], 40.0, 1500.0, "speed"),
        "power": lambda: power_figure(power, (900.0, 1100.0), "power"),
        "sobol": lambda: sobol_figure(indices, "Sobol indices"),
    }
    out = Path(tempfile.mkdtemp(prefix="bench_figures_"))
    for name, make in makers.items():
        save(make(), out / f"{name}.png")  # fonts loaded, caches warm
        seconds = []
        for _ in range(args.repeat):
            t0 = time.process_time()
            save(make(), out / f"{name}.png")
            seconds.append(time.process_time() - t0)
        print(f"{name:7s} CPU per figure made and saved: median {statistics.median(seconds):.3f} s, best {min(seconds):.3f} s")
    print(f"PNGs in {out}")


if __name__ == "__main__":
    main()
