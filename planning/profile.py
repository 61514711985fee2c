"""A plan sampled in time for a press controller: the rows of profile.csv.

Between knots the toppra profile has constant crank acceleration u_i, so crank angle, speed and
acceleration at any time are exact (theta = theta_i + sd_i tau + u_i tau^2 / 2). The slide height comes
from a cubic Hermite interpolation of the knots' H and dH/dtheta (the slide velocity is its derivative times
the crank speed), and the motor torque is linear in the crank angle between its full-model values at the
two ends of the segment (the values the planner re-checked), so no sample exceeds the re-checked peak.
Samples are every ``sample_time`` s from the start, plus the exact end of the stroke and of the cycle; the
dwell (stop-at-top) holds the crank at TDC with the static holding torque.
"""
from __future__ import annotations

import math

import numpy as np
from scipy.interpolate import CubicHermiteSpline

from .planner import Plan

COLUMNS = ("time_s", "crank_angle_deg", "crank_speed_rad_s", "crank_accel_rad_s2", "slide_height_m",
           "slide_velocity_m_s", "motor_torque_Nm", "motor_speed_rpm")


def _times(t_end: float, dt: float) -> np.ndarray:
    """0, dt, 2 dt, ... below t_end, then t_end itself (s)."""
    n = math.floor(t_end / dt * (1.0 - 1e-12))
    t = np.arange(n + 1) * dt
    return np.append(t[t < t_end - 1e-9 * dt], t_end)


def reference(plan: Plan, t, torque_right=None, torque_left=None, hold_torque: float | None = None) -> dict[str, np.ndarray]:
    """Crank angle (rad, unwrapped from TDC), speed, acceleration and motor torque of the plan at times ``t`` (s).

    ``torque_right/left`` (N m per knot, the two ends of each segment) default to the plan's own full-model
    motor torque; another model's values give that model's feed-forward. After the stroke the crank rests
    at TDC with the holding torque ``hold_torque`` (N m per motor; default the plan's own), the dwell.
    """
    prof, pd = plan.profile, plan.pd
    tr = plan.evaluation.motor_right if torque_right is None else np.asarray(torque_right, float)
    tl = plan.evaluation.motor_left if torque_left is None else np.asarray(torque_left, float)
    theta = pd.theta
    t = np.atleast_1d(np.asarray(t, float))
    t_knots = np.concatenate([[0.0], np.cumsum(prof.dt)])
    T = t_knots[-1]
    seg = np.clip(np.searchsorted(t_knots, t, side="right") - 1, 0, len(prof.u) - 1)
    tau = np.minimum(t, T) - t_knots[seg]
    u = prof.u[seg]
    sd = np.maximum(prof.sd[seg] + u * tau, 0.0)
    th = np.minimum(theta[seg] + prof.sd[seg] * tau + 0.5 * u * tau * tau, theta[seg + 1])  # round-off at the segment end
    end = t >= T
    th[end], sd[end] = theta[-1], prof.sd[-1]
    frac = (th - theta[seg]) / (theta[seg + 1] - theta[seg])
    torque = (1.0 - frac) * tr[seg] + frac * tl[seg + 1]
    after = t > T
    if plan.spec.mode == "stop-at-top":
        u = np.where(after, 0.0, u)
        torque = np.where(after, plan.hold_torque if hold_torque is None else hold_torque, torque)
    return {"theta": th, "theta_dot": sd, "theta_ddot": u, "motor_torque": torque}


def sample_plan(plan: Plan, gear_ratio: float) -> dict[str, np.ndarray]:
    """The columns of profile.csv (see :data:`COLUMNS`), SI units except degrees and rpm as named."""
    pd = plan.pd
    T = plan.stroke_time
    t = _times(T, plan.spec.sample_time)
    if plan.dwell > 0:
        t = np.concatenate([t, T + _times(plan.dwell, plan.spec.sample_time)[1:]])
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
