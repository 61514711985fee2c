"""Crank motions for SYNTHETIC logs that no shipped job file describes: a two-speed motion with raised-cosine ramps,
the kind of motion a validation run may use (slow through one arc, fast elsewhere).

Units: rad, rad/s, rad/s^2 and s inside; the constructor takes the arcs in degrees, the user's edge.
"""
from __future__ import annotations

import math

import numpy as np


class TwoSpeedMotion:
    """A SYNTHETIC two-speed crank motion: ``slow`` rad/s from ``a_deg`` to ``b_deg``, ``fast`` rad/s elsewhere, each
    change of speed a raised cosine over ``ramp_deg`` after a and after b. Gives theta_dot (rad/s), theta_ddot
    (rad/s^2), time (s since theta = 0) and period (s), as press_model.motion's motions do."""

    def __init__(self, slow: float, fast: float, a_deg: float, b_deg: float, ramp_deg: float):
        self.slow, self.fast = slow, fast
        self.a, self.b, self.ramp = math.radians(a_deg), math.radians(b_deg), math.radians(ramp_deg)
        fine = np.linspace(0.0, 2.0 * math.pi, 72001)
        inv = 1.0 / self.theta_dot(fine)
        self._fine, self._table = fine, np.concatenate(([0.0], np.cumsum(0.5 * (inv[1:] + inv[:-1]) * np.diff(fine))))

    def _shape(self, theta):
        th = np.mod(np.asarray(theta, float), 2.0 * math.pi)
        x1, x2 = (np.clip((th - s) / self.ramp, 0.0, 1.0) for s in (self.a, self.b))
        inside1, inside2 = ((x > 0.0) & (x < 1.0) for x in (x1, x2))
        g = 1.0 - 0.5 * (1.0 - np.cos(math.pi * x1)) + 0.5 * (1.0 - np.cos(math.pi * x2))
        dg = 0.5 * math.pi / self.ramp * (-np.sin(math.pi * x1) * inside1 + np.sin(math.pi * x2) * inside2)
        return g, dg

    def theta_dot(self, theta):
        return self.slow + (self.fast - self.slow) * self._shape(theta)[0]

    def theta_ddot(self, theta):
        return self.theta_dot(theta) * (self.fast - self.slow) * self._shape(theta)[1]

    def time(self, theta):
        th = np.asarray(theta, float)
        turns = np.floor(th / (2.0 * math.pi))
        return turns * self.period + np.interp(th - turns * 2.0 * math.pi, self._fine, self._table)

    @property
    def period(self) -> float:
        return float(self._table[-1])
