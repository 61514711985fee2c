"""The [planning.power] table of a job file: the supply limit a plan is checked against (the jerk-limited stage plans
under it where the press file has [drive.electrical]), and the grid-power row of a motor torque and speed.

Frozen settings, each field with its default, unit and reason (:func:`press_model.settings_fields.setting`), read
like the other sections (:func:`press_model.settings_fields.read_section`).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from press_io.errors import PlanningError, PressDataError
from press_model.electrical import Electrical
from press_model.jobs import Job
from press_model.limits import LIMITS_FILE, run_limits
from press_model.readers import FieldReader
from press_model.settings_fields import read_section, setting

from .toppra_solve import toppra
from .evaluation import Member, evaluate_members
from .limits import Limits, ToppraPoint
from .toppra_solve import solve_toppra

SECTION = ("planning", "power")


@dataclass(frozen=True)
class PowerLimit:
    """[planning.power]: ``grid_peak_limit_W``, the most the plan may draw from the grid at any instant (W; inf: none), and
    the front of ``plan --pareto`` (:mod:`planning.energy`)."""

    grid_peak_limit_W: float = setting(
        math.inf, "W drawn from the grid, the largest instant",
        "no limit by default: the press file's supply ([drive.electrical.supply] motoring_limit_W) alone bounds the draw; at "
        "most 1 GW, 180 x the reference press's 5.5 MW supply and beyond any press line's feed (1e308 W limits nothing and was "
        "printed as a 309-digit number)",
        unit="W drawn from the grid, the largest instant", gt=0.0, le=1.0e9)
    grid_feedback_reserve: float = setting(
        0.005, "of grid_peak_limit_W",
        "the plan's feed-forward draws at most (1 - this) x the limit, the rest is the feedback's (the door-panel playback's "
        "PD adds ~0.05 % at the grid peak), as peak_torque_margin keeps feedback_reserve free",
        unit="of grid_peak_limit_W", ge=0.0, lt=0.5)
    pareto_points: int = setting(8, "plans", "eight limits draw the front's shape (plan --pareto); each is one jerk-limited "
                                 "plan (~5-15 s on the door panel, 2 shared cores), so at most 50: a point every 0.8 % of the "
                                 "swept range, finer than the front bends (1,000,000 asked for weeks of plans)", ge=2, le=50)
    pareto_lowest_fraction: float = setting(
        0.6, "of the unconstrained plan's grid peak",
        "the front down to 60 % of the free plan's peak; much lower, the forming phase's own draw (process force x "
        "forming speed) leaves no stroke",
        unit="of the unconstrained plan's grid peak", gt=0.0, lt=1.0)

    target_strokes_per_min: float = setting(
        0.0, "strokes per minute",
        "0: off, the plan is the time-optimal stroke; a rate at or below its rate plans the stroke that draws the least grid "
        "energy per cycle at that rate, under the same limits (planning/energy.py); else at least 60 / max_dwell_s "
        "(run_limits.toml: an hour's dwell per stroke, 1/60 spm), since the profile samples the whole cycle (1e-6 spm asked "
        "for 224 GiB), and at most max_strokes_per_min",
        unit="strokes per minute", ge=0.0, limit="max_strokes_per_min", what="any press's rate")

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
    slowest = 60.0 / run_limits().max_dwell_s  # strokes per minute: a cycle of at most an hour's dwell
    if 0.0 < limit.target_strokes_per_min < slowest:
        raise PressDataError(job.source, "planning.power.target_strokes_per_min", limit.target_strokes_per_min,
                             f"must be 0 (off) or at least {slowest:.4g} strokes per minute: a slower cycle dwells more than "
                             f"max_dwell_s = {run_limits().max_dwell_s:g} s per stroke ({LIMITS_FILE}); check the unit (strokes per minute)")
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


# ----------------------------------------------------------------------------------------------------------------------
# toppra under the grid limit: a second formulation
#
# A second formulation of the fastest stroke under a grid peak-power limit ([planning.power] grid_peak_limit_W): toppra
# with the grid power as a constraint object of its own, to check the jerk-limited stage's grid rows against
# (:mod:`planning.energy`, :class:`planning.limits.GridRow`).
#
# What differs from the stage: toppra's discretisation (the acceleration constant over each segment of crank angle, the
# limits held at both ends of every segment and nowhere between; no jerk limit, so it is the jerk-free optimum), Eq. 16
# as its two linear rows (not the smooth form), and the grid limit as an exact bound on the motor torque at a given
# speed: the grid power k (T w + a T^2 + b w + c w^2) (:func:`planning.power.grid_bound_coefficients`) grows with T for
# T > -w / (2 a), so it keeps the limit exactly while T <= T_hi(w), the larger root. In x = theta_dot^2, T_hi is convex
# (about limit / (k w) - b - c w, w = u sqrt(x)), so its tangent at the previous profile's x lies below it: the rows
# T <= tangent are linear in (u, x) as toppra needs, never let through a power above the limit, and are exact at the
# point of tangency. The tangent points and the friction are re-taken from each solution until both settle (the
# planner's friction fixed point, with the tangent point as one more held quantity). What it shares with the stage: the
# path dynamics, toppra's other limits (:meth:`planning.limits.Limits.toppra`) and the grid power's
# coefficients.


DiscretizationType, LinearConstraint = toppra.constraint.DiscretizationType, toppra.constraint.LinearConstraint

MAX_ROUNDS = 60  # toppra solves at most (friction and tangent points re-taken each time; 10-20 settle the door panel)
MIN_SPEED = 1.0e-3  # rad/s at the motor: tangent points are taken at least this fast (T_hi's slope is infinite at rest)


def torque_bound(el: Electrical, motors: int, limit: float, w) -> np.ndarray:
    """The largest per-motor torque (N m) at motor speed ``w`` (rad/s, >= 0) whose grid power is within ``limit`` (W):
    the larger root of k (T w + a T^2 + b w + c w^2) = limit."""
    a, b, c, k = grid_bound_coefficients(el, motors)
    w = np.asarray(w, float)
    disc = w * w - 4.0 * a * (b * w + c * w * w - limit / k)
    return (-w + np.sqrt(np.maximum(disc, 0.0))) / (2.0 * a)


def torque_bound_slope(el: Electrical, motors: int, limit: float, w) -> np.ndarray:
    """dT_hi/dw (N m per rad/s) of :func:`torque_bound`, by the implicit function theorem: -(dP/dw) / (dP/dT)."""
    a, b, c, _ = grid_bound_coefficients(el, motors)
    w = np.asarray(w, float)
    t = torque_bound(el, motors, limit, w)
    return -(t + b + 2.0 * c * w) / (w + 2.0 * a * t)


class GridPowerLimit(LinearConstraint):
    """The grid power <= ``limit`` (W) at both ends of every segment, as two rows per end (Eq. 16's motoring and braking
    rows of the motor torque, ``torque`` a :class:`planning.toppra_solve.MotorTorqueLimit` on the same knots, each <= the
    tangent of T_hi at the crank speed ``speed`` (rad/s per knot))."""

    name = "grid_power"

    def __init__(self, torque, el: Electrical, motors: int, gear_ratio: float, limit: float, speed):
        super().__init__()
        self.discretization_type = DiscretizationType.Interpolation
        self.identical = True
        self.torque = torque
        x0 = np.maximum(np.asarray(speed, float), MIN_SPEED / gear_ratio) ** 2  # tangent points, (rad/s)^2
        w0 = gear_ratio * np.sqrt(x0)
        t0 = torque_bound(el, motors, limit, w0)
        slope = torque_bound_slope(el, motors, limit, w0) * gear_ratio**2 / (2.0 * w0)  # dT_hi/dx
        # T <= t0 + slope (x - x0)  <=>  T - slope x <= t0 - slope x0
        self.slope, self.offset = slope, t0 - slope * x0

    def compute_constraint_params(self, path, gridpoints, *args, **kwargs):
        a, b, c, *_ = self.torque.compute_constraint_params(path, gridpoints)
        # the torque object's columns: (+T, -T) at knot i, then (+T, -T) at knot i+1 (x_{i+1} = x_i + 2 Delta_i u_i).
        # Both +T (the motoring row) and -(-T) (the braking row, T = B eta / (n u)) must keep T <= the tangent
        deltas = np.diff(np.asarray(gridpoints, float))
        s0, o0 = self.slope, self.offset
        s1, o1 = np.append(s0[1:], s0[-1]), np.append(o0[1:], o0[-1])
        d = np.append(deltas, 0.0)
        ga = np.stack([a[:, 0], -a[:, 1], a[:, 2] - 2.0 * d * s1, -a[:, 3] - 2.0 * d * s1], axis=1)
        gb = np.stack([b[:, 0] - s0, -b[:, 1] - s0, b[:, 2] - s1, -b[:, 3] - s1], axis=1)
        gc = np.stack([c[:, 0] - o0, -c[:, 1] - o0, c[:, 2] - o1, -c[:, 3] - o1], axis=1)
        return ga, gb, gc, np.eye(4), np.zeros(4), None, None


def toppra_under_grid_limit(pm, grid, pd, spec, level: float, limit: float, still):
    """toppra's jerk-free time optimum of the stroke under torque ``level`` (N m per motor), every other toppra limit and
    the grid peak ``limit`` (W), with its friction and tangent points settled; returns the knot profile (``stroke_time`` s).
    Raises :class:`PlanningError` if they have not settled in :data:`MAX_ROUNDS` solves."""
    press = pm.press
    el, drive = press.electrical, press.drive
    members = [Member(pd, drive, press.friction)]
    frics = [(np.zeros(pd.n), np.zeros(pd.n))]
    speed = np.full(pd.n, press.motor.max_speed / drive.gear_ratio)
    t_prev = math.inf
    limits = Limits.declare(pm, spec, grid, pd, still)
    for _ in range(MAX_ROUNDS):
        cons = limits.toppra(ToppraPoint(members, level, frics))
        cons.append(GridPowerLimit(cons[0], el, drive.motors, drive.gear_ratio, limit, speed))
        prof = solve_toppra(cons, grid.theta, spec, pd)
        ev = evaluate_members(pm, members, prof)[0]
        change = max(np.max(np.abs(ev.fric_right - frics[0][0])), np.max(np.abs(ev.fric_left - frics[0][1])))
        moved = float(np.max(np.abs(prof.sd - speed)))
        frics, speed = [(ev.fric_right, ev.fric_left)], np.asarray(prof.sd, float)
        if abs(prof.stroke_time - t_prev) < spec.friction_tolerance and change < spec.friction_tolerance_torque and moved < 1e-6:
            return prof
        t_prev = prof.stroke_time
    raise PlanningError(f"{spec.source}: toppra under the grid limit did not settle in {MAX_ROUNDS} solves "
                        f"(stroke time still changing by {abs(prof.stroke_time - t_prev):.3g} s)")
