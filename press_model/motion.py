"""Prescribed crank motions over one turn: crank speed and acceleration as functions of crank angle.

Each motion gives theta_dot(theta) (rad/s), theta_ddot(theta) (rad/s^2) and the time t(theta) (s)
since theta = 0, so a cycle can be sampled on a uniform crank-angle grid.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class ConstantSpeed:
    """Uniform rotation at ``speed`` rad/s."""

    speed: float

    @classmethod
    def from_spm(cls, strokes_per_min: float) -> "ConstantSpeed":
        return cls(2.0 * math.pi * strokes_per_min / 60.0)

    def theta_dot(self, theta):
        return np.full_like(np.asarray(theta, dtype=float), self.speed)

    def theta_ddot(self, theta):
        return np.zeros_like(np.asarray(theta, dtype=float))

    def time(self, theta):
        return np.asarray(theta, dtype=float) / self.speed

    @property
    def period(self) -> float:
        return 2.0 * math.pi / self.speed


@dataclass(frozen=True)
class ModulatedSpeed:
    """theta_dot = k (1 - depth cos(theta - slow_angle)): slowest at ``slow_angle`` (rad)."""

    k: float  # rad/s
    depth: float
    slow_angle: float

    @classmethod
    def from_spm(cls, strokes_per_min: float, depth: float, slow_angle: float) -> "ModulatedSpeed":
        """k such that one turn takes 60 / spm seconds: the period is 2 pi / (k sqrt(1 - depth^2))."""
        period = 60.0 / strokes_per_min
        return cls(2.0 * math.pi / (period * math.sqrt(1.0 - depth * depth)), depth, slow_angle)

    def theta_dot(self, theta):
        return self.k * (1.0 - self.depth * np.cos(np.asarray(theta, dtype=float) - self.slow_angle))

    def theta_ddot(self, theta):
        th = np.asarray(theta, dtype=float)
        return self.theta_dot(th) * self.k * self.depth * np.sin(th - self.slow_angle)

    def _antiderivative(self, x):
        a, b = self.k, self.k * self.depth
        root = math.sqrt(a * a - b * b)
        n = np.floor((x + math.pi) / (2.0 * math.pi))
        xr = x - 2.0 * math.pi * n
        return 2.0 / root * (np.arctan(math.sqrt((a + b) / (a - b)) * np.tan(xr / 2.0)) + math.pi * n)

    def time(self, theta):
        x = np.asarray(theta, dtype=float) - self.slow_angle
        return self._antiderivative(x) - self._antiderivative(np.asarray(-self.slow_angle))

    @property
    def period(self) -> float:
        return 2.0 * math.pi / (self.k * math.sqrt(1.0 - self.depth**2))


@dataclass(frozen=True, eq=False)
class FourierSpeed:
    """Measured crank speed over one turn, as a truncated Fourier series in crank angle.

    theta_dot(theta) = a0 + sum_k (a_k cos k theta + b_k sin k theta) (rad/s). A smooth periodic fit
    rather than an interpolant, so that theta_ddot = theta_dot * d(theta_dot)/d(theta) does not
    amplify the speed signal's noise; ``harmonics`` sets how fine a feature it keeps (360 / harmonics deg).
    """

    coef: np.ndarray  # [a0, a1, b1, a2, b2, ...]
    _time_table: np.ndarray  # t(theta) on a fine uniform grid over [0, 2 pi], s

    _TABLE_POINTS = 7200  # time table step 0.05 deg: trapezoid error far below a sampling period

    @classmethod
    def fit(cls, theta, theta_dot, harmonics: int) -> "FourierSpeed":
        """Least-squares fit to samples (rad, rad/s); refuses a fit that is not positive everywhere."""
        th, w = np.asarray(theta, dtype=float), np.asarray(theta_dot, dtype=float)
        coef = np.linalg.lstsq(cls._basis(th, harmonics), w, rcond=None)[0]
        fine = np.linspace(0.0, 2.0 * math.pi, cls._TABLE_POINTS + 1)
        speed = cls._basis(fine, harmonics) @ coef
        if not np.all(speed > 0):
            raise ValueError(f"the fitted crank speed is not positive over the whole turn (min {speed.min():.4g} rad/s)")
        inv = 1.0 / speed
        table = np.concatenate(([0.0], np.cumsum(0.5 * (inv[1:] + inv[:-1]) * np.diff(fine))))
        return cls(coef, table)

    @staticmethod
    def _basis(theta, harmonics: int) -> np.ndarray:
        k = np.arange(1, harmonics + 1)
        ang = np.multiply.outer(np.asarray(theta, dtype=float), k)
        cols = np.empty(ang.shape[:-1] + (2 * harmonics + 1,))
        cols[..., 0] = 1.0
        cols[..., 1::2], cols[..., 2::2] = np.cos(ang), np.sin(ang)
        return cols

    @property
    def harmonics(self) -> int:
        return (len(self.coef) - 1) // 2

    def theta_dot(self, theta):
        return self._basis(theta, self.harmonics) @ self.coef

    def theta_ddot(self, theta):
        th = np.asarray(theta, dtype=float)
        k = np.arange(1, self.harmonics + 1)
        ang = np.multiply.outer(th, k)
        d = (-np.sin(ang) * k) @ self.coef[1::2] + (np.cos(ang) * k) @ self.coef[2::2]
        return self.theta_dot(th) * d

    def time(self, theta):
        th = np.asarray(theta, dtype=float)
        turns = np.floor(th / (2.0 * math.pi))
        fine = np.linspace(0.0, 2.0 * math.pi, len(self._time_table))
        return turns * self.period + np.interp(th - turns * 2.0 * math.pi, fine, self._time_table)

    @property
    def period(self) -> float:
        return float(self._time_table[-1])


@dataclass(frozen=True, eq=False)
class TabulatedSpeed:
    """A crank motion given by samples over one turn, repeated every turn (a planned profile's stroke).

    ``theta`` (rad) rises strictly from theta0 = theta[0] to theta0 + 2 pi; ``speed`` (rad/s) and ``accel``
    (rad/s^2) are the crank speed and acceleration at those samples, ``time`` (s) the time since the first.
    Between samples the crank acceleration is taken as constant, as in a toppra profile: theta_dot^2 is then
    linear in theta, so theta_dot = sqrt of the linear interpolation of theta_dot^2, and theta_ddot is the
    acceleration of the sample the interval starts from. The speed may be zero only at the two ends
    (a stroke that starts and stops at rest); the turn's period is the stroke time.
    """

    theta: np.ndarray
    speed: np.ndarray
    accel: np.ndarray
    time_s: np.ndarray

    def _wrap(self, theta):
        th0 = self.theta[0]
        return th0 + np.mod(np.asarray(theta, dtype=float) - th0, 2.0 * math.pi)

    def theta_dot(self, theta):
        return np.sqrt(np.maximum(np.interp(self._wrap(theta), self.theta, self.speed**2), 0.0))

    def theta_ddot(self, theta):
        idx = np.clip(np.searchsorted(self.theta, self._wrap(theta), side="right") - 1, 0, len(self.theta) - 2)
        return self.accel[idx]

    def time(self, theta):
        """Time (s) since theta = 0, counting whole turns."""
        th = np.asarray(theta, dtype=float)

        def since_start(x):
            turns = np.floor((x - self.theta[0]) / (2.0 * math.pi))
            return turns * self.period + np.interp(self._wrap(x), self.theta, self.time_s)

        return since_start(th) - since_start(np.zeros(()))

    @property
    def period(self) -> float:
        return float(self.time_s[-1] - self.time_s[0])
