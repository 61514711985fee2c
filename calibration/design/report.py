"""The designed calibration experiment as files: run_N/job.toml, profile.csv and cam_table.csv per run, prediction.json
(predicted 95 % half-widths and correlations of the design and of the job's single cushion test) and report.md with
design.png (the runs and the predicted intervals side by side).

:func:`design_experiment` designs (:mod:`calibration.design.runs`) and predicts (:mod:`calibration.design.information`);
:func:`write_design` writes. The playback check of every run through the forward dynamics is the planner's
(:mod:`servo_press.design_experiment`), which calls both.
"""
from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy import stats
from scipy.interpolate import CubicHermiteSpline

from press_model.batch import build_batch_model, motor_torques
from press_io.errors import PressDataError
from press_model.forces import NO_PROCESS
from press_model.jobs import Job, make_motion
from press_model.kinematics import force_step_angles
from press_model.limits import check_design_runs, run_limits
from press_model.model import PressModel
from press_io.outputs import atomic_write_text, versions, write_csv, write_json
from press_model.plots import save, subplots, tight_layout, torque_limit_lines
from press_model.press_data import PressData
from press_model.schema import CURRENT as SCHEMA

from calibration.design.information import (ForceNoise, PeakPin, Prediction, accuracy_factor, contact_angle, filter_gain,
                                            fitted_points, force_noise_terms, per_standard_deviation, predict, torque_per_newton)
from calibration.design.noise import NoiseLevel
from calibration.design.run_family import RunFamily, run_family
from calibration.design.runs import DENSE_STEP_DEG, DesignResult, DesignSettings, Evaluator, Run, RunCheck, parameter_draws, search
from calibration.synthetic.experiment import theta_of_time, torque_table
from calibration.identification.force_noise import FORCE_PROBE
from calibration.identification.problem import CalibrationProblem, peak_points
from calibration.identification.process_force import scaled, smooth_between_steps, step_indices
from calibration.identification.settings import CalibrationSettings


@dataclass(frozen=True, eq=False)
class Design:
    """A designed experiment with its prediction and the job's single cushion test's, on the same noise level."""

    press: PressData
    job: Job
    problem: CalibrationProblem
    settings: DesignSettings
    calibration: CalibrationSettings
    family: RunFamily
    result: DesignResult
    prediction: Prediction  # all runs together
    run_predictions: tuple[Prediction, ...]  # each run alone (a single-run calibration of it)
    cushion: RunCheck  # the job's own run
    cushion_prediction: Prediction
    nuisance: bool
    draws: np.ndarray
    noise: NoiseLevel  # what the intervals are predicted for

    def aim(self) -> dict:
        """The issue's aim on the prediction: every |correlation| below the job's limit, every interval under its width
        limit, and the widest interval (share of its range) at least 3x narrower than the cushion test's."""
        cs, d, c = self.calibration, self.prediction, self.cushion_prediction
        wd, wc = d.width_of_range(), c.width_of_range()
        corr, a, b = d.max_abs_correlation()
        ccorr, ca, cb = c.max_abs_correlation()
        i, j = int(np.argmax(wd)), int(np.argmax(wc))
        return {
            "correlation_limit": cs.correlation_limit, "interval_width_limit": cs.interval_width_limit,
            "design_max_abs_correlation": {"value": corr, "pair": [a, b]},
            "cushion_test_max_abs_correlation": {"value": ccorr, "pair": [ca, cb]},
            "design_widest": {"parameter": d.names[i], "width_share_of_range": float(wd[i])},
            "cushion_test_widest": {"parameter": c.names[j], "width_share_of_range": float(wc[j])},
            "widest_interval_ratio": float(wc[j] / wd[i]),
            "all_correlations_below_limit": bool(corr < cs.correlation_limit),
            "all_intervals_under_width_limit": bool(np.all(wd <= cs.interval_width_limit)),
            "widest_at_least_3x_narrower": bool(wc[j] / wd[i] >= 3.0),
        }


def design_experiment(press: PressData, job: Job, names: tuple[str, ...] | None = None, runs: int | None = None,
                      pm: PressModel | None = None, polish_evaluations: int | None = None, noise: NoiseLevel | None = None) -> Design:
    """Design ``runs`` calibration runs (default the job's [design] runs) for the parameters ``names`` (default the
    job's [calibration] parameters) of ``press``, and predict their intervals and the job's own run's.
    ``polish_evaluations`` overrides the job's (0: the exchange's grid runs, unpolished; `reproduce --quick`). ``noise``:
    the noise level of a first calibration (:func:`calibration.design.noise.noise_from_calibrated`), default the job's
    [design] keys."""
    cs = CalibrationSettings.from_job(job)
    ds = DesignSettings.from_job(job)
    noise = noise or ds.noise(job.source)
    if polish_evaluations is not None:
        ds = dataclasses.replace(ds, polish_evaluations=int(polish_evaluations))
    n_runs = ds.runs if runs is None else int(runs)
    if runs is not None:
        check_design_runs(n_runs)
    pm = pm or PressModel(press)
    ev = design_evaluator(press, job, names, pm, noise, ds)
    problem, nuisance, fam, draws = ev.problem, ev.nuisance, ev.family, ev.draws
    result = search(ev, n_runs, (job_run(job),))
    cushion = _job_run(press, job, problem, ev, pm)
    level = cs.interval_level
    F = sum(c.info[0] for c in result.runs)
    points = sum(c.points for c in result.runs)
    cushion_process = job.process if job.process.forces and max(job.process.forces) > 0.0 else None
    pins = [peak_pin(c, c.run.process(), fam.one.theta, pm, cs, noise) for c in result.runs]
    top = max(range(len(pins)), key=lambda r: pins[r][0])
    loads = [run_load(fam.model(c.run.motion(), c.run.cushion_force_N, c.run.cushion_stroke_m),
                      fam.model(c.run.motion(), c.run.cushion_force_N * (1.0 + FORCE_PROBE), c.run.cushion_stroke_m),
                      c.run.process(), problem) for c in result.runs]
    fitted = [fitted_of(c, fam.one, cs) for c in result.runs]

    def errors(checks, runs_loads, runs_fitted, pinned, peak_point):  # the logged force's noise and stated accuracy
        noises = [run_force_noise(ld, fam.one.theta, cs, noise) for ld in runs_loads]
        accs = [None if ld is None else (ld[0], accuracy_factor(ld[1])) for ld in runs_loads]
        acc = design_force(checks, accs, runs_fitted, noise, nuisance, pinned, peak_point, common=True)
        return (design_force(checks, noises, runs_fitted, noise, nuisance, pinned, peak_point),
                None if acc is None else per_standard_deviation(acc, cs.process_force))

    pred = predict(F, problem, points, level, pins[top][1], *errors(result.runs, loads, fitted, top, pins[top][2]))
    singles = tuple(predict(c.info[0], problem, c.points, level, p[1], *errors([c], [ld], [fi], 0, p[2]))
                    for c, p, ld, fi in zip(result.runs, pins, loads, fitted))
    cpin = peak_pin(cushion, cushion_process, fam.one.theta, pm, cs, noise)
    cload = None
    if cushion_process is not None:
        cm = make_motion(job.motion, job.source)
        cload = run_load(build_batch_model(press, cm, job.process, pm=pm),
                         build_batch_model(press, cm, scaled(job.process, 1.0 + FORCE_PROBE), pm=pm), job.process, problem)
    cfit = fitted_points(fam.one.theta, make_motion(job.motion, job.source),
                         contact_angle(fam.one.theta, fam.one.height, fam.one.height_dot, job.process.contact_height)
                         if cushion_process is not None else None, cs.peak_window_after_contact_s)
    cpred = predict(cushion.info[0], problem, cushion.points, level, cpin[1], *errors([cushion], [cload], [cfit], 0, cpin[2]))
    return Design(press, job, problem, ds, cs, fam, result, pred, singles, cushion, cpred, nuisance, draws, noise)


def design_evaluator(press: PressData, job: Job, names: tuple[str, ...] | None, pm: PressModel, noise: NoiseLevel,
                     settings: DesignSettings) -> Evaluator:
    """The :class:`calibration.design.runs.Evaluator` a design searches with: the parameters ``names`` (None: the job's
    [calibration] list) of ``press`` (its model ``pm``) under the job's [design] ``settings``, its draws, the noise level
    ``noise`` and what `calibrate` fits and carries ([calibration]: the recording's nuisance, the peak window and
    filter, the logged force's stated accuracy, the correlation and width limits)."""
    cs = CalibrationSettings.from_job(job)
    problem = CalibrationProblem.from_press(press, names or cs.parameters, cs.weight, job.source)
    return Evaluator(run_family(press, pm), problem, settings, parameter_draws(problem, settings.draws, settings.seed),
                     cs.correlation_limit, cs.recording.estimate, noise=noise, window_s=cs.peak_window_after_contact_s,
                     force_accuracy=cs.process_force, peak_filter=(cs.peak_filter_window_deg, cs.peak_filter_order),
                     width_limit=(cs.interval_width_limit, float(stats.norm.ppf(0.5 + cs.interval_level / 2.0))))


def run_load(bm, bm_more, process, problem: CalibrationProblem) -> tuple[np.ndarray, np.ndarray] | None:
    """(torque per N (n,) N m / N, the force curve (n,) N) of a run whose process force is logged (the model takes the
    logged curve): the run's model ``bm`` and ``bm_more`` (its force :data:`FORCE_PROBE` higher) at the theoretical
    values give the torque per N where the force acts. None without a process force, or one that is nowhere on."""
    if process is None:
        return None
    curve = np.asarray(process(bm.height, bm.height_dot), float)
    if not np.any(curve != 0.0):
        return None
    x = problem.theoretical[None]
    T0 = motor_torques(bm, problem.full_sets(bm, x))[0]
    T1 = motor_torques(bm_more, problem.full_sets(bm_more, x))[0]
    return torque_per_newton(T0, T1, curve, FORCE_PROBE), curve


def run_force_noise(load, theta: np.ndarray, cs: CalibrationSettings, noise: NoiseLevel) -> tuple[np.ndarray, np.ndarray] | None:
    """(torque per N (n,) N m / N, the force curve's noise factor (n, n) N per unit standard normal) of a run of
    :func:`run_load` ``load`` whose process force is logged with the noise ``noise.force_noise_N`` on each grid point's
    stroke-averaged bin mean (grid ``theta``): the calibration's smoothing of the logged force (piecewise Savitzky-Golay
    between its steps, [calibration.process_force], an unloaded piece set to zero:
    :mod:`calibration.identification.process_force`) applied to that noise gives the factor. None without a load or
    without force noise."""
    if load is None or not noise.force_noise_N > 0.0:
        return None
    g, curve = load
    pf = cs.process_force
    S = smooth_between_steps(curve, np.eye(curve.size), step_indices(curve, pf.step_fraction), pf.filter_window_deg, theta,
                             pf.filter_order)
    S[curve == 0.0] = 0.0
    return g, noise.force_noise_N * S


def fitted_of(check: RunCheck, one, cs: CalibrationSettings) -> np.ndarray:
    """(bool, n): the grid points `calibrate` fits of a designed run (outside its die-contact window), on the family's grid ``one``."""
    run = check.run
    contact = contact_angle(one.theta, one.height, one.height_dot, run.cushion_stroke_m) if run.cushion_force_N > 0.0 else None
    return fitted_points(one.theta, run.motion(), contact, cs.peak_window_after_contact_s)


def design_force(checks, forces, fitted, noise: NoiseLevel, nuisance: bool, pinned: int, peak_point: int,
                 common: bool = False) -> ForceNoise | None:
    """The :class:`calibration.design.information.ForceNoise` of runs ``checks`` fitted together: each run's
    (torque per N, factor) in ``forces`` (None: no logged force) on its ``fitted`` points; the run ``pinned`` pins the
    estimate at its grid point ``peak_point``. Each run's error its own (the noise), or with ``common`` one error of all
    runs' logs (the channel's stated accuracy: the runs' factors share their coordinates). None when no run has a
    logged force with that error."""
    blocks, peaks = [], []
    for r, (c, fo, fi) in enumerate(zip(checks, forces, fitted)):
        if fo is None:
            continue
        g, factor = fo
        blocks.append(force_noise_terms(c.columns, fi, noise.variance, g, factor, nuisance))
        peaks.append(g[peak_point] * factor[peak_point] if r == pinned else np.zeros(factor.shape[1]))
    if not blocks:
        return None
    if common:
        return ForceNoise(sum(blocks), sum(peaks))
    return ForceNoise(np.hstack(blocks), np.concatenate(peaks))


def peak_pin(check: RunCheck, process, theta: np.ndarray, pm: PressModel, cs: CalibrationSettings,
             noise: NoiseLevel) -> tuple[float, PeakPin, int]:
    """The model's peak |torque| (N m) of a run at the theoretical values over the points `calibrate` takes Eq. 23's
    peak from (farther than the job's peak window after die contact), and its :class:`PeakPin`: the scaled [J Z] row
    there (sign of the torque's) and the noise the job's peak filter leaves in the measured peak (the grid point's
    noise times the filter's gain, :mod:`calibration.identification.peak`). Over several runs `calibrate` compares the
    largest peak: the run with the largest model peak pins the estimate. Third: that peak's grid index."""
    motion = check.run.motion()
    steps = force_step_angles(pm, process) if process is not None else []
    mask = peak_points(theta, motion.time, steps[:1], cs.peak_window_after_contact_s)
    cols = check.columns
    T = np.where(mask, np.abs(cols.torque), -np.inf)
    i = int(np.argmax(T))
    row = math.copysign(1.0, float(cols.torque[i])) * np.concatenate([cols.J[i], cols.Z[i]])
    return float(T[i]), PeakPin(row, math.sqrt(noise.variance) * filter_gain(theta, steps, i, cs.peak_filter_window_deg,
                                                                             cs.peak_filter_order)), i


def job_run(job: Job) -> Run:
    """The job's own run (its [motion] and [process]) as a :class:`Run`: a candidate of the design's search (so the
    design is at least as informative as that run repeated) and what its prediction is compared with."""
    if job.motion is None:
        raise PressDataError(job.source, "[motion]", None, "is missing: the design compares its runs with the job's own run")
    motion = make_motion(job.motion, job.source)
    f = max(job.process.forces) if job.process.forces else 0.0
    return Run(60.0 / motion.period, float(job.motion.get("speed_depth", 0.0)), float(job.motion.get("slow_angle_deg", 0.0)),
               float(f), float(job.process.contact_height))


def _job_run(press: PressData, job: Job, problem: CalibrationProblem, ev: Evaluator, pm: PressModel) -> RunCheck:
    """The job's own run (:func:`job_run`) under the same draws, limits and noise as the designed runs."""
    motion = make_motion(job.motion, job.source)
    return ev.check_model(job_run(job), build_batch_model(press, motion, job.process, pm=pm), motion)


# ------------------------------------------------------------------------------------------------
# files


def toml_text(table: dict, prefix: str = "") -> str:
    """TOML text of a nested table of numbers, strings, booleans and lists of them (the job files' kinds of value)."""
    lines, subs = [], []
    for k, v in table.items():
        if isinstance(v, dict):
            subs.append((k, v))
        else:
            lines.append(f"{k} = {_toml_value(v)}")
    out = ("\n".join(lines) + "\n") if lines else ""
    for k, v in subs:
        name = f"{prefix}.{k}" if prefix else k
        out += f"\n[{name}]\n" + toml_text(v, name)
    return out


def _toml_value(v) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, (int, np.integer)):
        return str(int(v))
    if isinstance(v, (float, np.floating)):
        return repr(float(v)) if math.isfinite(v) else ("inf" if v > 0 else "-inf" if v < 0 else "nan")
    if isinstance(v, str):
        return '"' + v.replace("\\", "\\\\").replace('"', '\\"') + '"'
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(_toml_value(x) for x in v) + "]"
    raise TypeError(f"no TOML form for {type(v).__name__}")


def run_job(design: Design, i: int, check: RunCheck) -> str:
    """The text of run_<i>/job.toml: the run's motion and cushion, the base job's [experiment] and [calibration]."""
    r = check.run
    job = design.job
    table = {"schema": SCHEMA, "job": {"name": f"designed calibration run {i} of {len(design.result.runs)} ({job.name})"},
             "motion": {"kind": "modulated", "strokes_per_min": round(r.strokes_per_min, 6), "speed_depth": round(r.speed_depth, 6),
                        "slow_angle_deg": round(r.slow_angle_deg % 360.0, 4)}}
    if r.process() is not None:
        table["process"] = {"contact_height_m": round(r.cushion_stroke_m, 6), "heights_m": [round(r.cushion_stroke_m, 6), 0.0],
                            "forces_N": [round(r.cushion_force_N, 1), round(r.cushion_force_N, 1)]}
    for section in ("experiment", "calibration"):
        if section in job.raw:
            table[section] = job.raw[section]
    # the parameters the runs were designed for, which `calibrate --job` fits (the base job's list may name more)
    table["calibration"] = {"parameters": list(design.problem.names),
                            **{k: v for k, v in table.get("calibration", {}).items() if k != "parameters"}}
    left = [n for n in design.calibration.parameters if n not in design.problem.names]
    head = [f"# Designed by `servo-press design-experiment` from {job.source} on {design.press.name}: run {i} of "
            f"{len(design.result.runs)} (D-optimal over the runs together, calibration/design/runs.py).",
            f"# Motor figures at the worst of {len(design.draws)} parameter draws: peak {max(check.peak_torque, check.dense_peak_torque or 0.0):.0f} N m, "
            f"RMS (Eq. 24) {check.rms_torque:.0f} N m, motor speed {check.max_motor_speed * 60 / (2 * math.pi):.0f} rpm.",
            "# [experiment] and [calibration] are the base job's: `servo-press experiment` writes a SYNTHETIC log of this run "
            "with its truth, `servo-press calibrate --job` fits it.",
            f"# [calibration] parameters: the {len(design.problem.names)} the runs were designed for"
            + (f" (the base job's {', '.join(left)} held at the press file's values)." if left else "."), ""]
    return "\n".join(head) + toml_text(table)


def run_profile(design: Design, check: RunCheck, pm: PressModel, period_s: float) -> tuple[dict, dict]:
    """(profile.csv columns, cam_table.csv columns) of one turn of the run at the theoretical parameters: the columns
    `plan` writes, from crank angle 0 deg (the run's continuous rotation has no start or stop), times every
    ``period_s`` (profile: the job's sample_time_s) and every controller_period_s (cam table)."""
    run = check.run
    motion = run.motion()
    process = run.process()
    grid, table = torque_table(pm, motion, process or NO_PROCESS, math.radians(0.25))
    bm = design.family.one
    dh = bm.height_dot  # at theta_dot = 1: dH/dtheta, m/rad
    th_g = np.append(bm.theta, 2.0 * math.pi)
    spline = CubicHermiteSpline(th_g, np.append(bm.height, bm.height[0]), np.append(dh, dh[0]))
    u = design.press.drive.gear_ratio

    def sample(dt):
        t = np.arange(int(math.floor(motion.period / dt + 1e-9)) + 1) * dt
        if t[-1] < motion.period - 1e-12:
            t = np.append(t, motion.period)
        th = theta_of_time(motion, t)
        th[-1] = 2.0 * math.pi if abs(t[-1] - motion.period) < 1e-12 else th[-1]
        w = np.mod(th, 2.0 * math.pi)
        return t, th, motion.theta_dot(w), motion.theta_ddot(w), np.interp(w, grid, table), w

    t, th, sd, sdd, tq, w = sample(period_s)
    profile = {"time_s": t, "crank_angle_deg": np.degrees(th), "crank_speed_rad_s": sd, "crank_accel_rad_s2": sdd + 0.0,
               "slide_height_m": spline(w), "slide_velocity_m_s": spline(w, 1) * sd, "motor_torque_Nm": tq,
               "motor_speed_rpm": sd * u * 60.0 / (2.0 * math.pi)}
    t, th, sd, sdd, tq, _ = sample(design.settings.controller_period)
    cam = {"time_s": t, "motor_position_deg": np.degrees(th) * u, "motor_speed_rpm": sd * u * 60.0 / (2.0 * math.pi),
           "motor_accel_rad_s2": sdd * u + 0.0, "feedforward_torque_Nm": tq}
    return profile, cam


def prediction_record(design: Design, playbacks: list[dict] | None = None) -> dict:
    """The content of prediction.json."""
    d = design
    runs = []
    for i, (c, p) in enumerate(zip(d.result.runs, d.run_predictions), start=1):
        entry = {"run": i, "folder": f"run_{i}", **c.run.record(), "peak_motor_torque_Nm": max(c.peak_torque, c.dense_peak_torque or 0.0),
                 "peak_motor_torque_on_grid_Nm": c.peak_torque, "rms_motor_torque_Nm": c.rms_torque,
                 "max_motor_speed_rpm": c.max_motor_speed * 60.0 / (2.0 * math.pi), "within_limits_for_every_draw": c.feasible,
                 "alone": p.record()}
        if playbacks is not None:
            entry["playback"] = playbacks[i - 1]
        runs.append(entry)
    c = d.cushion
    m = d.press.motor
    return {
        "design": {**d.prediction.record(), "runs": runs, "criterion_mean_log_det": d.result.score},
        "cushion_test": {**d.cushion_prediction.record(), "job": d.job.name, **c.run.record(), "peak_motor_torque_Nm": c.peak_torque,
                         "rms_motor_torque_Nm": c.rms_torque, "within_limits_for_every_draw": c.feasible},
        "aim": d.aim(),
        "parameters": list(d.problem.names),
        "theoretical": {n: float(x) for n, x in zip(d.problem.names, d.problem.theoretical)},
        "bounds": {n: [float(a), float(b)] for n, a, b in zip(d.problem.names, d.problem.low, d.problem.high)},
        "nuisance_estimated": d.nuisance,
        "noise": {"noise_rms_Nm": d.noise.rms_Nm, "noise_inflation": d.noise.inflation, "source": d.noise.source,
                  "strokes": d.noise.strokes, "force_noise_N": d.noise.force_noise_N,
                  "what": "the noise of one grid point of a run's stroke-averaged torque curve (N m per motor) and the AR(1) factor of "
                          "its correlation along the grid; the half-widths hold for runs logged with as many strokes as `strokes` "
                          "(each scales by sqrt(strokes / S) for S strokes; null: as many as the job's calibration had); "
                          "force_noise_N the noise of one grid point of a run's stroke-averaged logged process force (N), "
                          "which the model takes in place of the job's force"},
        "limits": {"peak_torque_Nm": d.settings.torque_limits(m.peak_torque).verdict, "feedback_reserve": d.settings.feedback_reserve,
                   "feedforward_torque_limit_Nm": d.settings.torque_limits(m.peak_torque).feedforward,
                   "peak_checked_on": f"the run family's {360.0 / d.family.one.n_points:g}-deg grid in the search; the chosen runs again on "
                                      f"{DENSE_STEP_DEG:g}-deg points (the grid's knots and 1/4, 1/2, 3/4 of each step): peak_motor_torque_Nm",
                   "rated_torque_Nm": d.settings.thermal_margin * m.rated_torque,
                   "max_motor_speed_rpm": d.settings.speed_margin * m.max_speed * 60.0 / (2.0 * math.pi)},
        "robust": {"criterion": "mean of log det over the draws, less a penalty on any |correlation| above the limit",
                   "limits": "worst case over the draws",
                   "draws": {n: [float(v) for v in d.draws[:, j]] for j, n in enumerate(d.problem.names)}, "seed": d.settings.seed},
        "search": {"candidates": d.result.candidates, "feasible_candidates": d.result.feasible_candidates, "model_cycles": d.result.cycles},
        "definitions": {
            "half_widths": f"predicted {100 * d.calibration.interval_level:g} % half-widths (SI units) of Eq. 28's estimate, linearised: "
                           "t-quantile x sqrt(diag(C)) with C = F^-1, F the information of the runs at the noise of `noise`, and the "
                           "variance along the model peak's gradient replaced by the measured peak's, which Eq. 28 holds the model's peak to "
                           "(calibration/design/information.py pinned_covariance), plus the covariance the logged process force's "
                           "noise (noise.force_noise_N) adds through the calibration's smoothing of the force and the model torque "
                           "per N of force (force_covariance), plus what the force channel's stated scale and offset accuracy "
                           "([calibration.process_force] logged_scale_accuracy, logged_offset_accuracy) moves the estimate, as "
                           "calibrate's intervals carry it (carried_covariance)",
            "correlation": "of the parameter estimates, from C (the nuisance effects eliminated)",
            "half_widths_given_nuisance": "the same with the channel delay and encoder offset known; half_widths carry their uncertainty, "
                                          "as calibrate's intervals do (the recording correction's uncertainty added in quadrature)",
        },
        "job": d.job.name, "job_source": d.job.source, **d.press.identity(), "versions": versions(),
    }


def write_design(design: Design, out: Path, playbacks: list[dict] | None = None, pm: PressModel | None = None) -> dict:
    """Write run_N/{job.toml, profile.csv, cam_table.csv}, design.png, report.md and prediction.json (last) into ``out``."""
    out = Path(out)
    pm = pm or design.family.pm
    for i, c in enumerate(design.result.runs, start=1):
        folder = out / f"run_{i}"
        folder.mkdir(parents=True, exist_ok=True)
        atomic_write_text(folder / "job.toml", run_job(design, i, c))
        profile, cam = run_profile(design, c, pm, design.settings.sample_time)
        write_csv(folder / "profile.csv", profile)
        write_csv(folder / "cam_table.csv", cam, comments=(
            f"interpolation: per-period: one row per controller period ({design.settings.controller_period:g} s), each row the set-point "
            "of its cycle (between rows linear in time); speed and acceleration from their columns, or from central differences "
            "of the position at the period (as `plan`'s cam_table.csv, planning/cams.py); one turn of a continuous "
            "rotation from crank angle 0: the next turn starts from the last row's motor position (endless positive)",))
    rec = prediction_record(design, playbacks)
    save(design_figure(design), out / "design.png")
    atomic_write_text(out / "report.md", report_markdown(rec))
    write_json(out / "prediction.json", rec)
    return rec


def design_figure(design: Design):
    """Crank speed and motor torque of each run and of the cushion test over the turn; the predicted interval widths
    (share of each calibration range) of the design and of the cushion test side by side."""
    d = design
    fig, axes = subplots(1, 3, figsize=(15, 4.6))
    bm = d.family.one
    deg = np.degrees(bm.theta)
    ax, ax2, ax3 = axes
    checks = [(f"run {i}", c) for i, c in enumerate(d.result.runs, start=1)] + [("cushion test", d.cushion)]
    for k, (label, c) in enumerate(checks):
        style = dict(color=f"C{k}", lw=1.3, ls="--" if label == "cushion test" else "-")
        ax.plot(deg, c.run.motion().theta_dot(bm.theta), label=f"{label}: {c.run.strokes_per_min:.1f} spm, cushion {c.run.cushion_force_N / 1e3:.0f} kN "
                f"below {1e3 * c.run.cushion_stroke_m:.0f} mm", **style)
        ax2.plot(deg, c.columns.torque / 1e3, label=label, **style)
    torque_limit_lines(ax2, d.settings.torque_limits(d.press.motor.peak_torque))  # T_max and the margin, as every torque figure
    ax.set(xlabel="crank angle [deg]", ylabel="crank speed [rad/s]", title="designed runs (theoretical parameters)")
    ax2.set(xlabel="crank angle [deg]", ylabel="motor torque per motor [kN m]", title="motor torque")
    ax.legend(fontsize=7)
    ax2.legend(fontsize=7)
    names = d.problem.names
    x = np.arange(len(names))
    ax3.bar(x - 0.2, 100 * d.cushion_prediction.width_of_range(), 0.4, label="single cushion test", color="0.6")
    ax3.bar(x + 0.2, 100 * d.prediction.width_of_range(), 0.4, label=f"design ({len(d.result.runs)} runs)", color="C0")
    ax3.axhline(100 * d.calibration.interval_width_limit, color="k", lw=0.8, ls=":", label="width limit")
    ax3.set_xticks(x, names)
    ax3.set(ylabel="predicted 95 % interval width [% of range]", title="predicted intervals")
    ax3.legend(fontsize=8)
    for a in axes:
        a.grid(alpha=0.3)
    tight_layout(fig)
    return fig


def ratio_words(r: float) -> str:
    """How one width compares with another, ``r`` = the other over this one: "2.0x narrower than" or "2.5x wider than"."""
    return f"{r:.1f}x narrower than" if r >= 1.0 else f"{1.0 / r:.1f}x wider than"


def aim_next_steps(a: dict, runs: int) -> list[str]:
    """One line per aim the prediction misses (``a``: prediction.json's ``aim``, for ``runs`` runs), each ending with the
    next step: what changes the prediction in that direction."""
    most = run_limits().max_runs
    more = f"--runs {min(2 * runs, most)}" if runs < most else f"no more than {most} runs: log more strokes"
    pair = " and ".join(a["design_max_abs_correlation"]["pair"])
    widest = a["design_widest"]["parameter"]
    steps = {
        "all_correlations_below_limit": (f"{pair} correlate {a['design_max_abs_correlation']['value']:+.2f}, beyond the limit "
                                         f"{a['correlation_limit']:g}: next, widen the job's [design] ranges (rate, speed depth, "
                                         f"cushion force and stroke) so the runs move them apart, or calibrate one of them only"),
        "all_intervals_under_width_limit": (f"{widest}'s interval spans {100 * a['design_widest']['width_share_of_range']:.0f} % of "
                                            f"its range, beyond {100 * a['interval_width_limit']:.0f} %: next, design more runs "
                                            f"({more}: a half-width narrows at most as 1 / sqrt(runs)) or log more strokes a run "
                                            f"(1 / sqrt(strokes)), or leave {widest} out of --parameters"),
        "widest_at_least_3x_narrower": (f"the widest interval is {ratio_words(a['widest_interval_ratio'])} the cushion test's, "
                                        f"short of 3x narrower: next, design more runs ({more}) or widen the job's [design] ranges"),
    }
    return [f"{k.replace('_', ' ')}: NO; {steps[k]}." for k, v in a.items() if v is False and k in steps]


def report_markdown(rec: dict) -> str:
    """report.md: the runs, their limits and playback verdicts, the predicted intervals beside the cushion test's."""
    d, c, a = rec["design"], rec["cushion_test"], rec["aim"]
    names = rec["parameters"]
    lines = [f"# Designed calibration experiment: {len(d['runs'])} runs on {rec['press']}", "",
             f"Base job: {rec['job']} (`{rec['job_source']}`). Criterion: {rec['robust']['criterion']} "
             f"({len(next(iter(rec['robust']['draws'].values())))} draws, seed {rec['robust']['seed']}); limits: {rec['robust']['limits']}. "
             f"Noise of the stroke-averaged curve: {rec['noise']['noise_rms_Nm']:g} N m x inflation {rec['noise']['noise_inflation']:g}, "
             f"of the logged process force {rec['noise']['force_noise_N']:g} N a grid point ({rec['noise']['source']}). Recording nuisance (delay, offset) {'estimated with the parameters' if rec['nuisance_estimated'] else 'not estimated'}.",
             "", "![runs and predicted intervals](design.png)", "",
             "## Runs", "",
             "| run | strokes/min | speed depth | slowest at [deg] | cushion force [kN] | cushion stroke [mm] | peak torque [N m] | RMS torque [N m] | motor speed [rpm] | playback |",
             "|---|---|---|---|---|---|---|---|---|---|"]
    for r in d["runs"]:
        pb = r.get("playback")
        verdict = pb["verdict"]["line"] if pb else "not played back"
        lines.append(f"| {r['folder']} | {r['strokes_per_min']:.3f} | {r['speed_depth']:.3f} | {r['slow_angle_deg'] % 360:.1f} | "
                     f"{r['cushion_force_N'] / 1e3:.0f} | {1e3 * r['cushion_stroke_m']:.0f} | {r['peak_motor_torque_Nm']:.0f} | "
                     f"{r['rms_motor_torque_Nm']:.0f} | {r['max_motor_speed_rpm']:.0f} | {verdict} |")
    lim = rec["limits"]
    lines += ["", f"Limits on every run and every draw: peak {lim['peak_torque_Nm']:.0f} N m with the feedback, the model's torque (the "
              f"feed-forward) {lim['feedforward_torque_limit_Nm']:.0f} N m (feedback reserve {lim['feedback_reserve']:g} T_max, as `plan`; "
              f"the runs' peaks checked on {DENSE_STEP_DEG:g}-deg points), RMS {lim['rated_torque_Nm']:.0f} N m, "
              f"motor speed {lim['max_motor_speed_rpm']:.0f} rpm. The job's single cushion test: peak {c['peak_motor_torque_Nm']:.0f} N m, "
              f"RMS {c['rms_motor_torque_Nm']:.0f} N m ({'within' if c['within_limits_for_every_draw'] else 'NOT within'} these limits for every draw).",
              "", "## Predicted 95 % intervals: design beside the single cushion test", "",
              "| parameter | theoretical | design: half-width | design: width / range | cushion test: half-width | cushion test: width / range | narrower by |",
              "|---|---|---|---|---|---|---|"]
    for n in names:
        hd, hc = d["half_widths"][n], c["half_widths"][n]
        lines.append(f"| {n} | {rec['theoretical'][n]:.5g} | {hd:.4g} | {100 * d['width_share_of_range'][n]:.1f} % | {hc:.4g} | "
                     f"{100 * c['width_share_of_range'][n]:.1f} % | {hc / hd:.1f}x |")
    if rec["nuisance_estimated"]:
        dn, cn = d["nuisance_standard_errors"], c["nuisance_standard_errors"]
        lines += ["", f"Recording nuisance (estimated by `calibrate` with the parameters; shared by the runs): standard error of the channel "
                  f"delay {1e3 * dn['channel_delay_s']:.2f} ms and of the encoder offset {dn['angle_offset_deg']:.3f} deg, correlated "
                  f"{d['nuisance_correlation']:+.2f} (single cushion test: {1e3 * cn['channel_delay_s']:.2f} ms, {cn['angle_offset_deg']:.3f} deg, "
                  f"{c['nuisance_correlation']:+.2f}). The half-widths above carry their uncertainty, as `calibrate`'s intervals do; with delay "
                  "and offset known they would be: "
                  + ", ".join(f"{n} {d['half_widths_given_nuisance'][n]:.4g}" for n in names) + "."]
    lines += ["", f"Largest |correlation|: design {a['design_max_abs_correlation']['value']:.2f} ({' and '.join(a['design_max_abs_correlation']['pair'])}), "
              f"cushion test {a['cushion_test_max_abs_correlation']['value']:.2f} ({' and '.join(a['cushion_test_max_abs_correlation']['pair'])}); "
              f"limit {a['correlation_limit']:g}.",
              f"Widest interval: design {a['design_widest']['parameter']} ({100 * a['design_widest']['width_share_of_range']:.1f} % of its range), "
              f"cushion test {a['cushion_test_widest']['parameter']} ({100 * a['cushion_test_widest']['width_share_of_range']:.1f} %): "
              f"{ratio_words(a['widest_interval_ratio']).removesuffix(' than')}.", "",
              "Aim: " + "; ".join(f"{k.replace('_', ' ')}: {'yes' if v else 'NO'}" for k, v in a.items() if isinstance(v, bool)) + ".",
              *(f"- {line}" for line in aim_next_steps(a, len(d["runs"]))),
              "", "## Correlation of the estimates (design)", "", "| | " + " | ".join(names) + " |", "|---" * (len(names) + 1) + "|"]
    M = d["correlation"]["matrix"]
    lines += [f"| {n} | " + " | ".join(f"{v:+.2f}" for v in row) + " |" for n, row in zip(names, M)]
    lines += ["", "## Correlation of the estimates (single cushion test)", "", "| | " + " | ".join(names) + " |", "|---" * (len(names) + 1) + "|"]
    M = c["correlation"]["matrix"]
    lines += [f"| {n} | " + " | ".join(f"{v:+.2f}" for v in row) + " |" for n, row in zip(names, M)]
    lines += ["", "## Running it", "",
              "Each `run_N/job.toml` is a job: `servo-press experiment --job run_N/job.toml` writes a SYNTHETIC log of it, "
              "`servo-press calibrate --log run1.csv --job run_1/job.toml --log run2.csv --job run_2/job.toml` fits the runs' logs "
              "together. `profile.csv` is one turn of the run as `plan` writes it; `cam_table.csv` is the run on the motor side "
              "for the controller (the turn repeats)."]
    return "\n".join(lines) + "\n"
