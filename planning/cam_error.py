"""How far a controller that runs the master cam by interpolation is from the plan: crank position and torque.

An importer that takes the master cam's positions alone (a point table, e.g. the ISG one-column form with Functiontype
1; not what the cam files declare: they carry quintic segments, :mod:`planning.cam_playback`) joins the cam's points by
straight lines in master position. Between two points the crank then runs at the chord's speed, and at
each point the speed steps to the next chord's. The figures below state what that costs against the plan, at the
controller period (the job's ``controller_period_s``, the rows of cam_table.csv), over the whole cycle:

* the **crank position error**: the largest |linear interpolation - plan| (crank deg);
* the **torque the linear cam implies**: the motor torque (the plan's full model, Eq. 16, friction carried along:
  :meth:`planning.evaluation.Evaluation.torque_between`) of the motion at the linear cam's crank position whose speed
  runs linearly from one chord's speed to the next between the chords' midpoints (the speed change spread over one
  master step, the gentlest way to follow the chords). A controller that changes speed faster at the points (within
  a controller period: the set-points' own differences) needs more, so this is a lower bound. The largest speed step
  at a point (motor rpm) is stated beside it;
* the same torque for an importer that takes the velocity column too (cubic Hermite segments, their own speed and
  acceleration), for comparison.

A master step above ``max_cam_master_step_deg`` (run_limits.toml) is refused before planning (:class:`planning.cams.CamSettings`);
after it, a linear cam that implies more than T_max (no reserve left at all) is refused with the largest step that
passes. A warning names a linear cam whose crank leaves the playback's ``tracking_tolerance_deg`` (the plan's own
verification criterion, [playback]) or whose implied torque spends part of the torque margin (above the plan's limit,
``torque_margin`` x T_max).
In the dwell of a stop-at-top cycle (the cam standing at TDC) the torque is the plan's holding torque.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.interpolate import CubicHermiteSpline

from press_io.errors import PressDataError

from .cams import CamSettings, master_cam, master_points
from .planner import Plan
from .profile import _cycle_times, reference

NICE_STEPS_DEG = (45.0, 40.0, 36.0, 30.0, 24.0, 20.0, 18.0, 15.0, 12.0, 10.0, 9.0, 8.0, 6.0, 5.0, 4.0, 3.0, 2.5, 2.0, 1.5, 1.25,
                  1.0, 0.75, 0.5, 0.25, 0.2, 0.125, 0.1)  # master steps a refusal suggests (they divide 360 deg)


@dataclass(frozen=True)
class CamError:
    """The master cam against its plan (module docstring); SI units except as named."""

    master_step_deg: float
    position_error_crank_deg: float  # largest |linear cam - plan|, crank deg
    position_error_at_master_deg: float
    tracking_tolerance_deg: float  # crank deg: the playback's, the bound the position error must keep
    implied_torque_Nm: float  # largest |motor torque| per motor the linear cam implies (a lower bound, module docstring)
    implied_torque_at_master_deg: float
    cubic_torque_Nm: float  # the same with the velocity column (cubic Hermite)
    plan_peak_torque_Nm: float  # the plan's own largest |motor torque| at the same samples
    torque_limit_Nm: float  # torque_margin x T_max
    peak_torque_Nm: float  # T_max
    speed_step_rpm: float  # largest speed step at a cam point, motor rpm

    @property
    def position_ok(self) -> bool:
        return self.position_error_crank_deg <= self.tracking_tolerance_deg

    @property
    def within_margin(self) -> bool:
        return self.implied_torque_Nm <= self.torque_limit_Nm

    @property
    def margin_used(self) -> float:
        """Share of the torque margin (T_max - limit) the linear cam's implied torque spends above the limit (0: none)."""
        return max(0.0, self.implied_torque_Nm - self.torque_limit_Nm) / (self.peak_torque_Nm - self.torque_limit_Nm)

    @property
    def ok(self) -> bool:
        """The implied torque within T_max (what is refused otherwise)."""
        return self.implied_torque_Nm <= self.peak_torque_Nm

    def record(self) -> dict:
        """summary.json's ``cam_master_csv.linear_interpolation``."""
        return {
            "method": "linear: the cam's points joined by straight lines in master position (a positions-only import, e.g. an ISG "
                      "Functiontype 1 point table; the cam files declare quintic segments), sampled at the "
                      "controller period; its torque: the plan's model at the linear cam's crank position with the speed running "
                      "linearly from one chord's speed to the next over one master step (a lower bound); cubic: positions and "
                      "velocity column joined by cubic Hermite segments (planning/cam_error.py)",
            "linear_position_error_crank_deg": self.position_error_crank_deg,
            "linear_position_error_at_master_deg": self.position_error_at_master_deg,
            "tracking_tolerance_deg": self.tracking_tolerance_deg,
            "linear_within_tracking_tolerance": self.position_ok,
            "linear_implied_peak_torque_Nm": self.implied_torque_Nm,
            "linear_implied_peak_torque_at_master_deg": self.implied_torque_at_master_deg,
            "linear_largest_speed_step_at_a_point_motor_rpm": self.speed_step_rpm,
            "linear_within_torque_margin": self.within_margin,
            "linear_share_of_torque_margin_spent": self.margin_used,
            "cubic_implied_peak_torque_Nm": self.cubic_torque_Nm,
            "plan_peak_torque_Nm": self.plan_peak_torque_Nm,
            "torque_limit_Nm": self.torque_limit_Nm,
        }

    def lines(self) -> tuple[str, ...]:
        """The ISG file's header comments stating the cam's interpolation error."""
        return (f"linear interpolation between the points (master step {self.master_step_deg:g} deg): crank within "
                f"{self.position_error_crank_deg:.4f} deg of the plan (largest at master {self.position_error_at_master_deg:.1f} deg; "
                f"tracking tolerance {self.tracking_tolerance_deg:g} deg)",
                f"motor torque it implies (chord speeds, changed over one master step; a lower bound): up to "
                f"{self.implied_torque_Nm:,.0f} N m at master {self.implied_torque_at_master_deg:.1f} deg; plan {self.plan_peak_torque_Nm:,.0f} "
                f"N m, limit {self.torque_limit_Nm:,.0f} N m ({100 * self.margin_used:.0f} % of the margin to T_max spent); speed steps "
                f"at the points up to {self.speed_step_rpm:.1f} motor rpm; cubic with cam_master.csv's velocity column: "
                f"{self.cubic_torque_Nm:,.0f} N m")



def cam_error(plan: Plan, gear_ratio: float, peak_torque: float, step_deg: float) -> CamError:
    """The :class:`CamError` of the plan's master cam at ``step_deg`` (deg); ``peak_torque``: the motor's T_max (N m)."""
    cam = master_cam(plan, gear_ratio, step_deg)
    master = cam["master_deg"]
    points = np.radians(cam["motor_position_deg"]) / gear_ratio + plan.pd.theta[0]  # crank rad
    t = _cycle_times(plan, plan.spec.controller_period)
    m = t / plan.cycle_time * 360.0
    ref = reference(plan, t)
    theta = np.interp(m, master, points)
    pos_err = np.abs(theta - ref["theta"])
    i_pos = int(np.argmax(pos_err))

    h = step_deg / 360.0 * plan.cycle_time  # s per master step
    chord = np.diff(points) / h  # crank rad/s on each segment
    mids = 0.5 * (master[:-1] + master[1:])
    speed = np.interp(m, mids, chord)  # the first and last chord's speed outside the midpoints
    between = np.clip(np.searchsorted(mids, m, side="right") - 1, 0, len(chord) - 2)  # the midpoints m lies between
    accel = np.where((m > mids[0]) & (m < mids[-1]), np.diff(chord)[between] / h, 0.0)  # the slope of ``speed``
    linear = _torque(plan, t, theta, speed, accel)
    i_tq = int(np.argmax(np.abs(linear)))

    w = 360.0 / plan.cycle_time  # master deg/s
    spline = CubicHermiteSpline(master, points, np.radians(cam["motor_velocity_deg_per_master_deg"]) / gear_ratio)
    cubic = _torque(plan, t, spline(m), spline(m, 1) * w, spline(m, 2) * w * w)
    steps = np.abs(np.diff(np.concatenate(([0.0], chord, [0.0]))))  # from and to rest at the cycle's ends
    return CamError(
        master_step_deg=step_deg,
        position_error_crank_deg=math.degrees(float(pos_err[i_pos])),
        position_error_at_master_deg=float(m[i_pos]),
        tracking_tolerance_deg=plan.spec.tracking_tolerance_deg,
        implied_torque_Nm=float(abs(linear[i_tq])),
        implied_torque_at_master_deg=float(m[i_tq]),
        cubic_torque_Nm=float(np.max(np.abs(cubic))),
        plan_peak_torque_Nm=float(np.max(np.abs(ref["motor_torque"]))),
        torque_limit_Nm=plan.spec.torque_limits(peak_torque).verdict,
        peak_torque_Nm=peak_torque,
        speed_step_rpm=float(np.max(steps)) * gear_ratio * 60.0 / (2.0 * math.pi),
    )


def _torque(plan: Plan, t: np.ndarray, theta: np.ndarray, speed: np.ndarray, accel: np.ndarray) -> np.ndarray:
    """Motor torque per motor (N m) of the plan's model along a crank motion (rad, rad/s, rad/s^2) at times ``t``;
    standing in a stop-at-top dwell, the plan's holding torque."""
    moving = (np.abs(speed) > 0.0) | (accel != 0.0)
    if plan.spec.mode == "stop-at-top":
        moving &= t <= plan.stroke_time + 1e-12 * plan.cycle_time
    torque = np.full(t.shape, plan.hold_torque)
    th = np.clip(theta, plan.pd.theta[0], plan.pd.theta[-1])
    torque[moving] = plan.evaluation.torque_between(plan.pd.theta, th[moving], np.maximum(speed[moving], 0.0), accel[moving])
    stopped = ~moving & (t < plan.stroke_time)
    if plan.stops and stopped.any():  # standing at a stop on the way (planning.hold): its holding torque, as the plan's
        torque[stopped] = reference(plan, t[stopped])["motor_torque"]
    return torque


def checked_cam_error(plan: Plan, gear_ratio: float, peak_torque: float, cfg: CamSettings, source: str) -> CamError:
    """:func:`cam_error` at the job's master step; refused (:class:`PressDataError` naming ``planning.cam.master_step_deg``
    and the largest step that passes) when following the linear cam's chords takes more than T_max."""
    err = cam_error(plan, gear_ratio, peak_torque, cfg.master_step_deg)
    if err.ok:
        return err
    fix = "no master step within isg_max_lines passes: raise isg_max_lines, or run cam_master.csv with its velocity column (cubic)"
    for step in NICE_STEPS_DEG:
        if step < cfg.master_step_deg and master_points(step) <= cfg.isg_max_lines and cam_error(plan, gear_ratio, peak_torque, step).ok:
            fix = f"use master_step_deg = {step:g} or a finer step that divides 360 deg"
            break
    raise PressDataError(source, "planning.cam.master_step_deg", cfg.master_step_deg,
                         f"following its linear interpolation's chords takes at least {err.implied_torque_Nm:,.0f} N m per motor, above "
                         f"T_max = {peak_torque:,.0f} N m: {fix}")
