"""The part transfer's window ([planning.transfer]): how long a planned stroke keeps the slide at or above the opening
the transfer needs, and the stop-at-top dwell that tops it up to the transfer's time.

A stop-at-top stroke leaves TDC above the opening and comes back to it: the slide is at or above the opening from the
start of the stroke to its crossing on the downstroke and from its crossing on the upstroke to the end, and all through
the dwell at TDC. With ``[planning.transfer]`` the dwell is what that time lacks of ``time_s`` (never negative), so the
stop-at-top plan holds the same requirement the pendulum plan holds at each of its turning points.

Units: rad, s, m inside.
"""
from __future__ import annotations

import dataclasses
import math

import numpy as np
from scipy.optimize import brentq

from press_io.errors import PlanningError
from press_model.kinematics import height_crossing
from press_model.model import PressModel, Workspace

from .evaluation import cycle_rms
from .hold import equivalent_rest
from .settings import PlanningSpec, Transfer

FULL_OPENING = 1.0 - 1e-9  # an opening at this fraction of the stroke or above (up to the stroke printed to the micrometre,
# check_opening) is the full opening: the slide at TDC


def time_at_angle(prof, theta_knots: np.ndarray, angle: float) -> float:
    """The time (s) from the start of the knot profile ``prof`` at which its crank angle reaches ``angle`` (rad, within
    the knots; the profile's crank angle never falls)."""
    t_knots = np.concatenate([[0.0], np.cumsum(prof.dt)])
    k = int(np.clip(np.searchsorted(theta_knots, angle, side="right") - 1, 0, len(prof.dt) - 1))
    lo, hi = t_knots[k], t_knots[k + 1]
    if angle <= theta_knots[k]:
        return float(lo)
    if angle >= theta_knots[k + 1]:
        return float(hi)
    return float(brentq(lambda t: float(prof.sample(np.array([t]), theta_knots)["theta"][0]) - angle, lo, hi, xtol=1e-12))


def opening_crossings(pm: PressModel, opening: float, lo: float, bdc: float, hi: float) -> tuple[float, float]:
    """Crank angles (rad) where the slide passes the height ``opening`` (m above BDC) on the downstroke in [lo, bdc]
    and on the upstroke in [bdc, hi]."""
    ws = Workspace(pm)
    eps = 1e-9
    return height_crossing(pm, ws, opening, lo + eps, bdc - eps), height_crossing(pm, ws, opening, bdc + eps, hi - eps)


def stroke_time_above(pm: PressModel, plan, opening: float) -> float:
    """Time (s) a stop-at-top stroke (TDC to TDC, ``plan``'s profile) spends with the slide at or above ``opening`` (m): 0
    for an opening at the stroke itself, which the slide reaches only at rest at TDC. A stop on the way (planning.hold)
    counts where the slide stands at or above the opening; the profile's clock is the moving crank's (stops excluded)."""
    if opening >= pm.assembly.stroke * FULL_OPENING:
        return 0.0
    if opening <= 0.0:  # no requirement (the default): the slide is never below BDC, so the whole stroke and its stops count
        return plan.profile.stroke_time + sum(st.time for st in plan.stops)
    theta = plan.grid.theta
    bdc = plan.grid.special["bdc"]
    down, up = opening_crossings(pm, opening, theta[0], bdc, theta[-1])
    resting = sum(st.time for st in plan.stops if st.height >= opening)
    return time_at_angle(plan.profile, theta, down) + plan.profile.stroke_time - time_at_angle(plan.profile, theta, up) + resting


def check_opening(pm: PressModel, spec: PlanningSpec, transfer: Transfer) -> None:
    """Refuse an opening the slide never reaches below TDC (no stroke can give it)."""
    stroke = pm.assembly.stroke
    # compared at the micrometre the message prints the stroke to: the stroke as printed is accepted (the full opening,
    # :data:`FULL_OPENING`), not refused for digits the user was never shown
    if not round(transfer.opening_height, 6) <= round(stroke, 6):
        raise PlanningError(f"{spec.source}: planning.transfer.opening_height_m = {transfer.opening_height:g} is not valid: "
                            f"must be at most the press's stroke ({stroke:.6f} m), the highest the slide goes (at TDC)")


def _rms(plan, dwell: float) -> float:
    """Cycle RMS (N m per motor, Eq. 24) of ``plan`` with ``dwell`` s at TDC, its stops on the way counted as rest too."""
    rest_torque, rest_time = equivalent_rest(plan.hold_torque, dwell, plan.stops)
    return cycle_rms(plan.evaluation, plan.profile, rest_time, rest_torque)


def plan_with_transfer(plan_at, pm: PressModel, spec: PlanningSpec, rms_limit: float):
    """The stop-at-top plan whose dwell at TDC tops the stroke's time above the opening up to the transfer's time.

    ``plan_at(dwell)`` plans the stroke with that dwell (s; it enters only the thermal limit). The first plan takes
    the whole transfer time as its dwell (the most a dwell can need); the dwell is then what the stroke leaves of the
    transfer time. If the cycle RMS with the shorter dwell breaks the thermal limit, the stroke is planned again with
    it, and the dwell re-measured (never below the one that stroke was planned with). ``rms_limit``: the thermal limit
    the planner plans the cycle RMS to (N m per motor). Returns the plan with ``dwell`` and ``transfer`` (opening, time
    required, time above while moving, dwell) set."""
    tr = spec.transfer
    check_opening(pm, spec, tr)
    plan = plan_at(tr.time)
    up = stroke_time_above(pm, plan, tr.opening_height)
    dwell = max(0.0, tr.time - up)
    replanned = False
    if dwell < plan.dwell and _rms(plan, dwell) > rms_limit:
        planned_with = dwell
        plan = plan_at(planned_with)
        up = stroke_time_above(pm, plan, tr.opening_height)
        dwell = max(planned_with, tr.time - up)
        replanned = True
    rms = _rms(plan, dwell)
    info = {**window_record(tr, up, dwell), "replanned_for_thermal": replanned,
            "rule": "dwell = max(0, time_s - time the moving slide spends at or above opening_height_m)"}
    return dataclasses.replace(plan, dwell=dwell, rms_torque=rms, transfer=info)


def window_record(tr: Transfer, up: float, dwell: float) -> dict:
    """The summary's ``transfer`` of a stroke whose moving slide spends ``up`` s at or above the opening, with ``dwell``
    s at TDC (all in s, the opening in m)."""
    return {"opening_height_m": tr.opening_height, "time_required_s": tr.time, "time_above_while_moving_s": up,
            "dwell_at_tdc_s": dwell, "time_above_per_stroke_s": up + dwell}


def segments_below(pm: PressModel, grid, opening: float) -> np.ndarray:
    """Per segment of ``grid``'s knots (a stop-at-top stroke, TDC to TDC), whether the slide is below ``opening`` (m above
    BDC) anywhere in it: the segments between the downstroke's and the upstroke's crossings, the two that hold a crossing
    included (so a bound on their time bounds the time below the opening, by at most those two segments' time too much)."""
    theta = np.asarray(grid.theta, float)
    if opening >= pm.assembly.stroke * FULL_OPENING:
        return np.ones(len(theta) - 1, bool)
    if opening <= 0.0:
        return np.zeros(len(theta) - 1, bool)
    down, up = opening_crossings(pm, opening, theta[0], grid.special["bdc"], theta[-1])
    return (theta[1:] > down) & (theta[:-1] < up)


def window_kept(pm: PressModel, plan, spec: PlanningSpec, dwell: float) -> dict:
    """The transfer record of a stop-at-top ``plan`` run with ``dwell`` s at TDC (a cycle set by a rate, not by the
    transfer); raises :class:`PlanningError` naming ``planning.transfer.time_s`` if the slide is then above the opening
    for less than the transfer's time."""
    tr = spec.transfer
    up = stroke_time_above(pm, plan, tr.opening_height)
    if up + dwell < tr.time * (1.0 - 1e-9):
        raise PlanningError(f"{spec.source}: planning.transfer.time_s = {tr.time:g} is not kept: the stroke keeps the slide above "
                            f"opening_height_m = {tr.opening_height:g} m for {up + dwell:.4f} s a cycle (moving {up:.4f} s, dwell "
                            f"{dwell:.4f} s); plan at a lower rate or shorten time_s")
    return window_record(tr, up, dwell)


def continuous_check(pm: PressModel, plan, spec: PlanningSpec) -> dict:
    """A continuous stroke has no dwell to top up: its time above the opening must reach the transfer's time by
    itself, else the job is refused naming the field. Returns the transfer record."""
    tr = spec.transfer
    check_opening(pm, spec, tr)
    up = stroke_time_above(pm, plan, tr.opening_height)
    if up < tr.time:
        raise PlanningError(f"{spec.source}: planning.transfer.time_s = {tr.time:g} is not valid in continuous mode: the "
                            f"continuous stroke keeps the slide above opening_height_m = {tr.opening_height:g} m for {up:.3f} s "
                            "only and has no dwell to add; use mode = \"stop-at-top\" or \"pendulum\"")
    return {"opening_height_m": tr.opening_height, "time_required_s": tr.time, "time_above_while_moving_s": up,
            "dwell_at_tdc_s": 0.0, "time_above_per_stroke_s": up}


def degrees(angle: float) -> float:
    """A crank angle (rad) in degrees folded into [0, 360) (the user's edge)."""
    return math.degrees(angle) % 360.0
