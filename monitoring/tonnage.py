"""Virtual tonnage: the process force on the slide that the measured motor torque leaves, stroke by stroke.

The calibrated model gives the motor torque at every crank angle as a function of the force on the slide: inertia,
gravity, the balance (Eqs. 13, 17), friction (Eqs. 10, 12, which grow with the force) and Eq. 16's efficiency switch
make it piecewise near-linear, not linear. :func:`build_force_map` computes it on the log's crank grid and motion at a
few force levels (``[tonnage] levels_of_job_force``), for the calibrated parameters and for parameter sets drawn in
the calibration's joint region (the batch model: one call per level for every set), and :func:`estimate` reads each
stroke's measured torque back through it, point by point, with a piecewise-linear inverse.

The 95 % interval at each point combines (in quadrature) the torque channel's noise, taken from the log's own
stroke-to-stroke scatter and divided by the torque's sensitivity to the force, and the spread of the estimates of the
joint region's parameter sets (the calibration's share, taken whole: the largest move of any set). Near the crank's
dead centres the force hardly moves the torque, the interval grows without bound, and the point is marked not
observable (``observable_half_width_of_job_force``).
"""
from __future__ import annotations

import json
import math
import warnings
from dataclasses import dataclass

import numpy as np

from press_model.batch import ConstantMotion, build_batch_model, motion_terms, motor_torques, with_motion, with_slide_force
from press_model.forces import NO_PROCESS
from press_model.model import PressModel
from press_model.press_data import PressData

from monitoring.rules import TonnageRules

Z95 = 1.959963984540054  # two-sided 95 % normal quantile


@dataclass(frozen=True)
class ForceMap:
    """The model's motor torque per motor (N m) at each grid angle and slide force: ``torque`` (B, K, n) for the B
    parameter sets (row 0 the calibrated values, the rest drawn in the joint region), the K forces ``forces`` (N, up
    on the slide) and the n grid angles ``theta`` (rad); ``height`` (n,) the slide height (m) along the grid."""

    theta: np.ndarray
    height: np.ndarray
    height_dot: np.ndarray
    forces: np.ndarray
    torque: np.ndarray
    job_force: float  # N: the job's peak process force, the scale of the observability rule and the alarms

    @property
    def sensitivity(self) -> np.ndarray:
        """(n,) N m per N: the calibrated model's motor torque per unit slide force, end to end over the levels."""
        t = self.torque[0]
        return (t[-1] - t[0]) / (self.forces[-1] - self.forces[0])


def region_sets(center: dict, box: dict | None, samples: int, seed: int) -> list[dict]:
    """Parameter sets (SI): ``center`` first, then ``samples`` drawn uniformly in the joint region ``box`` ({name: (low,
    high)}), half of them at the box's corners (the estimate moves most there), with the seeded generator."""
    sets = [dict(center)]
    if not box:
        return sets
    rng = np.random.default_rng(seed)
    names = list(box)
    lo = np.array([box[n][0] for n in names], dtype=float)
    hi = np.array([box[n][1] for n in names], dtype=float)
    for i in range(samples):
        u = rng.integers(0, 2, len(names)).astype(float) if i % 2 == 0 else rng.random(len(names))
        sets.append({**center, **dict(zip(names, lo + u * (hi - lo)))})
    return sets


_BASES: dict[str, tuple] = {}  # this process's base model and motion terms, of the press it reads (one at a time)


def _model_on(press: PressData, pm: PressModel, motion, step_deg: float):
    """The batch model of ``press`` without process force on ``motion``: moved from a base model of a constant speed
    by the motion terms (:func:`press_model.batch.with_motion`, array sums), both built once a process; a motion whose
    speed is not positive everywhere (a pendulum stroke) is built on its own."""
    key = json.dumps([press.fingerprint, press.parameter_values(), step_deg], sort_keys=True)
    if key not in _BASES:
        _BASES.clear()
        _BASES[key] = (build_batch_model(press, ConstantMotion(1.0, 0.0), NO_PROCESS, step_deg=step_deg, pm=pm),
                       motion_terms(press, pm, step_deg))
    base, terms = _BASES[key]
    td = np.asarray(motion.theta_dot(base.theta), dtype=float)
    if np.all(td > 0.0):
        return with_motion(base, NO_PROCESS, td, np.asarray(motion.theta_ddot(base.theta), dtype=float), terms)
    return build_batch_model(press, motion, NO_PROCESS, step_deg=step_deg, pm=pm)


def build_force_map(press: PressData, motion, job_force: float, sets: list[dict], rules: TonnageRules,
                    pm: PressModel | None = None, step_deg: float = 1.0) -> ForceMap:
    """The :class:`ForceMap` of ``press`` (the calibrated press: its parameters are the sets' base) on ``motion`` (the
    log's crank motion) for the parameter ``sets`` (full names of the press file, SI): one batch-model build (disk-cached
    by press and motion) and one batch evaluation per force level."""
    pm = pm if pm is not None else PressModel(press)
    bm = _model_on(press, pm, motion, step_deg)
    forces = np.asarray(rules.levels_of_job_force, dtype=float) * job_force
    torque = np.stack([motor_torques(with_slide_force(bm, f), sets) for f in forces], axis=1)
    return ForceMap(np.array(bm.theta), np.array(bm.height), np.array(bm.height_dot), forces, torque, float(job_force))


def invert(torque_k: np.ndarray, forces: np.ndarray, measured: np.ndarray) -> np.ndarray:
    """(..., n) N: the force at which the torque table ``torque_k`` (..., K, n; N m, monotone in the force at each point)
    gives ``measured`` (..., n or broadcastable), piecewise linear between the K ``forces``, extrapolated along the end
    segments. NaN where the measured torque is NaN or the table is flat."""
    sign = np.sign(torque_k[..., -1, :] - torque_k[..., 0, :])
    sign = np.where(sign == 0.0, 1.0, sign)
    t = torque_k * sign[..., None, :]  # increasing in the force at every point
    x = np.asarray(measured, dtype=float) * sign
    lead = np.broadcast_shapes(t.shape[:-2], x.shape[:-1])
    t, x = np.broadcast_to(t, lead + t.shape[-2:]), np.broadcast_to(x, lead + x.shape[-1:])
    k = len(forces)
    idx = np.clip(np.sum(t < x[..., None, :], axis=-2), 1, k - 1)
    t0 = np.take_along_axis(t, (idx - 1)[..., None, :], axis=-2)[..., 0, :]
    t1 = np.take_along_axis(t, idx[..., None, :], axis=-2)[..., 0, :]
    f0, f1 = forces[idx - 1], forces[idx]
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(t1 != t0, f0 + (x - t0) * (f1 - f0) / (t1 - t0), np.nan)


@dataclass(frozen=True)
class TonnageEstimate:
    """Per stroke and grid angle (S, n): ``force`` (N, up on the slide) and its 95 % ``half_width`` (N); ``observable``
    (n,) where the half-width is within the rule; ``noise_Nm`` the torque channel's noise per grid point (N m) it used."""

    force: np.ndarray
    half_width: np.ndarray
    observable: np.ndarray
    noise_Nm: float

    @property
    def low(self) -> np.ndarray:
        return self.force - self.half_width

    @property
    def high(self) -> np.ndarray:
        return self.force + self.half_width


def channel_noise(stroke_torque: np.ndarray) -> float:
    """N m: the torque channel's noise at one grid point of one stroke, pooled over the log: the root mean square of
    the stroke-to-stroke standard deviation at each point (what repeats every stroke, a model error or a ringing
    that is the same each time, is not noise and is not in it). NaN for a log of one stroke."""
    st = np.asarray(stroke_torque, dtype=float)
    if st.shape[0] < 2:
        return math.nan
    sd = np.nanstd(st, axis=0, ddof=1)
    return float(np.sqrt(np.nanmean(sd ** 2)))


def estimate(fmap: ForceMap, stroke_torque: np.ndarray, noise_Nm: float, rules: TonnageRules,
             transient: np.ndarray | None = None) -> TonnageEstimate:
    """The virtual tonnage of each stroke (rows of ``stroke_torque``, (S, n) N m per motor on the map's grid) with its
    95 % interval: the noise ``noise_Nm`` (N m per point, :func:`channel_noise`) through the calibrated sensitivity,
    and the joint region's largest move, combined in quadrature. ``transient`` (n,) marks the points inside a
    die-contact transient (the ringing the rigid model has not: the calibration's own peak window after contact,
    :func:`calibration.identification.problem.peak_points`): estimated, but never observable."""
    st = np.atleast_2d(np.asarray(stroke_torque, dtype=float))
    force = invert(fmap.torque[0], fmap.forces, st)
    with np.errstate(divide="ignore"):
        noise_part = Z95 * noise_Nm / np.abs(fmap.sensitivity)
    if len(fmap.torque) > 1:
        others = invert(fmap.torque[1:, None], fmap.forces, st[None])  # (B-1, S, n)
        region_part = np.fmax.reduce(np.abs(others - force[None]), axis=0)  # NaN only where every set is
    else:
        region_part = np.zeros_like(force)
    half = np.sqrt(noise_part[None, :] ** 2 + region_part ** 2)
    with warnings.catch_warnings():  # a point no stroke reaches (a pendulum's swing) is NaN: not observable, as meant
        warnings.simplefilter("ignore", RuntimeWarning)
        typical = np.nanmedian(half, axis=0) if len(half) > 1 else half[0]
    observable = np.isfinite(typical) & (typical <= rules.observable_half_width_of_job_force * fmap.job_force)
    if transient is not None:
        observable &= ~np.asarray(transient, dtype=bool)
    return TonnageEstimate(force, half, observable, float(noise_Nm))


def running_median(values: np.ndarray, points: int) -> np.ndarray:
    """(..., n): the running median of ``values`` over ``points`` neighbouring grid points (odd; ends: the window
    shrinks), NaN ignored."""
    v = np.asarray(values, dtype=float)
    half = points // 2
    pad = np.pad(v, [(0, 0)] * (v.ndim - 1) + [(half, half)], constant_values=np.nan)
    windows = np.lib.stride_tricks.sliding_window_view(pad, points, axis=-1)
    some = np.isfinite(windows).any(axis=-1)  # an all-NaN window stays NaN
    out = np.full(windows.shape[:-1], np.nan)
    out[some] = np.nanmedian(windows[some], axis=-1)
    return out


def not_observable_text(theta: np.ndarray, observable: np.ndarray) -> str:
    """The crank-angle ranges (deg) where the force is not observable, as text ('72-79, 179-181 deg'), 'none' if none."""
    idx = np.flatnonzero(~np.asarray(observable, dtype=bool))
    if not idx.size:
        return "none"
    cuts = np.flatnonzero(np.diff(idx) > 1)
    deg = np.degrees(theta)
    runs = zip(np.r_[idx[0], idx[cuts + 1]], np.r_[idx[cuts], idx[-1]])
    return ", ".join(f"{deg[a]:.0f}" if a == b else f"{deg[a]:.0f}-{deg[b]:.0f}" for a, b in runs) + " deg"
