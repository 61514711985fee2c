"""The jerk-limited stage of a plan: the friction fixed point around the collocation, its screening, and the stage object.

:func:`optimise` re-solves the collocation (:class:`planning.optimal.CollocationProblem`) with the friction held at the
previous solution's until it is consistent with its own friction; :func:`solve_jerk_limited` starts it from toppra's
profile smoothed (:class:`planning.jerk.SmoothProfile`), screens the motor-speed rows by toppra's envelope and a robust
plan's members (:func:`screen_members`), and rebuilds the problem where a screened-out row is broken; :class:`JerkStage`
is one plan's stage over its limits (:class:`planning.limits.Limits` held over a region), built at the first solve and
reused for the re-check rounds; :class:`Robust` says how a plan is planned over a region.

Units: rad, s, N m; torques per motor where they are motor torques.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import casadi as ca
import numpy as np

from .evaluation import evaluate_members, share_friction_slopes
from .jerk import JerkProfile, SmoothProfile
from .limits import Limits, OptimalControlError, Region, lossy_torque_magnitude, row_factors
from .optimal import TORQUE_TOLERANCE, CollocationProblem, SolverSettings, TorqueRows, rows_from_evaluation
from .settings import PlanningSpec

TORQUE_KEEP = 2  # robust plan: on each segment the torque rows of this many members with the largest torque at the start enter ...
TORQUE_SCREEN = 0.005  # ... and those of any member within this fraction of the largest
SCREEN_ROUNDS = 2  # rebuilds adding broken screened-out torque rows before every row goes in
SPEED_TOLERANCE = 1e-6  # relative excess of a screened-out speed row that makes the problem be rebuilt with every row
FIXED_POINT_CONTRACTION = 0.5  # a friction re-solve whose residual fell by less than this factor (it falls ~x15 per re-solve where the friction is smooth) and whose stroke time repeats the one before: a cycle over a friction kink


@dataclass
class Result:
    """The stage's outcome: the profile, the members' torque rows at it, and how the solves went."""

    profile: JerkProfile
    rows: list
    evaluation: object  # whatever ``evaluate`` returned with the rows (the planner's Evaluation per member)
    solves: list = field(default_factory=list)  # Solve per IPOPT call, friction re-solves in order
    friction_change: float = math.nan  # N m: the fixed point's residual at the solution (see _rest_change)
    kink: bool = False  # the fixed point ended in a cycle over a friction kink (optimise), not below its tolerance

    def convergence(self) -> dict:
        """What summary.json records about the stage's convergence (no timings: a re-run writes the same bytes)."""
        return {
            "solver": f"IPOPT via CasADi {ca.__version__}",
            "status": self.solves[-1].status if self.solves else "none",
            "ipopt_iterations": [s.iterations for s in self.solves],
            "friction_re_solves": len(self.solves),
            "friction_residual_Nm": self.friction_change,
            "friction_kink_cycle": self.kink,
        }


def _rest_change(old: list[TorqueRows], new: list[TorqueRows]) -> float:
    """Largest error (N m) of the friction model a solve used (``old``: rests with their slopes in the acceleration)
    at the solution's own accelerations and speeds (``new``): the fixed point's residual."""
    err = 0.0
    for a, b in zip(old, new):
        # the rows' c carries the friction's slope in x: the part of it that changed is the friction's too
        xb = b.x if b.x is not None else 0.0
        pred_r = a.rest_right + a.slope * (b.u_right - a.u_right) - (b.c - a.c) * xb
        pred_l = a.rest_left + a.left[2] * (b.u_left - a.u_left) - (b.left[1] - a.left[1]) * xb
        err = max(err, float(np.max(np.abs(b.rest_right - pred_r))), float(np.max(np.abs(b.rest_left - pred_l))))
    return err


def optimise(problem: CollocationProblem, evaluate, level: float, start, rows: list[TorqueRows] | None = None,
             rms_bound: float | None = None, holds=None, residual=None) -> Result:
    """The jerk-limited optimum at torque level ``level`` with the friction fixed point.

    ``evaluate(profile) -> (rows, evaluation)``: the members' :class:`TorqueRows` along a profile and the
    full-model evaluation they came from. ``start``: the first guess; ``rows``: friction to start from
    (default: evaluated along ``start``); ``rms_bound``: the thermal row's bound (N m, :meth:`CollocationProblem.solve`). Re-solves from the previous solution until the friction at a
    solution differs from the friction it was solved with by less than the settings'
    ``friction_tolerance_torque`` (N m) everywhere: the solution is then consistent with its own friction.
    ``holds(profile, level)``: with worst-case rows (:class:`planning.limits.WorstCase`), whether every member's rows hold at a
    solution; until they do, the fixed point goes on (the worst cases chosen again at that solution). ``residual(rows,
    new_rows)``: the fixed point's residual (N m; default :func:`_rest_change`; with worst-case rows, on the corners the
    solve used, not on those chosen at its solution).
    """
    st = problem.settings
    if rows is None:
        rows, _ = evaluate(start)
    solves = []
    x, last = start, math.inf
    for _ in range(st.friction_max_iterations):
        sol = problem.solve(rows, level, x, rms_bound)
        solves.append(sol)
        new_rows, evs = evaluate(sol.profile)
        change = (residual or _rest_change)(rows, new_rows)
        rows, x = new_rows, sol.z
        if change < st.friction_tolerance_torque and (holds is None or holds(sol.profile, level)):
            return Result(sol.profile, rows, evs, solves, change)
        if (change > FIXED_POINT_CONTRACTION * last and len(solves) > 2
                and problem.repeats(sol, solves[-2])
                and (holds is None or holds(sol.profile, level))):
            # a cycle over a kink of the friction in the acceleration (mu |reaction|, a joint's reaction through zero):
            # the linearised friction puts each solution on the kink's other side, so the residual stays; the cycle's
            # strokes are equally fast, and the plan's limits are checked on the full model at this one (the planner)
            return Result(sol.profile, rows, evs, solves, change, kink=True)
        last = change
    raise OptimalControlError(f"the friction fixed point did not settle in {st.friction_max_iterations} re-solves "
                              f"(friction torque still changing by {change:.3g} N m)")


def screen_members(problem_limits: Limits, rows: list[TorqueRows], prof) -> list[np.ndarray] | None:
    """Per member the segments where its torque rows can bind: along ``prof`` (the start), the ``TORQUE_KEEP``
    members with the largest |T_m| on a segment's ends, and any other within ``TORQUE_SCREEN`` of the largest.

    One member: None (every segment). The rows left out are verified on the solution
    (:meth:`CollocationProblem.check_torques`) and added where broken."""
    if len(rows) == 1:
        return None
    w, a = np.asarray(prof.sd, float), np.asarray(prof.knot_accels()[0], float)
    ratios = []
    for r in rows:
        lo, hi = row_factors(r.drive, problem_limits.standstill)
        j = r.drive.gear_inertia * r.drive.gear_ratio**2
        m_l, c_l, sl_l = r.left
        br = (r.m + j) * a + r.c * w * w + r.rest_right + r.slope * (a - r.u_right)
        bl = (m_l + j) * a + c_l * w * w + r.rest_left + sl_l * (a - r.u_left)
        if r.drive.has_losses:
            kr, kl = lossy_torque_magnitude(r.drive, br, w), lossy_torque_magnitude(r.drive, bl, w)
        else:
            kr = np.maximum(br / hi, br / lo)
            kl = np.maximum(bl / hi, bl / lo)
        ratios.append(np.maximum(kr[:-1], kl[1:]))  # per segment, |T_m| per N m of level
    R = np.array(ratios)
    best = np.max(R, axis=0)
    rank = np.argsort(np.argsort(-R, axis=0), axis=0)
    keep = (rank < TORQUE_KEEP) | (R >= best * (1.0 - TORQUE_SCREEN))
    return [np.flatnonzero(keep[k]) for k in range(len(rows))]


def solve_jerk_limited(limits: Limits, evaluate, level: float, base, settings: SolverSettings | None = None,
                       problem: CollocationProblem | None = None, rms_bound: float | None = None, start=None,
                       worst=None) -> tuple[Result, CollocationProblem]:
    """The stage: toppra's profile ``base`` -> a jerk-feasible start -> :func:`optimise` at ``level`` (N m per motor).

    The start is ``base`` filtered by a moving average of its acceleration (:class:`planning.jerk.SmoothProfile`),
    jerk-limited by construction though not within the other limits: from it IPOPT needs about a third of the
    iterations it needs from the bang-bang profile itself, and reaches the same optimum. ``base`` is also
    the speed envelope that screens the motor-speed rows, and with several members (robust plan) the start
    screens their torque rows (:func:`screen_members`); if a screened-out row is broken at the optimum, the
    problem is rebuilt with it (up to ``SCREEN_ROUNDS`` times, then with every row). ``problem``: a problem
    built before for the same limits and members (re-check rounds). ``limits.thermal``: the cycle-RMS limit the problem
    carries as a row, ``rms_bound`` (N m) its bound in this solve (None: free). ``start``: a jerk-limited profile on
    the same knots to start from instead (another plan's optimum: the robust plan from the nominal one, the
    calibrated plan from the theoretical one), or with ``problem`` a decision vector of it (a robust plan's re-solve after
    a cut: its last solution, whose multipliers IPOPT then starts from too). ``worst``: the evaluator's worst-case groups
    (:class:`planning.limits.WorstCase`; None: none), whose rows must hold at a solution and on whose kept corners the
    friction fixed point's residual is taken (:func:`optimise`'s ``holds``, ``residual``). ``limits.grid``: the supply's
    peak-power rows (:class:`GridRow`; None: none). Returns (result, problem).
    """
    z0 = None
    if isinstance(start, np.ndarray) and problem is not None:  # a decision vector of ``problem`` (its last solve's: with its multipliers)
        z0, start = start, problem.unpack(start)
    if start is None or not np.array_equal(getattr(start, "theta", None), limits.theta):
        start = SmoothProfile(base, limits.theta, limits.jerk, periodic=limits.periodic)
    rows, _ = evaluate(start)
    holds = (lambda prof, lv: worst.holds(prof, lv, TORQUE_TOLERANCE)) if worst is not None else None
    residual = (lambda rows_, new_rows: _rest_change(rows_, worst.kept)) if worst is not None else None
    if problem is None:
        problem = CollocationProblem(limits, rows, settings, envelope=base.sd, torque_segments=screen_members(limits, rows, start))
    for rnd in range(SCREEN_ROUNDS + 1):
        res = optimise(problem, evaluate, level, start if z0 is None else z0, rows, rms_bound, holds, residual)
        z = res.solves[-1].z
        speed_ok = problem.check_speeds(z) <= SPEED_TOLERANCE * problem.w_ref
        torque_ok = problem.check_torques(z, res.rows, level) <= TORQUE_TOLERANCE
        if speed_ok and torque_ok:
            return res, problem
        segs = None
        if rnd < SCREEN_ROUNDS and speed_ok:  # add the segments where a screened-out member breaks the limit
            segs = [np.union1d(keep, problem.broken_torque_segments(z, res.rows, level, k)) for k, keep in enumerate(problem.torque_segments)]
        problem = CollocationProblem(limits, rows, settings, envelope=None if not speed_ok else base.sd, torque_segments=segs)
    raise OptimalControlError("screened-out limit rows were still broken after the rebuilds with every row")


@dataclass
class Robust:
    """How a plan is planned over a region (:class:`planning.limits.Region`: ``members``, ``worst_case``, ``screen``;
    :mod:`planning.robust`): the region's data and ``warm``: an evaluation per member
    (:func:`planning.evaluation.evaluate_members`) whose friction toppra's fixed point starts from (None: from none);
    ``stage``: the jerk-limited stage of an earlier plan on the same knots, reused with its built problem (a re-solve after
    a cut: its own members, worst-case groups and start are then the plan's); ``fallback``: False raises
    :class:`planning.limits.OptimalControlError` where the jerk-limited stage fails instead of planning toppra's jerk-free
    stroke (a robust plan then tries every corner's rows). :func:`planning.planner.plan_stroke` holds its limits
    :meth:`planning.limits.Limits.over` :attr:`region`."""

    members: list
    worst_case: list | None = None
    screen: object = None
    warm: list | None = None
    stage: JerkStage | None = None
    fallback: bool = True

    @property
    def region(self) -> Region:
        """The region the limits hold over: the members, their worst-case groups and screen."""
        return Region(self.members, self.worst_case, self.screen)


class JerkStage:
    """The optimal-control stage of one plan: its limits, the members' evaluator and the collocation problem,
    built at the first solve and reused for the re-check rounds.

    ``limits``: what the stroke keeps (:class:`planning.limits.Limits`, with the cycle-RMS and grid rows it carries)
    over its region (:meth:`planning.limits.Limits.over`: the members, the first the press the plan is for, their
    worst-case groups and screen, whose ``screen(base, level) -> [(Member, row types)]`` is called once, at the first
    solve, with toppra's profile and the torque level); ``spec``: the job's solver settings; ``start``: a jerk-limited
    profile on the same knots to start from (None: toppra's, smoothed)."""

    def __init__(self, pm, limits: Limits, spec: PlanningSpec, start=None):
        region = limits.region
        if region is None:
            raise ValueError("JerkStage: the limits hold over no region; give them one (Limits.over)")
        self.pm, self.members, self.limits = pm, list(region.members), limits
        self.settings = SolverSettings(spec.optimal_tolerance, spec.optimal_max_iterations, spec.friction_tolerance_torque,
                                       spec.friction_max_iterations, spec.friction_tolerance)
        self.thermal, self.start = limits.thermal, start
        self.problem = None
        # groups of members whose worst case per segment enters the problem instead of each member
        self.worst = region.worst(limits.theta, limits.standstill)
        self.screen = region.screen if self.worst is not None else None

    def join(self, new) -> None:
        """Add members to the worst-case groups: ``new`` [(Member, row types)], each appended to the members and to the
        group of every row type it names (its drive alike the group's but for the gear inertia, :func:`planning.limits._combine`)."""
        for m, kinds in new:
            self.members = self.members + [m]
            for kind, idx in self.worst.groups:
                if kind in kinds:
                    idx.append(len(self.members) - 1)

    def evaluate(self, prof):
        """The members' torque rows along ``prof`` (with worst-case groups: the ungrouped members' and each group's
        worst case per segment) and every member's evaluation they come from."""
        evs = evaluate_members(self.pm, self.members, prof)
        # the friction's slopes per path dynamics, the members' frictions side by side (two full-model evaluations each
        # way, a third of the stage's; members differing in the drive alone share them)
        share_friction_slopes(evs)
        rows = [rows_from_evaluation(e) for e in evs]
        return (rows if self.worst is None else self.worst.compose(rows, prof)), evs

    def solve(self, level: float, base, rms_bound: float | None = None) -> Result:
        """The jerk-limited optimum at ``level`` (N m per motor) from toppra's profile ``base``, its cycle RMS within
        ``rms_bound`` (N m per motor; None: no thermal row); raises :class:`OptimalControlError` when it is not reached."""
        if self.screen is not None and self.problem is None:
            screen, self.screen = self.screen, None
            self.join(screen(base, level))
        try:
            res, self.problem = solve_jerk_limited(self.limits, self.evaluate, level, base, self.settings, self.problem,
                                                   rms_bound, self.start, self.worst)
        except ValueError as err:  # the moving-average start: the filter is wider than a continuous stroke
            raise OptimalControlError(f"no jerk-limited start: {err}") from None
        return res
