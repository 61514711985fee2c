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

SCHEMA_VERSION = 1  # of a stroke record (the Parquet store's column set); a new column is a new version

# every column of a stroke record and its kind (the store's Parquet types: int, float, str, bool, and time = UTC instant)
COLUMNS = {
    "schema_version": "int", "press": "str", "day": "str", "stroke_index": "int", "tdc_time": "time", "source": "str",
    "tdc_time_s": "float", "bdc_time_s": "float", "tdc_angle_deg": "float", "bdc_angle_deg": "float",
    "tdc_height_m": "float", "bdc_height_m": "float", "touch_angle_deg": "float", "touch_height_m": "float",
    "breakthrough_angle_deg": "float", "peak_force_N": "float", "peak_force_half_width_N": "float",
    "peak_force_angle_deg": "float", "process_work_J": "float", "observable_points": "int", "peak_motor_torque_Nm": "float",
    "energy_drawn_J": "float", "energy_returned_J": "float", "residual_rms_Nm": "float", "efficiency_ratio": "float",
    "overload": "bool", "process_low": "bool",
    "heaviest_motor": "int", "heaviest_share": "float", "eccentric_load": "bool",
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


def _contact(pm: PressModel, job: Job) -> list[float]:
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
    transient = ~peak_points(fmap.theta, motion.time, _contact(pm, job)[:1], cs.peak_window_after_contact_s)
    binned = np.asarray(log.stroke_torque_binned, dtype=float)
    complete = np.all(np.isfinite(binned), axis=1)  # a turn the log enters or leaves part-way is no stroke record
    n = binned.shape[1]
    first_turn = int(np.rint(np.degrees(np.min(log.torque_angles)) / (360.0 / n))) // n
    torque = binned[complete]
    est = estimate(fmap, torque, channel_noise(torque), rules.tonnage, transient)
    rows = np.flatnonzero(complete)
    return LogTonnage(fmap, est, torque, rows, first_turn + rows, np.asarray(motion.theta_dot(fmap.theta), float))


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
        return {"heaviest_motor": 0, "heaviest_share": math.nan, "eccentric_load": False}
    shares, peaks = motors
    k = int(np.argmax(shares[i]))
    expected = np.asarray(motor.load_shares, float) if len(motor.load_shares) == shares.shape[1] else np.full(shares.shape[1], 1.0 / shares.shape[1])
    off = shares[i] - expected
    return {"heaviest_motor": k + 1, "heaviest_share": float(shares[i, k]), "peak_motor_torque_Nm": float(np.max(peaks[i])),
            "eccentric_load": bool(np.max(off) - np.min(off) > motor.load_share_tolerance)}


def _crossing_time(speed_samples: np.ndarray, angle: np.ndarray) -> np.ndarray:
    """s since the log's start at which the crank passes the unwrapped ``angle`` (rad), from the speed samples' angles."""
    t, a = speed_samples[:, 0], speed_samples[:, 1]
    return np.interp(angle, a, t, left=np.nan, right=np.nan)


def _first_last(mask: np.ndarray) -> tuple[int | None, int | None]:
    idx = np.flatnonzero(mask)
    return (int(idx[0]), int(idx[-1])) if idx.size else (None, None)


def motor_turns(rows, turns: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
    """Per stroke (turn numbers ``turns``, as :class:`LogTonnage`'s): each motor's share of the total torque (S, M; the
    least-squares factor of T_i on their sum over the turn's samples, :mod:`calibration.traces.motor_shares`'s
    estimator) and its peak |torque| (S, M; N m); None for a log of one torque column (``rows``: its LogRows)."""
    if rows.motor_torques is None:
        return None
    deg = np.degrees(np.unwrap(np.radians(rows.data[:, 1])))  # the angle channel, turns counted from the first sample
    turn = np.floor((deg - 360.0 * np.floor(deg[0] / 360.0)) / 360.0).astype(int)
    motors = np.asarray(rows.motor_torques, dtype=float)
    total = motors.sum(axis=1)
    shares = np.full((len(turns), motors.shape[1]), np.nan)
    peaks = np.full_like(shares, np.nan)
    for k, t in enumerate(turns):
        m = (turn == t) & np.all(np.isfinite(motors), axis=1)
        if m.any():
            shares[k] = motors[m].T @ total[m] / float(total[m] @ total[m])
            peaks[k] = np.max(np.abs(motors[m]), axis=0)
    return shares, peaks


def log_records(lt: LogTonnage, pm: PressModel, log, rules: Rules, press_id: str, start: datetime | None,
                motors: tuple[np.ndarray, np.ndarray] | None = None) -> list[dict]:
    """The stroke records (dicts of plain values, :data:`SCHEMA_VERSION`) of a log's virtual tonnage ``lt``; ``start`` the
    log's recorded start (UTC), None for a log that does not say (times are then from the log's first sample);
    ``motors``: each motor's shares and peaks per stroke (:func:`motor_turns`) where each motor's torque is logged:
    the heaviest motor, its share and EccentricLoad (:func:`_motor_fields`)."""
    fm, est, tr = lt.fmap, lt.est, rules.tonnage
    drive = pm.press.drive
    step = float(fm.theta[1] - fm.theta[0])
    dt = step / lt.theta_dot  # s per grid point
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
        peak_at = int(np.nanargmax(f)) if np.any(np.isfinite(f)) else None
        t_tdc, t_bdc = crossings[i]
        power = drive.motors * tq * omega_m * dt  # J per grid point, all motors
        resid = (tq - model_free)[no_process]
        ratio = float(efficiency_ratio(model_free, tq, motoring))
        work = float(np.nansum(np.where(est.observable, est.force[i], 0.0) * -dh * (fm.height_dot <= 0.0)))
        peak = float(f[peak_at]) if peak_at is not None else math.nan
        when = base + timedelta(seconds=float(t_tdc)) if base is not None and math.isfinite(t_tdc) else None
        records.append({  # a log without a recorded start: no clock time, its strokes under day=undated
            "schema_version": SCHEMA_VERSION, "press": press_id, "day": when.date().isoformat() if when else "undated",
            "stroke_index": int(turn), "tdc_time": when, "source": log.source,
            "tdc_time_s": float(t_tdc), "bdc_time_s": float(t_bdc), "tdc_angle_deg": math.degrees(tdc), "bdc_angle_deg": math.degrees(bdc),
            "tdc_height_m": float(fm.height.max()), "bdc_height_m": float(fm.height.min()),
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
            "overload": bool(peak > rules.alarms.overload_of_job_force * fm.job_force) if math.isfinite(peak) else False,
            "process_low": bool(peak < rules.alarms.process_low_of_job_force * fm.job_force) if math.isfinite(peak) else False,
            **_motor_fields(motors, i, pm.press.motor),
        })
    return records
