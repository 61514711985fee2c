"""A cam file played the way its header declares, at the controller's period: the set-points a controller derives
from it, and the feed-forward torque a drive would derive from those set-points through the model.

Every cam file `plan` writes states in its header, on a line ``# interpolation: <kind> ...``, the interpolation it
needs (:data:`PER_PERIOD`, :data:`QUINTIC` or :data:`LINEAR`). :func:`play` samples a file's points that way every
controller period over one cycle of the virtual master (which turns once a cycle at constant speed):

* ``per-period`` (cam_table.csv): one row per controller period, each row the set-point of its cycle, stepped as
  they stand (the table's cycle is a whole number of periods, its last row the next cycle's first, checked); the
  speed and acceleration either the file's own columns or, as a drive that takes positions only derives them, central
  differences of the positions at the period;
* ``quintic`` (cam_master.csv, cam_master_isg.txt): between two points the quintic that matches position, velocity
  and acceleration (per master unit) at both (Beckhoff's POLYNOM5_MM, motion <-> motion); speed and acceleration are
  the quintic's own derivatives times the master speed;
* ``linear`` (a point table, e.g. the ISG one-column form with Functiontype 1): positions interpolated linearly
  between the points, speed and acceleration by central differences at the period (a linear segment has no
  acceleration of its own; its speed jumps at every point).

:func:`played_torque` is the motor torque (N m per motor, Eq. 16 with friction) of the played motion through the
plan's model (:meth:`planning.evaluation.Evaluation.torque_between`, the model the plan's own feed-forward comes from)
at the played crank angle, speed and acceleration. Units: crank rad, s inside; degrees as the files hold them.
"""
from __future__ import annotations

import math
import re

import numpy as np

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
    """The header line that says what a cam file played as it declares gives (planning/cam_playback.py)."""
    verdict = ("within" if peak <= limits.verdict else "ABOVE") + f" the margin {limits.verdict:,.0f} N m ({limits.margin:g} T_max)"
    return (f"played as declared every {period:g} s, feed-forward from the plan's model at the played set-points: peak "
            f"{peak:,.0f} N m per motor = {peak / limits.peak_torque:.4f} T_max, {verdict}")
