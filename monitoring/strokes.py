"""One record per stroke of a drive log, in OPC 40503's (Metal Forming) terms: forming positions and times (TDC,
touch, BDC, breakthrough), the peak and integrated process force from the virtual tonnage, the peak motor torque, the
energy drawn and returned, the model's residual outside the process, and the condition classes Overload and
ProcessForce against the job's force band.

:func:`log_records` takes a drive log read on the crank grid (:mod:`calibration.traces.drive_log`), the calibrated
press and the job; every value is SI (angles of the record in degrees, its only user-facing unit, named ``_deg``).
"""
from __future__ import annotations

import json
import math
from dataclasses import dataclass
from datetime import datetime, timedelta, timezone

import numpy as np

from press_io.errors import PressDataError

from calibration.identification.problem import peak_points
from calibration.identification.settings import CalibrationSettings
from calibration.identification.speed_fit import speed_harmonics
from press_model.jobs import Job
from press_model.kinematics import force_step_angles
from press_model.model import PressModel
from press_model.motion import FourierSpeed
from press_model.press_data import PressData

from monitoring.rules import Rules
from monitoring.tonnage import ForceMap, TonnageEstimate, build_force_map, channel_noise, estimate, region_sets, running_median

SCHEMA_VERSION = 2  # of a stroke record (the Parquet store's column set); a new column is a new version
# 2: motor_peak_torque_Nm and motor_share, each motor's own (lists in motor order; null for a log of one torque column);
#    peak_observable (peak_force_N NaN and no ProcessForce alarm where the job's peak cannot be seen: :func:`peak_zone`)

# every column of a stroke record and its kind (the store's Parquet types: int, float, str, bool, time = UTC instant, and
# floats = a list of floats, one per motor)
COLUMNS = {
    # tdc_time: the stroke's TDC as a clock time (a pendulum's swing, which never reaches TDC: its BDC); stroke_index: the
    # crank turn since the log's angle 0 (a pendulum log: the working swing's number)
    "schema_version": "int", "press": "str", "day": "str", "stroke_index": "int", "tdc_time": "time", "source": "str",
    "tdc_time_s": "float", "bdc_time_s": "float", "tdc_angle_deg": "float", "bdc_angle_deg": "float",
    "tdc_height_m": "float", "bdc_height_m": "float", "touch_angle_deg": "float", "touch_height_m": "float",
    "breakthrough_angle_deg": "float", "peak_force_N": "float", "peak_force_half_width_N": "float",
    "peak_force_angle_deg": "float", "process_work_J": "float", "observable_points": "int", "peak_motor_torque_Nm": "float",
    "energy_drawn_J": "float", "energy_returned_J": "float", "residual_rms_Nm": "float", "efficiency_ratio": "float",
    "overload": "bool", "process_low": "bool",
    "heaviest_motor": "int", "heaviest_share": "float", "eccentric_load": "bool",
    "motor_peak_torque_Nm": "floats", "motor_share": "floats", "peak_observable": "bool",
}


@dataclass(frozen=True)
class LogTonnage:
    """A log's virtual tonnage: the force map it was read through, the estimate of each complete stroke, the strokes'
    rows of the log's per-turn bins (``turns``), the grid's crank speed (rad/s) and the first turn's number."""

    fmap: ForceMap
    est: TonnageEstimate
    torque: np.ndarray  # (S, n) N m per motor, each complete stroke's bin means
    rows: np.ndarray  # (S,) each stroke's row in the log's per-turn bins (``stroke_torque_binned``)
    turns: np.ndarray  # (S,) the turn number of each stroke (crank turns since the log's angle 0)
    theta_dot: np.ndarray  # (n,) rad/s


def job_force(job: Job) -> float:
    """N: the job's peak process force (Eq. 14's table), the scale of the band alarms and the observability rule."""
    return float(max((abs(f) for f in job.process.forces), default=0.0))


_CONTACTS: dict[str, list[float]] = {}  # this process's force-step angles (rad) by press and process force


def contact_angles(pm: PressModel, job: Job) -> list[float]:
    """The crank angles (rad) of the job's force steps on this press: a Newton search a few hundred times, done once."""
    key = json.dumps([pm.press.fingerprint, pm.press.parameter_values(), repr(job.process)], sort_keys=True)
    if key not in _CONTACTS:
        _CONTACTS[key] = list(force_step_angles(pm, job.process))
    return _CONTACTS[key]


def log_tonnage(press: PressData, job: Job, parameters: dict, box: dict | None, log, rules: Rules,
                pm: PressModel | None = None) -> LogTonnage:
    """The virtual tonnage of every complete stroke of ``log`` under the calibrated ``parameters`` (SI) and their joint
    region ``box`` ({name: (low, high)}, None for none), on the log's own stroke-mean crank motion."""
    pm = pm if pm is not None else PressModel(press)
    cs = CalibrationSettings.from_job(job)
    # the stroke-mean crank speed as a Fourier series of the harmonics its own spectrum carries above its noise (the
    # calibration's rule, calibration/identification/speed_fit.py): milliseconds where the local fit takes seconds
    motion = FourierSpeed.fit(log.theta, log.crank_speed, speed_harmonics(log, cs))
    force = job_force(job)
    sets = region_sets(press.parameter_values() | dict(parameters), box, rules.tonnage.region_samples, rules.tonnage.region_seed)
    fmap = build_force_map(press, motion, force, sets, rules.tonnage, pm=pm, step_deg=float(np.degrees(log.theta[1] - log.theta[0])))
    transient = ~peak_points(fmap.theta, motion.time, contact_angles(pm, job)[:1], cs.peak_window_after_contact_s)
    binned = np.asarray(log.stroke_torque_binned, dtype=float)
    complete = np.all(np.isfinite(binned), axis=1)  # a turn the log enters or leaves part-way is no stroke record
    n = binned.shape[1]
    first_turn = int(np.rint(np.degrees(np.min(log.torque_angles)) / (360.0 / n))) // n
    torque = binned[complete]
    est = estimate(fmap, torque, channel_noise(torque), rules.tonnage, transient)
    rows = np.flatnonzero(complete)
    return LogTonnage(fmap, est, torque, rows, first_turn + rows, np.asarray(motion.theta_dot(fmap.theta), float))


def peak_zone(fm: ForceMap, job: Job, rules: Rules) -> np.ndarray:
    """(n,) the grid points where the job's own force (Eq. 14 on the map's slide height and speed) reaches the
    ProcessForce limit (``process_low_of_job_force`` of its peak): the only points where a stroke's force can show that
    the stroke's peak is low, and where its peak lies when the process runs as planned."""
    return job.process(fm.height, fm.height_dot) >= rules.alarms.process_low_of_job_force * fm.job_force


def peak_seen(zone: np.ndarray, observable: np.ndarray, rules: Rules) -> bool:
    """Whether a stroke's peak force is observable: at least ``peak_median_points`` observable points of the job's
    :func:`peak_zone`, so that the running median the peak is read from can stand wholly on the force's plateau. On a
    press whose process acts near a dead centre (a crank-slider's cushion in the last 20 % of the stroke) it is not:
    the force there hardly moves the torque, and the largest observable force is the plateau's edge, not its peak."""
    return int(np.sum(zone & observable)) >= rules.tonnage.peak_median_points


def efficiency_ratio(model: np.ndarray, torque: np.ndarray, motoring: np.ndarray) -> np.ndarray:
    """(...,): the least-squares scale of the measured ``torque`` (..., n; N m) on the ``model``'s (n,) over the
    ``motoring`` points (n,) without process force: Eq. 16 divides the motoring torque by eta_gear, so a drive whose
    efficiency fell by 3 % reads about 1.03 (NaN without motoring points)."""
    m = model[motoring]
    if m.size == 0:
        return np.full(np.shape(torque)[:-1], math.nan)
    return np.asarray(torque)[..., motoring] @ m / float(m @ m)


def clear_of_process(fm: ForceMap) -> np.ndarray:
    """(n,) the grid points where the slide is clear of the process (moving up, or at the top): no process force."""
    return (fm.height_dot > 0.0) | (fm.height > fm.height.max() * 0.999)


def motoring_points(lt: "LogTonnage") -> tuple[np.ndarray, np.ndarray]:
    """The calibrated model's torque without process force (n,; N m) and the points (n,) clear of the process
    (:func:`clear_of_process`) where the motors drive: where the efficiency ratio is read."""
    fm = lt.fmap
    model_free = fm.torque[0, int(np.argmin(np.abs(fm.forces)))]
    return model_free, clear_of_process(fm) & (model_free * lt.theta_dot > 0.0)


def _motor_fields(motors, i: int, motor) -> dict:
    """The record's per-motor columns of stroke ``i``: the heaviest motor (1-based; 0 for one torque column), its share
    of the total torque (NaN for one column), its peak torque, and EccentricLoad: two motors' shares, each taken from its
    expected share (the press file's [motor] load_shares, else even), differ by more than its load_share_tolerance (the
    difference calibrate warns beyond)."""
    if motors is None or not np.all(np.isfinite(motors[0][i])):
        return {"heaviest_motor": 0, "heaviest_share": math.nan, "eccentric_load": False, "motor_peak_torque_Nm": None,
                "motor_share": None}
    shares, peaks = motors
    k = int(np.argmax(shares[i]))
    expected = np.asarray(motor.load_shares, float) if len(motor.load_shares) == shares.shape[1] else np.full(shares.shape[1], 1.0 / shares.shape[1])
    off = shares[i] - expected
    return {"heaviest_motor": k + 1, "heaviest_share": float(shares[i, k]), "peak_motor_torque_Nm": float(np.max(peaks[i])),
            "eccentric_load": bool(np.max(off) - np.min(off) > motor.load_share_tolerance),
            "motor_peak_torque_Nm": [float(v) for v in peaks[i]], "motor_share": [float(v) for v in shares[i]]}


# deg: samples further apart than this do not bracket a crossing. A log is sampled far finer (500 Hz at 20 spm: 0.24
# deg); a pendulum's swings leave the 100-200 deg they do not sweep between their samples
CROSSING_GAP_DEG = 10.0


def _crossing_time(speed_samples: np.ndarray, angle: np.ndarray) -> np.ndarray:
    """s since the log's start at which the crank passes the unwrapped ``angle`` (rad), from the speed samples' angles;
    NaN where the samples around it are more than :data:`CROSSING_GAP_DEG` apart (the crank never passed there: a
    pendulum's TDC, between its swings' samples)."""
    t, a = speed_samples[:, 0], speed_samples[:, 1]
    at = np.clip(np.searchsorted(a, angle), 1, max(len(a) - 1, 1))
    gap = a[at] - a[at - 1] > math.radians(CROSSING_GAP_DEG)
    return np.where(gap, np.nan, np.interp(angle, a, t, left=np.nan, right=np.nan))


def _first_last(mask: np.ndarray) -> tuple[int | None, int | None]:
    idx = np.flatnonzero(mask)
    return (int(idx[0]), int(idx[-1])) if idx.size else (None, None)


def check_motor_columns(rows, press: PressData) -> None:
    """Refuse a log whose torque columns of one motor each (``rows``: its LogRows) are not one per motor of ``press``
    ([drive] motors): the shares and EccentricLoad would be read against the wrong motors. One torque column (the torque
    per motor) fits any press."""
    if rows.motor_torques is None:
        return
    found, motors = rows.motor_torques.shape[1], press.drive.motors
    if found != motors:
        raise PressDataError(rows.source, "torque columns", ", ".join(rows.motor_channels), f"are {found} motors' but the press "
                             f"file {press.source} has [drive] motors = {motors}: give --press the file of the press that wrote "
                             f"this log, or log one torque column per motor of this press")


def motor_turns(rows, turns: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
    """Per stroke (turn numbers ``turns``, as :class:`LogTonnage`'s): each motor's share and peak, :func:`motor_strokes`
    over the samples of each crank turn (counted from the log's first sample's turn)."""
    deg = np.degrees(np.unwrap(np.radians(rows.data[:, 1])))  # the angle channel, turns counted from the first sample
    return motor_strokes(rows, np.floor((deg - 360.0 * np.floor(deg[0] / 360.0)) / 360.0).astype(int), turns)


def motor_strokes(rows, label: np.ndarray, strokes: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
    """Per stroke (``strokes``: the values of ``label``, (rows,) each sample's stroke): each motor's share of the total
    torque (S, M; the least-squares factor of T_i on their sum over the stroke's samples,
    :mod:`calibration.traces.motor_shares`'s estimator) and its peak |torque| (S, M; N m); None for a log of one torque
    column (``rows``: its LogRows)."""
    if rows.motor_torques is None:
        return None
    motors = np.asarray(rows.motor_torques, dtype=float)
    total = motors.sum(axis=1)
    shares = np.full((len(strokes), motors.shape[1]), np.nan)
    peaks = np.full_like(shares, np.nan)
    for k, t in enumerate(strokes):
        m = (label == t) & np.all(np.isfinite(motors), axis=1)
        if m.any():
            shares[k] = motors[m].T @ total[m] / float(total[m] @ total[m])
            peaks[k] = np.max(np.abs(motors[m]), axis=0)
    return shares, peaks


def log_records(lt: LogTonnage, pm: PressModel, log, rules: Rules, press_id: str, start: datetime | None,
                motors: tuple[np.ndarray, np.ndarray] | None = None, job: Job | None = None) -> list[dict]:
    """The stroke records (dicts of plain values, :data:`SCHEMA_VERSION`) of a log's virtual tonnage ``lt``; ``start`` the
    log's recorded start (UTC), None for a log that does not say (times are then from the log's first sample);
    ``motors``: each motor's shares and peaks per stroke (:func:`motor_turns`) where each motor's torque is logged:
    the heaviest motor, its share and EccentricLoad (:func:`_motor_fields`); ``job``: the production's job, whose
    :func:`peak_zone` tells whether the peak is observable (None: taken as observable). Where it is not, the peak's
    columns are NaN and ProcessForce is not raised; Overload still is, from the largest observable force."""
    fm, est, tr = lt.fmap, lt.est, rules.tonnage
    seen = job is None or peak_seen(peak_zone(fm, job, rules), est.observable, rules)
    drive = pm.press.drive
    step = float(fm.theta[1] - fm.theta[0])
    moving = lt.theta_dot > 0.0  # a pendulum's grid points outside its swing are not passed: no time, no energy
    dt = np.divide(step, lt.theta_dot, out=np.full_like(lt.theta_dot, np.nan), where=moving)  # s per grid point
    omega_m = drive.gear_ratio * lt.theta_dot
    model_free, motoring = motoring_points(lt)
    no_process = clear_of_process(fm)
    smooth = running_median(np.where(est.observable, est.force, np.nan), tr.peak_median_points)
    dh = np.gradient(fm.height)
    base = start.astimezone(timezone.utc) if start is not None else None
    tdc, bdc = pm.assembly.theta_tdc, pm.assembly.theta_bdc
    # every stroke's TDC and BDC times in one interpolation: one per stroke would copy the log's whole speed-sample
    # columns each time, a cost that grows with the square of the log's length (a shift's log holds thousands)
    turn_angles = 2.0 * math.pi * np.asarray(lt.turns, dtype=float)
    crossings = _crossing_time(log.speed_samples, np.stack([turn_angles + tdc, turn_angles + bdc], axis=1).ravel()).reshape(-1, 2)
    records = []
    for i, turn in enumerate(lt.turns):
        f, tq = smooth[i], lt.torque[i]
        above = np.isfinite(f) & (f > tr.touch_of_job_force * fm.job_force)
        touch, breakthrough = _first_last(above)
        top_at = int(np.nanargmax(f)) if np.any(np.isfinite(f)) else None  # the largest observable force
        peak_at = top_at if seen else None
        t_tdc, t_bdc = crossings[i]
        power = drive.motors * tq * omega_m * dt  # J per grid point, all motors
        resid = (tq - model_free)[no_process]
        resid = resid[np.isfinite(resid)]  # a swing's grid points it does not reach have no torque
        ratio = float(efficiency_ratio(model_free, tq, motoring))
        work = float(np.nansum(np.where(est.observable, est.force[i], 0.0) * -dh * (fm.height_dot <= 0.0)))
        peak, top = (float(f[at]) if at is not None else math.nan for at in (peak_at, top_at))
        passes_tdc = math.isfinite(t_tdc)  # a pendulum's swing turns back before TDC: its TDC columns are NaN
        t_key = t_tdc if passes_tdc else t_bdc  # the record's clock: its TDC, a swing's BDC
        when = base + timedelta(seconds=float(t_key)) if base is not None and math.isfinite(t_key) else None
        records.append({  # a log without a recorded start: no clock time, its strokes under day=undated
            "schema_version": SCHEMA_VERSION, "press": press_id, "day": when.date().isoformat() if when else "undated",
            "stroke_index": int(turn), "tdc_time": when, "source": log.source,
            "tdc_time_s": float(t_tdc), "bdc_time_s": float(t_bdc), "tdc_angle_deg": math.degrees(tdc) if passes_tdc else math.nan,
            "bdc_angle_deg": math.degrees(bdc), "tdc_height_m": float(fm.height.max()) if passes_tdc else math.nan,
            "bdc_height_m": float(fm.height.min()),
            "touch_angle_deg": math.degrees(fm.theta[touch]) if touch is not None else math.nan,
            "touch_height_m": float(fm.height[touch]) if touch is not None else math.nan,
            "breakthrough_angle_deg": math.degrees(fm.theta[breakthrough]) if breakthrough is not None else math.nan,
            "peak_force_N": peak,
            "peak_force_half_width_N": float(est.half_width[i, peak_at]) if peak_at is not None else math.nan,
            "peak_force_angle_deg": math.degrees(fm.theta[peak_at]) if peak_at is not None else math.nan,
            "process_work_J": work, "observable_points": int(est.observable.sum()),
            "peak_motor_torque_Nm": float(np.max(np.abs(tq))),
            "energy_drawn_J": float(power[power > 0].sum()), "energy_returned_J": float(-power[power < 0].sum()),
            "residual_rms_Nm": float(np.sqrt(np.mean(resid ** 2))) if resid.size else math.nan,
            "efficiency_ratio": ratio,
            "overload": bool(top > rules.alarms.overload_of_job_force * fm.job_force) if math.isfinite(top) else False,
            "process_low": bool(peak < rules.alarms.process_low_of_job_force * fm.job_force) if math.isfinite(peak) else False,
            "peak_observable": peak_at is not None, **_motor_fields(motors, i, pm.press.motor),
        })
    return records
