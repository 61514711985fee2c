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
(:mod:`planning.cam_playback` plays it that way).
"""
from __future__ import annotations

import dataclasses
import re
from dataclasses import dataclass

import numpy as np

from press_model.jobs import Job
from press_model.limits import LIMITS_FILE, run_limits
from press_model.readers import FieldReader
from press_model.settings_fields import read_section, read_value, setting

from .cam_playback import QUINTIC
from .errors import PlanningError
from .planner import Plan
from .profile import reference

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
                                     "0.038; planning/cam_error.py)",
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


def cam_master_header(master_speed_deg_s: float) -> tuple[str, ...]:
    """The comment lines cam_master.csv starts with: the interpolation it needs, its master, wrap and phase."""
    return (f"interpolation: {QUINTIC}: between two master points the quintic matching motor position, velocity and acceleration "
            "(per master deg) at both (POLY5, Beckhoff POLYNOM5_MM); the positions interpolated linearly alone do not hold the "
            "torque margin (the speed steps at every point)",
            f"master: virtual axis, deg, one turn (0-360) per cycle at {master_speed_deg_s:.10g} deg/s; phase: master 0 = the start "
            "of the stroke; wrap: the motor turns on by the last row's position every cycle (endless positive)")


def pendulum_master_header(master_speed_deg_s: float, swing_motor_deg: float) -> tuple[str, ...]:
    """The comment lines cam_master.csv of a PENDULUM plan starts with: the interpolation, its master, and that the slave
    swings (it reverses every cycle and ends where it started: not endless)."""
    return (cam_master_header(master_speed_deg_s)[0],
            f"master: virtual axis, deg, one turn (0-360) per cycle at {master_speed_deg_s:.10g} deg/s; phase: master 0 = the start "
            "of the working swing, at rest at turning point A",
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

