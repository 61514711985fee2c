#!/usr/bin/env python
"""The chain a user walks, checked on the press that made the log: SYNTHETIC log -> calibrate -> plan -> the true press.

For each seed a truth is drawn (each of the job's calibrated parameters uniform in the middle 60 % of its range in the
press file; seed and truth printed), and for each effect a SYNTHETIC cushion-test log is made with it
(`servo-press experiment`, calibration/synthetic), calibrated (`servo-press calibrate`, the job's six parameters) and
planned as README step 4 says (`servo-press plan --params calibrated.json`, no other flag: the default) and with
`--nominal`. Each plan's profile.csv (every 2 ms of the cycle, dwell included) is then played on the TRUE press: the
motor torque per motor that the truth's press needs for that crank motion, per sample on the per-point model
(press_model.kinematics.state_at + press_model.dynamics.inverse_dynamics + Eq. 16, not the planner's path dynamics),
plus the effect where the effect acts on the drive (the load-dependent efficiency and the viscous loss, applied as the
log generator applies them). The effects:

* ``clean``: nothing the model lacks beyond the log's ringing and noise;
* ``viscous``: a viscous drive loss whose RMS over the log is 2 % of the model torque's (its coefficient c, N m s/rad
  per motor, read off the log against the same seed's clean log; on the true press c x the motor speed is added);
* ``efficiency``: the gear efficiency falls 5 % at the motor's rated torque, linear in |torque|;
* ``cushion+4`` / ``cushion-4``: the cushion pushed 4 % above / below the force its job file states (the log is made with
  the scaled force, the calibration is told the job's): the door-panel job itself is unchanged.

Printed per row: seed, effect, the default plan's true peak / T_max and its rate, the same for `--nominal`, whether the
default `plan` printed a WARNING, and whether the row meets the issue's criterion (default plan's true peak <= the
10 % margin, 0.90 T_max, or a WARNING). Exit status 1 when a row fails it.

Usage: python scripts/check_chain.py [--seeds 1 2 3] [--effects clean viscous ...] [--work DIR] [--job door-panel]
"""
from __future__ import annotations

import argparse
import csv
import json
import math
import os
import re
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from calibration.synthetic.effects import load_dependent  # noqa: E402
from calibration.synthetic.experiment import ExperimentSettings, synthetic_log  # noqa: E402
from press_model.dynamics import inverse_dynamics, slide_loads  # noqa: E402
from press_model.jobs import load_job  # noqa: E402
from press_model.kinematics import state_at  # noqa: E402
from press_model.model import PressModel, Workspace  # noqa: E402
from press_model.motor import motor_torque  # noqa: E402
from press_model.params import apply_overrides  # noqa: E402
from press_model.press_data import load_press  # noqa: E402

CALIBRATION_JOB = "cushion-test"
# effect name -> (experiment --effect items, cushion force factor of the log, what it is)
EFFECTS = {
    "clean": ((), 1.0, "no effect the model lacks beyond ringing and noise"),
    "viscous": (("viscous_loss_of_rms=0.02",), 1.0, "viscous drive loss, RMS 2 % of the model torque's"),
    "efficiency": (("efficiency_drop_at_rated=0.05",), 1.0, "gear efficiency falling 5 % at rated torque"),
    "cushion+4": ((), 1.04, "cushion force 4 % above the job's"),
    "cushion-4": ((), 0.96, "cushion force 4 % below the job's"),
}
MARGIN = 0.90  # the criterion: the true press within the 10 % torque margin (peak_torque_margin)
MIDDLE = 0.6  # truths drawn in the middle 60 % of each parameter's range


def draw_truth(press, names, seed: int) -> dict:
    """Each parameter uniform in the middle ``MIDDLE`` of its press-file range (SI), from ``seed``."""
    rng = np.random.default_rng(seed)
    out = {}
    for n in names:
        p = press.parameters[n]
        out[n] = float(p.low + (0.5 - MIDDLE / 2 + MIDDLE * rng.uniform()) * (p.high - p.low))
    return out


def run_servo_press(args: list[str], cwd: Path) -> subprocess.CompletedProcess:
    """`python -m servo_press.cli args` of this checkout in a subprocess in the folder ``cwd``: its exit code and
    captured output (tests/test_plan_chain_on_true_press.py runs the same commands in its own process instead)."""
    env = dict(os.environ, PYTHONPATH=str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    return subprocess.run([sys.executable, "-m", "servo_press.cli", *args], cwd=cwd, env=env, capture_output=True, text=True)


def cli(*args, cwd: Path, refusal_ok: bool = False) -> subprocess.CompletedProcess:
    """One `servo-press` command (this checkout's code), its output captured; a failure stops the check (with
    ``refusal_ok`` not a refusal, exit status 2 with its `servo-press: error:` line: `plan` saying it cannot)."""
    res = run_servo_press([str(a) for a in args], cwd)
    if res.returncode not in (0, 3) and not (refusal_ok and res.returncode == 2 and "servo-press: error:" in res.stderr):
        raise SystemExit(f"servo-press {' '.join(map(str, args))} failed ({res.returncode}):\n{res.stderr}")
    return res


def cushion_job(factor: float, work: Path) -> str:
    """The calibration job's name, or a copy of its file with the cushion force scaled by ``factor``."""
    if factor == 1.0:
        return CALIBRATION_JOB
    import press_model.data

    text = (Path(press_model.data.__file__).parent / "cushion_test.toml").read_text()  # the built-in job's file
    forces = [float(v) * factor for v in re.search(r"forces_N\s*=\s*\[([^\]]*)\]", text).group(1).split(",")]
    text = re.sub(r"forces_N\s*=\s*\[[^\]]*\]", "forces_N = [" + ", ".join(f"{f:.6e}" for f in forces) + "]", text)
    path = work / f"cushion_x{factor:g}.toml"
    path.write_text(text)
    return str(path)


def viscous_coefficient(press, truth: dict, seed: int, items) -> float:
    """c (N m s/rad per motor at the motor shaft) of the log's viscous loss: the log minus the same seed's clean log is
    c x the motor speed (the same noise and ringing), fitted by least squares."""
    job = load_job(CALIBRATION_JOB)
    base = ExperimentSettings.from_job(job)
    import dataclasses

    with_fx = synthetic_log(press, job, truth, seed, dataclasses.replace(base, effects=base.effects.with_args(items)))["columns"]
    clean = synthetic_log(press, job, truth, seed, base)["columns"]
    w = np.asarray(with_fx["motor_speed_rpm"]) * 2.0 * math.pi / 60.0
    d = np.asarray(with_fx["motor_torque_Nm"]) - np.asarray(clean["motor_torque_Nm"])
    return float(np.dot(d, w) / np.dot(w, w))


def true_peak(press, truth: dict, job, profile_csv: Path, effect: str, c_viscous: float) -> float:
    """Largest |motor torque| per motor (N m) the true press needs to follow ``profile_csv``'s crank motion (every row),
    per point: the truth's model, Eq. 16, and the effect on the drive."""
    pm = PressModel(apply_overrides(press, truth, "truth"))
    ws = Workspace(pm)
    loads = slide_loads(pm, job.process)
    with open(profile_csv, newline="") as fh:
        rows = list(csv.DictReader(fh))
    th = np.radians([float(r["crank_angle_deg"]) for r in rows])
    sd = np.array([float(r["crank_speed_rad_s"]) for r in rows])
    u = np.array([float(r["crank_accel_rad_s2"]) for r in rows])
    tau = np.array([inverse_dynamics(pm, ws, state_at(pm, ws, float(a), float(b), float(c)), loads).crank_torque
                    for a, b, c in zip(th, sd, u)])
    T = np.asarray(motor_torque(pm.press.drive, tau, sd, u), float)
    if effect == "efficiency":
        T = load_dependent(T, 0.05, press.motor.rated_torque)
    if effect == "viscous":
        T = T + c_viscous * sd * pm.press.drive.gear_ratio
    return float(np.max(np.abs(T)))


def run_row(seed: int, effect: str, work: Path, job_name: str = "door-panel", press_file: str | None = None,
            plans=("default", "nominal")) -> dict:
    """One row of the table (module docstring) in the folder ``work``; ``plans``: which of the two plans to make. A row
    whose ``row.json`` is in ``work`` already is read from it (a check resumed)."""
    done = work / "row.json"
    if done.exists():
        return json.loads(done.read_text())
    press = load_press(press_file)
    names = load_job(CALIBRATION_JOB).raw["calibration"]["parameters"]
    truth = draw_truth(press, names, seed)
    items, factor, _ = EFFECTS[effect]
    work.mkdir(parents=True, exist_ok=True)
    log = work / "log.csv"
    cli("experiment", "--job", cushion_job(factor, work), "--seed", seed, "--truth", json.dumps(truth),
        *sum((["--effect", i] for i in items), []), "--out", log, cwd=work)
    cal = cli("calibrate", "--log", log, "--out", work / "cal", cwd=work)
    params = work / "cal" / "calibrated.json"
    row = {"seed": seed, "effect": effect, "truth": truth,
           "calibration_warned": "WARNING" in cal.stdout + cal.stderr or "NOT ADEQUATE" in cal.stdout + cal.stderr}
    c_visc = viscous_coefficient(press, truth, seed, items) if effect == "viscous" else 0.0
    job = load_job(job_name)
    t_max = press.motor.peak_torque
    for key, extra in (("default", ()), ("nominal", ("--nominal",))):
        if key not in plans:
            continue
        out = work / f"plan_{key}"
        res = cli("plan", "--job", job_name, "--params", params, *extra, "--out", out, cwd=work, refusal_ok=True)
        warnings = [ln for ln in (res.stdout + res.stderr).splitlines() if ln.startswith("WARNING")]
        if res.returncode == 2:  # plan refused: it says plainly that it cannot
            row[key] = {"refused": res.stderr.strip().splitlines()[-1], "true_peak_ratio": math.nan, "strokes_per_min": math.nan,
                        "warned": bool(warnings), "warnings": warnings}
            continue
        summary = json.loads((out / "summary.json").read_text())
        row[key] = {"true_peak_ratio": true_peak(press, truth, job, out / "profile.csv", effect, c_visc) / t_max,
                    "strokes_per_min": summary["strokes_per_min"],
                    "warned": bool(warnings), "warnings": warnings}
    d = row.get("default")
    row["ok"] = d is None or "refused" in d or d["true_peak_ratio"] <= MARGIN or d["warned"]
    done.write_text(json.dumps(row, indent=1))
    return row


def table(rows) -> str:
    """The rows as a Markdown table."""
    out = ["| seed | effect | default plan: true peak / T_max | spm | `--nominal`: true peak / T_max | spm | plan warned | ok |",
           "|---|---|---|---|---|---|---|---|"]
    for r in rows:
        d, n = r["default"], r["nominal"]
        cells = [("refused" if "refused" in p else f"{p['true_peak_ratio']:.3f}", "-" if "refused" in p else f"{p['strokes_per_min']:.3f}")
                 for p in (d, n)]
        out.append(f"| {r['seed']} | {r['effect']} | {cells[0][0]} | {cells[0][1]} | {cells[1][0]} | {cells[1][1]} | "
                   f"{'refused' if 'refused' in d else ('yes' if d['warned'] else 'no')} | {'yes' if r['ok'] else 'NO'} |")
    return "\n".join(out)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, nargs="+", default=[1, 2, 3])
    ap.add_argument("--effects", nargs="+", default=list(EFFECTS), choices=list(EFFECTS))
    ap.add_argument("--job", default="door-panel", help="the job planned (default: door-panel)")
    ap.add_argument("--work", help="folder for the logs, calibrations and plans (default: a new temporary one)")
    ap.add_argument("--json", help="also write the rows to this JSON file")
    args = ap.parse_args()
    work = Path(args.work) if args.work else Path(tempfile.mkdtemp(prefix="check_chain_"))
    rows = []
    for seed in args.seeds:
        for effect in args.effects:
            r = run_row(seed, effect, work / f"seed{seed}_{effect}", args.job)
            d = r["default"]
            print(f"seed {seed}, {effect} ({EFFECTS[effect][2]}): truth "
                  + ", ".join(f"{k} = {v:.6g}" for k, v in r["truth"].items())
                  + f"; default {d['true_peak_ratio']:.3f} T_max, --nominal {r['nominal']['true_peak_ratio']:.3f} T_max"
                  + ("; plan refused: " + d["refused"] if "refused" in d else "")
                  + ("; plan warned: " + " | ".join(d["warnings"]) if d["warned"] else ""), flush=True)
            rows.append(r)
    print()
    print(table(rows))
    if args.json:
        Path(args.json).write_text(json.dumps(rows, indent=1))
    bad = [r for r in rows if not r["ok"]]
    print(f"\n{len(rows) - len(bad)} of {len(rows)} rows keep {MARGIN:.2f} T_max on the true press or warn; work folder {work}")
    sys.exit(1 if bad else 0)


if __name__ == "__main__":
    main()
