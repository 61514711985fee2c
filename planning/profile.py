"""A plan sampled in time for a press controller: the rows of profile.csv and of cam_table.csv.

The crank angle, speed and acceleration at any time are exact: the profile's own ``sample`` (toppra's
constant acceleration per segment, or the jerk-limited moving average of :mod:`planning.jerk`). The slide height comes
from a cubic Hermite interpolation of the knots' H and dH/dtheta (the slide velocity is its derivative times
the crank speed). The motor torque between knots is the model's at the sample's own speed and acceleration:
the inertial terms exactly, gravity, balance, process force and friction interpolated in crank angle
between their full-model values at the segment's ends (see ``Evaluation.torque_between``).
Samples are every ``sample_time`` s from the start, plus the exact end of the stroke and of the cycle; the
dwell (stop-at-top) holds the crank at TDC with the static holding torque, a stop on the way (:mod:`planning.hold`)
at its angle with its static torque, the process force held.
"""
from __future__ import annotations

import math

import numpy as np
from scipy.interpolate import CubicHermiteSpline

from .evaluation import Evaluation
from .hold import static_stop_torque, stop_clock
from .planner import Plan

CAM_COLUMNS = ("time_s", "motor_position_deg", "motor_speed_rpm", "motor_accel_rad_s2", "feedforward_torque_Nm")
COLUMNS = ("time_s", "crank_angle_deg", "crank_speed_rad_s", "crank_accel_rad_s2", "slide_height_m",
           "slide_velocity_m_s", "motor_torque_Nm", "motor_speed_rpm")


def _times(t_end: float, dt: float) -> np.ndarray:
    """0, dt, 2 dt, ... below t_end, then t_end itself (s)."""
    n = math.floor(t_end / dt * (1.0 - 1e-12))
    t = np.arange(n + 1) * dt
    return np.append(t[t < t_end - 1e-9 * dt], t_end)


def reference(plan: Plan, t, ev: Evaluation | None = None, hold_torque: float | None = None) -> dict[str, np.ndarray]:
    """Crank angle (rad, unwrapped from TDC), speed, acceleration and motor torque of the plan at times ``t`` (s).

    The torque (N m per motor) is :meth:`Evaluation.torque_between` of ``ev``, the plan's knot profile through
    a model's full inverse dynamics (default: the plan's own; another model's gives that model's
    feed-forward). After the stroke the crank rests at TDC with the holding torque ``hold_torque`` (N m per
    motor; default the plan's own), the dwell.
    """
    if hasattr(plan, "cycle_reference"):  # a pendulum cycle (planning.pendulum) samples its swings and dwells itself
        return plan.cycle_reference(t)
    prof, pd = plan.profile, plan.pd
    ev = plan.evaluation if ev is None else ev
    t = np.atleast_1d(np.asarray(t, float))
    tm, which, held = (stop_clock(t, np.concatenate([[0.0], np.cumsum(prof.dt)]), plan.stops) if plan.stops
                       else (t, None, np.zeros(t.shape, bool)))
    smp = prof.sample(tm, pd.theta)
    th = smp["theta"]
    sd = np.where(held, 0.0, smp["theta_dot"])
    acc = np.where(held, 0.0, smp["theta_ddot"])
    torque = ev.torque_between(pd.theta, th, sd, acc)
    if held.any():  # at a stop the crank rests with the process force held: the static torque of ev's model
        torque = np.where(held, np.array([stop_torque(ev, plan, s) for s in plan.stops])[which], torque)
    if plan.spec.mode == "stop-at-top":
        torque = np.where(t > plan.stroke_time, plan.hold_torque if hold_torque is None else hold_torque, torque)
    return {"theta": th, "theta_dot": sd, "theta_ddot": acc, "motor_torque": torque}


def stop_torque(ev: Evaluation, plan: Plan, stop) -> float:
    """The motor torque (N m per motor) holding ``stop`` on the model ``ev`` was evaluated on (the plan's own: the
    plan's value; another model's, as compare cross-evaluates: that model's static torque there)."""
    if ev is plan.evaluation or ev.pd is None:
        return stop.torque
    cache = ev.__dict__.setdefault("_stop_torques", {})
    if stop.index not in cache:
        cache[stop.index] = static_stop_torque(ev.pd, ev.drive, ev.friction, stop.index)[0]
    return cache[stop.index]


def sample_plan(plan: Plan, gear_ratio: float) -> dict[str, np.ndarray]:
    """The columns of profile.csv (see :data:`COLUMNS`), SI units except degrees and rpm as named."""
    pd = plan.pd
    t = _cycle_times(plan, plan.spec.sample_time)
    ref = reference(plan, t)
    th, sd = ref["theta"], ref["theta_dot"]
    spline = CubicHermiteSpline(pd.theta, pd.height, pd.dh)
    return {
        "time_s": t,
        "crank_angle_deg": np.degrees(th),
        "crank_speed_rad_s": sd,
        "crank_accel_rad_s2": ref["theta_ddot"] + 0.0,  # no "-0" in the CSV
        "slide_height_m": spline(th),
        "slide_velocity_m_s": spline(th, 1) * sd,
        "motor_torque_Nm": ref["motor_torque"],
        "motor_speed_rpm": sd * gear_ratio * 60.0 / (2.0 * math.pi),
    }


def _cycle_times(plan: Plan, period: float) -> np.ndarray:
    """Sample times (s) of a whole cycle every ``period`` s, the stroke's and the cycle's exact ends included."""
    T = plan.stroke_time  # the stops on the way included
    t = _times(T, period)
    if plan.dwell > 0:
        t = np.concatenate([t, T + _times(plan.dwell, period)[1:]])
    return t


def rate_text(strokes_per_min: float) -> str:
    """A plan's production rate as every output names it (`plan`, `compare`, the cam files' headers, the figures'
    titles): "13.109 spm", three decimals, so that one plan reads as one rate wherever it is printed."""
    return f"{strokes_per_min:.3f} spm"


def controller_cycle(plan: Plan, period: float) -> tuple[int, float]:
    """(N, slow) of cam_table.csv: the N controller periods its cycle takes (the plan's cycle time rounded up to a whole
    number of periods), and the factor the plan's time runs slower by in it (1: the cycle ends at rest, the rest takes
    the rest of the last period; else N x period / cycle time, a few 1e-4 at most).

    A controller steps its cam table one row per period: a cycle that is not a whole number of periods would make the
    last step short, which a drive differencing the positions turns into a speed dip and a huge acceleration where the
    crank moves through the wrap (continuous mode: 10.8 T_max on the door panel at 2 ms)."""
    T = plan.cycle_time
    n = max(1, math.ceil(T / period * (1.0 - 1e-12)))
    end = reference(plan, np.array([T]))
    if end["theta_dot"][0] == 0.0 and end["theta_ddot"][0] == 0.0:
        return n, 1.0
    return n, n * period / T


def cam_table(plan: Plan, gear_ratio: float) -> dict[str, np.ndarray]:
    """The columns of cam_table.csv (see :data:`CAM_COLUMNS`): the plan on the motor side at the controller period.

    Motor position = gear ratio x crank angle travelled since the start of the stroke (deg, unwrapped, from 0),
    speed in rpm and acceleration in rad/s^2 at the motor shaft; feed-forward torque per motor (N m), the
    plan's full-model torque (Eq. 16). Rows exactly every ``controller_period_s`` over a cycle of a whole number of
    periods (:func:`controller_cycle`), dwell included, the last row the next cycle's first.
    """
    period = plan.spec.controller_period
    n, slow = controller_cycle(plan, period)
    t = np.arange(n + 1) * period
    ref = reference(plan, np.minimum(t / slow, plan.cycle_time))
    sd, acc, torque = ref["theta_dot"] / slow, ref["theta_ddot"] / (slow * slow), ref["motor_torque"]
    if slow != 1.0:  # the feed-forward of the slower motion; at a stop the static torque stands
        moving = (ref["theta_dot"] != 0.0) | (ref["theta_ddot"] != 0.0)
        torque = np.where(moving, _motion_torque(plan, ref["theta"], sd, acc), torque)
    return {
        "time_s": t,
        "motor_position_deg": np.degrees(ref["theta"] - plan.pd.theta[0]) * gear_ratio,
        "motor_speed_rpm": sd * gear_ratio * 60.0 / (2.0 * math.pi),
        "motor_accel_rad_s2": acc * gear_ratio + 0.0,
        "feedforward_torque_Nm": torque,
    }


def _motion_torque(plan: Plan, theta, theta_dot, theta_ddot) -> np.ndarray:
    """Motor torque per motor (N m, the plan's model) of the crank motion ``theta`` (rad), speed, acceleration."""
    if hasattr(plan, "motion_torque"):  # a pendulum turns back on its return
        return plan.motion_torque(theta, theta_dot, theta_ddot)
    return plan.evaluation.torque_between(plan.pd.theta, theta, theta_dot, theta_ddot)
