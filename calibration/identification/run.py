"""The 'calibrate' command: Eq. 28 against a drive log, solved, with intervals, tables and Figure 5.

Outputs in the folder: calibrated.json (parameters, intervals, metrics, correlation, provenance),
table4.csv / table4.md (theoretical, calibrated, relative error, beside the paper's Table 4),
solvers.csv when several methods ran, and figure5.png (measured, theoretical and calibrated torque).
"""
from __future__ import annotations

import dataclasses
import json
import math
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy import stats
from threadpoolctl import threadpool_limits

from press_model.batch import build_batch_model, motor_torques
from press_model.errors import PressDataError, ServoPressError, one_line
from press_model.jobs import Job, load_job
from press_model.kinematics import force_step_angles
from press_model.model import PressModel
from press_model.motion import FourierSpeed
from press_model.outputs import atomic_write_text, output_folder, versions, write_json, write_table
from press_model.plots import plt, save
from press_model.progress import progress as show_progress
from press_model.press_data import PressData, load_press
from press_model.readers import is_file, read_text_file
from calibration.sensitivity.report import paper_figures

from calibration.identification import recording
from calibration.traces import log_identity
from calibration.identification.adequacy import Adequacy, assess, candidate_columns
from calibration.identification.bootstrap import Bootstrap, bound_fallback, join_where, on_bound, parametric_bootstrap, refit_batch, statements
from calibration.traces.channel_map import ChannelMap, load_channel_map
from calibration.identification.joint import joint_objective
from calibration.traces.drive_log import DriveLog, check_against_model, read_drive_log, summary
from calibration.identification.peak import MeasuredPeak, filter_curve, measured_peak
from calibration.identification.problem import CalibrationProblem, Objective, metrics, objective, peak_points
from calibration.identification.settings import METHODS, CalibrationSettings, joint_settings_warning
from calibration.identification.solvers import SOLVERS, SolverRun
from calibration.traces.trace_log import read_trace_log
from calibration.identification.uncertainty import Uncertainty, analyse, jacobian


@dataclass(frozen=True)
class LogProblem:
    """Eq. 28 built on one drive log: the log, its fitted crank motion, the batch model on that motion, the peak
    points, the force-step angles, the robust measured peak and the objective."""

    log: DriveLog
    objective: Objective
    steps: tuple[float, ...]  # rad, process-force step angles (die contact first)
    peak: MeasuredPeak


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
        return _once(tuple(names), str(path), "key_parameters")
    return _once(tuple(n.strip() for n in arg.split(",") if n.strip()), "--parameters", "--parameters")


def _once(names: tuple[str, ...], source: str, field: str) -> tuple[str, ...]:
    """``names`` when none is repeated; a repeated name is refused where the user wrote it (not the job file)."""
    twice = sorted({n for n in names if names.count(n) > 1})
    if twice:
        raise PressDataError(source, field, list(names), f"names {', '.join(twice)} twice: give each parameter once")
    return names


def calibration_parameters(arg: str | None, press: PressData, job: Job, cs: CalibrationSettings) -> tuple[str, ...]:
    """The parameters to calibrate: :func:`key_parameters` of ``arg`` (--parameters), checked to name parameters of ``press``."""
    names = key_parameters(arg, cs.parameters)
    if not names:
        raise ServoPressError(f"--parameters = {one_line(arg)!r} is not valid: it names no parameter; give a comma "
                              "list such as eta_gear,mu_r or a key_parameters.json with at least one name (or leave "
                              "--parameters out for the job's list)")
    unknown = [n for n in names if n not in press.parameters]
    if unknown:
        where = ("--parameters", "--parameters") if arg is not None else (f"{job.source}", "calibration.parameters")
        raise PressDataError(where[0], where[1], unknown, f"must be parameters of the press {press.name} (known: "
                             f"{', '.join(press.parameters)}); give --parameters with names of this press, e.g. the "
                             "key_parameters.json of `servo-press sensitivity` on it, or a comma list such as eta_gear,mu_r")
    return names


def _data_rows(path: str) -> bytes | None:
    """The log's lines other than comments and blank lines (its data, whatever its header comments say), or None
    when it cannot be read (the reader then says why)."""
    try:
        text = Path(path).read_bytes()
    except OSError:
        return None
    return b"\n".join(ln.strip() for ln in text.splitlines() if ln.strip() and not ln.lstrip().startswith(b"#"))


def _refuse_fitted_log_as_validation(log: str, validate: str) -> None:
    """Refuse ``--validate`` naming the fitted log itself, or a copy of its data: that is no out-of-sample check."""
    try:
        same = Path(log).resolve() == Path(validate).resolve()
    except (OSError, ValueError):
        same = False
    rows = None if same else _data_rows(validate)
    if same or (rows is not None and rows == _data_rows(log)):
        raise PressDataError("--validate", "--validate", validate, f"is {'the' if same else 'a copy of the data of the'} log "
                             f"that is fitted (--log {one_line(log)}): a validation predicts a log the fit did not see; give "
                             "another recording (another day or motion), e.g. `servo-press experiment --job cushion-validation`")


def calibrate_job(press: str, job, log, method: str | None, parameters: str | None, seed: int, torque_unit: str,
                  validate: str | None, out: str, log_format: str | None = None) -> tuple[list[str], list[str]]:
    """The 'calibrate' command: :func:`calibrate` on the drive log ``log`` and :func:`write_outputs` into the folder
    ``out`` (written whole at the end). ``method``: one of :data:`METHODS`, "all", or None for the job's default.
    ``log`` and ``job`` may be lists (several ``--log`` / ``--job``): the logs are fitted jointly, paired with the jobs
    in order, one job serving all (the first job's [calibration] settings apply; a warning names the keys where
    another job's differ).
    ``log_format``: the channel map every log and ``validate`` are read through (None: plain drive-log CSVs).

    Returns (warnings, lines) for the command to print (:func:`calibrate_lines`).
    """
    logs = [log] if isinstance(log, str) else list(log)
    jobs = [job] if isinstance(job, str) else list(job)
    if len(jobs) not in (1, len(logs)):
        raise ServoPressError(f"--job given {len(jobs)} times for {len(logs)} --log: give one --job for all logs, or one per "
                              "--log (paired in order)")
    press_ = load_press(press)
    jobs_ = [load_job(j) for j in jobs]
    cs = CalibrationSettings.from_job(jobs_[0])
    methods = list(METHODS) if method == "all" else [method or cs.default_method]
    names = calibration_parameters(parameters, press_, jobs_[0], cs)
    fmt = Path(log_format) if log_format is not None else None
    channel_map_for(fmt, torque_unit, press_)  # a bad map is refused before the output folder is made
    if validate is not None:
        for lg in logs:
            _refuse_fitted_log_as_validation(lg, validate)
    pairs = [(Path(lg), jobs_[min(i, len(jobs_) - 1)]) for i, lg in enumerate(logs)]
    t0 = time.perf_counter()
    with output_folder(out, [press, *jobs, *logs, parameters, validate, log_format], "calibrate") as tmp:
        cal = calibrate(press_, jobs_[0], pairs[0][0], methods, seed, names, torque_unit,
                        validate=Path(validate) if validate is not None else None, log_format=fmt, more_logs=pairs[1:])
        rec = write_outputs(cal, press_, jobs_[0], seed, tmp)
    return [*cal.log.warnings, *cal.warnings], calibrate_lines(cal, rec, logs, out, time.perf_counter() - t0)


def signed(x: float) -> str:
    """A whole number with its sign, never '-0' (a value that rounds to zero)."""
    return f"{int(round(x)) + 0:+d}" if math.isfinite(x) else str(x)


def calibrate_lines(cal: Calibration, rec: dict, logs: list[str], out: str, seconds: float) -> list[str]:
    """The summary of a calibration for the terminal: errors before and after, the methods compared, the values
    with their intervals, identifiability notes, the validation, and the files written in ``seconds`` s."""
    m = rec["metrics"]
    lines = [f"{'SYNTHETIC ' if cal.log.synthetic else ''}log {', '.join(map(str, logs))}: "
             f"{'+'.join(str(lg.strokes) for lg in cal.logs)} strokes; method {rec['method']}: "
             f"RMSE {m['rmse_before_Nm']:.1f} -> {m['rmse_after_Nm']:.1f} N m, peak error {signed(m['peak_error_before_Nm'])} -> "
             f"{signed(m['peak_error_after_Nm'])} N m, "
             f"thermal error {100 * m['thermal_error_before']:+.2f} % -> {100 * m['thermal_error_after']:+.2f} %"]
    if len(cal.runs) > 1:
        low = rec["objective_eq28_minimum_of_methods"]
        for r in cal.runs:
            lines.append(f"  {r.method:<24} Eq. 28 {r.objective:.6f} ({100 * (r.objective - low) / low:+.3f} % above the minimum)  "
                         f"{r.cycles:>6} model cycles  {r.time_s:.1f} s")
        lines.append(f"  minimum of all methods: Eq. 28 = {low:.6f}")
    jr = rec["joint_region"]
    for n, x in rec["parameters"].items():
        lo, hi = rec["intervals"][n]
        jlo, jhi = jr["box"][n]
        lines.append(f"  {n:>9} = {x:.6g}  ({100 * jr['level']:g} % interval {lo:.6g} .. {hi:.6g}; joint region {jlo:.6g} .. {jhi:.6g})")
    lines.append(f"  {100 * jr['level']:g} % interval: this parameter alone (one at a time); joint region: every parameter at once "
                 f"({jr['method_short']})")
    if cal.bootstrap is not None:
        lines.append(f"  intervals: parametric bootstrap, {cal.bootstrap.refits} refits, {cal.bootstrap.cycles} model cycles, "
                     f"{cal.bootstrap_time_s:.1f} s")
    lines += [f"  - {s}" for s in rec["identifiability"][1:]]
    lines += [f"  {line}" for line in verdict_lines(cal)]
    v = rec.get("validation")
    if v:
        fitted = (f"{100 * v['shared_samples_with_fit']:.3g} % of its samples fitted" if v.get("shared_samples_with_fit")
                  else "not fitted")
        lines.append(f"validation on {'SYNTHETIC ' if v['synthetic'] else ''}log {v['log']} ({fitted}): RMSE {v['rmse_before_Nm']:.1f} -> "
                     f"{v['rmse_after_Nm']:.1f} N m, peak error {v['peak_error_before_Nm']:+.0f} -> {v['peak_error_after_Nm']:+.0f} N m, "
                     f"thermal error {100 * v['thermal_error_before']:+.2f} % -> {100 * v['thermal_error_after']:+.2f} %")
    lines.append(f"-> {Path(out)}/calibrated.json, table4.csv/.md, figure5.png{', solvers.csv' if len(cal.runs) > 1 else ''} ({seconds:.1f} s)")
    return lines


def _progress(method: str):
    def show(i, total, best):
        if i < total and i % max(1, total // 20):
            return  # about twenty updates a run
        show_progress(method, i, total, f"Eq. 28 objective {best:.5f}")
    return show


def log_problem(press: PressData, job: Job, cs: CalibrationSettings, problem: CalibrationProblem, log_path: Path,
                torque_unit: str = "N*m", pm: PressModel | None = None, correction: tuple[float, float] = (0.0, 0.0),
                models: dict | None = None, log_format: ChannelMap | None = None) -> LogProblem:
    """Read a log and build Eq. 28 on its own crank motion (a periodic Fourier fit of its speed), the job's process
    force, the peak window after die contact and the filtered measured peak. ``correction``: (channel delay in s,
    encoder offset in deg) the log is corrected for (:mod:`calibration.identification.recording`); ``models``: batch models already
    built, by the log's crank speed curve (a delay correction leaves it as it was), filled in here. ``log_format``:
    the channel map of a drive trace (TwinCAT Scope export, TDMS, CSV with other names); None reads the plain CSV."""
    log = (read_drive_log(log_path, press.drive.gear_ratio, press.motor.rated_torque, 1.0, torque_unit,
                          peak_torque_Nm=press.motor.peak_torque, channel_delay_s=correction[0],
                          angle_offset_deg=correction[1]) if log_format is None
           else read_trace_log(log_path, log_format, press, 1.0, correction=correction))
    try:
        motion = FourierSpeed.fit(log.theta, log.crank_speed, cs.speed_harmonics)
    except ValueError as exc:
        raise PressDataError(str(log_path), "motor_speed_rpm", "fitted crank speed", f"must stay positive over the turn ({exc}); the log must come from continuous running") from None
    pm = pm or PressModel(press)
    key = (log.crank_speed.tobytes(), job.source, job.name)  # the motion and the process force the model is built on
    bm = models.get(key) if models is not None else None
    if bm is None:
        bm = build_batch_model(press, motion, job.process, pm=pm)
        if models is not None:
            models[key] = bm
    check_against_model(log, motor_torques(bm, bm.nominal[None])[0], torque_unit)  # sign and scale, before fitting
    steps = tuple(force_step_angles(pm, job.process))
    mask = peak_points(bm.theta, motion.time, steps[:1], cs.peak_window)  # die contact; BDC rings no impact
    peak = measured_peak(bm.theta, log.torque, log.torque_spread, log.strokes, mask, steps,
                         cs.peak_filter_window_deg, cs.peak_filter_order)
    return LogProblem(log, objective(problem, bm, log.torque, mask, peak.value_Nm), steps, peak)


def _objective_on_curve(lp: LogProblem, cs: CalibrationSettings):
    """Eq. 28 against another curve on the same grid, built as the calibration built it against the log."""
    o = lp.objective
    t0 = o.torques(o.problem.theoretical[None])[0]

    def make(curve):
        filtered = filter_curve(o.bm.theta, curve, lp.steps, cs.peak_filter_window_deg, cs.peak_filter_order)
        return objective(o.problem, o.bm, curve, o.peak_points, float(np.max(np.abs(filtered[o.peak_points]))), t0)

    return make


def _fixed_points(lp: LogProblem, guard_deg: float) -> np.ndarray:
    """Grid points that keep their own residual in the bootstrap: the die-contact window and the force steps' neighbours."""
    th = lp.objective.bm.theta
    fixed = ~lp.objective.peak_points
    for a in lp.steps:
        fixed |= np.abs(np.angle(np.exp(1j * (th - a)))) <= np.radians(guard_deg) + 1e-12
    return fixed


def peak_noise_warning(lp: LogProblem, limit: float) -> str | None:
    """A warning when |Y_PR,0| x the measured peak is within ``limit`` times the noise left in the filtered peak."""
    o, pk = lp.objective, lp.peak
    gap = abs(o.pr0) * o.measured_peak
    if pk.sigma_Nm > 0.0 and gap < limit * pk.sigma_Nm:
        return (f"the theoretical model's peak error |Y_PR,0| x peak = {gap:.0f} N m is only {gap / pk.sigma_Nm:.1f} times the noise "
                f"left in the filtered measured peak ({pk.sigma_Nm:.0f} N m; warning below {limit:g} times): Eq. 28's peak term, "
                "normalised by it, then largely fits noise; trust the intervals, not the digits, and prefer a log with more strokes")
    return None


def trust_warnings(problem: CalibrationProblem, x: np.ndarray) -> list[str]:
    """What makes this fit untrustworthy whatever its intervals say: estimates on a range bound. (A fit that misses
    the log by more than its stroke-to-stroke noise is the adequacy verdict's to name, :mod:`calibration.identification.adequacy`.)"""
    edge = on_bound(x, problem.low, problem.high)
    if not edge.any():
        return []
    return [f"{', '.join(n for n, e in zip(problem.names, edge) if e)} ended on a bound of the calibration range: the data "
            "pull beyond the range, which no press of this kind should need; check the log's torque scale and unit, the "
            "press file and the job's process force before using these values"]


def calibrate(press: PressData, job: Job, log_path: Path, methods: list[str], seed: int, names: tuple[str, ...] | None = None,
              torque_unit: str = "N*m", progress: bool = True, *, validate: Path | None = None,
              bootstrap_refits: int | None = None, log_format: Path | None = None, more_logs=()) -> Calibration:
    """Read the log, build Eq. 28 on the log's own crank motion and the job's process force, and solve it.

    Then the intervals: the parametric bootstrap of the reported estimate (``bootstrap_refits`` refits, default
    the job's ``[calibration.bootstrap] refits``; 0 skips it and the Jacobian intervals are reported) and the
    Jacobian second opinion. ``validate``: a second drive log (another day, another motion) predicted with
    the theoretical and the calibrated parameters. ``log_format``: the channel map (``--log-format``) both logs are
    read through; their units are the map's, so ``torque_unit`` must then be the default.
    ``more_logs``: further (log path, job) pairs fitted jointly with the first (:mod:`calibration.identification.joint`; another
    speed or cushion force).
    """
    # OpenBLAS splits a product differently for another thread count, which moves the estimate in its last
    # digits: one BLAS thread makes the result the same on every machine and in every worker (the matrices are small)
    with threadpool_limits(1, user_api="blas"):
        return _calibrate(press, job, log_path, methods, seed, names, torque_unit, progress, validate, bootstrap_refits,
                          log_format, more_logs)


def channel_map_for(log_format: Path | None, torque_unit: str, press: PressData) -> ChannelMap | None:
    """The channel map of ``--log-format`` checked against the press, or None; refuses ``--torque-unit`` beside a map."""
    if log_format is None:
        return None
    if torque_unit != "N*m":
        raise PressDataError("--torque-unit", "--torque-unit", torque_unit, "is for a plain drive-log CSV: with --log-format "
                             "the channel map gives each channel's unit (unit = \"kN*m\" in the map); leave --torque-unit out")
    cmap = load_channel_map(log_format)
    cmap.check_press(press.name, press.drive.motors)
    return cmap


def _calibrate(press, job, log_path, methods, seed, names, torque_unit, progress, validate, bootstrap_refits,
               log_format, more_logs=()) -> Calibration:
    cs = CalibrationSettings.from_job(job)
    cmap = channel_map_for(log_format, torque_unit, press)
    for m in methods:
        if m not in METHODS:
            raise PressDataError("--method", "--method", m, f"must be one of {', '.join(METHODS)} or 'all'")
    problem = CalibrationProblem.from_press(press, names or cs.parameters, cs.weight, job.source)
    pm = PressModel(press)
    pairs = [(Path(log_path), job), *((Path(lg), jb) for lg, jb in more_logs)]  # each log with the job it was run with
    models: dict = {}
    lps = [log_problem(press, jb, cs, problem, lg, torque_unit, pm, models=models, log_format=cmap) for lg, jb in pairs]
    vp = log_problem(press, job, cs, problem, validate, torque_unit, pm, log_format=cmap) if validate is not None else None  # bad input fails before the fit
    shared = log_identity.check([lp.log for lp in lps], vp.log if vp is not None else None)  # one recording twice is refused
    warnings = [w for w in (joint_settings_warning([jb for _, jb in pairs]), *log_identity.validation_warning(shared),
                            *(peak_noise_warning(lp, cs.peak_noise_ratio_warning) for lp in lps)) if w]
    obj = joint_objective(problem, [lp.objective for lp in lps])
    runs = []
    for m in methods:
        runs.append(SOLVERS[m](obj, cs, seed, _progress(m) if progress else None))
    best = min(runs, key=lambda r: r.objective)  # ties: the first in METHODS order, so reruns agree
    rec_est = None
    if cs.recording_estimate:
        rec_est, lps, obj, best, spread_rec = _correct_recording(press, pairs, cs, problem, torque_unit, pm, lps, obj, best,
                                                                 models, cmap)
    # the validation log is predicted as logged: on one motion only a combination of delay and offset is known, and
    # the split that fits this motion shifts another motion's curve differently
    log = lps[0].log
    unc = analyse(obj, best.x, cs.interval_level, cs.correlation_limit, cs.interval_width_limit)
    if rec_est is None:
        spread_rec = np.zeros(len(best.x))
    q_level = float(stats.norm.ppf(0.5 + cs.interval_level / 2.0))
    unc = dataclasses.replace(unc, **_widened(unc.low, unc.high, best.x, q_level * spread_rec, problem))
    q_joint = float(stats.norm.ppf(0.5 + unc.joint_level / 2.0))  # the recording's share at the joint region's (Sidak) level
    unc = dataclasses.replace(unc, **_joint_widened(unc, best.x, q_joint * spread_rec, problem))
    fixed = np.concatenate([_fixed_points(lp, cs.bootstrap_step_guard_deg) for lp in lps])
    parts_adequacy = _adequacy(lps, best.x, cs, press)
    adequacy = min(parts_adequacy, key=lambda a: (a.adequate, a.p_value))  # the worst log speaks for all
    if any(a.noise_coloured for a in parts_adequacy):
        rho = max(a.pure_error_lag1 for a in parts_adequacy)
        warnings.append(f"the noise is coloured (lag-one correlation {rho:.2f} between neighbouring grid points of the stroke-to-stroke "
                        "scatter; white noise gives about 0): no model error, but the estimates scatter more than white noise would "
                        "make them, so the intervals are joined with the Jacobian intervals (AR(1) factor) and are wide; more "
                        "strokes, or a log without the drive's filtering, narrow them")
    for lp, a in zip(lps, parts_adequacy):
        if not a.adequate:
            warnings.append(a.warning() + (f" [log {lp.log.source}]" if len(lps) > 1 else ""))
    refits = cs.bootstrap_refits if bootstrap_refits is None else int(bootstrap_refits)
    boot, t_boot = None, 0.0
    if refits > 0:
        if progress:
            sys.stderr.write(f"  bootstrap: {refits} refits on resampled logs ...\n")
        t0 = time.perf_counter()
        boot = parametric_bootstrap(obj, best.x, _objective_on_curves(lps, problem, cs), fixed,
                                    refits, max(block_points(cs, lp.objective.bm.theta, a.pure_error_lag1)
                                                for lp, a in zip(lps, parts_adequacy)),
                                    cs.bootstrap_iterations, cs.interval_level, seed,
                                    np.array([cs.bootstrap_allowance.get(n, 0.0) for n in problem.names]))
        t_boot = time.perf_counter() - t0
        boot = dataclasses.replace(boot, **_widened(boot.low, boot.high, best.x, q_level * spread_rec, problem))
        boot = dataclasses.replace(boot, **_joint_widened(boot, best.x, q_joint * spread_rec, problem))
        # unc carries the same widening: the unions below add none twice
        boot, at_bound = bound_fallback(boot, best.x, problem.low, problem.high, unc.low, unc.high, unc.joint_low, unc.joint_high)
        if any(a.noise_coloured for a in parts_adequacy):  # blocks see coloured noise only in part; the Jacobian interval carries its AR(1) model
            boot = join_where(boot, np.ones(len(best.x), bool), unc.low, unc.high, unc.joint_low, unc.joint_high)
        st = statements(problem.names, boot.low, boot.high, problem.low, problem.high, boot.correlation, cs.correlation_limit,
                        cs.interval_width_limit, f"parametric bootstrap, {refits} refits", best.x)
        if at_bound.any():
            st.append("on a bound of its calibration range (the estimate or bootstrap refits): "
                      + ", ".join(n for n, a in zip(problem.names, at_bound) if a)
                      + "; a bootstrap cannot cross a bound, so the interval is the union with the Jacobian interval")
    else:
        st = statements(problem.names, unc.low, unc.high, problem.low, problem.high, unc.correlation, cs.correlation_limit,
                        cs.interval_width_limit, "Jacobian (linearised least squares)", best.x)
    T0 = obj.torques(problem.theoretical[None])[0]
    T1 = obj.torques(best.x[None])[0]
    warnings += trust_warnings(problem, best.x)
    mk = obj.measured_peak
    validation = _validation(vp, problem, best.x) if vp is not None else None
    if validation is not None and shared:
        validation["shared_samples_with_fit"] = shared
    return Calibration(log, obj, tuple(runs), best, unc, metrics(T0, obj.measured, obj.bm.theta_dot, obj.peak_points, mk),
                       metrics(T1, obj.measured, obj.bm.theta_dot, obj.peak_points, mk), lps[0].peak, boot, validation, vp,
                       tuple(warnings), tuple(st), t_boot, adequacy, rec_est, tuple(lp.log for lp in lps), tuple(parts_adequacy),
                       spread_rec)


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


def verdict_lines(cal: Calibration) -> list[str]:
    """The recording correction and the adequacy verdict in one line each, for the console."""
    out = [f"recording: {cal.recording.statement()}"] if cal.recording is not None else []
    a = cal.adequacy
    if a is not None:
        out.append(f"adequacy: {'adequate' if a.adequate else 'NOT ADEQUATE'} (lack-of-fit F = {a.lack_of_fit_ratio:.2f}, "
                   f"p = {a.p_value:.2g}; residual lag-1 {a.residual_lag1:.2f}, noise {a.pure_error_lag1:.2f}; suspects: "
                   + (", ".join(f"{t.name} (t = {t.t:.1f}, {t.size:.3g} {t.unit})" for t in a.suspects) or "none") + ")")
    return out


def _correct_recording(press, pairs, cs, problem, torque_unit, pm, lps, obj, best, models, cmap=None):
    """Estimate the channel delay and encoder offset with the parameters (:mod:`calibration.identification.recording`), the same in
    every log; returns (the estimate, the log problems corrected, their joint objective, the best run refitted
    locally on them)."""
    states = {(0.0, 0.0): (lps, obj)}

    def state(delay_s, offset_deg):
        key = (delay_s, offset_deg)
        if key not in states:
            qs = [log_problem(press, jb, cs, problem, lg, torque_unit, pm, key, models, cmap) for lg, jb in pairs]
            states[key] = (qs, joint_objective(problem, [q.objective for q in qs]))
        qs, o = states[key]
        mask = ~np.concatenate([_fixed_points(q, cs.bootstrap_step_guard_deg) for q in qs])

        def curves(x):  # each log's model curve at x; end to end they are o.torques(x)
            return [q.objective.torques(x[None])[0] for q in qs]

        def design(T):
            return recording.shift_design([(q.objective.bm.theta, q.objective.bm.theta_dot, t) for q, t in zip(qs, T)])

        def resid(x):  # one model evaluation for the residual and the bins' angle correction
            T = curves(x)
            return measured - np.concatenate(T) + design(T)[:, 1] * delta

        measured = recording.measured_curve([(q.log.torque_binned, q.objective.measured) for q in qs])
        delta = recording.bin_angle_correction([(q.log.torque_binned, q.log.angle_binned_offset, q.objective.measured) for q in qs])
        return (qs, o), resid, lambda x: jacobian(o, x), lambda x: design(curves(x)), mask

    cycles = [0]

    def refit(q, x):
        X, _, used = refit_batch([q[1]], x, cs.bootstrap_iterations)
        cycles[0] += used
        return X[0]

    est, (lps2, obj2), x = recording.estimate(state, refit, best.x, cs.recording_iterations, cs.interval_level,
                                              cs.correlation_limit, len(pairs), cs.adequacy_level,
                                              cs.recording_stop_standard_errors)
    applied = (est.channel_delay_s, est.angle_offset_deg) if est.corrected else (0.0, 0.0)
    spread = _recording_spread(state, refit, est, applied, x)
    if est.iterations == 0:
        return est, lps, obj, best, spread
    f = float(obj2(x[None])[0])
    return est, lps2, obj2, SolverRun(best.method, x, f, best.cycles + cycles[0] + 1, best.time_s,
                                      best.detail + f"; then refitted locally ({cycles[0]} model cycles) on the log corrected "
                                      "for the recording's channel delay and encoder offset (calibration/identification/recording.py)"), spread


def _recording_spread(state, refit, est: recording.RecordingEstimate, applied: tuple[float, float], x: np.ndarray) -> np.ndarray:
    """(k,) standard deviation (SI) each parameter gains from the uncertainty of the recording estimate: the
    estimator itself (Eq. 28 refitted locally from x) on the log corrected one standard deviation beyond the
    ``applied`` correction (delay s, offset deg) and one short of it along each principal axis of the delay/offset
    covariance; the mean square of the two refits' moves from x (two-point Gauss-Hermite rule for the mean square
    move under a normal error along that axis), summed over the two axes. Through the estimator, not a
    linearisation on the tested points: a shift also moves the force steps and the peak, which Eq. 28 sees and the
    tested points leave out; and one-sided moves, not their mean, so that a response with a kink (a force step
    crossing a grid point) is not cancelled. ``state`` and ``refit`` as for :func:`calibration.identification.recording.estimate`."""
    sd = np.array([est.std[0], np.radians(est.std[1])])
    V = np.outer(sd, sd) * np.array([[1.0, est.correlation], [est.correlation, 1.0]])
    lam, axes = np.linalg.eigh(V)
    var = np.zeros(len(x))
    for value, axis in zip(lam, axes.T):
        if value <= 0.0:
            continue
        step = math.sqrt(value) * axis  # one standard deviation along this axis, (s, rad)
        ends = [refit(state(applied[0] + sg * step[0], applied[1] + math.degrees(sg * step[1]))[0], x) for sg in (1.0, -1.0)]
        var += 0.5 * ((ends[0] - x) ** 2 + (ends[1] - x) ** 2)
    return np.sqrt(var)


def _adequacy(lps: list[LogProblem], x: np.ndarray, cs: CalibrationSettings, press: PressData) -> list[Adequacy]:
    """The lack-of-fit verdict of :mod:`calibration.identification.adequacy` at x for each log, on the points outside its die-contact
    window and force steps; the job's level is shared among the logs (Bonferroni). A parameter on a bound of its
    range cannot move on to absorb a misfit, so its Jacobian column is left out of what the test projects off."""
    free = ~on_bound(x, lps[0].objective.problem.low, lps[0].objective.problem.high)
    out = []
    for lp in lps:
        o = lp.objective
        T = o.torques(np.asarray(x, float)[None])[0]
        cands = candidate_columns(o.bm.theta, o.bm.theta_dot, T, press.drive.gear_ratio, press.motor.rated_torque,
                                  cs.ripple_orders)
        try:
            out.append(assess(lp.log.stroke_torque, lp.log.torque, T, ~_fixed_points(lp, cs.bootstrap_step_guard_deg),
                              int(free.sum()), cs.adequacy_level / len(lps), jacobian(o, x)[:, free], cands))
        except ValueError:
            raise PressDataError(lp.log.source, "strokes", lp.log.strokes, "leave too few crank angles covered by two "
                                 "strokes to judge the model against the stroke-to-stroke noise: log at least two whole "
                                 "strokes") from None
    return out


def block_points(cs: CalibrationSettings, theta: np.ndarray, noise_lag1: float) -> int:
    """Block length (grid points) of the bootstrap's residual resampling: the job's block_deg, or the job's
    block_noise_lengths correlation lengths of the noise (-1 / ln rho grid points for the pure error's lag-one
    correlation rho), whichever is longer, so that a block holds the noise's correlation (coloured noise then widens
    the intervals as it should)."""
    job_points = max(1, int(round(cs.bootstrap_block_deg / np.degrees(theta[1] - theta[0]))))
    rho = min(max(noise_lag1, 0.0), 0.99)
    return max(job_points, int(np.ceil(cs.bootstrap_block_noise_lengths * -1.0 / np.log(rho))) if rho > 0.0 else 1)


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
            "objective": f"Eq. 28: w Y_RMSE/Y_RMSE,0 + (1-w) |Y_PR|/|Y_PR,0|, w = {p.weight}, against the measured stroke-averaged curve",
            "peak_error": "max|T_pred| - max|T_meas| over the grid points outside the die-contact window (Eq. 23's numerator); "
                          "peak_error_with_impact: the same over every point, the impact spike included",
            "thermal_error": "(RMS_pred - RMS_meas) / RMS_meas, time-weighted RMS of Eq. 24 over the measured turn",
            "intervals": "95 % intervals of the reported estimator, one parameter at a time, see interval_method and "
                         "intervals_question (calibration/identification/bootstrap.py); coverage measured on synthetic logs by scripts/bench_coverage.py",
            "joint_region": "a box holding every calibrated parameter's truth at once at its level, see joint_region.method; "
                            "it holds each per-parameter interval; coverage (share of runs with every truth inside) measured "
                            "by scripts/bench_coverage.py and scripts/bench_adequacy.py",
            "intervals_jacobian": f"second opinion: {100 * u.level:g} % intervals of linearised least squares at the optimum "
                                  "(residual Jacobian, t-quantile), covariance inflated by the residuals' AR(1) factor; clipped to the bounds. "
                                  "They describe the least-squares estimator, not Eq. 28's",
            "measured_peak": "the measured peak of Eq. 23 is taken from the stroke-averaged curve after the job's filter "
                             "(see measured_peak.method); peak_error_* are against it",
        },
        "measured_peak": ({"value_Nm": cal.peak.value_Nm, "raw_maximum_Nm": cal.peak.raw_Nm, "noise_sigma_Nm": cal.peak.sigma_Nm,
                           "point_noise_sigma_Nm": cal.peak.point_sigma_Nm, "method": cal.peak.describe(),
                           "theoretical_peak_error_over_noise": abs(cal.objective.pr0) * cal.objective.measured_peak / cal.peak.sigma_Nm
                           if cal.peak.sigma_Nm > 0 else None} if cal.peak is not None else None),
        "warnings": list(cal.warnings),
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
        rec["definitions"]["objective"] += ("; over the logs end to end (calibration/identification/joint.py): Y_RMSE over every point of every "
                                            "log, the peak over every log's peak points against the largest measured peak")
    if cal.adequacy is not None:
        rec["adequacy"] = cal.adequacy.record()
        if len(cal.adequacy_logs) > 1:
            rec["adequacy"]["per_log"] = [{"log": lg.source, **a.record()} for lg, a in zip(cal.logs, cal.adequacy_logs)]
            rec["adequacy"]["adequate"] = all(a.adequate for a in cal.adequacy_logs)
        rec["intervals_cover_model_error"] = cal.adequacy.adequate
    if cal.recording_spread is not None:
        rec["interval_widening"] = {
            "recording_sd": {n: float(v) for n, v in zip(p.names, cal.recording_spread)},
            "level_quantile": float(stats.norm.ppf(0.5 + p_level(cal) / 2.0)),
            "noise_coloured": bool(cal.adequacy is not None and any(a.noise_coloured for a in cal.adequacy_logs)),
            "what": "each interval's half-widths with level_quantile x recording_sd added in quadrature (the recording "
                    "correction's uncertainty: Eq. 28 refitted on the log corrected one standard deviation beyond and short of "
                    "the estimated delay and offset along each principal axis of their covariance), then, on a bound or with coloured noise, joined with the Jacobian interval "
                    "(which carries the same widening)"}
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


def write_outputs(cal: Calibration, press: PressData, job: Job, seed: int, out: Path) -> dict:
    """Write calibrated.json, table4.csv/.md, solvers.csv and figure5.png; returns the calibrated.json record."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    rec = result_record(cal, press, job, seed)
    p, u = cal.objective.problem, cal.uncertainty
    paper = paper_figures()["calibration"]
    t4 = paper["table4"]
    rows = []
    for n, th, x in zip(p.names, p.theoretical, cal.best.x):
        pt = t4.get(n)
        (lo, hi), (jlo, jhi) = rec["intervals"][n], rec["intervals_jacobian"][n]
        slo, shi = rec["joint_region"]["box"][n]
        rows.append({"parameter": n, "theoretical": float(th), "calibrated": float(x), "interval_low": float(lo), "interval_high": float(hi),
                     "joint_region_low": float(slo), "joint_region_high": float(shi),
                     "jacobian_interval_low": float(jlo), "jacobian_interval_high": float(jhi),
                     "relative_error_pct": float(100 * (th - x) / x),
                     "paper_theoretical": float(pt[0]) if pt else float("nan"), "paper_calibrated": float(pt[1]) if pt else float("nan"),
                     "paper_relative_error_pct": float(100 * (pt[0] - pt[1]) / pt[1]) if pt else float("nan")})
    cols = list(rows[0])
    write_table(out / "table4.csv", cols, rows, digits=8)
    atomic_write_text(out / "table4.md", table4_markdown(rec, rows, paper, [r.time_s for r in cal.runs]))
    if len(cal.runs) > 1:
        low = min(r.objective for r in cal.runs)
        srows = [{"method": r.method, "objective_eq28": r.objective, "gap_to_minimum_pct": 100.0 * (r.objective - low) / low,
                  "model_cycles": r.cycles, **{n: float(x) for n, x in zip(p.names, r.x)}} for r in cal.runs]
        srows.append({**min(srows, key=lambda r: r["objective_eq28"]), "method": "minimum of all methods", "model_cycles": sum(r.cycles for r in cal.runs)})
        write_table(out / "solvers.csv", ["method", "objective_eq28", "gap_to_minimum_pct", "model_cycles", *p.names], srows)
    save(figure5(cal), out / "figure5.png")
    write_json(out / "calibrated.json", rec)
    return rec


def table4_markdown(rec: dict, rows: list[dict], paper: dict, times_s: list[float]) -> str:
    m = rec["metrics"]
    syn = rec["log"]["synthetic"]
    lines = [f"# Calibration against {'a SYNTHETIC' if syn else 'a measured'} drive log",
             "", f"Log: `{rec['log']['source']}`" + (f" ({rec['log']['label']})" if syn else "") + f"; method {rec['method']}, seed {rec['seed']}.", "",
             "## Table 4 analogue (relative error = (theoretical - calibrated) / calibrated, as in the paper)", "",
             "| parameter | theoretical | calibrated | 95 % interval (this parameter alone) | joint 95 % region (all at once) | Jacobian interval (second opinion) | rel. error | paper: theoretical | paper: calibrated | paper: rel. error |",
             "|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        lines.append(f"| {r['parameter']} | {r['theoretical']:.5g} | {r['calibrated']:.5g} | [{r['interval_low']:.5g}, {r['interval_high']:.5g}] | "
                     f"[{r['joint_region_low']:.5g}, {r['joint_region_high']:.5g}] | "
                     f"[{r['jacobian_interval_low']:.5g}, {r['jacobian_interval_high']:.5g}] | "
                     f"{r['relative_error_pct']:+.1f} % | {r['paper_theoretical']:.5g} | {r['paper_calibrated']:.5g} | {r['paper_relative_error_pct']:+.1f} % |")
    lines += ["", f"Intervals: {rec['interval_method']}.", f"They answer: {rec['intervals_question']}.",
              f"Joint region: {rec['joint_region']['question']}; {rec['joint_region']['method']}."]
    if rec.get("measured_peak"):
        lines += [f"Measured peak of Eq. 23: {rec['measured_peak']['method']}."]
    lines += [f"**Warning:** {w}" for w in rec.get("warnings", [])]
    a = rec.get("adequacy")
    if a:
        lines += ["", "## Model adequacy (calibration/identification/adequacy.py)", "",
                  f"{'Adequate' if a['adequate'] else '**Not adequate**'}: lack-of-fit F = {a['lack_of_fit_ratio']:.2f} (p = {a['p_value']:.2g}), "
                  f"residual lag-1 {a['residual_lag1']:.2f} against the noise's {a['pure_error_lag1']:.2f}; suspects: "
                  + (", ".join(a["suspects"]) or "none") + f". {rec['intervals_note']}.", "",
                  "| candidate effect | t | implied size |", "|---|---|---|"]
        lines += [f"| {n} | {t['t']:.1f} | {t['size']:.3g} +/- {t['size_std']:.2g} {t['unit']} |" for n, t in a["score_tests"].items()]
    nz = rec.get("nuisance") or {}
    if "channel_delay_s" in nz:
        lines += ["", f"Recording: channel delay {1e3 * nz['channel_delay_s']:.2f} ms, encoder offset {nz['angle_offset_deg']:+.3f} deg "
                  f"(corrected in the log; {'separable' if nz['separable'] else 'not separable on this motion'}, correlation {nz['correlation']:+.2f})."]
    lines += ["", "## Prediction accuracy, ours beside the paper's", "",
              "| figure | ours: before | ours: after | paper: before | paper: after |", "|---|---|---|---|---|",
              f"| RMSE [N m] | {m['rmse_before_Nm']:.1f} | {m['rmse_after_Nm']:.1f} | {paper['rmse_before_Nm']} | {paper['rmse_after_Nm']} |",
              f"| peak error [N m] | {m['peak_error_before_Nm']:+.1f} | {m['peak_error_after_Nm']:+.1f} | {paper['peak_error_before_Nm']} | {paper['peak_error_after_Nm']} |",
              f"| peak error incl. die-contact spike [N m] | {m['peak_error_with_impact_before_Nm']:+.1f} | {m['peak_error_with_impact_after_Nm']:+.1f} | | |",
              f"| thermal error (Eq. 24) | {100 * m['thermal_error_before']:+.2f} % | {100 * m['thermal_error_after']:+.2f} % | {100 * paper['thermal_error_before']:.1f} % | {100 * paper['thermal_error_after']:.1f} % |",
              "", "## What this experiment can tell apart", ""] + [f"* {s}" for s in rec["identifiability"]]
    v = rec.get("validation")
    if v:
        lines += ["", f"## Out-of-sample validation: `{v['log']}`" + (" (SYNTHETIC)" if v["synthetic"] else ""), "",
                  "Predicted with the theoretical and the calibrated parameters; " + (
                      f"{100 * v['shared_samples_with_fit']:.3g} % of this log's samples are fitted ones (part of a fitted "
                      "recording): not wholly out of sample." if v.get("shared_samples_with_fit") else
                      "nothing was fitted to this log."), "",
                  "| figure | theoretical | calibrated |", "|---|---|---|"] + validation_rows(v)
    if len(rec["solver_runs"]) > 1:
        lines += ["", "## Solvers on the same objective", "", "| method | Eq. 28 | above the minimum of all methods | model cycles | time [s] |", "|---|---|---|---|---|"]
        lines += [f"| {r['method']} | {r['objective_eq28']:.6f} | {r['gap_to_minimum_pct']:.3f} % | {r['model_cycles']} | {t:.2f} |"
                  for r, t in zip(rec["solver_runs"], times_s)]
        lines += [f"| minimum of all methods | {rec['objective_eq28_minimum_of_methods']:.6f} | | | |"]
    return "\n".join(lines) + "\n"


def validation_rows(v: dict) -> list[str]:
    """Markdown table rows of a validation record (theoretical | calibrated)."""
    return [f"| RMSE [N m] | {v['rmse_before_Nm']:.1f} | {v['rmse_after_Nm']:.1f} |",
            f"| peak error [N m] | {v['peak_error_before_Nm']:+.1f} | {v['peak_error_after_Nm']:+.1f} |",
            f"| thermal error (Eq. 24) | {100 * v['thermal_error_before']:+.2f} % | {100 * v['thermal_error_after']:+.2f} % |"]


def figure5(cal: Calibration):
    """Measured (stroke mean and spread), theoretical and calibrated motor torque over one turn; with a validation
    log, a third panel with its measured curve and the predictions of both parameter sets."""
    obj, log = cal.objective, cal.log
    deg = np.degrees(obj.bm.theta)
    T0 = obj.torques(obj.problem.theoretical[None])[0]
    T1 = obj.torques(cal.best.x[None])[0]
    vp = cal.validation_problem
    if vp is None:
        fig, (ax, ax2) = plt.subplots(2, 1, figsize=(9, 6.5), sharex=True, gridspec_kw={"height_ratios": [3, 1.3]})
    else:
        fig, (ax, ax2, ax3) = plt.subplots(3, 1, figsize=(9, 9.5), sharex=True, gridspec_kw={"height_ratios": [3, 1.3, 2.5]})
    spread = np.nan_to_num(np.concatenate([lg.torque_spread for lg in cal.logs]) if len(cal.logs) > 1 else log.torque_spread)
    meas = obj.measured  # the stroke mean (of every log end to end when several were fitted)
    ax.fill_between(deg, (meas - spread) / 1e3, (meas + spread) / 1e3, color="0.8", label="measured +/- stroke spread")
    ax.plot(deg, meas / 1e3, color="k", lw=1.0, label=f"T_act ({'SYNTHETIC, ' if log.synthetic else ''}{log.strokes}-stroke mean)")
    ax.plot(deg, T0 / 1e3, color="C3", lw=1.2, ls="--", label=f"T_the (theoretical), RMSE {cal.before['rmse_Nm']:.0f} N m")
    ax.plot(deg, T1 / 1e3, color="C0", lw=1.2, label=f"T_cal ({cal.best.method}), RMSE {cal.after['rmse_Nm']:.0f} N m")
    for d in deg[~obj.peak_points][:1]:
        ax.axvline(d, color="0.5", lw=0.8, ls=":")
    ax.set_ylabel("motor torque per motor [kN m]")
    title = "Figure 5 analogue: servo motor torque over one cycle"
    ax.set_title(title + (" - SYNTHETIC drive log" if log.synthetic else ""), fontsize=10)
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3)
    ax2.plot(deg, (T0 - meas), color="C3", lw=0.9, ls="--", label="theoretical - measured")
    ax2.plot(deg, (T1 - meas), color="C0", lw=0.9, label="calibrated - measured")
    ax2.set_ylabel("error [N m]")
    ax2.grid(alpha=0.3)
    ax2.legend(fontsize=8)
    ax2.set_xlim(0, 360 * max(1, len(cal.logs)))
    last = ax2
    if vp is not None:
        v, vo = cal.validation, vp.objective
        Tv = vo.torques(np.vstack([obj.problem.theoretical, cal.best.x]))
        vdeg = np.degrees(vo.bm.theta)
        ax3.plot(vdeg, vo.measured / 1e3, color="k", lw=1.0,
                 label=f"validation log ({'SYNTHETIC, ' if vp.log.synthetic else ''}{vp.log.strokes}-stroke mean, "
                       + (f"{100 * v['shared_samples_with_fit']:.3g} % of its samples fitted)" if v.get("shared_samples_with_fit")
                          else "not fitted)"))
        ax3.plot(vdeg, Tv[0] / 1e3, color="C3", lw=1.2, ls="--", label=f"theoretical, RMSE {v['rmse_before_Nm']:.0f} N m")
        ax3.plot(vdeg, Tv[1] / 1e3, color="C0", lw=1.2, label=f"calibrated, RMSE {v['rmse_after_Nm']:.0f} N m")
        ax3.set_ylabel("motor torque [kN m]")
        ax3.set_title("validation: a second log (another motion) predicted with both parameter sets", fontsize=9)
        ax3.legend(fontsize=8)
        ax3.grid(alpha=0.3)
        last = ax3
    last.set_xlabel("crank angle theta_c [deg]")
    fig.tight_layout()
    return fig
