"""calibrated.json of a calibration: the record of a :class:`calibration.identification.run.Calibration` (parameters, intervals and
the joint region, metrics, correlation, adequacy, recording correction, provenance). Wall times stay out of it:
the same seed gives the same bytes.
"""
from __future__ import annotations

import numpy as np
from scipy import stats

from press_model.jobs import Job
from press_io.outputs import versions
from press_model.press_data import PressData

from calibration.traces.drive_log import summary
from calibration.identification.peak_noise import carried
from calibration.identification.run import Calibration, p_level


def result_record(cal: Calibration, press: PressData, job: Job, seed: int) -> dict:
    """The content of calibrated.json."""
    p, u, b, bs = cal.objective.problem, cal.uncertainty, cal.best, cal.bootstrap
    log = cal.log
    lo, hi, std, corr = (bs.low, bs.high, bs.std, bs.correlation) if bs is not None else (u.low, u.high, u.std, u.correlation)
    rec = {
        "parameters": {n: float(x) for n, x in zip(p.names, b.x)},
        "intervals": {n: [float(a), float(c)] for n, a, c in zip(p.names, lo, hi)},
        "interval_method": (f"parametric bootstrap of the reported estimate ({bs.refits} refits on the calibrated model plus residuals "
                            f"block-resampled in {bs.block_points}-point blocks, each refitted by a local solver from the estimate), "
                            f"basic (reverse-percentile) {100 * bs.level:g} % intervals from the refits' (R+1)-rule order statistics, "
                            "each side widened by the window shift (how far the die-contact window and the force steps' neighbours, "
                            "which the model is not meant to follow, pull the estimate: the refit with the calibrated curve there) "
                            "and by the job's allowance if it sets one ([calibration.bootstrap.allowance]), clipped to the bounds"
                            if bs is not None else f"Jacobian (linearised least squares), {100 * u.level:g} %"),
        "intervals_jacobian": {n: [float(a), float(c)] for n, a, c in zip(p.names, u.low, u.high)},
        "intervals_question": (f"one parameter at a time: each interval holds its own parameter's truth in {100 * p_level(cal):g} % of "
                               f"calibrations; over {len(p.names)} parameters some interval misses more often (in up to "
                               f"{100 * (1 - p_level(cal) ** len(p.names)):.0f} % of calibrations, reached for independent estimates). For "
                               "a statement about all parameters together use joint_region"),
        "joint_region": joint_record(cal),
        "intervals_note": (("the model is adequate for this log (calibrated.json adequacy): the intervals describe the noise"
                            + ("; the noise is coloured (its lag-one correlation along the grid is "
                               f"{cal.adequacy.pure_error_lag1:.2f}), so each interval is joined with the Jacobian interval, whose "
                               "covariance carries the AR(1) factor of that colour" if cal.adequacy is not None and cal.adequacy.noise_coloured else ""))
                           if cal.adequacy is None or cal.adequacy.adequate else
                           "the model is NOT adequate for this log (calibrated.json adequacy): the intervals describe the noise "
                           "only and do not cover the model error the parameters have absorbed"),
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
            "objective": f"Eq. 28: w Y_RMSE/Y_RMSE,0 + (1-w) |Y_PR|/|Y_PR,0|, w = {p.weight}, against the measured stroke-averaged curve, "
                         "both terms over the grid points outside the die-contact window (peak_points_excluded_deg)",
            "peak_error": "max|T_pred| - max|T_meas| over the grid points outside the die-contact window (Eq. 23's numerator); "
                          "peak_error_with_impact: the same over every point, the impact spike included",
            "thermal_error": "(RMS_pred - RMS_meas) / RMS_meas, time-weighted RMS of Eq. 24 over the measured turn",
            "intervals": "95 % intervals of the reported estimator, one parameter at a time, see interval_method and "
                         "intervals_question (calibration/identification/bootstrap.py); coverage measured on synthetic logs by scripts/bench_coverage.py",
            "joint_region": "a box holding every calibrated parameter's truth at once at its level, see joint_region.method; "
                            "it holds each per-parameter interval; coverage (share of runs with every truth inside) measured "
                            "by scripts/bench_coverage.py and scripts/bench_adequacy.py",
            "intervals_jacobian": f"second opinion: {100 * u.level:g} % intervals of linearised least squares at the optimum "
                                  "(residual Jacobian, t-quantile), covariance inflated by the residuals' AR(1) factor, each standard error "
                                  "joined in quadrature with how far the measured peak's noise moves Eq. 28's estimate (interval_widening."
                                  "peak_move_sd, linearised); clipped to the bounds. Otherwise they describe the least-squares estimator, not Eq. 28's",
            "measured_peak": "the measured peak of Eq. 23 is taken from the stroke-averaged curve after the job's filter "
                             "(see measured_peak.method); peak_error_* are against it",
        },
        "measured_peak": ({"value_Nm": cal.peak.value_Nm, "raw_maximum_Nm": cal.peak.raw_Nm, "noise_sigma_Nm": cal.peak.sigma_Nm,
                           "point_noise_sigma_Nm": cal.peak.point_sigma_Nm, "method": cal.peak.describe(),
                           "theoretical_peak_error_over_noise": abs(cal.objective.pr0) * cal.objective.measured_peak / cal.peak.sigma_Nm
                           if cal.peak.sigma_Nm > 0 else None,
                           # the peak's noise in the intervals (calibration/identification/peak_noise.py)
                           "refits_peak_scatter_Nm": carried(bs.measured_peaks) if bs is not None else None,
                           "refits_peak_scatter_meaning": "N m: the standard deviation of the bootstrap refits' filtered measured "
                                                          "peaks, the peak noise the bootstrap intervals carry (against noise_sigma_Nm); "
                                                          "the Jacobian intervals carry it as interval_widening.peak_move_sd"}
                          if cal.peak is not None else None),
        "warnings": list(cal.warnings),
        **({"motor_shares": {**cal.motor_shares.record(), "warnings": list(cal.share_warnings)}} if cal.motor_shares is not None else {}),
        "notes": list(cal.notes),
        **({"held_parameters": cal.held} if cal.held is not None else {}),
        "theoretical": {n: float(x) for n, x in zip(p.names, p.theoretical)},
        "bounds": {n: [float(lo), float(hi)] for n, lo, hi in zip(p.names, p.low, p.high)},
        "standard_errors": {n: float(s) for n, s in zip(p.names, std)},
        "correlation": {"names": list(p.names), "matrix": np.round(corr, 6).tolist()},
        "correlation_jacobian": {"names": list(p.names), "matrix": u.correlation.round(6).tolist()},
        "identifiability": list(cal.statements) or list(u.statements),
        "residual_lag1_autocorrelation": u.lag1,
        "covariance_inflation": u.inflation,
        "method": b.method,
        # wall times stay out of the JSON and CSV files (same seed, same bytes); table4.md and the console show them
        "solver_runs": [{"method": r.method, "objective_eq28": r.objective, "model_cycles": r.cycles,
                         "gap_to_minimum_pct": 100.0 * (r.objective - min(q.objective for q in cal.runs)) / min(q.objective for q in cal.runs),
                         "parameters": {n: float(x) for n, x in zip(p.names, r.x)}, "detail": r.detail} for r in cal.runs],
        "objective_eq28_minimum_of_methods": min(r.objective for r in cal.runs),
        "seed": seed,
        "log": {"source": log.source, "synthetic": log.synthetic, "label": log.label, "strokes": log.strokes,
                "sample_rate_Hz": log.sample_rate_hz, "warnings": list(log.warnings), "summary": summary(log)},
        "job": job.name, "job_source": job.source, **press.identity(),
        "peak_points_excluded_deg": [float(d) for d in np.degrees(cal.objective.bm.theta[~cal.objective.peak_points])],
        "all_parameters_after": press.with_overrides(dict(zip(p.names, map(float, b.x))), "calibration").parameter_values(),
        "versions": versions(),
    }
    if bs is not None:
        rec["bootstrap"] = {"refits": bs.refits, "block_points": bs.block_points, "fixed_points": bs.fixed_points,
                            "model_cycles": bs.cycles, "seed": seed,
                            "intervals_basic": {n: [float(a), float(c)] for n, a, c in zip(p.names, bs.low_basic, bs.high_basic)},
                            "allowance_of_range": {n: float(a) for n, a in zip(p.names, bs.allowance)},
                            "window_shift": {n: float(a) for n, a in zip(p.names, bs.window_shift)},
                            "on_bound": [n for n, a in zip(p.names, bs.on_bound if bs.on_bound is not None else []) if a],
                            "intervals_percentile": {n: [float(a), float(c)] for n, a, c in zip(p.names, bs.low_percentile, bs.high_percentile)},
                            "estimates": {n: [float(v) for v in bs.estimates[:, j]] for j, n in enumerate(p.names)}}
    if cal.validation is not None:
        rec["validation"] = cal.validation
    if len(cal.logs) > 1:
        rec["logs"] = [{"source": lg.source, "synthetic": lg.synthetic, "label": lg.label, "strokes": lg.strokes,
                        "sample_rate_Hz": lg.sample_rate_hz, "warnings": list(lg.warnings), "summary": summary(lg)} for lg in cal.logs]
        rec["definitions"]["objective"] += ("; over the logs end to end (calibration/identification/joint.py): Y_RMSE and the peak over every "
                                            "log's points outside its die-contact window, the peak against the largest measured peak")
    if cal.adequacy is not None:
        rec["adequacy"] = cal.adequacy.record()
        if len(cal.adequacy_logs) > 1:
            rec["adequacy"]["per_log"] = [{"log": lg.source, **a.record()} for lg, a in zip(cal.logs, cal.adequacy_logs)]
            rec["adequacy"]["adequate"] = all(a.adequate for a in cal.adequacy_logs)
        rec["intervals_cover_model_error"] = cal.adequacy.adequate
    if cal.recording_spread is not None:
        rec["interval_widening"] = {
            "recording_sd": {n: float(v) for n, v in zip(p.names, cal.recording_spread)},
            # the job force tolerance's share on a log without the force column (process_force.interval_sd; 0 without)
            "process_force_sd": {n: float((cal.process_force or {}).get("interval_sd", {}).get(n, 0.0)) for n in p.names},
            # the logged force's noise (calibration/identification/force_noise.py; 0 without a logged force)
            "logged_force_sd": {n: float(v) for n, v in zip(p.names, cal.logged_force_spread if cal.logged_force_spread is not None
                                                             else np.zeros(len(p.names)))},
            # the logged force's stated accuracy (force_accuracy.py: process_force.logged_force_accuracy.interval_sd; 0
            # without a logged force)
            "logged_force_accuracy_sd": {n: float(((cal.process_force or {}).get("logged_force_accuracy") or {})
                                                  .get("interval_sd", {}).get(n, 0.0)) for n in p.names},
            # the crank motion's own error, linearised (motion_error.estimate_sd; 0 for an exact speed)
            "crank_motion_sd": {n: float(v) for n, v in zip(p.names, cal.motion_sd if cal.motion_sd is not None else np.zeros(len(p.names)))},
            "level_quantile": float(stats.norm.ppf(0.5 + p_level(cal) / 2.0)),
            "noise_coloured": bool(cal.adequacy is not None and any(a.noise_coloured for a in cal.adequacy_logs)),
            # the measured peak's noise: in the Jacobian intervals only (the bootstrap's refits redraw the peak)
            "peak_move_sd": {n: float(v) for n, v in zip(p.names, cal.peak_move if cal.peak_move is not None else np.zeros(len(p.names)))},
            "peak_move_held_share": cal.peak_held_share,
            "what": "each interval's half-widths with level_quantile x the root sum of squares of recording_sd, process_force_sd, "
                    "logged_force_sd and crank_motion_sd added in quadrature (the logged process force's noise carried into the "
                    "estimate, logged_force; crank_motion_sd: the move of the least-squares estimate by the error of the crank "
                    "speed and acceleration fitted from the log, which, the same for every stroke and refit, no noise estimate "
                    "sees; the job force tolerance's move of the estimate on a log without the force column; the recording "
                    "correction's uncertainty: Eq. 28 refitted on the curve shifted by the model curve's delay and offset columns "
                    "one standard deviation either way along each principal axis of their covariance), then, on a bound or with coloured noise, joined with the Jacobian interval "
                    "(which carries the same widening and, in the same quadrature, peak_move_sd: the move of Eq. 28's estimate by one standard "
                    "deviation of the measured peak's noise, linearised, which least squares has no term for; the bootstrap's refits redraw "
                    "the peak themselves, all but peak_move_held_share of its variance, which sits on points they keep in place: the "
                    "bootstrap intervals add sqrt(peak_move_held_share) x peak_move_sd in the same quadrature)"}
    if cal.process_force is not None:
        rec["process_force"] = cal.process_force
    if cal.logged_force_noise is not None:
        rec["logged_force_noise"] = cal.logged_force_noise
    rec["nuisance"] = cal.recording.record() if cal.recording is not None else {
        "estimated": False, "why": "the job's [calibration.recording] estimate = false: the log is fitted as logged"}
    if cal.recording is not None and cal.adequacy is not None:
        rec["nuisance"]["reliable"] = cal.adequacy.adequate  # a model that misses the log pushes part of its misfit into the shift
        if not cal.adequacy.adequate:
            rec["nuisance"]["note"] = ("the model is not adequate for this log: the delay and offset estimates absorb part of its "
                                       "misfit and do not describe the recording")
    return rec


def joint_record(cal: Calibration) -> dict:
    """calibrated.json's ``joint_region``: the box holding every parameter's truth at once at the intervals' level,
    the method that made it, and the question it answers (beside the per-parameter ``intervals``)."""
    p, u, bs = cal.objective.problem, cal.uncertainty, cal.bootstrap
    box = (lambda lo, hi: {n: [float(a), float(c)] for n, a, c in zip(p.names, lo, hi)})
    rec = {"level": p_level(cal),
           "question": (f"all parameters at once: the box holds every calibrated parameter's truth together in {100 * p_level(cal):g} % "
                        "of calibrations (use it for a statement about the whole parameter set, e.g. a plan that must hold for "
                        "all of them); each side contains the parameter's own interval")}
    if bs is not None:
        rec.update(box=box(bs.joint_low, bs.joint_high),
                   method_short=f"Sidak box: each side moved out by (t_S - t_1) x the refits' standard deviation, t_S at "
                                f"{100 * u.joint_level:.2f} %, t_1 at {100 * p_level(cal):g} %",
                   method=(f"Sidak box on the bootstrap (calibration/identification/bootstrap.py simultaneous_extra): each side of the basic interval "
                           f"moved out by (t_S - t_1) s, s the {bs.refits} refits' standard deviation, t_1 and t_S the t-quantiles "
                           f"({bs.refits - 1} degrees of freedom) at {p_level(cal):g} and at the Sidak level {u.joint_level:.6f} = "
                           f"{p_level(cal):g}^(1/{len(p.names)}), which holds all at once with at least {p_level(cal):g} whatever the "
                           "correlation; then the same window shift and allowance as the intervals, the recording correction's "
                           "uncertainty at the Sidak level, and on a bound or with coloured noise the union with the Jacobian joint region"),
                   extra_beyond_interval={n: float(e) for n, e in zip(p.names, bs.joint_extra)})
    else:
        rec.update(box=box(u.joint_low, u.joint_high), method_short=f"Sidak: each side at the {100 * u.joint_level:.2f} % level",
                   method=(f"Sidak box from the Jacobian covariance (calibration/identification/uncertainty.py): each interval at the per-parameter "
                           f"level {u.joint_level:.6f} = {p_level(cal):g}^(1/{len(p.names)}), which holds all at once with at least "
                           f"{p_level(cal):g} whatever the correlation"))
    rec["jacobian_box"] = box(u.joint_low, u.joint_high)
    rec["jacobian_per_parameter_level"] = u.joint_level
    return rec
