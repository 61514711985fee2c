"""The plan as a master-position cam, the table a press or motion controller runs against a virtual master axis.

The master axis turns once per cycle at constant speed (360 deg per cycle time: stroke and dwell), so master
position m and time t are one: t = m / 360 x cycle time. :func:`master_cam` samples the plan at equidistant
master positions from 0 to 360 deg (both ends): the motor position (deg at the motor shaft, gear ratio applied,
0 at the start of the stroke, unwrapped: gear ratio x 360 at the end of the cycle), and its first and second
derivatives with respect to the master position (deg per master deg, deg per master deg^2), which importers that
take slave velocity and acceleration use for their polynomial segments. The positions are the plan's exact
profile (its own ``sample``), not an interpolation of the time-based cam table.

:func:`isg_cam_table` writes the same cam for an ISG/Beckhoff controller as polynomial segments: one interpolation
point per line with the slave's position, velocity and acceleration (the fields of Beckhoff's MC_MotionFunctionPoint,
TwinCAT NC camming), each segment to the next point a quintic matching all three at both ends (POLYNOM5_MM, motion
<-> motion), inside the header keywords of the ISG ASCII cam table ("File format of the cam tables (ASCII
interpreter)", ISG kernel / Beckhoff TwinCAT NC/CNC MC platform) with Functiontype 6 (TABLE_DEFINED: the function is
named per line). A point table interpolated linearly (the ISG one-column form, Functiontype 1) does not do: a drive
that differences its set-points at the controller's period commands several T_max at every point, where the slave's
speed steps (planning/README.md, "Cam files"). The slave is the crank (eccentric-shaft) axis in crank degrees, one turn
a cycle (the motor's gear-ratio turns belong in the axis scaling), endless positive: the point at master 360 deg is the
first point with the slave one turn on, not written. Every cam file's header states the interpolation it needs
(:mod:`planning.cams` plays it that way).
"""
from __future__ import annotations

import dataclasses
import math
import re
from dataclasses import dataclass

import numpy as np
from scipy.interpolate import CubicHermiteSpline

from press_io.errors import PlanningError, PressDataError
from press_model.jobs import Job
from press_model.limits import LIMITS_FILE, run_limits
from press_model.readers import FieldReader
from press_model.settings_fields import read_section, read_value, setting

from .planner import Plan
from .profile import _cycle_times, controller_cycle, rate_text, reference

CAM_MASTER_COLUMNS = ("master_deg", "motor_position_deg", "motor_velocity_deg_per_master_deg", "motor_accel_deg_per_master_deg2")
ISG_FUNCTION_TYPE = 6  # TABLE_DEFINED: the function of each segment is given in the table (ISG cam-table function types)
POLYNOM5_MM = 15  # MC_MotionFunctionType MOTIONFUNCTYPE_POLYNOM5_MM: quintic, motion <-> motion (Beckhoff TwinCAT NC camming)
MOTIONPOINTTYPE_MOTION = 8  # MC_MotionPointType 16#0008: a point the slave passes in motion
ISG_COLUMNS = ("PointIndex", "FunctionType", "PointType", "RelIndexNextPoint", "MasterPos", "SlavePos", "SlaveVelo", "SlaveAcc",
               "SlaveJerk")  # MC_MotionFunctionPoint's fields, in its order
HLI_CI_ENDLESS_POSITIVE = 0x20  # MC_CamIn.StartMode bit of the ISG kernel: the slave passes its modulo range forwards, endlessly


CAM_FILE = "cam_master.csv"
ISG_FILE = "cam_master_isg.txt"


@dataclass(frozen=True)
class CamSettings:
    """The ``[planning.cam]`` section of a job file: the master step (deg) and the ISG table's ID and largest size."""

    master_step_deg: float = setting(0.5, "deg", "720 master points a cycle: played as the cam files declare (quintic "
                                     "segments) every 2 ms the door-panel plan's cams reach 0.8913 T_max, within 0.9 (each "
                                     "file's header states it); positions joined linearly stay within 0.009 crank deg (1 deg: "
                                     "0.038; planning/cams.py)",
                                     gt=0.0, unit="deg", limit="min_step_deg", what="the crank step any run needs")
    isg_table_id: int = setting(1, "", "Table-ID of the ISG cam table: set the ID the controller's cam coupling "
                                "(MC_CamIn) uses", ge=1)
    isg_max_lines: int = setting(720, "", "most interpolation points (lines, one per master step) of the ISG table; lower "
                                 "it to the controller's table size (the ISG pages read give 360 for two-column tables)", ge=2)

    @classmethod
    def from_job(cls, job: Job) -> "CamSettings":
        """Read and check ``[planning.cam]`` of a job to plan; absent keys (or an absent table) take their defaults."""
        planning = job.raw.get("planning")
        raw = planning.get("cam") if isinstance(planning, dict) else None
        rd = FieldReader(job.source, {"planning": {"cam": raw}} if raw is not None else {})
        path = ("planning", "cam")
        rd.table(path, required=False)
        step = read_value(rd, (*path, "master_step_deg"), cls.__dataclass_fields__["master_step_deg"])
        bound = run_limits().max_cam_master_step_deg
        if step > bound:
            rd.fail((*path, "master_step_deg"), step, f"must be at most {bound:g} deg (max_cam_master_step_deg in {LIMITS_FILE}): "
                    "a linear cam's chords stray from the plan with the step squared (38 crank deg at 90 deg on the door panel); "
                    "e.g. 0.5")
        try:
            master_points(step)
        except PlanningError:
            rd.fail((*path, "master_step_deg"), step, "must divide 360 deg into equal steps (e.g. 0.25, 0.5, 1)")
        cfg = read_section(rd, path, cls, skip=("master_step_deg",))
        cfg = dataclasses.replace(cfg, master_step_deg=step)
        if master_points(step) > cfg.isg_max_lines:
            rd.fail((*path, "master_step_deg"), step, f"gives {master_points(step)} points a turn, more than isg_max_lines = "
                    f"{cfg.isg_max_lines} of the ISG cam table: raise the step to {360.0 / cfg.isg_max_lines:g} deg or more, or "
                    "isg_max_lines if the controller takes more")
        rd.reject_unread("see [planning.cam] in press_model/README.md")
        return cfg


def master_points(step_deg: float) -> int:
    """How many equal master steps of ``step_deg`` make one turn; raises :class:`PlanningError` unless the step divides 360 deg."""
    n = round(360.0 / step_deg) if step_deg > 0 else 0
    if n < 2 or abs(n * step_deg - 360.0) > 1e-9 * 360.0:
        raise PlanningError(f"master_step_deg = {step_deg!r} is not valid: it must divide 360 deg into at least two equal steps "
                            "(e.g. 0.5, 1, 2); a cam table's master positions are equidistant over one turn")
    return n


def master_speed_deg_s(plan: Plan) -> float:
    """Speed of the virtual master axis for the planned cycle (deg/s): one turn per cycle time."""
    return 360.0 / plan.cycle_time


def master_cam(plan: Plan, gear_ratio: float, step_deg: float) -> dict[str, np.ndarray]:
    """The columns of cam_master.csv (:data:`CAM_MASTER_COLUMNS`): the plan against a master turning once per cycle."""
    n = master_points(step_deg)
    master = np.arange(n + 1) * (360.0 / n)  # exact multiples, 360 itself last
    w = master_speed_deg_s(plan)
    ref = reference(plan, master / 360.0 * plan.cycle_time)
    return {
        "master_deg": master,
        "motor_position_deg": np.degrees(ref["theta"] - plan.pd.theta[0]) * gear_ratio,
        "motor_velocity_deg_per_master_deg": np.degrees(ref["theta_dot"]) * gear_ratio / w,
        "motor_accel_deg_per_master_deg2": np.degrees(ref["theta_ddot"]) * gear_ratio / (w * w) + 0.0,  # no "-0" in the CSV
    }


def isg_table_name(text: str) -> str:
    """A table name the ISG interpreter takes (no blanks): every run of other characters than letters, digits, '-' and '_' as '_'."""
    return re.sub(r"[^A-Za-z0-9_-]+", "_", text).strip("_")[:64] or "servo_press_cam"


def master_axis_line(plan: Plan) -> str:
    """The master cams' line on their master: one turn per cycle, at which speed, and the plan's rate (:func:`rate_text`)."""
    return (f"master: virtual axis, deg, one turn (0-360) per cycle at {master_speed_deg_s(plan):.10g} deg/s = "
            f"{rate_text(plan.strokes_per_min)} (cycle {plan.cycle_time:.6f} s)")


def slave_axis_line(gear_ratio: float, this: str) -> str:
    """The line each master cam states its follower (slave) axis with and how to turn it into the other cam's: ``this``
    is :data:`CAM_FILE` (the motor shaft) or :data:`ISG_FILE` (the crank)."""
    both = (f"{CAM_FILE} follows the MOTOR shaft, {ISG_FILE} the CRANK (eccentric shaft), the same cam: motor deg = crank deg x "
            f"{gear_ratio:g} (the gear ratio), per master deg and per master deg^2 alike")
    axis = "motor shaft deg (gear ratio applied)" if this == CAM_FILE else "crank deg"
    return f"slave: {axis}; {both}"


def cam_master_header(plan: Plan, gear_ratio: float) -> tuple[str, ...]:
    """The comment lines cam_master.csv starts with: the interpolation it needs, its master (with the plan's rate), its
    follower axis against the ISG file's, wrap and phase."""
    return (f"interpolation: {QUINTIC}: between two master points the quintic matching motor position, velocity and acceleration "
            "(per master deg) at both (POLY5, Beckhoff POLYNOM5_MM); the positions interpolated linearly alone do not hold the "
            "torque margin (the speed steps at every point)",
            f"{master_axis_line(plan)}; phase: master 0 = the start of the stroke; wrap: the motor turns on by the last row's "
            "position every cycle (endless positive)",
            slave_axis_line(gear_ratio, CAM_FILE))


def pendulum_master_header(plan: Plan, gear_ratio: float, swing_motor_deg: float) -> tuple[str, ...]:
    """The comment lines cam_master.csv of a PENDULUM plan starts with: the interpolation, its master, and that the slave
    swings (it reverses every cycle and ends where it started: not endless)."""
    return (cam_master_header(plan, gear_ratio)[0],
            f"{master_axis_line(plan)}; phase: master 0 = the start of the working swing, at rest at turning point A",
            f"slave: motor shaft deg (gear ratio {gear_ratio:g} applied: motor deg = crank deg x {gear_ratio:g})",
            f"PENDULUM: the slave swings, it is not endless: the motor turns forward through BDC to {swing_motor_deg:.6f} deg (turning "
            "point B), rests, turns BACK to 0 deg (turning point A) and rests; each cycle ends where it started (couple without "
            "an endless wrap; the velocity column is negative on the return)")


def isg_cam_table(cam: dict[str, np.ndarray], gear_ratio: float, name: str, table_id: int, max_lines: int,
                  comments: tuple[str, ...] = ()) -> str:
    """The text of the ISG/Beckhoff cam table of the crank position as quintic segments (see the module docstring).

    ``cam``: :func:`master_cam`'s columns. ``max_lines``: the most interpolation points the controller takes (the
    job's ``[planning.cam] isg_max_lines``). Refused (:class:`PlanningError`): master positions that are not
    ascending and equidistant from 0 to 360 deg, fewer than 2 or more than ``max_lines`` lines, a Table-ID below 1.
    """
    master = np.asarray(cam["master_deg"], float)
    lines = master.size - 1  # the row at 360 deg is the first row of the next turn, the slave one turn on: not written
    step = np.diff(master)
    if lines < 2 or master[0] != 0.0 or abs(master[-1] - 360.0) > 1e-9 or np.any(step <= 0) \
            or np.ptp(step) > 1e-9 * 360.0:
        raise PlanningError("ISG cam table: the master positions must ascend in equal steps from 0 to 360 deg with at least two "
                            f"steps (got {master.size} points from {master[0]:g} to {master[-1]:g} deg)")
    if lines > max_lines:
        raise PlanningError(f"ISG cam table: {lines} interpolation points exceed isg_max_lines = {max_lines} of the job's "
                            "[planning.cam]: raise master_step_deg, or isg_max_lines if the controller takes more")
    if isinstance(table_id, bool) or not isinstance(table_id, int) or table_id < 1:
        raise PlanningError(f"ISG cam table: Table-ID {table_id!r} must be a whole number >= 1")
    crank, vel, acc = (np.asarray(cam[k], float)[:-1] / gear_ratio + 0.0 for k in  # + 0.0: no "-0" in the file
                       ("motor_position_deg", "motor_velocity_deg_per_master_deg", "motor_accel_deg_per_master_deg2"))
    out = [f"# {c}" for c in comments]
    out += [f"# interpolation: {QUINTIC}: from each point to the next a quintic matching the slave's position, velocity and "
            f"acceleration at both (FunctionType {POLYNOM5_MM} = MOTIONFUNCTYPE_POLYNOM5_MM, motion <-> motion); not linear: a "
            "point table interpolated linearly makes the speed step at every point",
            "# rows: the fields of Beckhoff's MC_MotionFunctionPoint (TwinCAT NC camming), in its order: " + " ".join(ISG_COLUMNS),
            "# units: MasterPos deg of the virtual master (one turn per cycle); SlavePos crank (eccentric-shaft) deg from the start "
            "of the stroke; SlaveVelo crank deg per master deg; SlaveAcc crank deg per master deg^2; SlaveJerk 0 (POLYNOM5_MM "
            "takes position, velocity and acceleration only)",
            "# phase: the first point is master 0 deg, the start of the stroke; every row carries its master position (the ISG "
            "one-column form, which starts at the first master step, is not used)",
            f"# wrap: endless positive: the slave passes 360 deg every cycle; the point at master 360 deg is the first point with "
            f"SlavePos + 360 (implied, not written). ISG kernel: MC_CamIn.StartMode OR HLI_CI_ENDLESS_POSITIVE (16#{HLI_CI_ENDLESS_POSITIVE:02X}); "
            "a TwinCAT motion function: append that point",
            "# confidence: sure: MC_MotionFunctionPoint's fields, POLYNOM5_MM = 15, MOTIONPOINTTYPE_MOTION = 8, the ISG header "
            "keywords and Functiontype 6 = TABLE_DEFINED, HLI_CI_ENDLESS_POSITIVE = 16#20; medium: that the controller's importer "
            "takes these rows as they stand (no ISG page read shows a TABLE_DEFINED row); not yet loaded on a controller",
            f"Tablename = {isg_table_name(name)}",
            f"Table-ID = {table_id}",
            f"Functiontype = {ISG_FUNCTION_TYPE}     # TABLE_DEFINED: each row names the function of its segment",
            f"Lines = {lines}           # master step {360.0 / lines:g} deg over 0-360 deg (the point at 360 implied)",
            "Begintable"]
    for i in range(lines):
        out.append(f"{i + 1} {POLYNOM5_MM} {MOTIONPOINTTYPE_MOTION} 1 {master[i]:.10g} {crank[i]:.10g} {vel[i]:.10g} {acc[i]:.10g} 0")
    out.append("EndTable")
    return "\n".join(out) + "\n"


def read_isg_cam_table(text: str) -> tuple[dict[str, str], dict[str, np.ndarray]]:
    """The header keywords and the columns (:data:`ISG_COLUMNS`) of an ISG cam table as :func:`isg_cam_table` writes it."""
    header, rows, inside = {}, [], False
    for raw in text.splitlines():
        line = raw.split("#", 1)[0].strip()
        if not line:
            continue
        if line.lower() == "begintable":
            inside = True
        elif line.lower() == "endtable":
            inside = False
        elif inside:
            rows.append([float(v) for v in line.split()])
        else:
            key, _, val = line.partition("=")
            header[key.strip()] = val.strip()
    if int(header.get("Lines", -1)) != len(rows):
        raise ValueError(f"Lines = {header.get('Lines')} but {len(rows)} table lines")
    data = np.array(rows).reshape(-1, len(ISG_COLUMNS))
    return header, {k: data[:, j] for j, k in enumerate(ISG_COLUMNS)}


def hermite_position(cam: dict[str, np.ndarray], master_deg) -> np.ndarray:
    """Motor position (deg) between the cam's points by cubic Hermite interpolation of position and velocity, as an
    importer that takes the slave velocity per master unit runs the table."""
    from scipy.interpolate import CubicHermiteSpline

    spline = CubicHermiteSpline(cam["master_deg"], cam["motor_position_deg"], cam["motor_velocity_deg_per_master_deg"])
    return spline(np.asarray(master_deg, float))


def cycle_master(t_s, cycle_time_s: float) -> np.ndarray:
    """Master position (deg) at cycle times ``t_s`` (s): the master turns once per cycle at constant speed."""
    return np.asarray(t_s, float) / cycle_time_s * 360.0


# ----------------------------------------------------------------------------------------------------------------------
# How far a controller that runs the master cam by interpolation is from the plan: crank position and torque.
#
# An importer that takes the master cam's positions alone (a point table, e.g. the ISG one-column form with Functiontype
# 1; not what the cam files declare: they carry quintic segments, :mod:`planning.cams`) joins the cam's points by
# straight lines in master position. Between two points the crank then runs at the chord's speed, and at
# each point the speed steps to the next chord's. The figures below state what that costs against the plan, at the
# controller period (the job's ``controller_period_s``, the rows of cam_table.csv), over the whole cycle:
#
# * the **crank position error**: the largest |linear interpolation - plan| (crank deg);
# * the **torque the linear cam implies**: the motor torque (the plan's full model, Eq. 16, friction carried along:
#   :meth:`planning.evaluation.Evaluation.torque_between`) of the motion at the linear cam's crank position whose speed
#   runs linearly from one chord's speed to the next between the chords' midpoints (the speed change spread over one
#   master step, the gentlest way to follow the chords). A controller that changes speed faster at the points (within
#   a controller period: the set-points' own differences) needs more, so this is a lower bound. The largest speed step
#   at a point (motor rpm) is stated beside it;
# * the same torque for an importer that takes the velocity column too (cubic Hermite segments, their own speed and
#   acceleration), for comparison.
#
# A master step above ``max_cam_master_step_deg`` (run_limits.toml) is refused before planning (:class:`planning.cams.CamSettings`);
# after it, a linear cam that implies more than T_max (no reserve left at all) is refused with the largest step that
# passes. A warning names a linear cam whose crank leaves the playback's ``tracking_tolerance_deg`` (the plan's own
# verification criterion, [playback]) or whose implied torque spends part of the torque margin (above the plan's limit,
# ``torque_margin`` x T_max).
# In the dwell of a stop-at-top cycle (the cam standing at TDC) the torque is the plan's holding torque.


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
                      "velocity column joined by cubic Hermite segments (planning/cams.py)",
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


# ----------------------------------------------------------------------------------------------------------------------
# A cam file played the way its header declares, at the controller's period: the set-points a controller derives
# from it, and the feed-forward torque a drive would derive from those set-points through the model.
#
# Every cam file `plan` writes states in its header, on a line ``# interpolation: <kind> ...``, the interpolation it
# needs (:data:`PER_PERIOD`, :data:`QUINTIC` or :data:`LINEAR`). :func:`play` samples a file's points that way every
# controller period over one cycle of the virtual master (which turns once a cycle at constant speed):
#
# * ``per-period`` (cam_table.csv): one row per controller period, each row the set-point of its cycle, stepped as
#   they stand (the table's cycle is a whole number of periods, its last row the next cycle's first, checked); the
#   speed and acceleration either the file's own columns or, as a drive that takes positions only derives them, central
#   differences of the positions at the period;
# * ``quintic`` (cam_master.csv, cam_master_isg.txt): between two points the quintic that matches position, velocity
#   and acceleration (per master unit) at both (Beckhoff's POLYNOM5_MM, motion <-> motion); speed and acceleration are
#   the quintic's own derivatives times the master speed;
# * ``linear`` (a point table, e.g. the ISG one-column form with Functiontype 1): positions interpolated linearly
#   between the points, speed and acceleration by central differences at the period (a linear segment has no
#   acceleration of its own; its speed jumps at every point).
#
# :func:`played_torque` is the motor torque (N m per motor, Eq. 16 with friction) of the played motion through the
# plan's model (:meth:`planning.evaluation.Evaluation.torque_between`, the model the plan's own feed-forward comes from)
# at the played crank angle, speed and acceleration. Units: crank rad, s inside; degrees as the files hold them.


PER_PERIOD = "per-period"
QUINTIC = "quintic"
LINEAR = "linear"
KINDS = (PER_PERIOD, QUINTIC, LINEAR)
_DECLARED = re.compile(r"^#\s*interpolation:\s*([a-z-]+)", re.MULTILINE)


def declared_interpolation(text: str) -> str:
    """The interpolation kind a cam file's header declares (one of :data:`KINDS`); ValueError if it declares none."""
    m = _DECLARED.search(text)
    if m is None or m.group(1) not in KINDS:
        raise ValueError(f"no '# interpolation: <{'|'.join(KINDS)}>' line in the cam file's header")
    return m.group(1)


def controller_times(cycle_time: float, period: float) -> np.ndarray:
    """0, period, 2 period, ... below the cycle time (s): one cycle of the controller's clock (the next cycle's 0 is
    this one's end)."""
    n = int(math.floor(cycle_time / period * (1.0 - 1e-12)))
    return np.arange(n + 1) * period


def central_differences(pos: np.ndarray, dt: float, turn: float) -> tuple[np.ndarray, np.ndarray]:
    """(speed, acceleration) of periodic set-points ``pos`` sampled every ``dt`` s over one cycle, by central
    differences; the set-point after the last is the first plus ``turn`` (the slave's travel per cycle, endless)."""
    p = np.concatenate([[pos[-1] - turn], pos, [pos[0] + turn]])
    return (p[2:] - p[:-2]) / (2.0 * dt), (p[2:] - 2.0 * p[1:-1] + p[:-2]) / (dt * dt)


def per_period_rows(points: dict[str, np.ndarray], period: float, turn: float) -> tuple[np.ndarray, np.ndarray]:
    """(times in s, positions) of a per-period table's cycle as a controller steps it, one row per ``period``: every row
    but the last, which is the next cycle's first (``turn`` on). ValueError if the rows are not exactly one period apart
    from 0 or the last row is not the first ``turn`` on: a controller stepping the rows would play another motion."""
    t, pos = np.asarray(points["time"], float), np.asarray(points["position"], float)
    k = np.arange(t.size)
    if t.size < 3 or np.max(np.abs(t - k * period)) > 1e-9 * max(period, t[-1]):
        bad = int(np.argmax(np.abs(t - k * period)))
        raise ValueError(f"the per-period table's row {bad + 1} is at {t[bad]:.9g} s, not {bad * period:.9g} s: its rows must be "
                         f"one controller period ({period:g} s) apart from 0, the cycle a whole number of periods")
    if abs(pos[-1] - pos[0] - turn) > 1e-6 * max(1.0, abs(turn)):
        raise ValueError(f"the per-period table's last row ({pos[-1]:.9g}) is not its first ({pos[0]:.9g}) plus the turn ({turn:g})")
    return t[:-1], pos[:-1]


def quintic_segments(master: np.ndarray, pos: np.ndarray, vel: np.ndarray, acc: np.ndarray, m) -> tuple[np.ndarray, ...]:
    """Position and its first and second derivatives per master unit at master positions ``m``: on each interval
    [master_i, master_i+1] the quintic matching ``pos``, ``vel`` (per master unit) and ``acc`` (per master unit^2) at
    both ends. ``m`` must lie within [master_0, master_-1]."""
    m = np.asarray(m, float)
    i = np.clip(np.searchsorted(master, m, side="right") - 1, 0, len(master) - 2)
    h = master[i + 1] - master[i]
    s = (m - master[i]) / h
    c0, c1, c2 = pos[i], h * vel[i], 0.5 * h * h * acc[i]
    d_p = pos[i + 1] - c0 - c1 - c2
    d_v = h * vel[i + 1] - c1 - 2.0 * c2
    d_a = h * h * acc[i + 1] - 2.0 * c2
    c3 = 10.0 * d_p - 4.0 * d_v + 0.5 * d_a
    c4 = -15.0 * d_p + 7.0 * d_v - d_a
    c5 = 6.0 * d_p - 3.0 * d_v + 0.5 * d_a
    p = c0 + s * (c1 + s * (c2 + s * (c3 + s * (c4 + s * c5))))
    dp = (c1 + s * (2.0 * c2 + s * (3.0 * c3 + s * (4.0 * c4 + s * 5.0 * c5)))) / h
    ddp = (2.0 * c2 + s * (6.0 * c3 + s * (12.0 * c4 + s * 20.0 * c5))) / (h * h)
    return p, dp, ddp


def play(kind: str, points: dict[str, np.ndarray], cycle_time: float, period: float, turn: float,
         use_columns: bool = True) -> dict[str, np.ndarray]:
    """The set-points of one cycle played as ``kind`` declares, every ``period`` s (a per-period table over its own
    cycle, :func:`per_period_rows`; a master cam over ``cycle_time``): ``t`` (s), slave ``position``
    (slave units), ``speed`` (per s) and ``accel`` (per s^2).

    ``points``: ``master`` (deg, ascending over 0-360, the closing point at 360 included) with ``position``,
    ``velocity`` (per master deg) and ``accel`` (per master deg^2) for a quintic or a linear table; ``time``,
    ``position``, ``speed`` and ``accel`` for a per-period table. ``turn``: the slave's travel per cycle (endless
    wrap). ``use_columns`` (per-period only): speed and acceleration from the columns, else by central differences."""
    if kind == PER_PERIOD:
        t, pos = per_period_rows(points, period, turn)
        if use_columns:
            return {"t": t, "position": pos, "speed": points["speed"][:-1], "accel": points["accel"][:-1]}
        speed, accel = central_differences(pos, period, turn)
        return {"t": t, "position": pos, "speed": speed, "accel": accel}
    t = controller_times(cycle_time, period)
    w = 360.0 / cycle_time  # master deg/s
    m = t * w
    if kind == QUINTIC:
        p, dp, ddp = quintic_segments(points["master"], points["position"], points["velocity"], points["accel"], m)
        return {"t": t, "position": p, "speed": dp * w, "accel": ddp * w * w}
    if kind == LINEAR:
        pos = np.interp(m, points["master"], points["position"])
        speed, accel = central_differences(pos, period, turn)
        return {"t": t, "position": pos, "speed": speed, "accel": accel}
    raise ValueError(f"interpolation {kind!r} is not one of {KINDS}")


def played_torque(plan, crank_deg: np.ndarray, crank_speed_deg_s: np.ndarray, crank_accel_deg_s2: np.ndarray) -> np.ndarray:
    """Motor torque per motor (N m, Eq. 16 with friction) the plan's model gives for the played crank motion: angle
    (deg travelled from the start of the stroke), speed (deg/s) and acceleration (deg/s^2); where the crank rests
    (the dwell, speed 0) the model's static torque at that angle."""
    pd = plan.pd
    theta = pd.theta[0] + np.radians(np.asarray(crank_deg, float))
    theta = np.clip(theta, pd.theta[0], pd.theta[-1])
    if hasattr(plan, "motion_torque"):  # a pendulum (planning.pendulum): the crank also turns back
        return plan.motion_torque(theta, np.radians(crank_speed_deg_s), np.radians(crank_accel_deg_s2))
    return plan.evaluation.torque_between(pd.theta, theta, np.radians(crank_speed_deg_s), np.radians(crank_accel_deg_s2))


def cam_table_points(cols: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """cam_table.csv's columns as :func:`play`'s per-period points, in motor deg, deg/s and deg/s^2."""
    return {"time": cols["time_s"], "position": cols["motor_position_deg"], "speed": cols["motor_speed_rpm"] * 6.0,
            "accel": np.degrees(cols["motor_accel_rad_s2"])}


def cam_master_points(cols: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """cam_master.csv's columns as :func:`play`'s master points, in motor deg per master deg (and ^2)."""
    return {"master": cols["master_deg"], "position": cols["motor_position_deg"], "velocity": cols["motor_velocity_deg_per_master_deg"],
            "accel": cols["motor_accel_deg_per_master_deg2"]}


def isg_points(cols: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """The ISG table's columns (:data:`planning.cams.ISG_COLUMNS`) as :func:`play`'s master points in crank deg, with
    the implied closing point at master 360 deg (the first point, the slave one turn on: endless positive)."""
    return {"master": np.append(cols["MasterPos"], 360.0), "position": np.append(cols["SlavePos"], cols["SlavePos"][0] + 360.0),
            "velocity": np.append(cols["SlaveVelo"], cols["SlaveVelo"][0]), "accel": np.append(cols["SlaveAcc"], cols["SlaveAcc"][0])}


def peak_played(plan, kind: str, points: dict[str, np.ndarray], period: float, per_crank_deg: float,
                use_columns: bool = True, turn_deg: float = 360.0) -> float:
    """Largest |motor torque| (N m per motor) of the cam ``points`` played as ``kind`` every ``period`` s over the plan's
    cycle (:func:`play`, :func:`played_torque`); ``per_crank_deg``: slave units per crank deg (the gear ratio for a
    motor-side table, 1 for the crank); ``turn_deg``: the crank's travel per cycle (0 for a pendulum: it swings back)."""
    pl = play(kind, points, plan.cycle_time, period, turn_deg * per_crank_deg, use_columns)
    k = 1.0 / per_crank_deg
    return float(np.max(np.abs(played_torque(plan, pl["position"] * k, pl["speed"] * k, pl["accel"] * k))))


def played_line(peak: float, period: float, limits) -> str:
    """The header line that says what a cam file played as it declares gives (planning/cams.py)."""
    verdict = ("within" if peak <= limits.verdict else "ABOVE") + f" the margin {limits.verdict:,.0f} N m ({limits.margin:g} T_max)"
    return (f"played as declared every {period:g} s, feed-forward from the plan's model at the played set-points: peak "
            f"{peak:,.0f} N m per motor = {peak / limits.peak_torque:.4f} T_max, {verdict}")


def cam_table_header(period_s: float, plan: Plan | None = None) -> tuple[str, ...]:
    """The comment lines cam_table.csv starts with: the interpolation it needs (one row per controller period) and,
    given the ``plan``, its cycle as a whole number of periods (:func:`controller_cycle`)."""
    lines = (f"interpolation: {PER_PERIOD}: one row per controller period ({period_s:g} s), each row the set-point of its cycle "
             "(between rows linear in time); speed and acceleration from their columns, or from central differences of the "
             "position at the period; motor position unwrapped (endless positive: the next cycle starts from the last row's "
             "position), time 0 = the start of the stroke",)
    if plan is None:
        return lines
    n, slow = controller_cycle(plan, period_s)
    how = (f"the rest at its end {n * period_s - plan.cycle_time:.6f} s longer" if slow == 1.0 else
           f"the motion {slow - 1.0:.3e} slower (speed / {slow:.9f}, acceleration / {slow:.9f}^2), as the plan scaled in time")
    # the one place a rate other than the plan's is printed: what rounding the cycle to whole periods gives
    return lines + (f"rate: the plan's {rate_text(plan.strokes_per_min)} (cycle {plan.cycle_time:.6f} s); this table rounds the "
                    f"cycle up to whole controller periods, {n} x {period_s:g} s = {n * period_s:.6f} s, with {how}: run as it "
                    f"stands it gives {60.0 / (n * period_s):.4f} spm; the last row, at {n * period_s:.6f} s, is the next cycle's first",)
