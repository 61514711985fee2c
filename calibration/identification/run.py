"""The calibration fit: Eq. 28 against one or more drive logs, solved, with its intervals and verdict, as a
:class:`Calibration` (:func:`calibrate`).

The fit takes its inputs as objects read once (:mod:`calibration.identification.inputs`: the logs' rows, the channel map,
the parameter names); a recording correction grids the rows already read again, never the file. What is made of a
:class:`Calibration`: calibrated.json (:mod:`calibration.identification.record`), the console lines
(:mod:`calibration.identification.console`), table4.csv / table4.md / solvers.csv (:mod:`calibration.identification.report`),
figure5.png (:mod:`calibration.identification.figure`); the 'calibrate' command wires them
(:mod:`servo_press.calibrate`).
"""
from __future__ import annotations

import dataclasses
import math
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy import stats
from threadpoolctl import threadpool_limits

from press_model.batch import build_batch_model, motor_torques
from press_io.errors import PressDataError
from press_model.jobs import Job
from press_model.kinematic_tables import force_steps, geometry_key, heights_table
from press_model.model import PressModel
from press_io.progress import progress as show_progress
from press_model.press_data import PressData

from calibration.identification import force_delay, recording
from calibration.traces import log_identity
from calibration.identification.adequacy import Adequacy, Suspects, assess, candidate_columns, lag1
from calibration.identification.bootstrap import Bootstrap, bound_fallback, join_where, on_bound, parametric_bootstrap, refit_batch, statements
from calibration.identification.force_accuracy import logged_force_accuracy, scale_candidates, scale_models, scale_warning
from calibration.identification.force_noise import logged_force_spread
from calibration.identification.held import Held, disagreeing, freed_warning, held_candidates, held_names, held_warning
from calibration.identification.inputs import read_log
from calibration.identification.joint import joint_objective
from calibration.identification.motion_error import estimate_sd, torque_variance
from calibration.traces.drive_log import DriveLog, LogRows, check_against_model, grid_rows
from calibration.traces.motor_shares import MotorShares, shares_of_rows
from calibration.identification.peak import MeasuredPeak, Ringing, fit_ringing, measured_peak, peak_filter
from calibration.identification.peak_noise import carried, held_share, linearised_move, peak_noise_note
from calibration.identification.problem import CalibrationProblem, Objective, metrics, objective, peak_points
from calibration.identification.process_force import (LoggedForce, force_candidate, force_columns, job_force_models,
                                                      logged_force, process_force_account)
from calibration.identification.settings import METHODS, CalibrationSettings, joint_settings_warning
from calibration.identification.solvers import SolverRun, solve
from calibration.identification.speed_fit import crank_motion, describe
from calibration.identification.uncertainty import Uncertainty, analyse, jacobian


@dataclass(frozen=True)
class LogProblem:
    """Eq. 28 built on one drive log: the log, its fitted crank motion, the batch model on that motion, the peak
    points, the force-step angles, the robust measured peak and the objective."""

    log: DriveLog
    objective: Objective
    steps: tuple[float, ...]  # rad, process-force step angles (die contact first)
    peak: MeasuredPeak
    force: LoggedForce | None = None  # the logged process force the model uses (None: the job's nominal curve)
    motion: object = None  # the crank motion the model is built on (calibration/identification/speed_fit.py)
    process: object = None  # the process force the batch model is built on (press_model.forces.ProcessForce)
    ringing: Ringing | None = None  # the die-contact ringing removed before the peak filter (peak.py fit_ringing)


@dataclass(frozen=True)
class Calibration:
    """Everything a calibration run found; ``runs`` holds every solver that ran, ``best`` the one reported.

    ``uncertainty`` is the Jacobian (linearised least-squares) second opinion; ``bootstrap`` the intervals of
    the reported estimator (None when no refits were asked for); ``validation`` the prediction of a second
    log (None without one); ``warnings`` what the user must know about this fit; ``adequacy`` the lack-of-fit
    verdict (:mod:`calibration.identification.adequacy`); ``recording`` the estimated channel delay and encoder offset the log
    was corrected for (None when the job turns it off).
    """

    log: DriveLog
    objective: Objective
    runs: tuple[SolverRun, ...]
    best: SolverRun
    uncertainty: Uncertainty
    before: dict
    after: dict
    peak: MeasuredPeak | None = None
    bootstrap: Bootstrap | None = None
    validation: dict | None = None
    validation_problem: LogProblem | None = None
    warnings: tuple[str, ...] = ()
    statements: tuple[str, ...] = ()
    bootstrap_time_s: float = 0.0
    adequacy: Adequacy | None = None
    recording: recording.RecordingEstimate | None = None
    logs: tuple[DriveLog, ...] = ()  # every log fitted (the first is ``log``)
    adequacy_logs: tuple[Adequacy, ...] = ()  # the verdict of each log; ``adequacy`` is the worst
    recording_spread: np.ndarray | None = None  # (k,) SI: standard deviation the recording correction adds to each parameter
    process_force: dict | None = None  # calibrated.json's account of the process force: logged, or the job's with its sensitivity
    process_force_line: str = ""  # the console's line on it
    notes: tuple[str, ...] = ()  # what the user should know that does not make the fit untrustworthy
    peak_move: np.ndarray | None = None  # (k,) SI: standard deviation the measured peak's noise gives the estimate (peak_noise.py)
    peak_held_share: float = 0.0  # share of that noise's variance on points the bootstrap keeps in place (peak_noise.held_share)
    logged_force_spread: np.ndarray | None = None  # (k,) SI: standard deviation the logged force's noise adds to each parameter
    logged_force_noise: dict | None = None  # calibrated.json's account of it (calibration/identification/force_noise.py)
    motion_sd: np.ndarray | None = None  # (k,) SI: standard deviation the crank motion's own error gives the estimate (motion_error.py)
    motor_shares: MotorShares | None = None  # each motor's share of the total torque (logs with one torque channel per motor)
    # warnings on those shares (share_warnings): the plan holds the heaviest motor to the margin, so they are no doubt
    # about the fit, and calibrated.json keeps them beside the shares, not among its warnings
    share_warnings: tuple[str, ...] = ()
    # the job's parameters this fit held and those it freed because the log disagreed with them, with what freeing did
    # (calibration/identification/held.py; None: the fit held none); not among ``warnings``: a fit freed to adequacy is one to trust
    held: dict | None = None


def _progress(method: str):
    def show(i, total, best):
        if i < total and i % max(1, total // 20):
            return  # about twenty updates a run
        show_progress(method, i, total, f"Eq. 28 objective {best:.5f}")
    return show


def log_problem(press: PressData, job: Job, cs: CalibrationSettings, problem: CalibrationProblem, rows: LogRows,
                pm: PressModel | None = None, correction: tuple = (0.0, 0.0), models: dict | None = None) -> LogProblem:
    """Bring a log's rows (read once, :func:`calibration.identification.inputs.read_log`) onto the crank grid and build
    Eq. 28 on its own crank motion (:func:`calibration.identification.speed_fit.crank_motion`), the job's process force, the peak window
    after die contact and the filtered measured peak. ``correction``: (channel delay in s, encoder offset in deg) the
    samples are corrected for (:mod:`calibration.identification.recording`), and optionally third the lost motion
    (motor deg, the gear torque's curve on the grid whose sign says which way) they are corrected for; ``models``: crank motions and batch models
    already built, by the log's crank speed curve and samples (a delay correction leaves them as they were), and the
    job's force step angles, filled in here. The force steps and the grid's slide heights are read from the disk cache
    by the press's geometry (:mod:`press_model.kinematic_tables`: the same numbers, ~0.4 s of CPU a log
    otherwise)."""
    pm = pm or PressModel(press)
    geometry = models.get("geometry") if models is not None else None
    if geometry is None:  # the press's kinematics' key: its grid heights and force steps are kept on disk by it
        geometry = geometry_key(pm)
        if models is not None:
            models["geometry"] = geometry
    steps_key = ("force steps", job.source, job.name)  # the job's, on the nominal press: no correction moves them
    steps = models.get(steps_key) if models is not None else None
    if steps is None:
        steps = tuple(force_steps(pm, geometry, job.process))
        if models is not None:
            models[steps_key] = steps
    log = grid_rows(rows, press.drive.gear_ratio, press.motor.rated_torque, 1.0, peak_torque_Nm=press.motor.peak_torque,
                    correction=correction, force_steps_deg=np.degrees(steps))
    motion_key = ("motion", log.crank_speed.tobytes(), None if log.speed_samples is None else log.speed_samples.tobytes())
    try:
        motion = models.get(motion_key) if models is not None else None
        if motion is None:  # the speed channel is the angle's: a delay correction leaves the motion as it was
            motion = crank_motion(log, cs)
            if models is not None:
                models[motion_key] = motion
    except ValueError as exc:
        raise PressDataError(rows.source, "motor_speed_rpm", "fitted crank speed", f"must stay positive over the turn ({exc}); the log must come from continuous running") from None
    force, process = None, job.process
    if log.stroke_force is not None:  # a logged force replaces the job's nominal curve (calibration/identification/process_force.py)
        heights = models.get("heights") if models is not None else None
        if heights is None:
            heights = heights_table(pm, geometry, log.theta)
            if models is not None:
                models["heights"] = heights
        turns = (log.stroke_force_binned, log.stroke_force_counts) if log.stroke_force_binned is not None else None
        force = logged_force(rows.source, log.theta, log.stroke_force, heights, job.process, cs.process_force, log.force_binned,
                             turns)
        process = force.process
    # the motion and the process force the model is built on
    key = (motion_key, cs.speed_harmonics, job.source, job.name, None if force is None else force.curve.tobytes())
    bm = models.get(key) if models is not None else None
    if bm is None:
        bm = build_batch_model(press, motion, process, pm=pm)
        if models is not None:
            models[key] = bm
    nominal = motor_torques(bm, bm.nominal[None])[0]
    check_against_model(log, nominal, log.torque_unit)  # sign and scale, before fitting
    if force is not None and force.steps:  # the logged force's own steps (the grid read the samples beside the job's)
        steps = force.steps
    mask = peak_points(bm.theta, motion.time, steps[:1], cs.peak_window_after_contact_s)  # die contact; BDC rings no impact
    ringing = None
    if cs.peak_ringing_fit and steps and not mask.all():  # the nominal model's misfit is smooth, the ringing is not
        period = float(motion.time(np.array([2.0 * math.pi]))[0])
        ringing = fit_ringing(motion.time(bm.theta), period, log.torque, nominal, float(motion.time(np.array([steps[0]]))[0]),
                              ~mask, (cs.peak_filter_window_deg, cs.peak_filter_order), math.degrees(bm.theta[1] - bm.theta[0]))
    refused = ringing.unresolved() if ringing is not None else ""
    if refused:  # a fit on the edge of what the grid resolves is no result: nothing removed, and its numbers not reported
        ringing = None
    cleared = log.torque if ringing is None else ringing.clear(log.torque)
    peak = measured_peak(bm.theta, cleared, log.torque_spread, log.strokes, mask, steps,
                         cs.peak_filter_window_deg, cs.peak_filter_order)
    if ringing is not None or refused:
        peak = dataclasses.replace(peak, ringing=refused or ringing.describe())
    return LogProblem(log, objective(problem, bm, log.torque, mask, peak.value_Nm), steps, peak, force, motion,
                      process, ringing)


def _objective_on_curve(lp: LogProblem, cs: CalibrationSettings):
    """Eq. 28 against another curve on the same grid, built as the calibration built it against the log."""
    o = lp.objective
    t0 = o.torques(o.problem.theoretical[None])[0]

    def make(curve):
        filtered = peak_filter(o.bm.theta, curve, lp.steps, cs.peak_filter_window_deg, cs.peak_filter_order, lp.ringing)
        return objective(o.problem, o.bm, curve, o.peak_points, float(np.max(np.abs(filtered[o.peak_points]))), t0)

    return make


def _fixed_points(lp: LogProblem, guard_deg: float) -> np.ndarray:
    """Grid points that keep their own residual in the bootstrap: the die-contact window and the force steps' neighbours."""
    th = lp.objective.bm.theta
    fixed = ~lp.objective.peak_points
    for a in lp.steps:
        fixed |= np.abs(np.angle(np.exp(1j * (th - a)))) <= np.radians(guard_deg) + 1e-12
    return fixed


def peak_noise(lps: list[LogProblem], cs: CalibrationSettings) -> tuple[float, float, float]:
    """(|Y_PR,0| x the measured peak in N m, the noise left in the filtered measured peak in N m, the share of its
    variance on the points the bootstrap keeps in place (:func:`calibration.identification.peak_noise.held_share`)) of
    the log whose peak Eq. 28 compares against (the largest measured peak, :mod:`calibration.identification.joint`)."""
    lp = max(lps, key=lambda q: q.objective.measured_peak)
    o = lp.objective
    share = held_share(o.bm.theta, o.measured, o.peak_points, _fixed_points(lp, cs.bootstrap.step_guard_deg), lp.steps,
                       cs.peak_filter_window_deg, cs.peak_filter_order, lp.ringing)
    return abs(o.pr0) * o.measured_peak, lp.peak.sigma_Nm, share


def trust_warnings(problem: CalibrationProblem, x: np.ndarray, force_logged: int = 0, logs: int = 1) -> list[str]:
    """What makes this fit untrustworthy whatever its intervals say: estimates on a range bound. (A fit that misses
    the log by more than its stroke-to-stroke noise is the adequacy verdict's to name, :mod:`calibration.identification.adequacy`.)
    ``force_logged`` of the ``logs`` logs carry their process force, which the model took in place of the job's: the
    advice names the force the model used."""
    edge = on_bound(x, problem.low, problem.high)
    if not edge.any():
        return []
    force = ("the logged process force (process_force_N: its unit and scale, which replaced the job's)" if force_logged == logs
             else "the job's process force and the logged one (process_force_N, which replaced it in the logs that have it)"
             if force_logged else "the job's process force")
    return [f"{', '.join(n for n, e in zip(problem.names, edge) if e)} ended on a bound of the calibration range: the data "
            "pull beyond the range, which no press of this kind should need; check the log's torque scale and unit, the "
            f"press file and {force} before using these values"]


def calibrate(press: PressData, job: Job, log: LogRows | str | Path, methods: list[str], seed: int,
              settings: CalibrationSettings | None = None, *, progress: bool = True,
              validate: LogRows | str | Path | None = None, more_logs=()) -> Calibration:
    """Build Eq. 28 on the log's own crank motion and the job's process force, and solve it; returns the
    :class:`Calibration`.

    ``log``: the drive log's rows as read once (:func:`calibration.identification.inputs.read_log`: a drive trace
    through its channel map, or a torque in another unit, is read there), or the path of a plain drive-log CSV with
    its torque in N m, read here once. ``settings``: the job's [calibration] as read (default: read from ``job``):
    its ``parameters`` are calibrated (a caller's choice replaces the job's list), and its ``bootstrap.refits``
    refits give the parametric bootstrap of the reported estimate (0 skips it and the Jacobian intervals are
    reported); the Jacobian second opinion is made always. ``validate``: a second drive log (another day, another
    motion; rows or path as ``log``) predicted with the theoretical and the calibrated parameters. ``more_logs``:
    further (log, job) pairs fitted jointly with the first (:mod:`calibration.identification.joint`; another speed or
    cushion force). ``progress``: the solvers' progress lines on stderr.
    """
    # OpenBLAS splits a product differently for another thread count, which moves the estimate in its last
    # digits: one BLAS thread makes the result the same on every machine and in every worker (the matrices are small)
    with threadpool_limits(1, user_api="blas"):
        cs = settings if settings is not None else CalibrationSettings.from_job(job)
        for m in methods:
            if m not in METHODS:
                raise PressDataError("--method", "--method", m, f"must be one of {', '.join(METHODS)} or 'all'")
        problem = CalibrationProblem.from_press(press, cs.parameters, cs.weight, job.source)

        def rows_of(x) -> LogRows:  # a path given by a library caller is read here, once
            return x if isinstance(x, LogRows) else read_log(x, press, "N*m", None)

        pairs = [(rows_of(log), job), *((rows_of(lg), jb) for lg, jb in more_logs)]  # each log with the job it was run with
        vrows = rows_of(validate) if validate is not None else None
        held = Held(held_names(CalibrationSettings.from_job(job).parameters, cs.parameters))  # the job's list less a subset's
        return _calibrate(press, pairs, vrows, cs, problem, methods, seed, progress, held)


@dataclass(frozen=True)
class _FirstPass:
    """What a fit repeated with more parameters (held parameters freed, :func:`_calibrate`) takes over from the first
    fit of the same logs: the press model, each log's rows with its force read late by its lag and that lag, the crank
    motions and batch models built (``models``, :func:`log_problem`), and the log problems (the validation log's
    ``vp``) before any recording correction (their Eq. 28 rebuilt on each fit's parameters, :func:`_on_problem`)."""

    pm: PressModel
    pairs: list
    lags: list
    models: dict
    lps: list
    vp: LogProblem | None


def _on_problem(lp: LogProblem | None, problem: CalibrationProblem) -> LogProblem | None:
    """``lp`` with Eq. 28 built on ``problem`` as :func:`log_problem` builds it (the same curve, peak points and peak)."""
    if lp is None:
        return None
    o = lp.objective
    return dataclasses.replace(lp, objective=objective(problem, o.bm, o.measured, o.peak_points, o.measured_peak))


def _first_pass(press: PressData, pairs, vrows, cs: CalibrationSettings, problem: CalibrationProblem) -> _FirstPass:
    """The logs read onto the crank grid and Eq. 28 built on them (:class:`_FirstPass`); bad input fails here, before
    any fit."""
    pm = PressModel(press)
    models: dict = {}
    # each log's force read against its torque channel, late by its lag where that is beyond its noise (force_delay.py)
    lags = [force_delay.lag_of_rows(rows) for rows, _ in pairs]
    pairs = [(force_delay.with_lag(rows, lag, cs.interval_level), jb) for (rows, jb), lag in zip(pairs, lags)]
    lps = [log_problem(press, jb, cs, problem, rows, pm, models=models) for rows, jb in pairs]
    vp = log_problem(press, pairs[0][1], cs, problem, vrows, pm) if vrows is not None else None
    return _FirstPass(pm, pairs, lags, models, lps, vp)


def _calibrate(press: PressData, pairs: list[tuple[LogRows, Job]], vrows: LogRows | None, cs: CalibrationSettings,
               problem: CalibrationProblem, methods: list[str], seed: int, progress: bool, held: Held = Held(),
               first: _FirstPass | None = None) -> Calibration:
    """:func:`calibrate` on the logs read: ``pairs`` (rows, job) of each log fitted, ``vrows`` the validation log's;
    ``held`` the job's parameters held at the press file's values (:mod:`calibration.identification.held`), each
    score-tested, and those the log disagrees with freed and the fit repeated (``free_held``) or named in a warning;
    a fit repeated so says what freeing did, and takes over from ``first`` what does not depend on the parameters
    fitted (:class:`_FirstPass`). What only the reported fit needs (the intervals' widenings, the Jacobian analysis,
    the peak's noise) is made once the fit is not to be repeated, from the same inputs."""
    if first is None:
        first = _first_pass(press, pairs, vrows, cs, problem)
        lps, vp = first.lps, first.vp
    else:
        lps, vp = [_on_problem(lp, problem) for lp in first.lps], _on_problem(first.vp, problem)
    pm, pairs, lags, models = first.pm, first.pairs, first.lags, first.models
    shared = log_identity.check([lp.log for lp in lps], vp.log if vp is not None else None)  # one recording twice is refused
    warnings = [w for w in (joint_settings_warning([jb for _, jb in pairs]), *log_identity.validation_warning(shared)) if w]
    shares = heaviest_shares([rows for rows, _ in pairs])
    obj = joint_objective(problem, [lp.objective for lp in lps])
    runs = []
    for m in methods:
        runs.append(solve(m, obj, cs, seed, _progress(m) if progress else None))
    best = min(runs, key=lambda r: r.objective)  # ties: the first in METHODS order, so reruns agree
    rec_est, motion_var = None, None
    if cs.recording.estimate:
        rec_est, lps, obj, best, lash_u, motion_var = _correct_recording(pm, pairs, cs, problem, lps, obj, best, models)
    # the validation log is predicted as logged: on one motion only a combination of delay and offset is known, and
    # the split that fits this motion shifts another motion's curve differently
    log = lps[0].log
    # the force's scale columns the adequacy test takes as suspects, and the models its account is read from
    pf_models = job_force_models([jb for _, jb in pairs], problem, pm, lps)
    fa_models = scale_models(problem, pm, lps)
    # the crank motion's own error (calibration/identification/motion_error.py): in the lack-of-fit test and the intervals
    if rec_est is None or rec_est.iterations > 0:  # a corrected log: its motion and parameters moved
        motion_var = _motion_variance(lps, problem, best.x, pm)
    parts_adequacy = _adequacy(lps, best.x, cs, press, (force_columns(lps, pf_models, best.x), held.names), motion_var,
                               scale_candidates(lps, fa_models, best.x))
    adequacy = min(parts_adequacy, key=lambda a: (a.adequate, a.p_value))  # the worst log speaks for all
    scale_warnings = [w for lp, a in zip(lps, parts_adequacy)
                      if (w := scale_warning(a.tests, cs.process_force, lp.log.source if len(lps) > 1 else "",
                                             lp.force.scale if lp.force is not None else None))]
    wrong = list({t.name: t for a in parts_adequacy for t in disagreeing(a.tests)}.values())
    if wrong and cs.adequacy.free_held:  # the subset's fit is the best fit of a press with a wrong value: fit again
        if progress:
            sys.stderr.write(f"  held parameters the log disagrees with: {', '.join(t.name for t in wrong)}; freed, fitting again\n")
        rmse = metrics(obj.torques(best.x[None])[0], obj.measured, obj.bm.theta_dot, obj.peak_points)["rmse_Nm"]
        names = (*problem.names, *(t.name for t in wrong))
        problem2 = CalibrationProblem.from_press(press, names, cs.weight, pairs[0][1].source)
        return _calibrate(press, pairs, vrows, dataclasses.replace(cs, parameters=names), problem2, methods, seed, progress,
                          held.free(wrong, problem.names, {"rmse": rmse, "F": adequacy.lack_of_fit_ratio}), first)
    pf_record, pf_line, pf_warnings, pf_spread = process_force_account(press, cs, problem, lps, best.x, pf_models)
    warnings += pf_warnings
    fa_record, fa_line, fa_warnings, fa_spread = logged_force_accuracy(cs, problem, pm, lps, best.x, press.motor.peak_torque,
                                                                       fa_models)
    if fa_record is not None:  # the logged force's own accuracy beside its account (force_accuracy.py)
        pf_record = {**pf_record, "logged_force_accuracy": fa_record}
        pf_line = f"{pf_line}\n{fa_line}"
    warnings += fa_warnings
    delays = _force_delays(lags, pairs, rec_est, cs.interval_level)
    if delays:
        pf_record = {**pf_record, "logged_force_delay": [{"log_index": i, **d.record()} for i, d in delays]}
        pf_line += "".join(f"\n{d.statement()}" + (f" [log {pairs[i][0].source}]" if len(pairs) > 1 else "") for i, d in delays)
    lf_spread, lf_record = logged_force_spread(pm, lps, obj, _objective_on_curves(lps, problem, cs), best.x,
                                               cs.bootstrap.iterations, (cs.peak_filter_window_deg, cs.peak_filter_order))
    unc = analyse(obj, best.x, cs.interval_level, cs.correlation_limit, cs.interval_width_limit)
    spread_rec = (np.zeros(len(best.x)) if rec_est is None
                  else _recording_spread(rec_est, best.x, _shifted_refits(lps, problem, cs, best.x, lash_u)))
    motion_all = _end_to_end(lps, motion_var)
    motion_sd = np.zeros(len(best.x)) if motion_all is None else estimate_sd(jacobian(obj, best.x), motion_all)
    # the recording's, the job force's, the logged force's and the crank motion's uncertainty, each a standard deviation,
    # independent
    widen = np.sqrt(spread_rec ** 2 + pf_spread ** 2 + fa_spread ** 2 + lf_spread ** 2 + motion_sd ** 2)
    # least squares has no peak term: the Jacobian intervals add the move the measured peak's noise gives Eq. 28's
    # estimate (the bootstrap's refits redraw the peak themselves)
    gap, peak_sigma, peak_held = peak_noise(lps, cs)
    peak_move = linearised_move(obj, best.x, peak_sigma)
    q_level = float(stats.norm.ppf(0.5 + cs.interval_level / 2.0))
    unc = dataclasses.replace(unc, **_widened(unc.low, unc.high, best.x, q_level * np.hypot(widen, peak_move), problem))
    q_joint = float(stats.norm.ppf(0.5 + unc.joint_level / 2.0))  # the recording's share at the joint region's (Sidak) level
    unc = dataclasses.replace(unc, **_joint_widened(unc, best.x, q_joint * np.hypot(widen, peak_move), problem))
    fixed = np.concatenate([_fixed_points(lp, cs.bootstrap.step_guard_deg) for lp in lps])
    warnings += scale_warnings
    if wrong:
        warnings.append(held_warning(wrong))
    if any(a.noise_coloured for a in parts_adequacy):
        rho = max(a.pure_error_lag1 for a in parts_adequacy)
        warnings.append(f"the noise is coloured (lag-one correlation {rho:.2f} between neighbouring grid points of the stroke-to-stroke "
                        "scatter; white noise gives about 0): no model error, but the estimates scatter more than white noise would "
                        "make them, so the intervals are joined with the Jacobian intervals (AR(1) factor) and are wide; more "
                        "strokes, or a log without the drive's filtering, narrow them")
    for lp, a in zip(lps, parts_adequacy):
        if not a.adequate:
            warnings.append(a.warning() + (f" [log {lp.log.source}]" if len(lps) > 1 else ""))
    refits = cs.bootstrap.refits
    boot, t_boot = None, 0.0
    if refits > 0:
        if progress:
            sys.stderr.write(f"  bootstrap: {refits} refits on resampled logs ...\n")
        t0 = time.perf_counter()
        blocks = max(block_points(cs, lp.objective.bm.theta, a.pure_error_lag1, residual_lag1(lp, best.x, cs))
                     for lp, a in zip(lps, parts_adequacy))
        boot = parametric_bootstrap(obj, best.x, _objective_on_curves(lps, problem, cs), fixed, blocks, cs.bootstrap,
                                    cs.interval_level, seed)
        t_boot = time.perf_counter() - t0
        # the share of the peak's noise on points the refits keep in place is not redrawn by them
        widen_boot = np.hypot(widen, math.sqrt(peak_held) * peak_move)
        boot = dataclasses.replace(boot, **_widened(boot.low, boot.high, best.x, q_level * widen_boot, problem))
        boot = dataclasses.replace(boot, **_joint_widened(boot, best.x, q_joint * widen_boot, problem))
        # unc carries the same widening: the unions below add none twice
        boot, at_bound = bound_fallback(boot, best.x, problem.low, problem.high, unc.low, unc.high, unc.joint_low, unc.joint_high)
        if any(a.noise_coloured for a in parts_adequacy):  # blocks see coloured noise only in part; the Jacobian interval carries its AR(1) model
            boot = join_where(boot, np.ones(len(best.x), bool), unc.low, unc.high, unc.joint_low, unc.joint_high)
        st = statements(problem, boot, cs.correlation_limit,
                        cs.interval_width_limit, f"parametric bootstrap, {refits} refits", best.x)
        if at_bound.any():
            st.append("on a bound of its calibration range (the estimate or bootstrap refits): "
                      + ", ".join(n for n, a in zip(problem.names, at_bound) if a)
                      + "; a bootstrap cannot cross a bound, so the interval is the union with the Jacobian interval")
    else:
        st = statements(problem, unc, cs.correlation_limit,
                        cs.interval_width_limit, "Jacobian (linearised least squares)", best.x)
    T0 = obj.torques(problem.theoretical[None])[0]
    T1 = obj.torques(best.x[None])[0]
    after = {"rmse": metrics(T1, obj.measured, obj.bm.theta_dot, obj.peak_points)["rmse_Nm"],
             "F": adequacy.lack_of_fit_ratio, "adequate": adequacy.adequate}
    held_record = held.record(freed_warning(held.freed, held.chosen, held.before, after) if held.freed else "")
    warnings += trust_warnings(problem, best.x, sum(lp.force is not None for lp in lps), len(lps))
    notes = [n for n in (peak_noise_note(gap, peak_sigma, cs.peak_noise_ratio_warning,
                                         carried(boot.measured_peaks) if boot is not None else None),) if n]
    # the log's reading of its crank motion where its speed column was set aside (calibration/identification/speed_fit.py)
    notes += [f"crank motion of {lp.log.source}: {describe(lp.motion)}" for lp in (*lps, *([vp] if vp is not None else []))
              if getattr(lp.motion, "disagree", False)]
    mk = obj.measured_peak
    validation = _validation(vp, problem, best.x) if vp is not None else None
    if validation is not None and shared:
        validation["shared_samples_with_fit"] = shared
    return Calibration(log, obj, tuple(runs), best, unc, metrics(T0, obj.measured, obj.bm.theta_dot, obj.peak_points, mk),
                       metrics(T1, obj.measured, obj.bm.theta_dot, obj.peak_points, mk), lps[0].peak, boot, validation, vp,
                       tuple(warnings), tuple(st), t_boot, adequacy, rec_est, tuple(lp.log for lp in lps), tuple(parts_adequacy),
                       spread_rec, pf_record, pf_line, tuple(notes), peak_move, peak_held, lf_spread, lf_record,
                       motion_sd, shares, tuple(share_warnings(shares, press)), held_record)


def _force_delays(lags, pairs, rec_est, level: float) -> list[tuple[int, force_delay.ForceDelay]]:
    """(log index, :class:`calibration.identification.force_delay.ForceDelay`) of each log whose force's lag behind
    its torque channel was timed (``lags``, None elsewhere): that lag plus the torque channel's delay as the calibration
    took it (the recording's estimate ``rec_est`` where it corrected the log, else 0), with the recording's standard
    error (none without a recording estimate)."""
    torque = (0.0, 0.0, False) if rec_est is None else (rec_est.channel_delay_s, rec_est.std[0], rec_est.corrected)
    return [(i, force_delay.delay_estimate(lag, rows.force_lag_s is not None, torque, level))
            for i, (lag, (rows, _)) in enumerate(zip(lags, pairs)) if lag is not None]


def heaviest_shares(rows: list[LogRows]) -> MotorShares | None:
    """The motors' shares (:mod:`calibration.traces.motor_shares`) of the log, of those fitted, that loads its heaviest
    motor most; None when no log holds one torque channel per motor."""
    found = [s for s in map(shares_of_rows, rows) if s is not None]
    return max(found, key=lambda s: s.torque_factor) if found else None


def share_warnings(shares: MotorShares | None, press: PressData) -> list[str]:
    """A warning where the motors' shares differ by more than the press file's ``[motor] load_share_tolerance``, or
    where they disagree with its stated ``load_shares`` by more than it."""
    if shares is None:
        return []
    tol, out = press.motor.load_share_tolerance, []
    m, up, where = shares.heaviest
    if shares.spread > tol:
        out.append(f"the motors do not share the load evenly: {shares.line()}; they differ by {100 * shares.spread:.1f} points, more "
                   f"than [motor] load_share_tolerance = {100 * tol:g} points of {press.source}: calibrated.json's motor_shares "
                   f"makes `plan --params` hold motor {m + 1} to the torque margin (the mean motor torque to 1/{shares.torque_factor:.3f} "
                   "of it); check the drives' torque sharing (their speed controllers' droop, the gear's meshes)")
    stated = press.motor.load_shares
    if stated and len(stated) == shares.motors and np.max(np.abs(np.array(stated) - shares.shares)) > tol:
        out.append(f"the motors' shares measured ({', '.join(f'{100 * s:.1f} %' for s in shares.shares)}) differ from those "
                   f"[motor] load_shares states in {press.source} ({', '.join(f'{100 * s:.1f} %' for s in stated)}) by more than "
                   f"load_share_tolerance = {100 * tol:g} points: a plan with --params takes the measured; correct the press file")
    return out


def _widened(low, high, x, extra, problem) -> dict:
    """Interval ends with ``extra`` (k,) added in quadrature to each half-width, clipped to the bounds."""
    lo = x - np.sqrt((x - low) ** 2 + extra ** 2)
    hi = x + np.sqrt((high - x) ** 2 + extra ** 2)
    return {"low": np.maximum(lo, problem.low), "high": np.minimum(hi, problem.high)}


def _joint_widened(iv, x, extra, problem) -> dict:
    """The joint region of ``iv`` (Uncertainty or Bootstrap, its intervals already widened) with ``extra`` (k,) added in
    quadrature as :func:`_widened` does, joined with the widened intervals: a basic interval that leaves out the
    estimate has a side beyond x, which the quadrature can move less than the interval's own side."""
    w = _widened(iv.joint_low, iv.joint_high, x, extra, problem)
    return {"joint_low": np.minimum(w["low"], iv.low), "joint_high": np.maximum(w["high"], iv.high)}


def _objective_on_curves(lps: list[LogProblem], problem: CalibrationProblem, cs: CalibrationSettings):
    """Eq. 28 against other curves on the logs' grids (end to end), built as the calibration built it on the logs."""
    makes = [_objective_on_curve(lp, cs) for lp in lps]
    if len(makes) == 1:
        return makes[0]
    edges = np.cumsum([lp.objective.bm.n_points for lp in lps])[:-1]
    return lambda curve: joint_objective(problem, [m(c) for m, c in zip(makes, np.split(curve, edges))])


def p_level(cal: Calibration) -> float:
    """The confidence level of the reported intervals."""
    return cal.bootstrap.level if cal.bootstrap is not None else cal.uncertainty.level


def _motion_variance(lps: list[LogProblem], problem: CalibrationProblem, x: np.ndarray, pm) -> list:
    """Per log, its model curve's variance (n,) N m^2 from its crank motion's error at x, or None (exact;
    :func:`calibration.identification.motion_error.torque_variance`)."""
    return [torque_variance(lp.objective.bm, lp.motion, problem.full_sets(lp.objective.bm, x)[0], lp.process, pm)
            for lp in lps]


def _end_to_end(lps: list[LogProblem], motion_var: list) -> np.ndarray | None:
    """Every log's model-curve variance (:func:`_motion_variance`) end to end (N m^2; 0 on a log whose motion is
    exact), or None when every log's is."""
    if all(v is None for v in motion_var):
        return None
    return np.concatenate([np.zeros(lp.objective.bm.n_points) if v is None else v for lp, v in zip(lps, motion_var)])


def _correct_recording(pm, pairs, cs, problem, lps, obj, best, models):
    """Estimate the channel delay and encoder offset with the parameters (:mod:`calibration.identification.recording`), the same in
    every log; returns (the estimate, the log problems corrected, their joint objective, the best run refitted
    locally on them, the gear ratio where lost motion was estimated beside them (else None: :func:`_shifted_refits`,
    for the parameters' spread from the estimate's uncertainty, :func:`_recording_spread`), each log's model-curve
    variance at the first fit, :func:`_motion_variance`, which the estimate weighs its rows by). ``pairs``: (rows, job) of each log; a
    correction grids the rows read once again, in memory; ``pm`` the press's model (its ``press`` the press)."""
    press = pm.press
    motion_var = _motion_variance(lps, problem, best.x, pm)
    weights = _end_to_end(lps, motion_var)
    states = {(0.0, 0.0, 0.0): (lps, obj)}
    # the gear torque's sign at the first fit says which way lost motion moves each sample; it is estimated beside the
    # delay and offset where some log's torque reverses (elsewhere it is an encoder offset)
    signs = [lp.objective.torques(best.x[None])[0] for lp in lps]
    lash_u = press.drive.gear_ratio if recording.torque_reverses(signs) else None

    def state(delay_s, offset_deg, lash_deg=0.0):
        key = (delay_s, offset_deg, lash_deg)
        if key not in states:
            qs = [log_problem(press, jb, cs, problem, rows, pm, (*key[:2], (lash_deg, sg) if lash_deg else None), models)
                  for (rows, jb), sg in zip(pairs, signs)]
            states[key] = (qs, joint_objective(problem, [q.objective for q in qs]))
        qs, o = states[key]
        mask = ~np.concatenate([_fixed_points(q, cs.bootstrap.step_guard_deg) for q in qs])

        def curves(x):  # each log's model curve at x; end to end they are o.torques(x)
            return [q.objective.torques(x[None])[0] for q in qs]

        def design(T):
            return recording.shift_design([(q.objective.bm.theta, q.objective.bm.theta_dot, t) for q, t in zip(qs, T)], lash_u)

        def resid(x):  # the bin means less the model's own bin means (recording.bin_smear) at x
            T = curves(x)
            return measured - np.concatenate([t + recording.bin_smear(q.log.torque_angles if q.log.torque_binned is not None
                                                                      else None, q.objective.bm.theta, t) for q, t in zip(qs, T)])

        measured = recording.measured_curve([(q.log.torque_binned, q.objective.measured) for q in qs])
        return (qs, o), resid, lambda x: jacobian(o, x), lambda x: design(curves(x)), mask

    cycles = [0]

    def refit(q, x):
        X, _, used = refit_batch([q[1]], x, cs.bootstrap.iterations)
        cycles[0] += used
        return X[0]

    est, (lps2, obj2), x = recording.estimate(state, refit, best.x, cs, len(pairs), weights)
    if est.iterations == 0:
        return est, lps, obj, best, lash_u, motion_var
    f = float(obj2(x[None])[0])
    return est, lps2, obj2, SolverRun(best.method, x, f, best.cycles + cycles[0] + 1, best.time_s,
                                      best.detail + f"; then refitted locally ({cycles[0]} model cycles) on the log corrected "
                                      "for the recording's channel delay, encoder offset and lost motion (calibration/identification/recording.py)"), \
        lash_u, motion_var


def _recording_spread(est: recording.RecordingEstimate, x: np.ndarray, refits) -> np.ndarray:
    """(k,) standard deviation (SI) each parameter gains from the uncertainty of the recording estimate: the
    estimator itself refitted locally from x on the logs' curves shifted one standard deviation beyond their
    correction and one short of it along each principal axis of the covariance of the delay, offset and (where it is
    tested: its test's standard error where it was not entered, recording.RecordingEstimate.cov) lost motion; the mean square of the
    two refits' moves from the refit on the unshifted curves (two-point Gauss-Hermite rule for the mean square move
    under a normal error along that axis), summed over the axes. One-sided moves, not their mean, so a response
    with a kink is not cancelled. ``refits(shifts)``: for a list of (delay s, offset rad[, lost motion motor rad])
    shifts, the (1 + len(shifts), k) refits, the unshifted curves' first (:func:`_shifted_refits`)."""
    lam, axes = np.linalg.eigh(est.cov())
    shifts = [sg * math.sqrt(value) * axis for value, axis in zip(lam, axes.T) if value > 0.0 for sg in (1.0, -1.0)]
    if not shifts:
        return np.zeros(len(x))
    X = np.asarray(refits(shifts), float)
    return np.sqrt(0.5 * np.sum((X[1:] - X[0]) ** 2, axis=0))


def _shifted_refits(lps: list[LogProblem], problem: CalibrationProblem, cs: CalibrationSettings, x: np.ndarray,
                    lash_u: float | None = None):
    """For :func:`_recording_spread`: a function of (delay s, offset rad) shifts giving Eq. 28 rebuilt on the logs'
    curves ``lps`` (as the calibration built it: its own normalisation and filtered peak) and refitted locally from ``x``
    (:func:`calibration.identification.bootstrap.refit_batch`), the unshifted curves first, then each shifted by it.
    Through the estimator, so the peak term sees the peak move.

    The shift is the model curve's (:func:`calibration.identification.recording.shift_design` at x: what the measured
    curve gains per second of delay and radian of offset), not the log gridded again with another correction: that
    reads the samples with other interpolation weights (an offset of 0.04 deg is a quarter of the 0.16 deg between
    samples at 14 spm and 500 Hz), a fresh share of the noise that no recording error causes: on the designed runs of
    scripts/check_design_coverage.py it made eta_gear's widening 0.10-0.57 of the predicted half-width from seed to
    seed, 0.18-0.20 with the model curve's shift. The curve is shifted everywhere the estimator reads it: the
    die-contact window too (out of Y_RMSE, but the peak filter of Eq. 23 reaches into it), and the force steps'
    neighbours with their own side's slope (:func:`_shift_design_by_side`)."""
    measured = np.concatenate([lp.objective.measured for lp in lps])
    make = _objective_on_curves(lps, problem, cs)

    def refits(shifts):
        T = [lp.objective.torques(np.asarray(x, float)[None])[0] for lp in lps]
        Z = np.vstack([_shift_design_by_side(lp, t, lash_u) for lp, t in zip(lps, T)])
        X, _, _ = refit_batch([make(measured)] + [make(measured + Z @ step) for step in shifts], np.asarray(x, float),
                              cs.bootstrap.iterations)
        return X

    return refits


def _shift_design_by_side(lp: LogProblem, torque: np.ndarray, lash_u: float | None) -> np.ndarray:
    """(n, 2 or 3) :func:`calibration.identification.recording.shift_design` of one log at its model curve ``torque``
    (N m on the log's grid): the delay, offset (and, with the gear ratio ``lash_u``, lost-motion) columns, with the
    slope dT/dtheta of the two grid points beside each force step taken one-sided, second order, on the point's own
    side (a piece starts at the first grid point at or after the step, as the peak filter's pieces do,
    :func:`calibration.identification.peak.filter_curve`): a shift of a fraction of a sample moves such a point along
    its own side's slope, where the central difference reads the step's jump."""
    th, thd = lp.objective.bm.theta, lp.objective.bm.theta_dot
    T = np.asarray(torque, float)
    n, h = T.size, float(th[1] - th[0])
    dT = (np.roll(T, -1) - np.roll(T, 1)) / (2.0 * h)
    for c in {int(np.searchsorted(th, a % (2.0 * math.pi))) % n for a in lp.steps}:
        b = (c - 1) % n
        dT[c] = (-3.0 * T[c] + 4.0 * T[(c + 1) % n] - T[(c + 2) % n]) / (2.0 * h)
        dT[b] = (3.0 * T[b] - 4.0 * T[(b - 1) % n] + T[(b - 2) % n]) / (2.0 * h)
    cols = [-thd * dT, -dT]  # as adequacy.shift_columns: per second of delay, per radian of offset
    if lash_u is not None:
        cols.append(np.sign(T) * -dT / (2.0 * lash_u))  # as recording.shift_design: per motor radian of lost motion
    return np.column_stack(cols)


def _adequacy(lps: list[LogProblem], x: np.ndarray, cs: CalibrationSettings, press: PressData,
              tested=(None, ()), motion_var=None, force_candidates=None) -> list[Adequacy]:
    """The lack-of-fit verdict of :mod:`calibration.identification.adequacy` at x for each log, on the points outside its die-contact
    window and force steps; the job's level is shared among the logs (Bonferroni). A parameter on a bound of its
    range cannot move on to absorb a misfit, so its Jacobian column is left out of what the test projects off.
    ``tested``: (per log, its force-scale column (None: its force is logged or the job has none), tested as
    one more suspect (:func:`calibration.identification.process_force.force_candidate`); the names of the parameters the
    fit holds, each tested as one more suspect (:func:`calibration.identification.held.held_candidates`)).
    ``force_candidates``: per log, the logged force's scale as a suspect
    (:func:`calibration.identification.force_accuracy.scale_candidate`) or None. ``motion_var``: per log, the
    model curve's variance from its crank motion's error (:func:`calibration.identification.motion_error.torque_variance`,
    None: exact), which the lack-of-fit test weighs each residual by."""
    force_columns, held = tested
    free = ~on_bound(x, lps[0].objective.problem.low, lps[0].objective.problem.high)
    out = []
    for i, lp in enumerate(lps):
        o = lp.objective
        T = o.torques(np.asarray(x, float)[None])[0]
        cands = candidate_columns(o.bm.theta, o.bm.theta_dot, T, press.drive.gear_ratio, press.motor.rated_torque,
                                  cs.adequacy.ripple_orders_per_motor_turn)
        if force_columns is not None and force_columns[i] is not None:
            cands.append(force_candidate(force_columns[i]))
        if force_candidates is not None and force_candidates[i] is not None:  # a logged force's scale (force_accuracy.py)
            cands.append(force_candidates[i])
        cands += held_candidates(o, x, press, held)
        # the bin means less the model's own bin mean's departure from its grid value (recording.bin_smear): the
        # first-order angle correction the recording estimate makes (_correct_recording) left the curvature over a bin,
        # which read as lost motion where the crank changes speed within a few degrees
        binned = (recording.measured_curve([(lp.log.torque_binned, lp.log.torque)])
                  - recording.bin_smear(lp.log.torque_angles if lp.log.torque_binned is not None else None, o.bm.theta, T))
        try:
            out.append(assess(lp.log.stroke_torque, lp.log.torque, T, ~_fixed_points(lp, cs.bootstrap.step_guard_deg),
                              int(free.sum()), cs.adequacy.level / len(lps),
                              Suspects(jacobian(o, x)[:, free], cands, binned,
                                       1.0 / o.bm.theta_dot),  # samples per bin: the sample rate over the crank's speed
                              None if motion_var is None else motion_var[i]))
        except ValueError:
            raise PressDataError(lp.log.source, "strokes", lp.log.strokes, "leave too few crank angles covered by two "
                                 "strokes to judge the model against the stroke-to-stroke noise: log at least two whole "
                                 "strokes") from None
    return out


def block_points(cs: CalibrationSettings, theta: np.ndarray, noise_lag1: float, resid_lag1: float = 0.0) -> int:
    """Block length (grid points) of the bootstrap's residual resampling: block_noise_lengths correlation lengths
    (-1 / ln rho grid points) of the larger lag-one correlation rho of the noise (the pure error's, ``noise_lag1``) and
    of the residual the bootstrap resamples (``resid_lag1``: the stroke average, the interpolation, slow misfit), and
    at least the job's block_deg; so a block holds the residual's correlation (coloured noise then widens the
    intervals as it should), and no more. Longer blocks than that lose noise: the residual of a fitted model lacks
    what its parameters absorbed, along the smooth directions the estimate is read in, and a block of b points
    carries that lack into every resample (the resample's variance along a smooth direction falls by about a share
    p b / n for p parameters on n points: with 20-point blocks the refits of a least-squares fit of six smooth terms
    to 346 points of white noise kept 0.69 of the estimate's variance, with 1-point blocks 0.98)."""
    job_points = max(1, int(round(cs.bootstrap.block_deg / np.degrees(theta[1] - theta[0]))))
    rho = min(max(noise_lag1, resid_lag1, 0.0), 0.99)
    return max(job_points, int(np.ceil(cs.bootstrap.block_noise_lengths * -1.0 / np.log(rho))) if rho > 0.0 else 1)


def residual_lag1(lp: LogProblem, x: np.ndarray, cs: CalibrationSettings) -> float:
    """Lag-one correlation of the calibrated model's residual (measured - predicted, N m) over the points the bootstrap
    resamples (not :func:`_fixed_points`), neighbouring pairs of them only."""
    o = lp.objective
    resid = o.measured - o.torques(np.asarray(x, float)[None])[0]
    return lag1(resid, ~_fixed_points(lp, cs.bootstrap.step_guard_deg))[0]


def _validation(vp: LogProblem, problem: CalibrationProblem, x: np.ndarray) -> dict:
    """The second log predicted with the theoretical and the calibrated parameters (nothing is fitted to it)."""
    o = vp.objective
    T = o.torques(np.vstack([problem.theoretical, x]))
    before = metrics(T[0], o.measured, o.bm.theta_dot, o.peak_points, o.measured_peak)
    after = metrics(T[1], o.measured, o.bm.theta_dot, o.peak_points, o.measured_peak)
    return {
        "log": vp.log.source, "synthetic": vp.log.synthetic, "label": vp.log.label, "strokes": vp.log.strokes,
        "rmse_before_Nm": before["rmse_Nm"], "rmse_after_Nm": after["rmse_Nm"],
        "peak_error_before_Nm": before["peak_error_Nm"], "peak_error_after_Nm": after["peak_error_Nm"],
        "thermal_error_before": before["thermal_error"], "thermal_error_after": after["thermal_error"],
        "measured_peak_Nm": o.measured_peak, "mean_crank_speed_rad_s": float(np.mean(o.bm.theta_dot)),
        "crank_speed_range_rad_s": [float(np.min(o.bm.theta_dot)), float(np.max(o.bm.theta_dot))],
        "warnings": list(vp.log.warnings),
    }
