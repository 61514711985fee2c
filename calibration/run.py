"""The 'calibrate' command: Eq. 28 against a drive log, solved, with intervals, tables and Figure 5.

Outputs in the folder: calibrated.json (parameters, intervals, metrics, correlation, provenance),
table4.csv / table4.md (theoretical, calibrated, relative error, beside the paper's Table 4),
solvers.csv when several methods ran, and figure5.png (measured, theoretical and calibrated torque).
"""
from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from press_model.batch import build_batch_model
from press_model.errors import PressDataError
from press_model.jobs import Job
from press_model.kinematics import force_step_angles
from press_model.model import PressModel
from press_model.motion import FourierSpeed
from press_model.outputs import atomic_write_text, versions, write_json, write_table
from press_model.plots import plt, save
from press_model.progress import progress as show_progress
from press_model.press_data import PressData, is_file, read_text_file
from calibration.sensitivity_report import paper_figures

from .drive_log import DriveLog, check_against_model, read_drive_log, summary
from .problem import CalibrationProblem, Objective, metrics, objective, peak_points
from .settings import METHODS, CalibrationSettings
from .solvers import SOLVERS, SolverRun
from .uncertainty import Uncertainty, analyse


@dataclass(frozen=True)
class Calibration:
    """Everything a calibration run found; ``runs`` holds every solver that ran, ``best`` the one reported."""

    log: DriveLog
    objective: Objective
    runs: tuple[SolverRun, ...]
    best: SolverRun
    uncertainty: Uncertainty
    before: dict
    after: dict


def key_parameters(arg: str | None, default: tuple[str, ...]) -> tuple[str, ...]:
    """Parameter names from a key_parameters.json of ``servo-press sensitivity``, a comma list, or the job's default."""
    if arg is None:
        return default
    path = Path(arg)
    if path.suffix == ".json" or is_file(path):
        if not is_file(path):
            raise PressDataError("--parameters", "--parameters", arg, "must be an existing key_parameters.json or a comma-separated list of names")
        try:
            obj = json.loads(read_text_file(path, "--parameters"))
        except json.JSONDecodeError as exc:
            raise PressDataError(str(path), "<json>", exc.msg, "is not valid JSON") from None
        names = obj.get("key_parameters") if isinstance(obj, dict) else None
        if not isinstance(names, list) or not all(isinstance(n, str) for n in names):
            raise PressDataError(str(path), "key_parameters", names, "must be a list of names (the file `servo-press sensitivity` writes)")
        return tuple(names)
    return tuple(n.strip() for n in arg.split(",") if n.strip())


def _progress(method: str):
    def show(i, total, best):
        if i < total and i % max(1, total // 20):
            return  # about twenty updates a run
        show_progress(method, i, total, f"Eq. 28 objective {best:.5f}")
    return show


def calibrate(press: PressData, job: Job, log_path: Path, methods: list[str], seed: int, names: tuple[str, ...] | None = None,
              torque_unit: str = "N*m", progress: bool = True) -> Calibration:
    """Read the log, build Eq. 28 on the log's own crank motion and the job's process force, and solve it."""
    cs = CalibrationSettings.from_job(job)
    for m in methods:
        if m not in METHODS:
            raise PressDataError("--method", "--method", m, f"must be one of {', '.join(METHODS)} or 'all'")
    log = read_drive_log(log_path, press.drive.gear_ratio, press.motor.rated_torque, 1.0, torque_unit)
    try:
        motion = FourierSpeed.fit(log.theta, log.crank_speed, cs.speed_harmonics)
    except ValueError as exc:
        raise PressDataError(str(log_path), "motor_speed_rpm", "fitted crank speed", f"must stay positive over the turn ({exc}); the log must come from continuous running") from None
    pm = PressModel(press)
    bm = build_batch_model(press, motion, job.process, pm=pm)
    contacts = force_step_angles(pm, job.process)[:1]  # die contact; BDC rings no impact
    mask = peak_points(bm.theta, motion.time, contacts, cs.peak_window)
    problem = CalibrationProblem.from_press(press, names or cs.parameters, cs.weight, job.source)
    obj = objective(problem, bm, log.torque, mask)
    check_against_model(log, obj.torques(problem.theoretical[None])[0], torque_unit)  # sign and scale, before fitting
    runs = []
    for m in methods:
        runs.append(SOLVERS[m](obj, cs, seed, _progress(m) if progress else None))
    best = min(runs, key=lambda r: r.objective)  # ties: the first in METHODS order, so reruns agree
    unc = analyse(obj, best.x, cs.interval_level, cs.correlation_limit, cs.interval_width_limit)
    T0 = obj.torques(problem.theoretical[None])[0]
    T1 = obj.torques(best.x[None])[0]
    return Calibration(log, obj, tuple(runs), best, unc, metrics(T0, log.torque, bm.theta_dot, mask), metrics(T1, log.torque, bm.theta_dot, mask))


def result_record(cal: Calibration, press: PressData, job: Job, seed: int) -> dict:
    """The content of calibrated.json."""
    p, u, b = cal.objective.problem, cal.uncertainty, cal.best
    log = cal.log
    return {
        "parameters": {n: float(x) for n, x in zip(p.names, b.x)},
        "intervals": {n: [float(lo), float(hi)] for n, lo, hi in zip(p.names, u.low, u.high)},
        "metrics": {
            "rmse_before_Nm": cal.before["rmse_Nm"], "rmse_after_Nm": cal.after["rmse_Nm"],
            "peak_error_before_Nm": cal.before["peak_error_Nm"], "peak_error_after_Nm": cal.after["peak_error_Nm"],
            "thermal_error_before": cal.before["thermal_error"], "thermal_error_after": cal.after["thermal_error"],
            "peak_error_with_impact_before_Nm": cal.before["peak_error_with_impact_Nm"],
            "peak_error_with_impact_after_Nm": cal.after["peak_error_with_impact_Nm"],
            "rms_torque_measured_Nm": cal.before["rms_torque_Nm"] / (1.0 + cal.before["thermal_error"]),
            "rms_torque_theoretical_Nm": cal.before["rms_torque_Nm"], "rms_torque_calibrated_Nm": cal.after["rms_torque_Nm"],
            "objective_eq28_before": 1.0, "objective_eq28_after": b.objective,
        },
        "definitions": {
            "objective": f"Eq. 28: w Y_RMSE/Y_RMSE,0 + (1-w) |Y_PR|/|Y_PR,0|, w = {p.weight}, against the measured stroke-averaged curve",
            "peak_error": "max|T_pred| - max|T_meas| over the grid points outside the die-contact window (Eq. 23's numerator); "
                          "peak_error_with_impact: the same over every point, the impact spike included",
            "thermal_error": "(RMS_pred - RMS_meas) / RMS_meas, time-weighted RMS of Eq. 24 over the measured turn",
            "intervals": f"{100 * u.level:g} % intervals of linearised least squares at the optimum (residual Jacobian, t-quantile), "
                         "covariance inflated by the residuals' AR(1) factor; clipped to the bounds",
        },
        "theoretical": {n: float(x) for n, x in zip(p.names, p.theoretical)},
        "bounds": {n: [float(lo), float(hi)] for n, lo, hi in zip(p.names, p.low, p.high)},
        "standard_errors": {n: float(s) for n, s in zip(p.names, u.std)},
        "correlation": {"names": list(p.names), "matrix": u.correlation.round(6).tolist()},
        "identifiability": list(u.statements),
        "residual_lag1_autocorrelation": u.lag1,
        "covariance_inflation": u.inflation,
        "method": b.method,
        # wall times stay out of the JSON and CSV files (same seed, same bytes); table4.md and the console show them
        "solver_runs": [{"method": r.method, "objective_eq28": r.objective, "model_cycles": r.cycles,
                         "parameters": {n: float(x) for n, x in zip(p.names, r.x)}, "detail": r.detail} for r in cal.runs],
        "seed": seed,
        "log": {"source": log.source, "synthetic": log.synthetic, "label": log.label, "strokes": log.strokes,
                "sample_rate_Hz": log.sample_rate_hz, "warnings": list(log.warnings), "summary": summary(log)},
        "job": job.name, "job_source": job.source, "press": press.name, "press_source": press.source,
        "press_fingerprint": press.fingerprint,
        "peak_points_excluded_deg": [float(d) for d in np.degrees(cal.objective.bm.theta[~cal.objective.peak_points])],
        "all_parameters_after": press.with_overrides(dict(zip(p.names, map(float, b.x))), "calibration").parameter_values(),
        "versions": versions(),
    }


def write_outputs(cal: Calibration, press: PressData, job: Job, seed: int, out: Path) -> dict:
    """Write calibrated.json, table4.csv/.md, solvers.csv and figure5.png; returns the calibrated.json record."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    rec = result_record(cal, press, job, seed)
    p, u = cal.objective.problem, cal.uncertainty
    paper = paper_figures()["calibration"]
    t4 = paper["table4"]
    rows = []
    for n, th, x, lo, hi in zip(p.names, p.theoretical, cal.best.x, u.low, u.high):
        pt = t4.get(n)
        rows.append({"parameter": n, "theoretical": float(th), "calibrated": float(x), "interval_low": float(lo), "interval_high": float(hi),
                     "relative_error_pct": float(100 * (th - x) / x),
                     "paper_theoretical": float(pt[0]) if pt else float("nan"), "paper_calibrated": float(pt[1]) if pt else float("nan"),
                     "paper_relative_error_pct": float(100 * (pt[0] - pt[1]) / pt[1]) if pt else float("nan")})
    cols = list(rows[0])
    write_table(out / "table4.csv", cols, rows, digits=8)
    atomic_write_text(out / "table4.md", table4_markdown(rec, rows, paper, [r.time_s for r in cal.runs]))
    if len(cal.runs) > 1:
        write_table(out / "solvers.csv", ["method", "objective_eq28", "model_cycles", *p.names],
                    [{"method": r.method, "objective_eq28": r.objective, "model_cycles": r.cycles,
                      **{n: float(x) for n, x in zip(p.names, r.x)}} for r in cal.runs])
    save(figure5(cal), out / "figure5.png")
    write_json(out / "calibrated.json", rec)
    return rec


def table4_markdown(rec: dict, rows: list[dict], paper: dict, times_s: list[float]) -> str:
    m = rec["metrics"]
    syn = rec["log"]["synthetic"]
    lines = [f"# Calibration against {'a SYNTHETIC' if syn else 'a measured'} drive log",
             "", f"Log: `{rec['log']['source']}`" + (f" ({rec['log']['label']})" if syn else "") + f"; method {rec['method']}, seed {rec['seed']}.", "",
             "## Table 4 analogue (relative error = (theoretical - calibrated) / calibrated, as in the paper)", "",
             "| parameter | theoretical | calibrated | 95 % interval | rel. error | paper: theoretical | paper: calibrated | paper: rel. error |",
             "|---|---|---|---|---|---|---|---|"]
    for r in rows:
        lines.append(f"| {r['parameter']} | {r['theoretical']:.5g} | {r['calibrated']:.5g} | [{r['interval_low']:.5g}, {r['interval_high']:.5g}] | "
                     f"{r['relative_error_pct']:+.1f} % | {r['paper_theoretical']:.5g} | {r['paper_calibrated']:.5g} | {r['paper_relative_error_pct']:+.1f} % |")
    lines += ["", "## Prediction accuracy, ours beside the paper's", "",
              "| figure | ours: before | ours: after | paper: before | paper: after |", "|---|---|---|---|---|",
              f"| RMSE [N m] | {m['rmse_before_Nm']:.1f} | {m['rmse_after_Nm']:.1f} | {paper['rmse_before_Nm']} | {paper['rmse_after_Nm']} |",
              f"| peak error [N m] | {m['peak_error_before_Nm']:+.1f} | {m['peak_error_after_Nm']:+.1f} | {paper['peak_error_before_Nm']} | {paper['peak_error_after_Nm']} |",
              f"| peak error incl. die-contact spike [N m] | {m['peak_error_with_impact_before_Nm']:+.1f} | {m['peak_error_with_impact_after_Nm']:+.1f} | | |",
              f"| thermal error (Eq. 24) | {100 * m['thermal_error_before']:+.2f} % | {100 * m['thermal_error_after']:+.2f} % | {100 * paper['thermal_error_before']:.1f} % | {100 * paper['thermal_error_after']:.1f} % |",
              "", "## What this experiment can tell apart", ""] + [f"* {s}" for s in rec["identifiability"]]
    if len(rec["solver_runs"]) > 1:
        lines += ["", "## Solvers on the same objective", "", "| method | Eq. 28 | model cycles | time [s] |", "|---|---|---|---|"]
        lines += [f"| {r['method']} | {r['objective_eq28']:.5f} | {r['model_cycles']} | {t:.2f} |" for r, t in zip(rec["solver_runs"], times_s)]
    return "\n".join(lines) + "\n"


def figure5(cal: Calibration):
    """Measured (stroke mean and spread), theoretical and calibrated motor torque over one turn."""
    obj, log = cal.objective, cal.log
    deg = np.degrees(obj.bm.theta)
    T0 = obj.torques(obj.problem.theoretical[None])[0]
    T1 = obj.torques(cal.best.x[None])[0]
    fig, (ax, ax2) = plt.subplots(2, 1, figsize=(9, 6.5), sharex=True, gridspec_kw={"height_ratios": [3, 1.3]})
    spread = np.nan_to_num(log.torque_spread)
    ax.fill_between(deg, (log.torque - spread) / 1e3, (log.torque + spread) / 1e3, color="0.8", label="measured +/- stroke spread")
    ax.plot(deg, log.torque / 1e3, color="k", lw=1.0, label=f"T_act ({'SYNTHETIC, ' if log.synthetic else ''}{log.strokes}-stroke mean)")
    ax.plot(deg, T0 / 1e3, color="C3", lw=1.2, ls="--", label=f"T_the (theoretical), RMSE {cal.before['rmse_Nm']:.0f} N m")
    ax.plot(deg, T1 / 1e3, color="C0", lw=1.2, label=f"T_cal ({cal.best.method}), RMSE {cal.after['rmse_Nm']:.0f} N m")
    for d in deg[~obj.peak_points][:1]:
        ax.axvline(d, color="0.5", lw=0.8, ls=":")
    ax.set_ylabel("motor torque per motor [kN m]")
    title = "Figure 5 analogue: servo motor torque over one cycle"
    ax.set_title(title + (" - SYNTHETIC drive log" if log.synthetic else ""), fontsize=10)
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3)
    ax2.plot(deg, (T0 - log.torque), color="C3", lw=0.9, ls="--", label="theoretical - measured")
    ax2.plot(deg, (T1 - log.torque), color="C0", lw=0.9, label="calibrated - measured")
    ax2.set_ylabel("error [N m]")
    ax2.set_xlabel("crank angle theta_c [deg]")
    ax2.grid(alpha=0.3)
    ax2.legend(fontsize=8)
    ax2.set_xlim(0, 360)
    fig.tight_layout()
    return fig
