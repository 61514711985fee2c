"""The [planning.power] table of a job file: the supply limit a plan is checked against (the jerk-limited stage plans
under it where the press file has [drive.electrical]), and the grid-power row of a motor torque and speed.

Frozen settings, each field with its default, unit and reason (:func:`press_model.settings_fields.setting`), read
like the other sections (:func:`press_model.settings_fields.read_section`).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

from press_model.electrical import Electrical
from press_io.errors import PressDataError
from press_model.jobs import Job
from press_model.readers import FieldReader
from press_model.settings_fields import read_section, setting

SECTION = ("planning", "power")


@dataclass(frozen=True)
class PowerLimit:
    """[planning.power]: ``grid_peak_limit_W``, the most the plan may draw from the grid at any instant (W; inf: none), and
    the front of ``plan --pareto`` (:mod:`planning.pareto`)."""

    grid_peak_limit_W: float = setting(
        math.inf, "W drawn from the grid, the largest instant",
        "no limit by default: the press file's supply ([drive.electrical.supply] motoring_limit_W) alone bounds the draw",
        unit="W drawn from the grid, the largest instant", gt=0.0)
    grid_feedback_reserve: float = setting(
        0.005, "of grid_peak_limit_W",
        "the plan's feed-forward draws at most (1 - this) x the limit, the rest is the feedback's (the door-panel playback's "
        "PD adds ~0.05 % at the grid peak), as peak_torque_margin keeps feedback_reserve free",
        unit="of grid_peak_limit_W", ge=0.0, lt=0.5)
    pareto_points: int = setting(8, "plans", "eight limits draw the front's shape (plan --pareto); each is one jerk-limited plan", ge=2)
    pareto_lowest_fraction: float = setting(
        0.6, "of the unconstrained plan's grid peak",
        "the front down to 60 % of the free plan's peak; much lower, the forming phase's own draw (process force x "
        "forming speed) leaves no stroke",
        unit="of the unconstrained plan's grid peak", gt=0.0, lt=1.0)

    target_strokes_per_min: float = setting(
        0.0, "strokes per minute",
        "0: off, the plan is the time-optimal stroke; a rate at or below its rate plans the stroke that draws the least grid "
        "energy per cycle at that rate, under the same limits (planning/power_energy.py)",
        unit="strokes per minute", ge=0.0)

    @property
    def min_energy(self) -> bool:
        """Whether the job asks for the minimum-energy plan at ``target_strokes_per_min``."""
        return self.target_strokes_per_min > 0.0

    @property
    def limited(self) -> bool:
        return math.isfinite(self.grid_peak_limit_W)

    @property
    def feedforward_limit_W(self) -> float:
        """The most the plan's feed-forward may draw (W): the limit less the feedback's share."""
        return self.grid_peak_limit_W * (1.0 - self.grid_feedback_reserve)


def read_power(job: Job, electrical: Electrical | None) -> PowerLimit:
    """The job's [planning.power] (defaults where absent); a grid limit on a press without [drive.electrical] is refused
    (nothing would compute the grid power it limits)."""
    rd = FieldReader(job.source, {"planning": {"power": job.raw.get("planning", {}).get("power", {})}})
    limit = read_section(rd, SECTION, PowerLimit)
    rd.reject_unread("see press_model/README.md, [planning.power]")
    if limit.min_energy and electrical is None:
        raise PressDataError(job.source, "planning.power.target_strokes_per_min", limit.target_strokes_per_min,
                             "needs a press file with [drive.electrical] (the grid energy it minimises); add that section to the "
                             "press file (see press_model/data/reference_press.toml) or remove the target")
    if limit.limited and electrical is None:
        raise PressDataError(job.source, "planning.power.grid_peak_limit_W", limit.grid_peak_limit_W,
                             "needs a press file with [drive.electrical] (the grid power it limits); add that section to the "
                             "press file (see press_model/data/reference_press.toml) or remove the limit")
    return limit


def grid_bound_coefficients(el: Electrical, motors: int) -> tuple[float, float, float, float]:
    """(a, b, c, k) with which the grid power of a motoring cycle is k (T w + a T^2 + b |w| + c w^2), per-motor torque
    T (N m) and motor speed w (rad/s): the motors' terminal power over the inverter's and the infeed's efficiency
    (:mod:`press_model.power_flow`), exact while the drives draw and the DC link stays at its nominal voltage. Where
    that sum is negative the drives regenerate and the grid power is negative too, so ``k (...) <= limit`` is the
    grid limit at every instant (storage, which can only lower the draw, left out)."""
    m = el.motor
    a = 3.0 * m.winding_resistance_ohm / m.torque_constant_Nm_per_A**2
    b = m.iron_loss_at_max_speed_W * m.iron_loss_hysteresis_share / el.max_speed
    c = m.iron_loss_at_max_speed_W * (1.0 - m.iron_loss_hysteresis_share) / el.max_speed**2
    k_inv, k_infeed = el.inverter.efficiency, el.supply.efficiency  # the converters' (not the gear's of Eq. 16)
    k = motors / (k_inv * k_infeed)
    return a, b, c, k
