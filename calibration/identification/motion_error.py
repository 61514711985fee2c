"""The crank motion's own uncertainty in the model's torque: errors in the variables of the lack-of-fit test.

The model's torque at each grid point is computed from the crank speed and acceleration that the speed fit
(:mod:`calibration.identification.speed_fit`) estimated from the log's noisy speed samples; the same estimate serves
every stroke, so its error is no part of the stroke-to-stroke (pure) error, yet it moves the model's curve. Where a
motion changes its acceleration abruptly (the ends of a sharp speed ramp) the fit's window stays narrow and the
acceleration's error is large: with 1 rpm of speed noise about 0.25-1 rad/s^2 at a 15-degree ramp's end (SYNTHETIC logs),
enough for the lack-of-fit test to call a correct model NOT ADEQUATE.

At grid point i the fit's speed error e_w and slope error e_s (d theta_dot / d theta) have the covariance S_i the fit
knows from the speed samples' white noise (:attr:`LocalSpeed.covariance`). The crank acceleration is
theta_ddot = theta_dot s, so its error is s e_w + theta_dot e_s, and to first order the torque's error is

    dT = (dT/d theta_dot + s dT/d theta_ddot) e_w + theta_dot dT/d theta_ddot e_s,     var dT_i = g_i' S_i g_i,

with the two sensitivities of the model at the calibrated parameters taken by forward differences of the batch
model on the motion moved by a small step (each grid point's torque depends on its own speed and acceleration
only; the moved model is the log's own, moved along the press's motion terms, :func:`press_model.batch.with_motion`,
not built anew). Nothing is chosen here: the steps are a cost of the numerical derivative (the torque is smooth in both; the
friction's signs follow the speed's, which stays positive).
"""
from __future__ import annotations

import math

import numpy as np

from press_model.batch import build_batch_model, motion_terms, motor_torques, with_motion
from press_model.model import PressModel

_STEP = 1e-4  # relative step of the numerical derivatives (the torque is smooth in speed and acceleration)


class _Moved:
    """The grid motion of a batch model with its speed and acceleration moved by constants (rad/s, rad/s^2)."""

    def __init__(self, bm, d_speed: float, d_accel: float):
        self.theta, self.period = bm.theta, bm.period
        self._w, self._a = bm.theta_dot + d_speed, bm.theta_ddot + d_accel

    def _at(self, values, theta):
        if not np.array_equal(np.asarray(theta, float), self.theta):
            raise ValueError("the moved motion is defined on its batch model's grid only")
        return values

    def theta_dot(self, theta):
        return self._at(self._w, theta)

    def theta_ddot(self, theta):
        return self._at(self._a, theta)


def torque_variance(bm, motion, sets: np.ndarray, process, pm=None) -> np.ndarray | None:
    """(n,) N m^2: the variance of the model's motor torque (per motor) at each grid point of ``bm`` (a
    press_model.batch.BatchModel built on ``motion`` and the process force ``process``) that the crank motion's own
    uncertainty gives, at the full parameter set ``sets`` (D,) (the module docstring); None when the motion carries
    no covariance (a Fourier series, a log without speed samples, an exact speed)."""
    cov = getattr(motion, "covariance", None)
    if cov is None or not np.any(cov):
        return None
    X = np.asarray(sets, float)[None]
    dw = _STEP * float(np.max(np.abs(bm.theta_dot)))
    da = _STEP * max(float(np.max(np.abs(bm.theta_ddot))), float(np.max(np.abs(bm.theta_dot))) ** 2)

    pm = pm if pm is not None else PressModel(bm.press)
    terms = motion_terms(bm.press, pm, math.degrees(bm.theta[1] - bm.theta[0]))

    def torque(d_speed, d_accel):
        try:  # the model moved along its motion terms: the same numbers as one built on the moved motion
            moved = with_motion(bm, process, bm.theta_dot + d_speed, bm.theta_ddot + d_accel, terms)
        except ValueError:  # a speed that changes sign changes the Coulomb terms: build it
            moved = build_batch_model(bm.press, _Moved(bm, d_speed, d_accel), process, pm=pm)
        return motor_torques(moved, X)[0]

    base = motor_torques(bm, X)[0]
    d_speed = (torque(dw, 0.0) - base) / dw
    d_accel = (torque(0.0, da) - base) / da
    slope = bm.theta_ddot / bm.theta_dot
    g = np.stack([d_speed + slope * d_accel, bm.theta_dot * d_accel], axis=1)  # (n, 2)
    return np.einsum("ni,nij,nj->n", g, cov, g)


def estimate_sd(jac: np.ndarray, variance: np.ndarray) -> np.ndarray:
    """(k,) SI: the standard deviation the crank motion's error gives each least-squares estimate, from the residual
    Jacobian ``jac`` (n, k) (zero rows outside the fitted points) and the model curve's variance ``variance`` (n,) N m^2
    (:func:`torque_variance`, every log's end to end), the grid points' errors taken as independent: the linearised
    least-squares step pinv(J) moves by pinv(J) dT. The same motion serves every stroke and every bootstrap refit,
    so neither the stroke-to-stroke noise nor the refits see this share; it widens the intervals in quadrature."""
    A = np.linalg.pinv(np.asarray(jac, float))
    return np.sqrt((A ** 2) @ np.where(np.isfinite(variance), np.maximum(variance, 0.0), 0.0))
