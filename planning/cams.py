"""The plan as a master-position cam, the table a press or motion controller runs against a virtual master axis.

The master axis turns once per cycle at constant speed (360 deg per cycle time: stroke and dwell), so master
position m and time t are one: t = m / 360 x cycle time. :func:`master_cam` samples the plan at equidistant
master positions from 0 to 360 deg (both ends): the motor position (deg at the motor shaft, gear ratio applied,
0 at the start of the stroke, unwrapped: gear ratio x 360 at the end of the cycle), and its first and second
derivatives with respect to the master position (deg per master deg, deg per master deg^2), which importers that
take slave velocity and acceleration use for their polynomial segments. The positions are the plan's exact
profile (its own ``sample``), not an interpolation of the time-based cam table.

:func:`isg_cam_table` writes the same cam as an ISG/Beckhoff ASCII cam table ("File format of the cam tables
(ASCII interpreter)", Beckhoff Infosys, TwinCAT NC/CNC MC platform, ISG-MCE): an interpolation-point table of
type 3 (TABLE_ONE_COLUMN_REAL64), one slave position per line at equidistant master positions over the master's
modulo range 0-360 deg (the master positions are not written; the slave position at 360 is the one at 0 by the
format's definition), positions in units of 1e-4 deg. The slave of that file is the crank (eccentric-shaft) axis
in crank degrees, one turn a cycle: the ISG cam moves a modulo slave by at most one revolution a cycle (more only
in an endless start mode), so the motor's gear-ratio turns belong in the axis scaling, not in the table.
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

from .errors import PlanningError
from .planner import Plan
from .profile import reference

CAM_MASTER_COLUMNS = ("master_deg", "motor_position_deg", "motor_velocity_deg_per_master_deg", "motor_accel_deg_per_master_deg2")
ISG_UNIT_DEG = 1e-4  # deg per unit of an ISG cam table's positions (3600000 = 360 deg)
ISG_TABLE_TYPE = 3  # TABLE_ONE_COLUMN_REAL64: equidistant slave interpolation points, no master column
ISG_FUNCTION_TYPE = 1  # HLI_LINEAR: linear interpolation between the interpolation points


CAM_FILE = "cam_master.csv"
ISG_FILE = "cam_master_isg.txt"


@dataclass(frozen=True)
class CamSettings:
    """The ``[planning.cam]`` section of a job file: the master step (deg) and the ISG table's ID and largest size."""

    master_step_deg: float = setting(0.5, "deg", "720 master points a cycle: a linear interpolation stays within 0.009 "
                                     "crank deg of the door-panel plan, a cubic one within 2e-5 (1 deg: 0.038); the error "
                                     "is stated in summary.json and the ISG header (planning/cam_error.py)",
                                     gt=0.0, unit="deg", limit="min_step_deg", what="the crank step any run needs")
    isg_table_id: int = setting(1, "", "Table-ID of the ISG cam table: set the ID the controller's cam coupling "
                                "(MC_CamIn) uses", ge=1)
    isg_max_lines: int = setting(720, "", "most interpolation points of the ISG table; lower it to the controller's "
                                 "table size (the ISG pages read give 360 for two-column tables)", ge=2)

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


def isg_cam_table(cam: dict[str, np.ndarray], gear_ratio: float, name: str, table_id: int, max_lines: int,
                  comments: tuple[str, ...] = ()) -> str:
    """The text of an ISG/Beckhoff ASCII cam table of the crank position (see the module docstring).

    ``cam``: :func:`master_cam`'s columns. ``max_lines``: the most interpolation points the controller takes (the
    job's ``[planning.cam] isg_max_lines``). Refused (:class:`PlanningError`): master positions that are not
    ascending and equidistant from 0 to 360 deg, fewer than 2 or more than ``max_lines`` lines, a Table-ID below 1.
    """
    master = np.asarray(cam["master_deg"], float)
    lines = master.size - 1  # the row at 360 deg is the row at 0 of the next turn: not written
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
    crank = np.asarray(cam["motor_position_deg"], float)[:-1] / gear_ratio
    units = np.rint(crank / ISG_UNIT_DEG).astype(np.int64)
    out = [f"# {c}" for c in comments]
    out += [f"Tablename = {isg_table_name(name)}",
            f"Tabletype = {ISG_TABLE_TYPE}        # TABLE_ONE_COLUMN_REAL64: one slave position per equidistant master step",
            f"Table-ID = {table_id}",
            f"Functiontype = {ISG_FUNCTION_TYPE}     # linear interpolation between the points",
            f"Lines = {lines}           # master step {360.0 / lines:g} deg over 0-360 deg; slave: crank axis, 1e-4 deg",
            "Begintable"]
    out += [str(int(u)) for u in units]
    out.append("EndTable")
    return "\n".join(out) + "\n"


def read_isg_cam_table(text: str) -> tuple[dict[str, str], np.ndarray]:
    """The header keywords and the slave positions (deg) of an ISG ASCII cam table; for checking written files."""
    header, values, inside = {}, [], False
    for raw in text.splitlines():
        line = raw.split("#", 1)[0].strip()
        if not line:
            continue
        if line.lower() == "begintable":
            inside = True
        elif line.lower() == "endtable":
            inside = False
        elif inside:
            values.append(float(line.split()[0]) * ISG_UNIT_DEG)
        else:
            key, _, val = line.partition("=")
            header[key.strip()] = val.strip()
    if int(header.get("Lines", -1)) != len(values):
        raise ValueError(f"Lines = {header.get('Lines')} but {len(values)} table lines")
    return header, np.array(values)


def hermite_position(cam: dict[str, np.ndarray], master_deg) -> np.ndarray:
    """Motor position (deg) between the cam's points by cubic Hermite interpolation of position and velocity, as an
    importer that takes the slave velocity per master unit runs the table."""
    from scipy.interpolate import CubicHermiteSpline

    spline = CubicHermiteSpline(cam["master_deg"], cam["motor_position_deg"], cam["motor_velocity_deg_per_master_deg"])
    return spline(np.asarray(master_deg, float))


def cycle_master(t_s, cycle_time_s: float) -> np.ndarray:
    """Master position (deg) at cycle times ``t_s`` (s): the master turns once per cycle at constant speed."""
    return np.asarray(t_s, float) / cycle_time_s * 360.0

