"""Time-optimal crank stroke (toppra along s = theta_c) with the friction fixed point and the thermal loop.

Layers, inner to outer:

1. :func:`planning.toppra_solve.solve_toppra`: one toppra solve with the friction torque held fixed
   (constraint objects from the limits, :mod:`planning.limits`); stop-at-top: sd = 0 at both ends; continuous: the
   same crank speed v at both ends, v found by a 1-D search (toppra has no periodic boundary).
2. :meth:`StrokePlanner.at_level`: friction fixed point. Friction depends on the reactions and on the speed, so it
   is not part of toppra's affine dynamics: start with none, solve, evaluate the full model along the
   profile (:mod:`planning.evaluation`, both one-sided accelerations at every knot), put the difference into
   the constraint's constant term, re-solve, until the stroke time changes less than ``friction_tolerance_s``
   and the friction torque less than ``friction_tolerance_Nm`` (it converges linearly, about x15 per
   re-solve). With a jerk limit, toppra's profile (the jerk-free optimum: a lower bound) then starts the
   optimal-control stage (:mod:`planning.jerk_stage`, its collocation :mod:`planning.optimal`): the time optimum under every limit and the jerk limit,
   limits held between the knots too, with its own friction fixed point; if it fails, the plan is toppra's
   profile and says why. The final profile is re-checked with the full model; if the torque limit is
   exceeded (round-off of the fixed points), the level is tightened by (limit / peak) * ``recheck_tightening``
   and both stages rerun.
3. :meth:`StrokePlanner.meet_thermal_limit`: the thermal limit, the cycle RMS of Eq. 24 (time-weighted, the dwell with the
   static holding torque at TDC included) <= (1 - ``thermal_feedback_reserve``) T_rated. The jerk-limited stage holds it as a row of its problem
   (:class:`planning.limits.ThermalLimit`), so the stroke is the time optimum under the RMS limit too; if the
   full model's RMS at the solution is above T_rated (the friction fixed point's round-off), the row's bound
   is tightened and the stage re-solved. toppra cannot take an integral limit: without a jerk limit, or when
   the stage fails, :meth:`StrokePlanner.bisect_thermal` bisects the peak-torque level L' <= margin * T_max given to the
   torque constraint until the RMS is within ``thermal_tolerance`` below T_rated (a feasible stroke, not the
   optimum under the RMS limit: it slows every torque-limited phase alike).

:func:`plan_stroke` puts these together into a :class:`Plan` for a :class:`StrokeProblem` (a press model, its process force,
the job's settings, knots and path dynamics, built once and shared by every mode and row planned on them); the loops are
:class:`StrokePlanner`'s. The planner knows one stroke's ends (at rest, or periodic); the motion modes above it are
:mod:`planning.modes`'. The grid and the knot profile are in :mod:`planning.grid`, which limit binds where in
:mod:`planning.limits`.

Units: rad, s, N m inside; degrees only in messages.
"""
from __future__ import annotations

import dataclasses
import logging
import math
from dataclasses import dataclass
from functools import cached_property

import numpy as np

from press_io.errors import PlanningError
from press_model.forces import ProcessForce
from press_model.model import PressModel
from press_model.motor import braking_ratio, crank_gain, loss_coefficients, motor_torque

from .evaluation import CHECKS, Evaluation, Member, creep_torque, cycle_rms, evaluate_members, static_check
from .grid import Grid, Profile, planning_grid
from .hold import equivalent_rest, stops_on_grid
from .limits import GridRow, Limits, OptimalControlError, ThermalLimit, ToppraPoint, binding_report
from .jerk_stage import JerkStage, Robust
from .path_dynamics import PathDynamics, build_path_dynamics, full_crank_torque
from .settings import PlanningSpec
from .toppra_solve import solve_toppra
from .transfer import continuous_check, plan_with_transfer

log = logging.getLogger(__name__)

THERMAL_STEPS = 8  # levels tried between the margin and the static torque before bisecting (thermal loop)
OPTIMAL_BACKOFF = 2.0e-5  # the jerk-limited stage plans to level x (1 - this): IPOPT meets its rows to ~1e-7 and the torque bulges between checks h/4 apart by up to ~6e-6 relative (measured on seven door-panel variants with the thermal row binding: 3.5-5.7e-6), so the written 2 ms profile stays under the level
GRID_BACKOFF = 1.0e-4  # ... and its grid rows to the grid limit x (1 - this); the written profile is re-checked (planning.energy)
THERMAL_BACKOFF = 1.0e-6  # ... and its thermal row to the thermal limit x (1 - this): the full model at the solution differs by the friction fixed point's residual


@dataclass(kw_only=True)
class Plan:
    """A planned stroke with its full-model re-check. SI units; per-motor torques."""

    spec: PlanningSpec
    grid: Grid
    pd: PathDynamics
    profile: Profile
    evaluation: Evaluation
    dwell: float  # s
    hold_torque: float  # N m per motor, static holding torque at TDC (the dwell)
    torque_level: float  # N m: the level given to toppra's torque constraint and the jerk-limited stage in the end
    peak_torque: float  # N m, max |T_m| over the knots (both sides) and 1/4, 1/2, 3/4 of every segment, over the members (robust plan)
    rms_torque: float  # N m, Eq. 24 over the cycle, dwell included
    max_motor_speed: float  # rad/s at the motor shaft
    max_window_slide_speed: float  # m/s inside the forming window
    thermal_binding: bool
    friction_iterations: int
    recheck_rounds: int
    thermal_iterations: int  # re-solves with a tightened thermal bound (jerk-limited stage) or levels tried (toppra's bisection)
    jerk_free_stroke_time: float  # s: toppra's stroke without the jerk limit at the planning limit, a lower bound (without the thermal limit too: toppra takes no RMS)
    jerk_free_profile: Profile | None = None  # toppra's profile at the final level (the bound; the plan itself without a jerk limit)
    optimiser: dict = dataclasses.field(default_factory=dict)  # the jerk-limited stage's convergence, or why it fell back to toppra's stroke
    transfer: dict | None = None  # with [planning.transfer]: the opening, the time required and how the dwell meets it (planning.transfer)
    stops: tuple = ()  # planning.hold.Stop per stop on the way (a hold at the bottom, a pause): the crank at rest at a knot for a time
    modes: dict | None = None  # mode = "auto": every mode's rate, or why it was not allowed or kept (planning.modes); None otherwise
    stage: JerkStage | None = dataclasses.field(default=None, repr=False)  # the jerk-limited stage with its built problem (a robust plan's cut re-solves in it)
    member_evaluations: list | None = dataclasses.field(default=None, repr=False)  # every member's evaluation at the final profile
    # mode = "auto": each mode's plan on the same job, kept or refused (planning.modes.plan_modes): another row's starts
    mode_plans: dict | None = dataclasses.field(default=None, repr=False, compare=False)

    @property
    def stop_time(self) -> float:
        """Time at rest at the stops on the way (s), part of the stroke's time."""
        return float(sum(s.time for s in self.stops))

    @cached_property
    def binding(self) -> dict:
        """Per phase of the stroke, the dominant limit and each limit's share of the phase's time (:func:`planning.limits.binding_report`)."""
        return binding_report(self.pd.pm, self)

    @property
    def stroke_time(self) -> float:
        """TDC to TDC (s): the crank's motion and its stops on the way (the dwell at TDC not included)."""
        return self.profile.stroke_time + self.stop_time

    @property
    def cycle_time(self) -> float:
        return self.stroke_time + self.dwell

    @property
    def strokes_per_min(self) -> float:
        return 60.0 / self.cycle_time

    @property
    def jerk_free_strokes_per_min(self) -> float:
        """Production rate of the same job without the jerk limit (toppra's bang-bang optimum, an upper bound), 1/min."""
        return 60.0 / (self.jerk_free_stroke_time + self.stop_time + self.dwell)

    @property
    def max_jerk(self) -> float:
        """Largest |crank jerk| of the profile (rad/s^3); inf for toppra's bang-bang profile."""
        return self.profile.max_jerk() if hasattr(self.profile, "max_jerk") else math.inf


def _viscous_change(members, old_speed, new_speed) -> float:
    """Largest change (N m at the crank) of the members' viscous drive loss between the crank speeds ``old_speed`` (None:
    at rest) and ``new_speed`` (rad/s per knot): c u |dw| per motor, carried to the crank by n u eta, as the friction's."""
    dw = float(np.max(np.abs(new_speed - (0.0 if old_speed is None else old_speed))))
    return max(m.drive.viscous * m.drive.gear_ratio * dw * crank_gain(m.drive, 1.0) for m in members)


def planning_limit(pm: PressModel, spec: PlanningSpec) -> float:
    """Torque level the feed-forward is planned to (N m per motor): (margin - feedback reserve) x T_max."""
    return spec.torque_limits(pm.press.motor.peak_torque).feedforward


def thermal_limit(pm: PressModel, spec: PlanningSpec) -> float:
    """Cycle RMS the feed-forward is planned to (N m per motor): (1 - thermal feedback reserve) x T_rated."""
    return spec.rms_limit(pm.press.motor.rated_torque)


def _between_knots_peak(ev: Evaluation, prof, theta) -> float:
    """Largest |T_m| (N m) at 1/4, 1/2 and 3/4 of every segment's duration (the jerk-limited stage's checks), by
    the written profile's interpolation of the full model (:meth:`Evaluation.torque_between`)."""
    t0 = np.concatenate([[0.0], np.cumsum(prof.dt)])[:-1]
    t = (t0[:, None] + np.asarray(CHECKS)[None, :] * prof.dt[:, None]).ravel()
    smp = prof.sample(t, theta)
    return float(np.max(np.abs(ev.torque_between(theta, smp["theta"], smp["theta_dot"], smp["theta_ddot"]))))


@dataclass(frozen=True)
class StrokeProblem:
    """What a stroke is planned on: a press model, its process force, the job's settings and the knots and path
    dynamics built from them, built once (:meth:`build`) and shared by every motion mode, robust member set, grid limit
    and comparison row planned on the same press and job (:meth:`using` another mode's settings on the same knots).
    ``hold_at``: the knot whose static torque holds the crank through the dwell (0: the start; a pendulum's backward
    swing, planned reversed, -1)."""

    pm: PressModel
    process: ProcessForce
    spec: PlanningSpec
    grid: Grid
    pd: PathDynamics
    hold_at: int = 0
    # the torques at rest of the knots (creeping speed; the hold at ``hold_at``): the same for every mode and settings on
    # these knots, computed once and shared with the copies :meth:`using` makes
    rest: dict = dataclasses.field(default_factory=dict, compare=False, repr=False)

    @classmethod
    def build(cls, pm: PressModel, process: ProcessForce, spec: PlanningSpec) -> "StrokeProblem":
        """The job's knots (:func:`planning.grid.planning_grid`) and path dynamics on ``pm`` with ``process``."""
        grid = planning_grid(pm, process, spec)
        return cls(pm, process, spec, grid, build_path_dynamics(pm, grid.theta, process, grid.contact_index))

    def using(self, spec: PlanningSpec) -> "StrokeProblem":
        """The same press, process, knots and path dynamics with the settings ``spec`` (another mode, a solver's limits)."""
        return dataclasses.replace(self, spec=spec)

    def limits(self, still, thermal: ThermalLimit | None = None, grid_row: GridRow | None = None) -> Limits:
        """What a stroke on these knots keeps (:meth:`planning.limits.Limits.declare`) with the crank at rest at the knots
        ``still``; ``thermal``, ``grid_row``: the jerk-limited stage's cycle-RMS and grid rows (None: without)."""
        return Limits.declare(self.pm, self.spec, self.grid, self.pd, still, thermal, grid_row)

    def creep_torque(self) -> np.ndarray:
        """:func:`planning.evaluation.creep_torque` of the knots (N m per motor), computed once."""
        if "creep" not in self.rest:
            self.rest["creep"] = creep_torque(self.pm, self.pd)
        return self.rest["creep"]

    def hold_torque(self) -> float:
        """The static torque (N m per motor) holding the crank at rest at knot ``hold_at`` through the dwell, computed once."""
        key = ("hold", self.hold_at)
        if key not in self.rest:
            pd = self.pd
            tau = full_crank_torque(pd, np.zeros(pd.n), np.zeros(pd.n)).crank_torque[self.hold_at]
            self.rest[key] = float(motor_torque(self.pm.press.drive, tau, 0.0, 0.0))
        return self.rest[key]


@dataclass
class StrokePlanner:
    """The loops of the module docstring on one problem's knots: toppra's friction fixed point (:meth:`fixed_point`),
    the jerk-limited stage at a torque level with the full-model re-check (:meth:`at_level`) and the thermal limit
    (:meth:`meet_thermal_limit`, :meth:`bisect_thermal`).

    ``members``: the parameter sets every torque row holds for (the first: the press on the knots' path dynamics);
    ``limits``: what the stroke keeps on the knots (:class:`planning.limits.Limits`; toppra takes each limit's
    constraint objects); ``static``: the static torque per knot (N m per motor,
    :func:`planning.evaluation.static_check`), the floor of the thermal loop's levels; ``rest_time``, ``rest_torque``:
    the dwell and the stops as the thermal limit counts them (s, N m per motor); ``stage``: the jerk-limited stage (None:
    no jerk limit); ``fallback``: False raises the stage's :class:`OptimalControlError` instead of falling back to
    toppra's stroke."""

    pm: PressModel
    members: list
    limits: Limits
    spec: PlanningSpec
    static: np.ndarray | None = None
    rest_time: float = 0.0
    rest_torque: float = 0.0
    stage: JerkStage | None = None
    fallback: bool = True

    def fixed_point(self, level: float, frics, speed=None):
        """toppra re-solved at torque ``level`` (N m per motor) with the friction of the previous profile until stroke
        time and friction settle.

        ``frics``: per member, the friction torque at the crank (right, left) to start from; ``speed``: the crank speed
        per knot (rad/s) to start from, at which a drive's viscous loss is held like the friction (None: at rest).
        Returns (knot profile, its full-model evaluation per member, re-solves)."""
        members, spec, limits = self.members, self.spec, self.limits
        t_prev, hint = None, None
        for it in range(1, spec.friction_max_iterations + 1):
            cons = limits.toppra(ToppraPoint(members, level, frics, speed))
            prof = solve_toppra(cons, limits.theta, spec, members[0].pd, hint)
            hint = prof.boundary_speed
            evs = evaluate_members(self.pm, members, prof)
            change = max(max(np.max(np.abs(ev.fric_right - fr)), np.max(np.abs(ev.fric_left - fl))) for ev, (fr, fl) in zip(evs, frics))
            if any(m.drive.viscous for m in members):  # the viscous loss's speed settles with the friction
                change = max(change, _viscous_change(members, speed, prof.sd))
                speed = prof.sd
            frics = [(ev.fric_right, ev.fric_left) for ev in evs]
            if (t_prev is not None and abs(prof.stroke_time - t_prev) < spec.friction_tolerance
                    and change < spec.friction_tolerance_torque):
                return prof, evs, it
            t_prev = prof.stroke_time
        raise PlanningError(
            f"{spec.source}: the friction fixed point did not settle in {spec.friction_max_iterations} re-solves "
            f"(stroke time still changing by {abs(prof.stroke_time - t_prev):.3g} s); raise planning.solver.friction_max_iterations"
        )

    def at_level(self, level: float, warm=None, stage: JerkStage | None = None, rms_bound: float | None = None):
        """toppra's friction fixed point, the jerk-limited optimum and the full-model re-check at torque level
        ``level`` (N m per motor).

        Returns (profile, evaluation per member, level used in the end, toppra re-solves, re-check rounds, toppra's
        jerk-free profile, the optimiser's record). The re-check takes the largest |T_m| over the members at the
        knots; a failure (the fixed points' round-off) scales the level by (limit / peak) * ``recheck_tightening``
        and both stages are re-solved. ``warm``: the members' evaluations toppra's friction starts from (None: none);
        ``stage``: the optimal-control stage (None: no jerk limit). If it fails, the plan falls back to toppra's jerk-free
        profile, with a warning logged and the reason in the record (unless not :attr:`fallback`). ``rms_bound``: the
        stage's thermal row's bound (N m per motor; None: free).
        """
        pm, spec = self.pm, self.spec
        limit = planning_limit(pm, spec)
        target = min(level, limit)
        pd = self.members[0].pd
        frics = [(np.zeros(pd.n), np.zeros(pd.n))] * len(self.members) if warm is None else [(e.fric_right, e.fric_left) for e in warm]
        speed = None if warm is None else np.sqrt(warm[0].x)
        toppra_level = level
        total_it, first, record = 0, None, {}
        for rounds in range(1, spec.recheck_max_rounds + 1):
            base, evs, it = self.fixed_point(toppra_level, frics, speed)
            frics = [(e.fric_right, e.fric_left) for e in evs]
            speed = np.sqrt(evs[0].x)
            total_it += it
            first = first or base
            prof = base
            if stage is not None:
                try:
                    res = stage.solve(toppra_level * (1.0 - OPTIMAL_BACKOFF), base, rms_bound)
                except OptimalControlError as err:
                    if not self.fallback:
                        raise
                    record = {"status": "fallback", "fallback_reason": str(err)}
                    log.warning("%s: the jerk-limited optimisation failed (%s); the plan is toppra's jerk-free stroke and does NOT "
                                "keep planning.limits.crank_jerk_rad_s3", spec.source, err)
                    stage = None
                else:
                    prof, evs, record = res.profile, res.evaluation, res.convergence()
            peak = float(np.max([np.maximum(np.abs(e.motor_right), np.abs(e.motor_left)) for e in evs]))
            if peak <= target:
                return prof, evs, toppra_level, total_it, rounds, first, record
            toppra_level *= target / peak * spec.recheck_tightening
        raise PlanningError(
            f"{spec.source}: the full-model re-check still exceeds the torque limit after {spec.recheck_max_rounds} rounds "
            f"(peak {peak:,.0f} N m against {target:,.0f} N m); raise planning.solver.recheck_max_rounds or refine grid_step_deg"
        )

    def meet_thermal_limit(self, warm=None):
        """The stroke at the planning limit whose cycle RMS (Eq. 24) keeps :func:`thermal_limit`.

        With the jerk-limited stage (:class:`planning.jerk_stage.JerkStage` with a thermal row) the RMS limit is a row
        of its problem: one solve gives the time optimum under it; if the full model's RMS at the solution is above
        the limit, the row's bound is scaled by limit / RMS and the stage re-solved. Without the stage, or if it
        falls back to toppra, :meth:`bisect_thermal`.

        Returns (profile, evaluation per member, torque level, toppra re-solves, re-check rounds, toppra's jerk-free
        profile, the optimiser's record, cycle RMS in N m, whether the thermal limit binds, thermal re-solves). ``warm``: the
        members' evaluations toppra's friction fixed point starts from (None: no friction)."""
        pm, spec, stage = self.pm, self.spec, self.stage
        rated = thermal_limit(pm, spec)
        limit = planning_limit(pm, spec)
        bound = rated * (1.0 - THERMAL_BACKOFF) if stage is not None and stage.thermal is not None else None
        for t_it in range(spec.recheck_max_rounds):
            out = self.at_level(limit, warm, stage=stage, rms_bound=bound)
            prof, evs, record = out[0], out[1], out[6]
            rms = cycle_rms(evs[0], prof, self.rest_time, self.rest_torque)
            if rms <= rated:
                return (*out, rms, rms > rated * (1.0 - spec.thermal_tolerance), t_it)
            if bound is None or record.get("status") == "fallback":
                return self.bisect_thermal(rms, evs, record)
            bound *= rated / rms * (1.0 - THERMAL_BACKOFF)
        raise PlanningError(f"{spec.source}: thermal limit: the full model's cycle RMS {rms:,.0f} N m is still above the thermal limit "
                            f"{rated:,.0f} N m ((1 - planning.limits.thermal_feedback_reserve) x motor.rated_torque_Nm) after {spec.recheck_max_rounds} re-solves of the jerk-limited stage; raise "
                            "planning.solver.recheck_max_rounds or tighten planning.solver.friction_tolerance_Nm")

    def bisect_thermal(self, rms, evs, record=None, stage=None):
        """The thermal limit for toppra's stroke, which cannot take an RMS: the highest peak-torque level whose
        stroke's cycle RMS is <= :func:`thermal_limit` (stepped down from the planning limit towards the static torque
        :attr:`static`, then bisected to ``thermal_tolerance``). ``rms``, ``evs``: the RMS and evaluations of the stroke at
        the planning limit; ``record``: the jerk-limited stage's fallback record, kept; ``stage``: a jerk-limited stage
        to plan each level with (tests compare the optimum under the RMS row against this bisection).

        Returns what :meth:`meet_thermal_limit` returns."""
        pm, spec = self.pm, self.spec
        dwell, hold = self.rest_time, self.rest_torque
        motor = pm.press.motor
        limit, rated = planning_limit(pm, spec), thermal_limit(pm, spec)
        if abs(hold) > rated and dwell > 0:
            raise PlanningError(f"{spec.source}: the holding torque at rest ({abs(hold):,.0f} N m: at TDC, and at the stops on the way "
                                f"as their time's RMS) alone exceeds the thermal limit {rated:,.0f} N m; shorten planning.dwell_s "
                                "(planning.hold.bottom_dwell_s, planning.pause.time_s) or check the balance system")
        t_it = 0
        # ok(L): feasible and RMS <= T_rated. It fails at the margin (RMS too high) and again below the level
        # the stroke needs at all (infeasible), so step down from the margin towards the static torque until
        # it holds, then bisect between that level and the last failing one above it.
        floor = float(np.max(np.abs(self.static)))
        hi, best, tried, stopped = limit, None, [], None
        for k in range(1, THERMAL_STEPS + 1):
            lo = limit - (limit - floor) * k / THERMAL_STEPS
            t_it += 1
            try:
                cand = self.at_level(lo, evs, stage)
            except PlanningError as err:
                stopped = err
                break
            tried.append((lo, cycle_rms(cand[1][0], cand[0], dwell, hold)))
            if tried[-1][1] <= rated:
                best = cand
                break
            hi = lo
        if best is None:
            seen = ", ".join(f"{lv:,.0f} N m -> RMS {r:,.0f}" for lv, r in tried) or "none"
            why = (f"the level {lo:,.0f} N m could not be planned ({stopped})" if stopped is not None
                   else f"down to the level {lo:,.0f} N m none brought it below")
            raise PlanningError(
                f"{spec.source}: thermal limit: the cycle RMS {rms:,.0f} N m exceeds {rated:,.0f} N m ((1 - planning.limits.thermal_feedback_reserve) "
                f"x the rated torque {motor.rated_torque:,.0f} N m) with toppra's jerk-free stroke at lower peak-torque levels "
                f"(levels tried: {seen}); {why}; lengthen planning.dwell_s, lower the process force, or use motors with a higher rated torque")
        while (hi - lo) > spec.thermal_tolerance * limit * 0.1:
            mid = 0.5 * (lo + hi)
            t_it += 1
            cand = self.at_level(mid, best[1], stage)
            r_mid = cycle_rms(cand[1][0], cand[0], dwell, hold)
            if r_mid <= rated:
                lo, best = mid, cand
                if rated - r_mid <= spec.thermal_tolerance * rated:
                    break
            else:
                hi = mid
        prof, evs, lvl, f_it, rounds, first, rec = best
        return prof, evs, lvl, f_it, rounds, first, record or rec, cycle_rms(evs[0], prof, dwell, hold), True, t_it


def grid_row(pm: PressModel, power, always: bool = False) -> GridRow | None:
    """The jerk-limited stage's rows of the supply limit ``power`` (:class:`planning.power.PowerLimit`; None or no limit:
    none, unless ``always``: then rows without a bound, for a grid-energy objective), in units of the grid power of both
    motors at peak torque and top speed."""
    if not always and (power is None or not power.limited):
        return None
    from .power import grid_bound_coefficients

    press = pm.press
    a, b, c, k = grid_bound_coefficients(press.electrical, press.drive.motors)
    scale = k * press.motor.peak_torque * press.motor.max_speed
    losses = tuple(float(x) for x in loss_coefficients(press.drive)) if press.drive.has_losses else None
    return GridRow(a, b, c, k, press.drive.gear_ratio, braking_ratio(press.drive), scale,
                   power.grid_peak_limit_W * (1.0 - GRID_BACKOFF), losses=losses)


class RefusedPlan(PlanningError):
    """A stroke planned whole and then refused by a check of the job (a continuous stroke's transfer window): the message
    says why; ``plan``: the stroke as planned, another row's start (:mod:`planning.modes`). Pickled as the message alone."""

    def __init__(self, message: str, plan: Plan | None = None):
        super().__init__(message)
        self.plan = plan

    def __reduce__(self):
        return PlanningError, (str(self),)


def plan_stroke(problem: StrokeProblem, dwell: float | None = None, power=None, start=None, robust: Robust | None = None,
                row: GridRow | None = None) -> Plan:
    """The time-optimal stroke of ``problem`` (a job on a press, its knots and path dynamics; see the module docstring
    for the loops).

    ``dwell`` (s) overrides the job's dwell (for :mod:`scripts.find_dwell`). Raises :class:`PlanningError` for an
    infeasible job. ``power``: the supply limit (:class:`planning.power.PowerLimit`) the jerk-limited stage holds at its
    knots and checks (None or no limit: none; :func:`planning.energy.plan_under_grid_limit` re-checks the written
    profile). ``start``: a jerk-limited profile on the same knots (another plan's optimum) to start the optimal-control
    stage from instead of toppra's smoothed stroke, or a :class:`Plan` on the same knots (another row's, of this mode): its
    optimum starts the stage and, unless ``robust`` brings its own, its jerk-free profile toppra's friction fixed point
    (the members evaluated along it: a robust plan from the nominal one needs a few re-solves instead of 8-13 from no
    friction; the fixed point ends within its tolerance of where it ends from none). ``robust``: the parameter sets the torque limit must hold for and how
    (:class:`Robust`; None: the problem's press alone). ``row``: the stage's grid rows as built instead of ``power``'s
    (:func:`planning.energy.plan_min_energy`). ``problem.spec.mode``: "stop-at-top" (at rest at both ends) or
    "continuous" (the same speed at both ends); the motion modes above one stroke ("auto", "pendulum") are
    :mod:`planning.modes`'.
    """
    pm, spec, grid, pd = problem.pm, problem.spec, problem.grid, problem.pd
    if spec.mode == "auto":  # the modes are strategies above the planner (planning.modes), which knows one stroke's ends
        raise PlanningError(f"{spec.source}: planning.mode = \"auto\" chooses among the motion modes: planned by "
                            "planning.modes.plan_in_mode, not by one stroke's planner")
    if spec.mode == "pendulum":
        raise PlanningError(f"{spec.source}: planning.mode = \"pendulum\" is planned by planning.pendulum.plan_pendulum "
                            "(servo-press plan); this command plans mode = \"stop-at-top\", \"continuous\" or \"auto\"")
    if dwell is None and spec.transfer is not None and spec.mode == "stop-at-top":
        return plan_with_transfer(lambda d: plan_stroke(problem, d, power, start, robust), pm, spec, thermal_limit(pm, spec))
    prior = start if isinstance(start, Plan) else None
    if prior is not None:
        start = prior.profile
    dwell = spec.dwell if dwell is None else float(dwell)
    static = static_check(pm, pd, planning_limit(pm, spec), spec.source, problem.creep_torque())
    still = np.zeros(pd.n, bool)
    if spec.mode == "stop-at-top":
        still[0] = still[-1] = True
    stops = stops_on_grid(pd, pm.press.drive, grid, spec.stops)
    for st in stops:  # the crank rests there (toppra: x <= STOP_X at the knot; the jerk-limited stage: speed and acceleration 0)
        still[st.index] = True
    hold = problem.hold_torque()
    if spec.mode == "continuous":
        dwell = 0.0
    robust = robust or Robust([Member(pd, pm.press.drive, pm.press.friction)])
    members, stage = robust.members, robust.stage
    rest_torque, rest_time = equivalent_rest(hold, dwell, stops)  # the dwell and the stops, as the thermal limit counts them
    limits = problem.limits(still, ThermalLimit(thermal_limit(pm, spec), rest_torque, rest_time), row or grid_row(pm, power)).over(robust.region)
    if stage is None:
        stage = JerkStage(pm, limits, spec, start) if math.isfinite(spec.crank_jerk) else None
    else:
        members = stage.members
    warm = robust.warm
    if warm is None and prior is not None and prior.jerk_free_profile is not None and np.array_equal(prior.grid.theta, grid.theta):
        warm = evaluate_members(pm, members, prior.jerk_free_profile)
    planner = StrokePlanner(pm, members, limits, spec, static, rest_time, rest_torque, stage, robust.fallback)
    prof, evs, lvl, f_it, rounds, first, record, rms, thermal_binding, t_it = planner.meet_thermal_limit(warm)
    peak = max(max(float(np.max(np.abs(e.motor_right))), float(np.max(np.abs(e.motor_left))), _between_knots_peak(e, prof, grid.theta))
               for e in evs)
    peak = max([peak] + [abs(st.torque) for st in stops])
    u = pm.press.drive.gear_ratio
    win = grid.in_window
    # toppra's stroke at the planning limit: a lower bound of the jerk-limited stroke; where the thermal limit
    # binds, toppra (no RMS) relaxes it too, so the bound stays a bound of the optimum under the RMS row
    plan = Plan(spec=spec, grid=grid, pd=pd, profile=prof, evaluation=evs[0], dwell=dwell, hold_torque=hold, torque_level=lvl,
                peak_torque=peak, rms_torque=rms, max_motor_speed=float(np.max(prof.sd) * u),
                max_window_slide_speed=float(np.max(np.abs(pd.dh[win]) * prof.sd[win])) if win.any() else 0.0,
                thermal_binding=thermal_binding, friction_iterations=f_it, recheck_rounds=rounds, thermal_iterations=t_it,
                jerk_free_stroke_time=first.stroke_time, jerk_free_profile=first, optimiser=record, stops=stops, stage=stage,
                member_evaluations=evs)
    if spec.transfer is not None and spec.mode == "continuous":
        try:
            plan.transfer = continuous_check(pm, plan, spec)
        except PlanningError as err:
            raise RefusedPlan(str(err), plan) from None
    return plan
