"""External forces on the slide along the guide axis (Section 2.3) and the friction law (Eqs. 10, 12).

Every slide force returned here is in N, positive along the guide axis (up), as a function of the
slide height H above BDC (m) and its rate (m/s).
"""
from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np

from press_io.errors import PressDataError
from .press_data import PressData

MPA = 1.0e6


def balance_mass(press: PressData) -> float:
    """The moving mass (kg) the balance pressure is set from, by the press file's ``balance.masses`` reading."""
    if press.balance.masses == "design":
        return press.balance.design_mass
    return sum(body.mass for body in press.bodies.values())


def check_balance_compression(press: PressData, stroke: float) -> None:
    """Refuse a balance whose gas pressure at BDC is more than max_balance_pressure_ratio of run_limits.toml times
    that at TDC (Eq. 13's (1 + A_b H_max / V)^n): a tank of 1e-300 m^3 overflowed the balance force, and the
    message blamed the joint reactions. ``stroke`` (m) is the slide's stroke H_max."""
    from .limits import LIMITS_FILE, run_limits

    b = press.balance
    if b.cylinders == 0:
        return
    bound = run_limits().max_balance_pressure_ratio
    with np.errstate(all="ignore"):  # a tank of 1e-300 m^3: the ratio is inf, refused below
        ratio = float(np.power(1.0 + stroke * np.float64(b.piston_area) / b.tank_volume, b.polytropic_exponent))
    if not ratio <= bound:
        raise PressDataError(press.source, "balance.tank_volume_m3", b.tank_volume,
                             f"compresses the balance gas to {ratio:.3g} times its TDC pressure at BDC (piston_area_m2 = "
                             f"{b.piston_area:g} over a stroke of {stroke:.4g} m): at most {bound:g} (max_balance_pressure_ratio "
                             f"in {LIMITS_FILE}); a balance tank holds many times the cylinders' swept volume, check the unit")


@dataclass(frozen=True)
class BalanceForce:
    """Pneumatic balance force, Eqs. 13 and 17."""

    cylinders: int
    piston_area: float  # m^2
    tank_volume: float  # m^3
    supply_pressure: float  # Pa, P0
    stroke: float  # m, H_max
    pressure_offset_mpa: float
    exponent: float

    @classmethod
    def from_press(cls, press: PressData, stroke: float) -> "BalanceForce":
        """P0 from psi: z*P0*A_b = psi * M * g, the force at TDC where u1 = 0.

        M is the design moving mass (``balance.masses = "design"``: the pressure the controller was set to) or
        the sum of the current body masses (``"actual"``: the balance follows the true masses)."""
        b = press.balance
        p0 = b.psi * balance_mass(press) * press.gravity / (b.cylinders * b.piston_area) if b.cylinders else 0.0
        return cls(b.cylinders, b.piston_area, b.tank_volume, p0, stroke, b.pressure_offset_mpa, b.polytropic_exponent)

    def __call__(self, height, height_dot=None):
        """Balance force (N, up) at slide height(s) H (m)."""
        if self.cylinders == 0:
            return np.zeros_like(np.asarray(height, dtype=float))
        p0_mpa = self.supply_pressure / MPA
        inv_u2 = (self.stroke - np.asarray(height, dtype=float)) * self.piston_area / self.tank_volume
        u1 = (p0_mpa + self.pressure_offset_mpa) * ((1.0 + inv_u2) ** self.exponent - 1.0) / p0_mpa
        return self.cylinders * self.supply_pressure * self.piston_area * (1.0 + u1)


@dataclass(frozen=True)
class ProcessForce:
    """Stamping process force, Eq. 14: F(H) while 0 <= H <= H_p and the slide moves down (or stands)."""

    contact_height: float  # m, H_p
    heights: tuple  # m, table of F(H), any order
    forces: tuple  # N, acting up on the slide
    source: str = "<process force>"  # the job file it comes from, for messages

    @cached_property
    def _table(self):
        order = np.argsort(self.heights)
        return np.asarray(self.heights, float)[order], np.asarray(self.forces, float)[order]

    def __call__(self, height, height_dot):
        """Process force (N, up) at slide height(s) H (m) and rate(s) (m/s): an array, or a float for two floats."""
        if type(height) is float and type(height_dot) is float:  # one state (the forward dynamics): no 0-d array steps
            active = 0.0 <= height <= self.contact_height and height_dot <= 0.0
            return float(np.interp(height, *self._table)) if active else 0.0
        h = np.asarray(height, dtype=float)
        f = np.interp(h, *self._table)
        active = (h <= self.contact_height) & (h >= 0.0) & (np.asarray(height_dot) <= 0.0)
        return np.where(active, f, 0.0)


NO_PROCESS = ProcessForce(0.0, (0.0, 1.0), (0.0, 0.0))


def revolute_friction(mu_r, c_r, radii, normal, rel_speed):
    """Friction torque at each revolute joint (N m), Eq. 10: -(mu_r r |N| + c_r |w|) sgn(w)."""
    return -(mu_r * radii * normal + c_r * np.abs(rel_speed)) * np.sign(rel_speed)


def guide_friction(mu_s, c_s, normal, speed):
    """Friction force of the guide on the slide (N, along the axis), Eq. 12."""
    return -(mu_s * normal + c_s * np.abs(speed)) * np.sign(speed)
