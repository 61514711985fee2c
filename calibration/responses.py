"""Response functions of the sensitivity analysis (Section 3.2.2, Eqs. 22-25), vectorised over a batch.

Every function takes motor-torque curves ``T`` of shape (B, n) (or one curve, shape (n,)) sampled per
motor on the uniform crank-angle grid theta_c = 0, 2 pi / n, ... (n = 360 in the paper: 1 degree), the
grid of :func:`cycle.simulate_cycle`, and returns one value per curve, shape (B,) (or a float).

Time integrals over the cycle use the weights of :class:`cycle.Cycle`: a sample stands for the time
dt = dtheta / theta_dot it takes the crank to turn one grid step (periodic rectangle rule), so
t_c = sum(dt) is the cycle time.
"""
from __future__ import annotations

import math

import numpy as np

from press_model.jit import compiled

RESPONSES = ("Y_RMSE", "Y_PR", "Y_TL", "Y_Work")  # the column order of :func:`all_responses`


def _curves(T) -> np.ndarray:
    return np.asarray(T, dtype=float)


def _out(y):
    return float(y) if np.ndim(y) == 0 else y


def time_weights(theta_dot) -> np.ndarray:
    """dt per sample (s) on the uniform grid: (2 pi / n) / theta_dot, theta_dot in rad/s (must be > 0)."""
    w = np.asarray(theta_dot, dtype=float)
    if not np.all(w > 0):
        raise ValueError("the time weights need a crank speed theta_dot > 0 at every sample (continuous rotation)")
    return (2.0 * math.pi / w.shape[-1]) / w


def y_rmse(T, T_ref):
    """Eq. 22: root-mean-square difference between T and the reference curve T_ref over the k = n samples (N m).

    T_ref (n,) is the curve of the theoretical (nominal) parameters; the mean is over samples, not time.
    """
    T = _curves(T)
    return _out(np.sqrt(np.mean((T - np.asarray(T_ref, dtype=float)) ** 2, axis=-1)))


def y_pr(T, T_ref):
    """Eq. 23: peak ratio (max|T| - max|T_ref|) / max|T_ref| (dimensionless; 0.05 means a 5 % higher peak)."""
    T = _curves(T)
    peak_ref = np.max(np.abs(np.asarray(T_ref, dtype=float)))
    return _out((np.max(np.abs(T), axis=-1) - peak_ref) / peak_ref)


def y_tl(T, theta_dot):
    """Eq. 24: thermal load, the time-weighted RMS sqrt(1/t_c * integral T^2 dt) over the cycle (N m).

    Same as :meth:`cycle.Cycle.rms_motor_torque`; theta_dot (n,) is the crank speed in rad/s.
    """
    T = _curves(T)
    dt = time_weights(theta_dot)
    return _out(np.sqrt(np.sum(dt * T**2, axis=-1) / np.sum(dt)))


def y_work(T, theta_dot, gear_ratio: float):
    """Eq. 25: motor work over the cycle, integral of u_gear T theta_dot dt (J, per motor).

    On the uniform grid this is u_gear * dtheta * sum(T); computed as :meth:`cycle.Cycle.motor_work_per_motor`
    does. Positive: the motor delivers energy over the cycle.
    """
    T = _curves(T)
    w = np.asarray(theta_dot, dtype=float)
    return _out(np.sum(gear_ratio * T * w * time_weights(w), axis=-1))


FUSED_ROWS = 64  # from this many curves the responses run compiled (when numba is installed)


def all_responses(T, T_ref, theta_dot, gear_ratio: float) -> np.ndarray:
    """The four responses as columns (B, 4) in the order of :data:`RESPONSES` (N m, 1, N m, J).

    Many curves at once (a sensitivity design) run through one compiled pass (:func:`_fused`) when numba
    is installed; its sums run in another order than numpy's, so the two agree to rounding (tests).
    """
    T = np.atleast_2d(_curves(T))
    fused = compiled(_fused) if len(T) >= FUSED_ROWS else None
    if fused is None:
        return np.column_stack([y_rmse(T, T_ref), y_pr(T, T_ref), y_tl(T, theta_dot), y_work(T, theta_dot, gear_ratio)])
    w = np.asarray(theta_dot, dtype=float)
    dt = time_weights(w)
    ref = np.ascontiguousarray(T_ref, dtype=float)
    out = np.empty((len(T), len(RESPONSES)))
    fused(np.ascontiguousarray(T), ref, float(np.max(np.abs(ref))), dt, float(np.sum(dt)), gear_ratio * w * dt, out)
    return out


def _fused(T, T_ref, peak_ref, dt, t_cycle, work_weight, out):
    """Eqs. 22-25 of every curve in one pass over T (B, n): the same sums as y_rmse, y_pr, y_tl, y_work.

    ``work_weight`` = u_gear theta_dot dt per sample; a curve with a NaN gives NaN in every column.
    """
    B, n = T.shape
    for b in range(B):
        sq = peak = heat = work = 0.0
        for p in range(n):
            t = T[b, p]
            d = t - T_ref[p]
            sq += d * d
            peak = max(peak, abs(t))
            heat += dt[p] * t * t
            work += work_weight[p] * t
        bad = math.isnan(sq)  # max() would pass a NaN over
        out[b, 0] = math.sqrt(sq / n)
        out[b, 1] = math.nan if bad else (peak - peak_ref) / peak_ref
        out[b, 2] = math.sqrt(heat / t_cycle)
        out[b, 3] = work
