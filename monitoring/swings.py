"""Pendulum logs (planning/pendulum.py's motion): the crank swings through BDC between two turning points and back,
never over TDC. A log of it is cut at its turning points into swings; each complete working swing (the crank turning
forward, as a turning stroke does: the slide comes down through die contact and BDC and rises to the far turning point)
is one stroke. The returns carry no process force (the die is empty) and make no record.

The force map is built on the working swings' own mean crank speed at each grid angle (zero outside the swing: the
batch model evaluates those points at rest, and no torque is logged there, so they are never observable); each swing's
torque is binned on the same 1-degree grid and read back through it as a turning stroke's is
(:func:`monitoring.tonnage.estimate`). Units: SI inside; the log's degrees and rpm converted on reading.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from calibration.identification.problem import peak_points
from calibration.identification.settings import CalibrationSettings
from press_model.jobs import Job
from press_model.model import PressModel
from press_model.press_data import PressData

from monitoring.rules import Rules
from monitoring.strokes import LogTonnage, contact_angles, job_force
from monitoring.tonnage import build_force_map, channel_noise, estimate, region_sets

BACK_DEG = 1.0  # a turn back by more than this (deg) is a turning point; less is an encoder's jitter


def turning_points(deg: np.ndarray) -> np.ndarray:
    """Indices of the samples where the unwrapped crank angle ``deg`` (deg) turns back by more than :data:`BACK_DEG`:
    each the furthest sample of its run, in time order."""
    if len(deg) < 2:  # no move at all: the log reader says what such a log lacks
        return np.empty(0, dtype=int)
    turns, ext, at, up = [], deg[0], 0, None
    for i, d in enumerate(deg):
        if up is None:  # the first move decides the direction
            if abs(d - deg[0]) > BACK_DEG:
                up, ext, at = d > deg[0], d, i
            continue
        if (d > ext) == up or d == ext:
            ext, at = d, i
        elif abs(d - ext) > BACK_DEG:
            turns.append(at)
            up, ext, at = not up, d, i
    return np.array(turns, dtype=int)


def is_pendulum(rows) -> bool:
    """Whether the log's crank turns back by more than :data:`BACK_DEG` (``rows``: its LogRows): a pendulum log, cut by
    :func:`swing_tonnage`, and forward somewhere too (a crank that only runs backward is the log reader's to refuse).
    A turning log of hours is not walked sample by sample: array operations first tell whether it ever turns back."""
    deg = np.degrees(np.unwrap(np.radians(rows.data[:, 1])))
    if not deg.size or not np.any(deg < np.maximum.accumulate(deg) - BACK_DEG):
        return False
    return turning_points(deg).size > 0


@dataclass(frozen=True)
class SwingLog:
    """What :func:`monitoring.strokes.log_records` reads of a log beside its tonnage, for a pendulum log: its ``source``,
    the working swings' samples (time s, angle rad increasing through the log, crank speed rad/s) and each row's working
    swing (-1: none; :func:`monitoring.strokes.motor_strokes`'s labels)."""

    source: str
    speed_samples: np.ndarray
    swing_of_row: np.ndarray


class SwingMotion:
    """The working swings' crank motion on the grid ``theta`` (rad): mean speed ``speed`` (rad/s, > 0 inside the swing,
    0 outside), its acceleration v dv/dtheta (rad/s^2) and the time since the swing's start (s), as press_model.motion's
    motions give them."""

    def __init__(self, theta: np.ndarray, speed: np.ndarray):
        self.grid, self.speed = theta, speed
        inside = speed > 0.0
        self.accel = np.where(inside, speed * np.gradient(speed, theta), 0.0)
        step = float(theta[1] - theta[0])
        dt = np.where(inside, step / np.where(inside, speed, 1.0), 0.0)  # no time passes outside the swing
        self.table = np.concatenate(([0.0], np.cumsum(dt)))

    def theta_dot(self, theta):
        return np.interp(np.mod(theta, 2.0 * math.pi), self.grid, self.speed)

    def theta_ddot(self, theta):
        return np.interp(np.mod(theta, 2.0 * math.pi), self.grid, self.accel)

    @property
    def period(self) -> float:
        """s: one working swing's time, turning point to turning point."""
        return float(self.table[-1])

    def time(self, theta):
        th = np.asarray(theta, dtype=float)
        grid = np.append(self.grid, 2.0 * math.pi)
        return np.floor(th / (2.0 * math.pi)) * self.table[-1] + np.interp(np.mod(th, 2.0 * math.pi), grid, self.table)


def working_swings(rows, gear_ratio: float, step_deg: float):
    """The complete working swings of a pendulum log: their torque per motor (S, n; N m, the bin means on the crank grid
    of ``step_deg``, NaN where a swing has no sample), the mean crank speed per grid point (n,; rad/s, 0 outside) and the
    samples' (time s, swing-unwrapped angle rad, crank speed rad/s), swing k's angles moved by k turns so that they
    increase through the log (the crossing times of :func:`monitoring.strokes.log_records`), and each row's swing (-1:
    none)."""
    t, deg = rows.data[:, 0], np.degrees(np.unwrap(np.radians(rows.data[:, 1])))
    speed = rows.data[:, 2] * 2.0 * math.pi / 60.0 / gear_ratio
    torque = rows.data[:, 3]
    turns = turning_points(deg)
    n = int(round(360.0 / step_deg))
    stroke_torque, stroke_speed, samples = [], [], []
    label = np.full(len(t), -1)
    for a, b in zip(turns[:-1], turns[1:]):
        if deg[b] <= deg[a]:  # a return swing: the die empty
            continue
        k = len(stroke_torque)
        sl = slice(a, b + 1)
        label[sl] = k
        idx = np.floor(np.mod(deg[sl], 360.0) / step_deg).astype(int) % n
        count = np.bincount(idx, minlength=n).astype(float)
        with np.errstate(invalid="ignore", divide="ignore"):
            stroke_torque.append(np.bincount(idx, torque[sl], minlength=n) / np.where(count > 0, count, np.nan))
            stroke_speed.append(np.bincount(idx, np.abs(speed[sl]), minlength=n) / np.where(count > 0, count, np.nan))
        samples.append(np.column_stack([t[sl], np.radians(deg[sl] - deg[a]) + 2.0 * math.pi * k + np.radians(deg[a] % 360.0),
                                        np.abs(speed[sl])]))
    if not stroke_torque:
        return np.empty((0, n)), np.zeros(n), np.empty((0, 3)), label
    torque_k, speed_k = np.array(stroke_torque), np.array(stroke_speed)
    covered = np.all(np.isfinite(torque_k), axis=0) & np.all(speed_k > 0.0, axis=0)  # points every swing passes, moving
    torque_k[:, ~covered] = np.nan
    mean_speed = np.zeros(n)
    mean_speed[covered] = speed_k[:, covered].mean(axis=0)
    return torque_k, mean_speed, np.concatenate(samples), label


def swing_tonnage(press: PressData, job: Job, parameters: dict, box: dict | None, rows, rules: Rules,
                  pm: PressModel | None = None, step_deg: float = 1.0) -> tuple[LogTonnage, SwingLog]:
    """The virtual tonnage of each complete working swing of a pendulum log (``rows``: its LogRows) under the calibrated
    ``parameters`` (SI) and their joint region ``box``: the :class:`LogTonnage` (``turns``: the swing's number) and
    the :class:`SwingLog` its records read."""
    pm = pm if pm is not None else PressModel(press)
    torque, speed, samples, label = working_swings(rows, press.drive.gear_ratio, step_deg)
    theta = np.radians(np.arange(torque.shape[1]) * step_deg)
    motion = SwingMotion(theta, speed)
    sets = region_sets(press.parameter_values() | dict(parameters), box, rules.tonnage.region_samples, rules.tonnage.region_seed)
    fmap = build_force_map(press, motion, job_force(job), sets, rules.tonnage, pm=pm, step_deg=step_deg)
    cs = CalibrationSettings.from_job(job)
    transient = ~peak_points(fmap.theta, motion.time, contact_angles(pm, job)[:1], cs.peak_window_after_contact_s)
    est = estimate(fmap, torque, channel_noise(torque[:, speed > 0.0]), rules.tonnage, transient)
    swings = np.arange(len(torque))
    return LogTonnage(fmap, est, torque, swings, swings, motion.theta_dot(fmap.theta)), SwingLog(rows.source, samples, label)
