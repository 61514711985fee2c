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
