"""Pendulum (swing) mode: the crank swings through BDC between two turning points and back, never over TDC.

The working stroke is the forward swing: from rest at turning point A (before BDC) the slide comes down, meets the part
at die contact, forms it through BDC and rises to turning point B (after BDC), where the formed part is taken out while
the slide rests at or above ``[planning.transfer] opening_height_m``; the return swings back through BDC with the die
empty (no process force) to A, where the next blank is put in. One part per cycle: strokes per minute = 60 / cycle.
(Forming on the return too, the crank press's pendulum with two parts a cycle, is not possible on the reference
eight-bar press: coming down after BDC its leverage is poor and the door panel's force alone needs more torque than
the margin allows; planning/README.md.)

Each swing is planned as the stop-at-top stroke is (:func:`planning.planner.plan_stroke`: toppra, the jerk-limited
IPOPT stage with the 10 % torque margin through Eq. 16, the motor speed, the forming window, the jerk limit and the
thermal RMS, the friction fixed point, the full-model re-check), on the knots from A to B. The return (B -> A, the
crank turning back) is planned as its time reversal on the same knots (:func:`planning.path_dynamics.reversed_swing`:
the rigid-body torque is the same at the mirrored instant; friction and the power's sign, and so Eq. 16's efficiency,
are those of the real backward motion). Each swing holds the thermal limit with the dwell at its end, so the cycle's
RMS (the time-weighted mean of the two) holds it too.

The turning points lie at the same slide height on both sides, at or above the opening, chosen by a golden-section
search of toppra's jerk-free cycle (:func:`_search_turning`); the transfer's ``time_s`` is split in half between them,
the dwell at each topping up the moving slide's time at or above the opening.

Stops on the way ([planning.hold], [planning.pause]; :mod:`planning.hold`) are the working swing's: knots of its grid
at their angles on the way down (below the opening), planned by :func:`planning.planner.plan_stroke` as the
stop-at-top stroke's (rest there, the static torque with the process force held, counted in the swing's RMS and peak
and so in the cycle's); the cycle's clock stands still there (:func:`planning.hold.stop_clock`). Units: rad, s, N m inside; degrees only
at the edges.
"""
from __future__ import annotations

import dataclasses
import math
import weakref
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, NamedTuple

import numpy as np

from press_io.errors import PlanningError
from press_io.outputs import versions
from press_model.disk_cache import cached_arrays, press_key, source_hash
from press_model.forces import NO_PROCESS, ProcessForce
from press_model.kinematics import height_crossing
from press_model.model import PressModel, Workspace

from .evaluation import Member
from .grid import Grid
from .hold import stop_angle, stop_clock
from .path_dynamics import build_path_dynamics, reversed_swing
from .jerk_stage import Robust
from .planner import Plan, StrokeProblem, plan_stroke
from .settings import PlanningSpec
from .transfer import FULL_OPENING, time_at_angle

STROKES_PER_CYCLE = 1  # the working swing A -> B; the return B -> A is empty


@dataclass
class PendulumPlan:
    """A planned pendulum cycle: the forward swing A -> B, the dwell at B, the backward swing B -> A (planned as its
    time reversal), the dwell at A. SI units; torques per motor."""

    spec: PlanningSpec  # the job's (mode "pendulum")
    forward: Plan  # A -> B, crank turning forward
    backward: Plan  # B -> A in its time reversal (its torques are minus the real ones, :func:`reversed_swing`)
    turning: tuple[float, float]  # rad, A (before BDC) and B (after BDC), unwrapped as the stop-at-top grid's angles
    dwell_a: float  # s at A (after the backward swing)
    dwell_b: float  # s at B (after the forward swing)
    hold_a: float  # N m per motor, the static holding torque at A
    hold_b: float  # N m per motor, at B
    transfer: dict
    rms_torque: float  # N m, Eq. 24 over the cycle, both dwells included
    modes: dict | None = None  # mode = "auto": every mode's rate, or why not (planning.modes); None otherwise
    mode_plans: dict | None = dataclasses.field(default=None, repr=False, compare=False)  # mode = "auto": every mode's plan (Plan.mode_plans)

    @property
    def swings(self) -> tuple[Plan, Plan]:
        """(forward, backward): the two swings' plans."""
        return self.forward, self.backward

    @property
    def grid(self) -> Grid:
        return self.forward.grid

    @property
    def pd(self):
        """The forward swing's path dynamics (the knots A -> B; the playback's gains)."""
        return self.forward.pd

    @property
    def profile(self):
        """The forward swing's knot profile (the playback starts from its first point, at rest at A)."""
        return self.forward.profile

    @property
    def evaluation(self):
        return self.forward.evaluation

    @property
    def stops(self) -> tuple:
        """The stops on the way (planning.hold.Stop: a hold at or near BDC, a pause on the way down), all on the working
        swing, at knots of its grid; the cycle starts at A with that swing, so their times are the cycle's."""
        return self.forward.stops

    @property
    def hold_torque(self) -> float:
        return self.hold_a

    @property
    def cycle_time(self) -> float:
        return self.forward.stroke_time + self.dwell_b + self.backward.stroke_time + self.dwell_a

    # profile.py's sampling of a cycle takes stroke_time + dwell: the pendulum's whole cycle is its "stroke"
    @property
    def stroke_time(self) -> float:
        return self.cycle_time

    dwell = 0.0

    @property
    def strokes_per_min(self) -> float:
        return STROKES_PER_CYCLE * 60.0 / self.cycle_time

    @property
    def peak_torque(self) -> float:
        return max(self.forward.peak_torque, self.backward.peak_torque)

    @property
    def max_motor_speed(self) -> float:
        return max(self.forward.max_motor_speed, self.backward.max_motor_speed)

    @property
    def max_window_slide_speed(self) -> float:
        return max(self.forward.max_window_slide_speed, self.backward.max_window_slide_speed)

    def phases(self) -> tuple[float, float, float, float]:
        """Ends of the cycle's four phases (s): forward swing, dwell at B, backward swing, dwell at A."""
        t1 = self.forward.stroke_time
        t2 = t1 + self.dwell_b
        t3 = t2 + self.backward.stroke_time
        return t1, t2, t3, t3 + self.dwell_a

    def cycle_reference(self, t) -> dict[str, np.ndarray]:
        """Crank angle (rad, as the grid's), speed (rad/s, negative on the backward swing), acceleration and motor torque
        (N m per motor, the full model's, Eq. 16) at times ``t`` (s) of the cycle: :func:`planning.profile.reference`'s
        columns for the whole pendulum cycle."""
        t = np.atleast_1d(np.asarray(t, float))
        t1, t2, t3, _ = self.phases()
        th = np.full(t.shape, self.turning[0])
        sd, acc, tq = np.zeros(t.shape), np.zeros(t.shape), np.full(t.shape, self.hold_a)
        theta = self.pd.theta
        f = t <= t1
        if f.any():
            prof = self.forward.profile
            tm, which, held = stop_clock(t[f], np.concatenate([[0.0], np.cumsum(prof.dt)]), self.stops)
            smp = prof.sample(tm, theta)
            th[f] = smp["theta"]
            sd[f], acc[f] = np.where(held, 0.0, smp["theta_dot"]), np.where(held, 0.0, smp["theta_ddot"])
            tq_f = self.forward.evaluation.torque_between(theta, smp["theta"], sd[f], acc[f])
            if held.any():  # at a stop the crank rests with the process force held: its static torque
                tq_f = np.where(held, np.array([st.torque for st in self.stops])[np.maximum(which, 0)], tq_f)
            tq[f] = tq_f
        d = (t > t1) & (t <= t2)
        th[d], tq[d] = self.turning[1], self.hold_b
        b = (t > t2) & (t <= t3)
        if b.any():
            smp = self.backward.profile.sample(t3 - t[b], theta)  # the reversal's time runs back
            th[b], sd[b], acc[b] = smp["theta"], -smp["theta_dot"], smp["theta_ddot"]
            tq[b] = -self.backward.evaluation.torque_between(theta, smp["theta"], smp["theta_dot"], smp["theta_ddot"])
        return {"theta": th, "theta_dot": sd + 0.0, "theta_ddot": acc + 0.0, "motor_torque": tq}

    def motion_torque(self, theta, theta_dot, theta_ddot) -> np.ndarray:
        """Motor torque per motor (N m, Eq. 16 with friction) of a crank motion near the plan's: angle (rad, as the
        knots'), speed (rad/s, negative turning back) and acceleration; turning forward the working swing's model,
        turning back the return's, at rest the holding torque of the nearer turning point (a played cam's torque)."""
        theta, w, a = (np.atleast_1d(np.asarray(x, float)) for x in (theta, theta_dot, theta_ddot))
        knots = self.pd.theta
        # at rest: the static torque of the nearest place the plan rests at (a turning point or a stop on the way)
        rest_at = np.array([self.turning[0], self.turning[1]] + [st.theta for st in self.stops])
        rest_tq = np.array([self.hold_a, self.hold_b] + [st.torque for st in self.stops])
        tq = rest_tq[np.argmin(np.abs(theta[:, None] - rest_at[None, :]), axis=1)]
        f, b = w > 0, w < 0
        if f.any():
            tq[f] = self.forward.evaluation.torque_between(knots, theta[f], w[f], a[f])
        if b.any():
            tq[b] = -self.backward.evaluation.torque_between(knots, theta[b], -w[b], a[b])
        return tq

    def process_on_at(self, t: float) -> bool:
        """Whether the process force acts at time ``t`` (s) of the cycle: on the working swing (and the dwell at B, above the
        die), not on the return, whose die is empty."""
        return t <= self.phases()[1]

    def summary(self) -> dict:
        """The pendulum's own entries of summary.json: turning points, swings, dwells, the transfer."""
        pm = self.pd.pm
        ws = Workspace(pm)
        from press_model.kinematics import height_at

        a, b = self.turning
        return {
            "strokes_per_cycle": STROKES_PER_CYCLE,
            "turning_points": [
                {"name": "A (before BDC)", "crank_angle_deg": math.degrees(a) % 360.0, "slide_height_m": float(height_at(pm, ws, a)),
                 "dwell_s": self.dwell_a, "holding_torque_Nm": self.hold_a},
                {"name": "B (after BDC)", "crank_angle_deg": math.degrees(b) % 360.0, "slide_height_m": float(height_at(pm, ws, b)),
                 "dwell_s": self.dwell_b, "holding_torque_Nm": self.hold_b}],
            "swing_angle_deg": math.degrees(b - a),
            "forward_swing_s": self.forward.stroke_time,
            "backward_swing_s": self.backward.stroke_time,
            "peak_torque_Nm": {"forward": self.forward.peak_torque, "backward": self.backward.peak_torque},
            "rms_torque_Nm": {"forward_with_dwell_at_A": self.forward.rms_torque, "backward_with_dwell_at_B": self.backward.rms_torque,
                              "cycle": self.rms_torque},
            "optimiser": {"forward": self.forward.optimiser, "backward": self.backward.optimiser},
            "jerk_free_swing_s": {"forward": self.forward.jerk_free_stroke_time, "backward": self.backward.jerk_free_stroke_time},
            "transfer": self.transfer,
            **({"stops": [st.record() for st in self.stops],
                "stops_on": "the working swing (forward, process force on), within forward_swing_s"} if self.stops else {}),
            "backward_swing": "planned as its time reversal on the same knots (planning/path_dynamics.reversed_swing); the return is empty (no process force)",
        }


def turning_points(pm: PressModel, spec: PlanningSpec, process: ProcessForce) -> tuple[float, float, float]:
    """(A, BDC, B) in rad on the stop-at-top grid's unwrapped angles: A and B where the slide passes the transfer's opening
    on the downstroke and the upstroke. A transfer that needs the full opening (the slide at TDC), or an opening at or
    below die contact (the die would not open over the part), makes pendulum mode infeasible: refused naming the field."""
    tr = spec.transfer
    asm = pm.assembly
    stroke = asm.stroke
    if not tr.opening_height < stroke * FULL_OPENING:
        raise PlanningError(f"{spec.source}: planning.transfer.opening_height_m = {tr.opening_height:g} is not valid in pendulum mode: "
                            f"the transfer needs the full opening (the stroke is {stroke:.4f} m, reached only at TDC), so the crank "
                            "cannot turn back before TDC; lower opening_height_m below the stroke or plan mode = \"stop-at-top\"")
    if not tr.opening_height > process.contact_height:
        raise PlanningError(f"{spec.source}: planning.transfer.opening_height_m = {tr.opening_height:g} is not valid: must be above "
                            f"process.contact_height_m ({process.contact_height:g} m), or the die never opens over the part")
    s0 = asm.theta_tdc
    bdc = asm.theta_bdc + 2.0 * math.pi * math.ceil((s0 - asm.theta_bdc) / (2.0 * math.pi))
    ws = Workspace(pm)
    eps = 1e-9
    a = height_crossing(pm, ws, tr.opening_height, s0 + eps, bdc - eps)
    b = height_crossing(pm, ws, tr.opening_height, bdc + eps, s0 + 2.0 * math.pi - eps)
    return a, bdc, b


def swing_grids(pm: PressModel, process: ProcessForce, spec: PlanningSpec, a: float, bdc: float, b: float,
                extra: dict | None = None) -> tuple[Grid, Grid]:
    """The knots from A to B (uniform ``grid_step`` plus BDC, die contact and the forming window's ends and the process
    breakpoints on both sides of BDC, solved, and the angles ``extra``, name -> rad) as two grids: the forward swing's
    (die contact before BDC) and the backward swing's (die contact after BDC, where its slide comes down)."""
    n = max(8, round((b - a) / spec.grid_step))
    uniform = np.linspace(a, b, n + 1)
    ws = Workspace(pm)
    eps = 1e-9
    hp = process.contact_height

    def both(name, h):
        return {f"{name}": height_crossing(pm, ws, h, a + eps, bdc - eps), f"{name}_return": height_crossing(pm, ws, h, bdc + eps, b - eps)}

    special = {"bdc": bdc, **both("die_contact", hp), **(extra or {})}
    h_win = hp + spec.forming_window
    if h_win < spec.transfer.opening_height:
        special.update(both("window_entry", h_win))
    for k, h in enumerate(sorted(set(process.heights))):
        if 0.0 < h < hp:
            special.update(both(f"process_breakpoint_{k}", h))
    step = (b - a) / n
    keep = np.ones(len(uniform), bool)
    for ang in special.values():
        near = np.abs(uniform - ang) < 0.01 * step
        near[0] = near[-1] = False
        keep &= ~near
    theta = np.unique(np.concatenate([uniform[keep], list(special.values())]))
    lo = special.get("window_entry", a)
    hi = special.get("window_entry_return", b)

    def window(lo_, hi_):
        return (theta >= lo_ - 1e-12) & (theta <= hi_ + 1e-12)

    both_ways = spec.window_directions == "both"
    fwd = Grid(theta, int(np.argmin(np.abs(theta - special["die_contact"]))), special, window(lo, hi if both_ways else bdc))
    bwd = Grid(theta, int(np.argmin(np.abs(theta - special["die_contact_return"]))), special, window(lo if both_ways else bdc, hi))
    return fwd, bwd


def _time_above(plan: Plan, crossing: float, at_start: bool) -> float:
    """Time (s) a swing's profile spends beyond ``crossing`` (rad) at its start (``at_start``) or at its end: the moving
    profile's (the stops on the way lie below the opening, :func:`_stop_angles`)."""
    t = time_at_angle(plan.profile, plan.grid.theta, crossing)
    return t if at_start else plan.profile.stroke_time - t


def _slice(pd, i: int, j: int):
    """The path dynamics ``pd`` on its knots i..j (both included)."""
    s = slice(i, j + 1)
    return dataclasses.replace(pd, theta=pd.theta[s], height=pd.height[s], dh=pd.dh[s], process_force=pd.process_force[s],
                               balance_force=pd.balance_force[s], m=pd.m[s], c=pd.c[s], g=pd.g[s], proc=pd.proc[s],
                               A_inv=pd.A_inv[s], u_s=pd.u_s[s], tau_terms=pd.tau_terms[:, s], P_terms=pd.P_terms[:, s],
                               w1=pd.w1[s], q=pd.q[s], kinematics=pd.kinematics[s])


def _grid_slice(g: Grid, i: int, j: int) -> Grid:
    return Grid(g.theta[i:j + 1], g.contact_index - i, g.special, g.in_window[i:j + 1])


@dataclass
class _Swings:
    """Both swings planned between the knots i (A) and j (B) of the wide grid, with the transfer's dwells."""

    i: int
    j: int
    forward: Plan
    backward: Plan
    up_a: float  # s the moving slide spends at or above the opening around A (both swings)
    up_b: float
    dwell_a: float  # s: what the transfer's half at A still needs
    dwell_b: float

    @property
    def cycle_time(self) -> float:
        return self.forward.stroke_time + self.backward.stroke_time + self.dwell_a + self.dwell_b


@dataclass(frozen=True)
class _Turn:
    """The whole turn's knots both swings are cut from, for one press model, process force and job: the forward swing's
    grid and path dynamics, the backward swing's (die contact after BDC; its path dynamics the forward's time reversal,
    :func:`reversed_swing`), the opening's crossings (rad, on the way down and up) and ``half``, the transfer's time at
    each turning point (s)."""

    pm: PressModel
    process: ProcessForce
    forward: Grid
    backward: Grid
    pd_forward: object
    pd_backward: object
    opening: tuple[float, float]
    half: float

    def swings(self, swing: PlanningSpec, i: int, j: int, dwells: tuple[float, float], region=None,
               starts: tuple[Plan, Plan] | None = None) -> _Swings:
        """Both swings from knot i to knot j, each planned with the dwell ``dwells`` at its end for the thermal limit; the
        dwells needed are :attr:`half` less the moving slide's time above the opening crossings. ``region``: a
        calibration's region (:class:`planning.robust.SwingRegion`) each swing holds the torque limit over
        (:func:`plan_swing_robust`); None: the press as given. ``starts``: another row's (forward, backward) swings on
        the same knots, each swing's start (:func:`planning.planner.plan_stroke`'s ``start``; None: toppra's)."""
        pm, process = self.pm, self.process
        g_f, g_b, pd_f, pd_b = self.forward, self.backward, self.pd_forward, self.pd_backward
        back = dataclasses.replace(swing, stops=())  # the stops (hold, pause) are the working swing's; the return passes them
        s_f, s_b = starts or (None, None)
        if region is None:
            fwd = plan_stroke(StrokeProblem(pm, process, swing, _grid_slice(g_f, i, j), _slice(pd_f, i, j)), dwells[0], start=s_f)
            bwd = plan_stroke(StrokeProblem(pm, process, back, _grid_slice(g_b, i, j), _slice(pd_b, i, j), hold_at=-1), dwells[1],
                              start=s_b)
        else:  # both on the forward path dynamics, one object: the box's members on these knots are built once for both
            pd_ij = _slice(pd_f, i, j)
            fwd = plan_swing_robust(StrokeProblem(pm, process, swing, _grid_slice(g_f, i, j), pd_ij), dwells[0], region, False, s_f)
            bwd = plan_swing_robust(StrokeProblem(pm, process, back, _grid_slice(g_b, i, j), pd_ij), dwells[1], region, True, s_b)
        a0, b0 = self.opening
        up_a = _time_above(fwd, a0, True) + _time_above(bwd, a0, True)
        up_b = _time_above(fwd, b0, False) + _time_above(bwd, b0, False)
        half = self.half
        return _Swings(i, j, fwd, bwd, up_a, up_b, max(0.0, half - up_a), max(0.0, half - up_b))


def _search_turning(turn: _Turn, swing: PlanningSpec, knots_at) -> _Swings:
    """The jerk-free swings (toppra's) of the fastest cycle over the turning height (the same on both sides, at or above
    the opening): golden-section search (each evaluation ~0.2 s of CPU); of those seen within ``TURNING_RATE_TIE`` of
    the fastest, the smallest swing."""
    # the search only ranks heights: toppra's friction fixed point to SEARCH_TOLERANCE (3-4 re-solves instead of 8-13)
    jerk_free = dataclasses.replace(swing, crank_jerk=math.inf, friction_tolerance=SEARCH_TOLERANCE[0],
                                    friction_tolerance_torque=SEARCH_TOLERANCE[1])
    lo, hi = knots_at.range
    seen: dict[tuple[int, int], _Swings | None] = {}
    refusals: list[PlanningError] = []  # why each infeasible height failed: the first is reported if none is feasible

    def cycle(h: float) -> float:
        key = knots_at(h)
        if key not in seen:
            try:
                seen[key] = turn.swings(jerk_free, *key, (turn.half, turn.half))
            except PlanningError as err:
                seen[key] = None
                refusals.append(err)
        return math.inf if seen[key] is None else seen[key].cycle_time

    r = (math.sqrt(5.0) - 1.0) / 2.0
    x1, x2 = hi - r * (hi - lo), lo + r * (hi - lo)
    f1, f2 = cycle(x1), cycle(x2)
    cycle(lo)
    while hi - lo > TURNING_TOLERANCE_M:
        if f1 <= f2:
            hi, x2, f2 = x2, x1, f1
            x1 = hi - r * (hi - lo)
            f1 = cycle(x1)
        else:
            lo, x1, f1 = x1, x2, f2
            x2 = lo + r * (hi - lo)
            f2 = cycle(x2)
    feasible = [v.cycle_time for v in seen.values() if v is not None]
    if not feasible:  # e.g. a motor too weak for the part: the swing's own refusal names the crank angle and the torque
        raise PlanningError(f"{refusals[0]} (pendulum mode: no turning height from {knots_at.range[0]:.3f} to "
                            f"{knots_at.range[1]:.3f} m above BDC gives a feasible swing)")
    best = min(feasible)
    # the smallest swing within TURNING_RATE_TIE of the best: the same rate for less travel (and a smaller problem)
    return min((v for v in seen.values() if v is not None and v.cycle_time <= best * (1.0 + TURNING_RATE_TIE)),
               key=lambda v: v.j - v.i)


class _KnotsAt:
    """Turning height (m) -> the knots (i, j) of the wide grid nearest the crossings at or above it on either side."""

    def __init__(self, height: np.ndarray, ia0: int, ib0: int):
        self.h, self.ia0, self.ib0 = height, ia0, ib0
        self.range = (float(height[ia0]), float(min(height[1], height[-2])))

    def __call__(self, h: float) -> tuple[int, int]:
        i = max(k for k in range(1, self.ia0 + 1) if self.h[k] >= h - 1e-12) if h > self.h[self.ia0] else self.ia0
        j = min(k for k in range(self.ib0, len(self.h) - 1) if self.h[k] >= h - 1e-12) if h > self.h[self.ib0] else self.ib0
        return i, j


def _stop_angles(pm: PressModel, spec: PlanningSpec, s0: float, bdc: float) -> dict[str, float]:
    """The stops' angles (name -> rad, on the downstroke, :func:`planning.hold.stop_angle`): knots of the working swing.
    A stop at or above the transfer's opening is refused naming its field: the turning point A lies at or above the
    opening, so the swing might not reach it, and its rest would count as transfer time."""
    ws = Workspace(pm)
    opening = spec.transfer.opening_height
    out = {}
    for req in spec.stops:
        if req.height >= opening:
            key = "planning.hold.height_above_bdc_m" if req.name == "hold" else "planning.pause.height_m"
            raise PlanningError(f"{spec.source}: {key} = {req.height:g} is not valid in pendulum mode: must be below "
                                f"planning.transfer.opening_height_m ({opening:g} m), where the swing turns")
        out[req.name] = stop_angle(pm, ws, req, s0, bdc, spec.source)
    return out


class _Turning(NamedTuple):
    """The turning knots (i: A, j: B, on the whole turn's grid) and the dwells at A and B (s) that the search found."""

    i: int
    j: int
    dwell_a: float
    dwell_b: float


def _knots_and_search(pm: PressModel, process: ProcessForce, spec: PlanningSpec, swing: PlanningSpec, half: float):
    """The whole turn's knots of both swings (:class:`_Turn`) and the :class:`_Turning` that :func:`_search_turning`
    finds on them (see :func:`plan_pendulum`): searched once per machine for the press data, process force, settings
    and code (:func:`press_model.disk_cache.cached_arrays`; the search is toppra's alone, no earlier plan enters it)."""
    a0, bdc, b0 = turning_points(pm, spec, process)
    s0 = pm.assembly.theta_tdc
    g_f, g_b = swing_grids(pm, process, spec, s0, bdc, s0 + 2.0 * math.pi,
                           {"opening": a0, "opening_return": b0, **_stop_angles(pm, spec, s0, bdc)})
    pd_f = build_path_dynamics(pm, g_f.theta, process, g_f.contact_index)
    drive = pm.press.drive
    pd_b = reversed_swing(pd_f, NO_PROCESS, None, drive.gear_inertia, drive.gear_ratio)  # the return is empty: no process force
    turn = _Turn(pm, process, g_f, g_b, pd_f, pd_b, (a0, b0), half)
    ia0, ib0 = int(np.argmin(np.abs(g_f.theta - a0))), int(np.argmin(np.abs(g_f.theta - b0)))

    def search() -> dict:
        found = _search_turning(turn, swing, _KnotsAt(pd_f.height, ia0, ib0))
        return {"knots": np.array([found.i, found.j]), "dwells": np.array([found.dwell_a, found.dwell_b])}

    # the key holds all the search reads: the press (its data with any overrides, press_model's code), the process force,
    # the job's settings but the IPOPT stage's (the search plans without it), the planning modules and toppra's version
    key = {**press_key(pm.press), "process": repr(process), "settings": repr(_search_key(spec)),
           "planning": source_hash(str(Path(__file__).parent)), "toppra": versions()["toppra"]}
    z = cached_arrays("turning", key, ("knots", "dwells"), search)
    return turn, _Turning(int(z["knots"][0]), int(z["knots"][1]), float(z["dwells"][0]), float(z["dwells"][1]))


def _search_key(spec: PlanningSpec) -> PlanningSpec:
    """``spec`` as the turning points' search reads it: without the IPOPT stage's settings."""
    return dataclasses.replace(spec, optimal_tolerance=None, optimal_max_iterations=None)


_SEARCHES: "weakref.WeakKeyDictionary[PressModel, list]" = weakref.WeakKeyDictionary()
SEARCHES_KEPT = 4  # per press model: compare's calibrated rows (the values alone, robust) search the same swings


def _searched(pm: PressModel, process: ProcessForce, spec: PlanningSpec, search: Callable):
    """``search()``'s result for this press model, process force and settings, searched once: the turning points' search
    plans toppra's jerk-free swings only (no IPOPT stage, whose settings are left out of the match; nothing of an
    earlier plan enters it), so the robust plan over a calibration's region and the plan at its centre search the same
    swings and take the same turning points (:func:`plan_pendulum`). Kept while ``pm`` lives."""
    key = _search_key(spec)
    seen = _SEARCHES.setdefault(pm, [])
    for proc, k, result in seen:
        if proc is process and k == key:
            return result
    result = search()
    seen.append((process, key, result))
    del seen[:-SEARCHES_KEPT]
    return result


TURNING_TOLERANCE_M = 0.05  # m of turning height: the jerk-free cycle is flat near its optimum (door panel: 9.041 to 9.063 spm over 0.96-1.30 m)
SEARCH_TOLERANCE = (1.0e-4, 50.0)  # s of swing time, N m of friction torque: the search's fixed point, 1e-4 of TURNING_RATE_TIE's 7 ms
TURNING_RATE_TIE = 1.0e-3  # relative cycle time within which a smaller swing is taken: 7 ms of the door panel's 6.6 s cycle


def plan_pendulum(pm: PressModel, process: ProcessForce, spec: PlanningSpec, *, region=None, start=None) -> PendulumPlan:
    """The pendulum cycle of a job (``spec``, its ``[planning.transfer]`` required) on press ``pm`` with ``process``:
    a :class:`PendulumPlan` with the stop-at-top plan's figures (``strokes_per_min``, ``cycle_time``, ``peak_torque``,
    ``rms_torque`` ...). Raises :class:`PlanningError` for an infeasible job. ``region``: a calibration's region
    (:class:`planning.robust.SwingRegion`, its box's centre = ``pm``) both jerk-limited swings hold the torque limit over, checked at every
    corner (:func:`plan_swing_robust`; the turning points are searched on the centre's jerk-free cycle). ``start``:
    another row's :class:`PendulumPlan` of the same job (the robust plan's: the centre's); where it turns at the same
    knots, each swing starts from its swing (:func:`planning.planner.plan_stroke`'s ``start``).

    The turning points: knots of the whole turn's grid at or above the opening, the same height on both sides, chosen
    by :func:`_search_turning` on toppra's jerk-free cycle; both swings are then planned with the jerk-limited stage
    (:func:`planning.planner.plan_stroke`)."""
    tr = spec.transfer
    swing = dataclasses.replace(spec, mode="stop-at-top", transfer=None, dwell=0.0)
    # half the transfer's time at each turning point: the formed part out at B, the next blank in at A
    half = 0.5 * tr.time
    turn, guess = _searched(pm, process, spec, lambda: _knots_and_search(pm, process, spec, swing, half))
    g_f = turn.forward
    i, j = guess.i, guess.j
    same = start is not None and start.turning == (float(g_f.theta[i]), float(g_f.theta[j]))
    sw = turn.swings(swing, i, j, (guess.dwell_a, guess.dwell_b), region, start.swings if same else None)
    fwd, bwd = sw.forward, sw.backward
    hold_a, hold_b = fwd.hold_torque, -bwd.hold_torque  # the backward swing's is its reversal's (minus the real one)
    # each swing's Eq. 24 integral from its RMS with the dwell it was planned with, then the dwells the transfer needs
    energy = (fwd.rms_torque ** 2 * (fwd.stroke_time + fwd.dwell) - hold_a ** 2 * fwd.dwell
              + bwd.rms_torque ** 2 * (bwd.stroke_time + bwd.dwell) - hold_b ** 2 * bwd.dwell)
    rms = math.sqrt((energy + hold_a ** 2 * sw.dwell_a + hold_b ** 2 * sw.dwell_b) / sw.cycle_time)
    if rms > spec.rms_limit(pm.press.motor.rated_torque):  # shorter dwells than planned with: plan the swings again with them
        sw = turn.swings(swing, i, j, (sw.dwell_a, sw.dwell_b), region)
        fwd, bwd = sw.forward, sw.backward
        rms = math.sqrt((fwd.rms_torque ** 2 * (fwd.stroke_time + fwd.dwell) + bwd.rms_torque ** 2 * (bwd.stroke_time + bwd.dwell))
                        / sw.cycle_time) if (fwd.dwell, bwd.dwell) == (sw.dwell_a, sw.dwell_b) else rms
        if rms > spec.rms_limit(pm.press.motor.rated_torque) * (1.0 + 1e-9):
            raise PlanningError(f"{spec.source}: thermal limit: the pendulum cycle's RMS {rms:,.0f} N m is above {spec.rms_limit(pm.press.motor.rated_torque):,.0f} N m "
                                "after the swings were planned again with the dwells the transfer needs; plan mode = \"stop-at-top\"")
    transfer = {"opening_height_m": tr.opening_height, "time_required_s": tr.time,
                "time_above_at_A_s": sw.up_a + sw.dwell_a, "time_above_at_B_s": sw.up_b + sw.dwell_b,
                "time_above_per_stroke_s": sw.up_a + sw.dwell_a + sw.up_b + sw.dwell_b,
                "time_above_while_moving_s": {"A": sw.up_a, "B": sw.up_b},
                "turning_height_search": "golden section over the turning height (the same both sides, at or above the opening) "
                                         "of toppra's jerk-free cycle, then both swings jerk-limited at the best",
                "rule": "per stroke (one working swing and its return) the slide's time at or above opening_height_m, the "
                        "dwells at both turning points counting, >= time_s: half at B (the formed part out), half at A (the next blank in)"}
    return PendulumPlan(spec, fwd, bwd, (float(g_f.theta[i]), float(g_f.theta[j])), sw.dwell_a, sw.dwell_b, hold_a, hold_b, transfer, rms)


# A swing robust over a calibration's region (|T_m| within the limit at every corner of the box): each swing's members
# are built on its slice of the knots (planning.robust._Builder, worst_case_members: the monotone parameters at their
# worst side per row type, the others at every corner), the backward swing's time-reversed as its centre is
# (reversed_swing with each member's own gear inertia, no process force: the return is empty). The swing is planned with
# every member's rows (no per-segment grouping: a swing is a small problem), then played through the full model at every
# corner; a corner that breaks the limit joins the members and the swing is planned again (at most
# planning.robust.MAX_CUTS rounds), as planning.robust.plan_robust does for a stroke. The region's tools come in as a
# planning.robust.SwingRegion (robust plans above the modes, which plan this one). Units: SI; torques N m per motor (the
# backward swing's in its reversal, minus the real ones: |T_m| is the real one).


class _ReversedBuilder:
    """A :class:`planning.robust._Builder`'s members in the time reversal of a backward swing (each member's path
    dynamics through :func:`reversed_swing` with its drive's gear inertia; shared where path dynamics and gear agree, so
    the corners still share their friction fixed points)."""

    def __init__(self, forward):
        self.forward, self.pm = forward, forward.pm
        self._reversed = {}

    def member(self, values: dict, label: str) -> Member:
        m = self.forward.member(values, label)
        key = (id(m.pd), m.drive.gear_inertia, m.drive.gear_ratio)
        if key not in self._reversed:
            self._reversed[key] = reversed_swing(m.pd, NO_PROCESS, None, m.drive.gear_inertia, m.drive.gear_ratio)
        return Member(self._reversed[key], m.drive, m.friction, label)


def plan_swing_robust(problem: StrokeProblem, dwell: float, region, backward: bool, start: Plan | None = None):
    """One swing planned to hold the torque limit at every corner of ``region``'s box
    (:class:`planning.robust.SwingRegion`, passed in: planning.robust plans a robust stroke above the modes; its box's
    centre = ``problem.pm``): ``problem`` the swing's knots with the forward path dynamics on them (the backward swing's
    are its reversal), ``dwell`` (s) at its end, ``start``: the centre's swing on these knots (None: none), the first
    plan's start (:func:`planning.planner.plan_stroke`), each plan after a cut starting from the one before. Returns the swing's :class:`planning.planner.Plan`, its
    ``robust_torques`` set to :func:`corner_torques` (per corner, T_m per knot, N m per motor), ``robust_members`` and
    ``robust_cuts`` to the members (:class:`planning.evaluation.Member`) planned with and the corners added. Raises :class:`PlanningError` when a corner still
    breaks the limit after ``region.max_cuts`` rounds."""
    pm, process, spec, grid = problem.pm, problem.process, problem.spec, problem.grid
    builder = region.builder(pm, process, grid, problem.pd)
    if backward:
        builder = _ReversedBuilder(builder)
    members, box, limit = region.members(builder), region.box, region.limit
    for cuts in range(region.max_cuts + 1):
        plan = plan_stroke(StrokeProblem(pm, process, spec, grid, members[0].pd, hold_at=-1 if backward else 0), dwell,
                           start=start, robust=Robust(members))
        start = plan
        torques = region.corner_torques(builder, plan)
        broken = [(c, t) for c, t in torques if np.max(np.abs(t)) > limit * (1.0 + 1e-9)]
        if not broken:
            plan.robust_torques = torques  # per corner (box.corners() order) the motor torque per knot, N m per motor
            plan.robust_members, plan.robust_cuts = members, cuts
            return plan
        members = members + [builder.member({**box.center, **c}, "corner that broke the limit") for c, _ in broken]
    worst = max(((c, float(np.max(np.abs(t)))) for c, t in torques), key=lambda ct: ct[1])
    raise PlanningError(f"{spec.source}: the robust pendulum's {'backward' if backward else 'forward'} swing still breaks the torque "
                        f"limit at a corner of the box after {region.max_cuts} rounds ({worst[1]:,.0f} N m against {limit:,.0f} N m at "
                        f"{worst[0]}); narrow the intervals")


def pendulum_corner_torques(plan) -> list[tuple[dict, np.ndarray]]:
    """Per corner of the box, the motor torque (N m per motor) at the knots of both swings of a robust
    :class:`planning.pendulum.PendulumPlan` (forward, then backward in its reversal: |T_m| is the real one)."""
    return [(c, np.concatenate([tf, tb])) for (c, tf), (_, tb) in zip(plan.forward.robust_torques, plan.backward.robust_torques)]
