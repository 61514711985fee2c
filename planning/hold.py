"""Stops on the way: a hold at or near bottom dead centre with the process force held ([planning.hold]), and a pause
at a stated slide height on the downstroke ([planning.pause]), in either mode.

A stop is a zero-speed segment of the cycle at one crank angle, with the force the slide feels there and a time:
the crank arrives at rest (speed and acceleration zero at that knot, toppra and the jerk-limited stage alike: the
stroke is two rest-to-rest pieces joined there), stays for the stop's time, and leaves from rest. Its knot is a grid
point (the angle solved from the height, not rounded).

The motor holds the static torque there: at the crank, the full model at rest with the process force on (the
downstroke's force at that height, held), gravity and the balance through the linkage, and no friction. At rest the
joints' static friction and the gear's losses keep the crank still for any motor torque in a band around it: the
joints' Coulomb friction +/- its breakaway torque, and the gear (Eq. 16) from B eta / (n u), the load driving the
motors, to B / (n u eta), the motors driving the load. The motor torque held is the middle of that band (the mean of
Eq. 16's two branches at the frictionless crank torque B), the one that leans least on either: the forward dynamics
creeps less there (a door-panel hold 5 mm above BDC under the 6 MN, 0.5 s: 0.042 deg against 0.075 deg with Eq. 16's
motoring branch alone, where the gear passes more back than it takes). The instants of arriving and leaving are the
knot's own, with the friction of a crank creeping forward (:mod:`planning.evaluation`). The stop
counts in the cycle's thermal RMS (:func:`equivalent_rest`) and in the peak, and the written profile, the cams and
the playback hold it (:func:`stop_clock` maps the cycle's time to the moving profile's).

Units: SI inside (rad, m, s, N m per motor).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from press_model.settings_fields import read_section, setting

CREEP = 1.0e-6  # rad/s: a crank about to turn, forward or back (Eq. 16's branch by the sign of the power)


@dataclass(frozen=True)
class HoldSection:
    """[planning.hold] of a job file: a dwell at or near BDC with the process force held (forming, coining)."""

    bottom_dwell_s: float = setting(0.0, "s", "off: a hold at the bottom is the part's own choice (coining, set the draw), "
                                    "none is needed to form the door panel", ge=0.0, unit="s", limit="max_dwell_s",
                                    what="any hold at the bottom")
    height_above_bdc_m: float = setting(0.0, "m", "at BDC itself, where the linkage carries the process force and the motors "
                                        "hold only friction and the static loads; a height above holds on the downstroke",
                                        ge=0.0, unit="m")


@dataclass(frozen=True)
class PauseSection:
    """[planning.pause] of a job file: a pause at a stated slide height on the downstroke (a multi-step motion)."""

    time_s: float = setting(0.0, "s", "off: a pause (let the blank settle on the die, a sensor check) is the part's own "
                            "choice", ge=0.0, unit="s", limit="max_dwell_s", what="any pause on the downstroke")
    height_m: float = setting(0.0, "m", "slide height above BDC of the pause on the downstroke: required with time_s > 0 "
                              "(no height is right for every part)", ge=0.0, unit="m")


@dataclass(frozen=True)
class StopRequest:
    """A stop as the job asks for it: ``name`` ("hold" or "pause"), the slide height above BDC on the downstroke (m;
    0: BDC) and the time at rest (s)."""

    name: str
    height: float
    time: float


def read_stops(rd) -> tuple[StopRequest, ...]:
    """The stops of the job's [planning.hold] and [planning.pause] (those with a time > 0), through the reader ``rd``."""
    hold = read_section(rd, ("planning", "hold"), HoldSection)
    pause = read_section(rd, ("planning", "pause"), PauseSection)
    out = []
    if hold.bottom_dwell_s > 0:
        out.append(StopRequest("hold", hold.height_above_bdc_m, hold.bottom_dwell_s))
    if pause.time_s > 0:
        if pause.height_m <= 0:
            rd.fail(("planning", "pause", "height_m"), pause.height_m, "must be > 0 with planning.pause.time_s > 0: the slide "
                    "height above BDC where the downstroke pauses (a pause at BDC is [planning.hold] bottom_dwell_s)")
        if hold.bottom_dwell_s > 0 and abs(pause.height_m - hold.height_above_bdc_m) < 1e-6:
            rd.fail(("planning", "pause", "height_m"), pause.height_m, "must differ from planning.hold.height_above_bdc_m: one "
                    "stop there is the hold, give its whole time as bottom_dwell_s")
        out.append(StopRequest("pause", pause.height_m, pause.time_s))
    return tuple(out)


def stop_angle(pm, ws, request: StopRequest, s0: float, bdc: float, source: str) -> float:
    """Crank angle (rad, unwrapped in [s0, bdc]) of ``request`` on the downstroke: where the slide is at its height."""
    from press_model.kinematics import height_crossing

    from press_io.errors import PlanningError

    if request.height == 0.0:
        return bdc
    top = pm.assembly.stroke
    if not 0.0 < request.height < top:
        key = "planning.hold.height_above_bdc_m" if request.name == "hold" else "planning.pause.height_m"
        raise PlanningError(f"{source}: {key} = {request.height} is not valid: must lie inside the stroke [0, {top:.4f}) m")
    eps = 1e-9
    return height_crossing(pm, ws, request.height, s0 + eps, bdc - eps)


@dataclass(frozen=True)
class Stop:
    """A stop on the planning knots: ``index`` its knot, ``theta`` (rad), ``height`` (m above BDC), ``time`` (s at rest),
    ``torque`` (N m per motor: the static torque the motors hold, :func:`static_stop_torque`), ``crank_torque`` (N m at
    the crank) and ``process_force`` (N, held)."""

    name: str
    index: int
    theta: float
    height: float
    time: float
    torque: float
    crank_torque: float
    process_force: float

    def record(self) -> dict:
        """summary.json's entry (degrees at the edge)."""
        return {"name": self.name, "crank_angle_deg": math.degrees(self.theta) % 360.0, "slide_height_m": self.height,
                "time_s": self.time, "holding_torque_Nm": self.torque, "crank_torque_Nm": self.crank_torque,
                "process_force_N": self.process_force,
                "friction": "none: the middle of the band static friction holds (+/- the breakaway torque), as the dwell at TDC"}


def static_stop_torque(pd, drive, friction, index: int) -> tuple[float, float]:
    """(motor torque per motor, crank torque), N m, holding the crank at rest at knot ``index`` of the path dynamics
    ``pd`` with the process force on: the crank torque of the full model at zero speed and acceleration (gravity,
    balance, process force; no friction at rest, see the module) and the middle of Eq. 16's band at it (``drive``: the
    mean of its motoring and braking branches). ``friction``: the press's friction data (None: ``pd``'s press's; it
    enters only through its viscous part, nil at rest)."""
    from press_model.motor import motor_torque

    from .path_dynamics import full_crank_torque

    n = pd.n
    on = np.zeros(n, bool)
    on[index] = pd.process_force[index] > 0
    crank = float(full_crank_torque(pd, np.zeros(n), np.zeros(n), process_on=on, friction=friction).crank_torque[index])
    # the two branches: the crank about to turn forward (power of the sign of B) and about to turn back
    branches = motor_torque(drive, np.array([crank, crank]), np.array([CREEP, -CREEP]), np.zeros(2))
    return float(np.mean(branches)), crank


def stops_on_grid(pd, drive, grid, requests, friction=None) -> tuple[Stop, ...]:
    """The stops ``requests`` at their knots of ``grid`` (their angles are the grid's special angles named after them)
    with the static torque of each on the press of ``pd`` (``drive``: its Eq. 16; ``friction``: None, the press's)."""
    out = []
    for r in requests:
        theta = grid.special[r.name]
        k = int(np.argmin(np.abs(grid.theta - theta)))
        torque, crank = static_stop_torque(pd, drive, friction, k)
        out.append(Stop(r.name, k, float(grid.theta[k]), float(pd.height[k]), r.time, torque, crank, float(pd.process_force[k])))
    return tuple(sorted(out, key=lambda s: s.index))


def equivalent_rest(hold: float, dwell: float, stops) -> tuple[float, float]:
    """One rest with the same time and the same integral of T^2 as the dwell at TDC (holding torque ``hold``, N m, for
    ``dwell`` s) and the ``stops`` together: (torque N m, time s), what the thermal limit's row and the cycle RMS take
    (they count the rests as time at a constant torque)."""
    t = dwell + sum(s.time for s in stops)
    if t <= 0.0 or not stops:  # the dwell alone is its own rest (exactly, sign and all)
        return hold, dwell
    return math.sqrt((hold * hold * dwell + sum(s.torque ** 2 * s.time for s in stops)) / t), t


def stop_clock(t, knot_times, stops) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The moving profile's time for each cycle time ``t`` (s), and which stop holds then (index into ``stops``, -1:
    none): at each stop the profile's clock stands still for the stop's time. ``knot_times``: the profile's time at its
    knots (s, from 0). Returns (profile time, stop index, whether held)."""
    t = np.atleast_1d(np.asarray(t, float))
    tm = t.copy()
    which = np.full(t.shape, -1)
    shift = 0.0
    for i, s in enumerate(stops):
        t_k = float(knot_times[s.index]) + shift  # the cycle's time when the crank reaches the stop
        held = (t >= t_k) & (t < t_k + s.time)
        after = t >= t_k + s.time
        which[held] = i
        tm[held] = t_k - shift
        tm[after] = t[after] - shift - s.time
        shift += s.time
    return tm, which, which >= 0


def stop_spans(plan) -> list[tuple[float, float, str]]:
    """(start s, end s, label) of each stop of ``plan`` in the cycle's time, for the figures."""
    knot_times = np.concatenate([[0.0], np.cumsum(plan.profile.dt)])
    out, shift = [], 0.0
    for st in plan.stops:
        t0 = float(knot_times[st.index]) + shift
        out.append((t0, t0 + st.time, f"{st.name}: at rest at {1000 * st.height:.0f} mm above BDC"))
        shift += st.time
    return out


def stop_comments(plan) -> tuple[str, ...]:
    """The cam files' comment lines on the stops of ``plan`` (none without stops): where the slave stands and for how
    long, in the cycle's time and on the master (one turn per cycle)."""
    return tuple(f"stop ({label.split(':')[0]}): the crank stands at {math.degrees(st.theta) % 360.0:.4f} deg for {t1 - t0:g} s, "
                 f"from {t0:.6f} s to {t1:.6f} s of the cycle (master {360.0 * t0 / plan.cycle_time:.4f} to "
                 f"{360.0 * t1 / plan.cycle_time:.4f} deg), holding {st.torque:,.0f} N m per motor"
                 for st, (t0, t1, label) in zip(plan.stops, stop_spans(plan)))
