"""The calibration model of Section 3.4 (Eqs. 26-28) as plain data plus a vectorised objective.

A :class:`CalibrationProblem` names the calibrated parameters, their bounds (the sensitivity ranges of
the press file) and the theoretical values; :func:`objective` turns it, a batch model on the measured
crank motion and the measured torque curve into ``f(P) -> Eq. 28`` for a whole colony of parameter
sets at once. Eq. 28: w * Y_RMSE(P) / Y_RMSE,0 + (1 - w) * |Y_PR(P)| / |Y_PR,0|, with Y_RMSE and Y_PR
(Eqs. 22-23) taken against the measured curve, and the ,0 values those of the theoretical parameters.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from calibration.identification.curves import motor_curves
from press_model.batch import BatchModel
from press_io.errors import PressDataError
from press_model.press_data import PressData, check_parameter_ranges
from calibration.responses import y_rmse, y_tl


NO_PARAMETERS = ("must name at least one parameter to calibrate: give the job's [calibration] parameters = [...] (the "
                 "paper's six: see cushion_test.toml) or --parameters (e.g. the key_parameters.json of `servo-press "
                 "sensitivity`)")

@dataclass(frozen=True)
class CalibrationProblem:
    """Names, bounds (SI units) and theoretical values of the calibrated parameters, and the weight w."""

    names: tuple[str, ...]
    low: np.ndarray
    high: np.ndarray
    theoretical: np.ndarray
    weight: float

    @classmethod
    def from_press(cls, press: PressData, names, weight: float, source: str = "calibration") -> "CalibrationProblem":
        names = tuple(names)
        if not names:
            raise PressDataError(source, "calibration.parameters", "<missing>", NO_PARAMETERS)
        unknown = [n for n in names if n not in press.parameters]
        if unknown:
            raise PressDataError(source, "parameters", unknown, f"must be parameters of the press file; known: {', '.join(press.parameters)}")
        if len(set(names)) != len(names):
            raise PressDataError(source, "parameters", list(names), "must not name a parameter twice")
        if not 0.0 <= weight <= 1.0:
            raise PressDataError(source, "weight", weight, "must lie in [0, 1] (Eq. 28's w)")
        check_parameter_ranges(press, names)  # the optimisers run the model anywhere in the box
        ps = [press.parameters[n] for n in names]
        values = press.parameter_values()
        return cls(names, np.array([p.low for p in ps]), np.array([p.high for p in ps]),
                   np.array([values[n] for n in names]), float(weight))

    def full_sets(self, bm: BatchModel, P: np.ndarray) -> np.ndarray:
        """All of the batch model's parameters (B, D): the theoretical values with the calibrated ones from P (B, k)."""
        P = np.atleast_2d(np.asarray(P, dtype=float))
        X = np.tile(bm.nominal, (len(P), 1))
        col = {n: i for i, n in enumerate(bm.names)}
        for j, n in enumerate(self.names):
            X[:, col[n]] = P[:, j]
        return X


@dataclass(frozen=True)
class Objective:
    """Eq. 28 on one measured curve. Call it with parameter sets P (B, k) in physical units -> (B,)."""

    problem: CalibrationProblem
    bm: BatchModel
    measured: np.ndarray  # (n,) N m per motor on bm's grid
    # (n,) bool: the grid points both terms of Eq. 28 compare, Y_RMSE and the peaks: outside the die-contact ringing,
    # which the rigid-body model has no term for (left in Y_RMSE it pulled J_gear 5 % and mu_r 4 % low on a SYNTHETIC log)
    peak_points: np.ndarray
    rmse0: float  # Y_RMSE of the theoretical parameters against the measurement over the peak points, N m
    pr0: float  # Y_PR of the theoretical parameters, dimensionless
    measured_peak: float  # N m: the measured peak of Eq. 23 (max |measured| over the peak points unless given filtered)

    def torques(self, P) -> np.ndarray:
        """Predicted motor torque curves (B, n), N m per motor (each distinct crank torque computed once: curves.py)."""
        return motor_curves(self.bm, self.problem.full_sets(self.bm, P))

    def parts(self, T) -> tuple[np.ndarray, np.ndarray]:
        """(Y_RMSE in N m, Y_PR) of predicted curves T (B, n) against the measurement, both over the peak points."""
        m = self.peak_points
        return y_rmse(T[..., m], self.measured[m]), y_pr_against(T[..., m], self.measured_peak)

    def value(self, T) -> np.ndarray:
        """Eq. 28 of predicted curves T (B, n)."""
        rmse, pr = self.parts(T)
        w = self.problem.weight
        return w * rmse / self.rmse0 + (1.0 - w) * np.abs(pr) / abs(self.pr0)

    def __call__(self, P) -> np.ndarray:
        return self.value(self.torques(P))

    def parts_of(self, P) -> tuple[np.ndarray, np.ndarray]:
        """(Y_RMSE in N m, Y_PR) of parameter sets P (B, k): the two parts of Eq. 28."""
        return self.parts(self.torques(P))

    def residuals(self, P) -> np.ndarray:
        """Predicted minus measured torque (n,) of one parameter set, N m, zero outside the peak points: the
        least-squares residual vector of Y_RMSE."""
        return np.where(self.peak_points, self.torques(np.asarray(P, dtype=float)[None])[0] - self.measured, 0.0)

    def residual_rows(self, P) -> np.ndarray:
        """:meth:`residuals` of each parameter set of P (B, k): (B, n) N m."""
        return np.where(self.peak_points, self.torques(np.asarray(P, dtype=float)) - self.measured, 0.0)


def y_pr_against(T, peak_Nm: float):
    """Eq. 23 with the measured peak given as a number (N m): (max|T| - peak) / peak, (B,) or float."""
    return (np.max(np.abs(np.asarray(T, dtype=float)), axis=-1) - peak_Nm) / peak_Nm


def objective(problem: CalibrationProblem, bm: BatchModel, measured, peak_points=None, measured_peak: float | None = None,
              theoretical_torque=None) -> Objective:
    """Eq. 28 normalised by the theoretical parameters' Y_RMSE,0 and Y_PR,0 against ``measured`` (N m, on bm's grid).

    ``peak_points`` (bool, n): the points Y_RMSE and the peaks of Eq. 23 are taken over (default everywhere); see
    :func:`peak_points` for leaving out the ringing after die contact that a rigid-body model cannot show.
    ``measured_peak`` (N m): the measured peak of Eq. 23, e.g. from the filtered curve
    (:func:`calibration.identification.peak.measured_peak`); default max |measured| over the peak points.
    ``theoretical_torque`` (n,): the theoretical parameters' curve on bm, if already computed.
    """
    measured = np.asarray(measured, dtype=float)
    if measured.shape != (bm.n_points,):
        raise PressDataError("calibration", "measured curve", measured.shape, f"must hold {bm.n_points} samples on the model's crank grid")
    mask = np.ones(bm.n_points, dtype=bool) if peak_points is None else np.asarray(peak_points, dtype=bool)
    if mask.shape != measured.shape or not mask.any():
        raise PressDataError("calibration", "peak points", int(mask.sum()), "must leave at least one grid point to compare peaks on")
    peak = float(np.max(np.abs(measured[mask]))) if measured_peak is None else float(measured_peak)
    if not (math.isfinite(peak) and peak > 0.0):
        raise PressDataError("calibration", "measured peak", peak, "must be a positive torque (N m)")
    t0 = motor_curves(bm, problem.full_sets(bm, problem.theoretical))[0] if theoretical_torque is None else np.asarray(theoretical_torque, float)
    rmse0, pr0 = float(y_rmse(t0[mask], measured[mask])), float(y_pr_against(t0[mask], peak))
    if rmse0 == 0.0 or pr0 == 0.0:
        raise PressDataError("calibration", "measured curve", "equal to the theoretical prediction",
                             "leaves Eq. 28's normalisation undefined (Y_RMSE,0 or Y_PR,0 is zero): nothing to calibrate")
    return Objective(problem, bm, measured, mask, rmse0, pr0, peak)


def peak_points(theta: np.ndarray, time_of, contact_angles, window_s: float) -> np.ndarray:
    """Grid points (bool) farther than ``window_s`` seconds after every die contact.

    The impact at die contact rings for a while in a real drive trace (the paper's Figure 5 shows the
    spike); the rigid-body model has no such term, so its peak is compared with the measured peak once
    the ringing has died away. ``time_of(theta)`` gives the time (s) of a crank angle within the turn.
    """
    keep = np.ones(len(theta), dtype=bool)
    if window_s <= 0.0:
        return keep
    t = np.asarray(time_of(theta), dtype=float)
    period = float(time_of(np.array([2.0 * np.pi]))[0])
    for a in contact_angles:
        since = np.mod(t - float(time_of(np.array([a]))[0]), period)
        keep &= since > window_s
    return keep


def metrics(T_pred: np.ndarray, measured: np.ndarray, theta_dot: np.ndarray, peak_points: np.ndarray,
            measured_peak: float | None = None) -> dict:
    """RMSE (N m); peak error max|T_pred| - measured peak (N m) over the peak points (``measured_peak``, N m,
    default max|T_meas| there), and max|T_pred| - max|T_meas| over every point (the die-contact spike
    included); thermal error (relative error of Eq. 24's RMS)."""
    tl_pred, tl_meas = float(y_tl(T_pred, theta_dot)), float(y_tl(measured, theta_dot))
    m = peak_points
    peak = float(np.max(np.abs(measured[m]))) if measured_peak is None else float(measured_peak)
    return {
        "rmse_Nm": float(y_rmse(T_pred, measured)),
        "peak_error_Nm": float(np.max(np.abs(T_pred[m])) - peak),
        "peak_error_with_impact_Nm": float(np.max(np.abs(T_pred)) - np.max(np.abs(measured))),
        "thermal_error": (tl_pred - tl_meas) / tl_meas,
        "rms_torque_Nm": tl_pred,
    }
