"""Jerk-limited time-optimal stroke: direct collocation of the crank motion, solved by IPOPT through CasADi.

Why this method. toppra has no third-order (jerk) constraint (upstream issue #133); a moving average of its
bang-bang acceleration makes the stroke jerk-limited, but pays the filter's width once and then more in the
rounds that re-tighten the limits the averaging breaks. Here the jerk limit is a constraint of the problem
itself, so the stroke is the time optimum under every limit at once (a local optimum of a nonconvex problem:
tests check it from different starts, against toppra's jerk-free lower bound and on a finer grid).

Transcription. The crank angle is fixed at the planning knots theta_0 < ... < theta_N (the same grid as
toppra's); the unknowns are the crank speed w_i and acceleration a_i at every knot and the duration h_i of
every segment (3 N + 2 variables: 1,097 on the door panel's 1-degree grid). The jerk is constant on a
segment, j_i = (a_{i+1} - a_i) / h_i, so the motion inside it is an exact cubic in time and

    theta_{i+1} - theta_i = h_i (w_i + h_i (2 a_i + a_{i+1}) / 6),   w_{i+1} = w_i + h_i (a_i + a_{i+1}) / 2,

are the collocation (continuity) conditions; |a_{i+1} - a_i| <= J h_i is the jerk limit (linear). The
objective is the stroke time sum h_i. Stop-at-top: w = a = 0 at both ends (the crank leaves and reaches the
dwell at rest without a jump of acceleration); continuous: w and a equal at both ends (the stroke repeats).

Limits between the knots, not only at them. A solution that keeps its limits at the knots may break them
between: checked only at knots, the forming-window slide speed reached 0.326 m/s against 0.30 m/s. Every
limit is therefore imposed at the knots and at 1/4, 1/2 and 3/4 of every segment's duration, where the
state is the segment's cubic. There:

* torque: per member (parameter set, see :class:`TorqueRows`) the crank torque m a + c w^2 + rest with m, c
  and the rest (gravity, balance, process force, friction) interpolated linearly in crank angle between the
  segment's two ends and the friction carried to the point's own acceleration by its slope, the same
  interpolation as the written profile's torque (``Evaluation.torque_between``); through Eq. 16 this is
  two linear rows in the crank torque (motoring: / (n u eta), braking: x eta / (n u)), the press file's
  standstill exponent at the knots where the crank rests; with the press file's drive losses ([drive.losses]) three
  smooth rows in (B, w) instead, exact on the physical branch (:func:`press_model.motor.lossy_torque_rows`: Eq. 16's
  motoring and braking forms with k (B / (n u))^2 + c u w, and the branch bound as a row of its own; where the crank
  rests its torque is fixed, and checked before the solve);
* speed: the motor speed and, in the forming window, the slide speed |dH/dtheta| w with dH/dtheta from the
  same cubic Hermite interpolation of the slide height as the written profile. The crank speed is a
  quadratic in time on a segment with |second derivative| = |j|, so between two checks h/4 apart it can rise
  at most |j| (h/4)^2 / 8 above the larger of them; that amount is kept free below the limit at every check
  (for the slide speed D(theta) w with the second derivative D j + 3 D' w a + D'' w^3 in its place).

Which rows enter. The motor-speed rows only where toppra's jerk-free profile (which bounds every admissible
speed) comes within 10 % of the limit or of standstill, and with several members (robust plan) a member's
torque rows only where it is among the two worst members at the start (or within 0.5 % of the worst); the rows left out are evaluated
on the solution, and a broken one is added and the problem rebuilt (:func:`planning.jerk_stage.solve_jerk_limited`).

Friction. Friction depends on the joint reactions and so on the motion; as in the toppra stage it is held at
the values of the previous solution (per knot and side, with its slopes in the acceleration and in x = theta_dot^2,
the latter carried in the rows' c) and the problem re-solved until the friction at the solution is the friction it was
solved with, to ``friction_tolerance_Nm`` (:func:`planning.jerk_stage.optimise`). With the slope in x the second solve is usually consistent
to 0.01 N m (seed-101 calibration: 2 solves instead of 5, the residual 27 -> 2 N m of the acceleration slope alone
being the speed's: the reactions carry the linkage's centripetal forces).

Thermal limit. The cycle RMS of Eq. 24 on the plan's press (the first member) is a limit of the problem too:
sum_i h_i Q_i + T_hold^2 t_dwell <= T_bound^2 (sum_i h_i + t_dwell), Q_i Boole's rule of T_m^2 over the
segment's knots and checks (the planner's own quadrature, :func:`planning.evaluation.segment_rms_integral`),
T_m from the same torque rows through Eq. 16 (eta switching with the sign of the power, in smooth form; with the drive
losses their terms at each point's own speed, :func:`press_model.motor.smooth_lossy_motor_torque`). The
sum is carried as a running sum over the segments (N more unknowns, banded rows) with the bound on its end:
one dense row would make the Jacobian's colouring touch every segment at once. So the stroke is the time
optimum under the RMS limit as well: it may keep the full torque where that pays most and give way elsewhere,
where lowering the torque level everywhere (bisection) slows every phase alike.

Building. The symbolic problem is built once per plan; the friction terms, the drive's factors, the rated
torque and the torque level are parameters or bounds, so re-solves need no rebuild, and a built IPOPT solver
is kept (``SOLVER_CACHE``) for later plans on the same knots with the same limits and rows (compare's
calibrated plan reuses the theoretical plan's).

Units: rad, s, N m; torques per motor where they are motor torques.
"""
from __future__ import annotations

import contextlib
import io
import math
import signal
import sys
import time
from dataclasses import dataclass

import casadi as ca
import numpy as np

from press_io.interrupts import Interrupted, watch
from press_model.motor import LOSS_TERMS, braking_ratio, loss_coefficients
from press_model.press_data import Drive

from .evaluation import CHECKS, Evaluation
from .jerk import JerkProfile
from .limits import Limits, OptimalControlError, branch_can_bind, lossy_torque_magnitude, row_factors
from .segment_map import segment_map

TORQUE_TOLERANCE = 1e-6  # relative excess of a torque row at the optimum that counts as broken (IPOPT meets its rows to ~1e-7)
TORQUE_PARAMS = 9  # per member and segment: m and c at both ends, the friction terms (fixed part and slope) at both ends, the row scale
WARM_MU_INIT = 1.0e-9  # a re-solve from a previous solution and its multipliers: IPOPT's monotone barrier from this (the cold start's adaptive one walks the barrier down again from far off the optimum: door panel 38-32-10-19 iterations against 38-19-13-13, stroke times within 4e-7 s)
SOLVER_CACHE = 8  # built IPOPT solvers kept for later plans with the same knots, limits and rows (compare, reproduce)
_SOLVERS: dict = {}


def clear_solvers() -> None:
    """Forget the built IPOPT solvers (:data:`SOLVER_CACHE`). Which one a plan reuses decides its speed rows (a superset
    gives the same optimum, not the same iterates), so a run that must give the same bytes whatever ran before it in
    the process (``reproduce``) starts from none."""
    _SOLVERS.clear()


# IPOPT's status when it was told to stop: CasADi returns it after a KeyboardInterrupt in its Python callbacks (and
# NonIpopt_Exception_Thrown after one in its own check of Ctrl-C, which watch() sees); never a reason to fall back
USER_STOP = "User_Requested_Stop"
_CASADI_INTERRUPT_NOTE = "KeyboardInterruptException"  # CasADi's warning line when it stops IPOPT for Ctrl-C


def call_solver(solver, **args):
    """``solver(**args)`` (a CasADi nlpsol), returning its result; a Ctrl-C or SIGTERM that reaches the process while
    IPOPT runs is raised as :class:`press_io.interrupts.Interrupted` after the call, never returned as a failed
    solve: CasADi catches the interrupt, stops IPOPT and returns a status, which the planner would take for a failure
    and plan toppra's jerk-free fallback in its place. CasADi's warning about the interrupt is kept off stderr."""
    text = io.StringIO()
    try:
        with watch() as seen, contextlib.redirect_stderr(text):  # CasADi writes its warnings to sys.stderr
            res = solver(**args)
    finally:
        notes = [line for line in text.getvalue().splitlines(keepends=True) if _CASADI_INTERRUPT_NOTE not in line]
        sys.stderr.write("".join(notes))
    if seen.signum is not None:
        raise Interrupted(seen.signum)
    if solver.stats().get("return_status") == USER_STOP:
        raise Interrupted(signal.SIGINT)
    return res


@dataclass(frozen=True)
class TorqueRows:
    """One parameter set's crank torque along the path, with friction held at a reference profile's values.

    At knot i with acceleration a and speed w the crank torque (N m) is m[i] a + c[i] w^2 + rest, where
    rest = rest_right[i] + slope[i] (a - u_right[i]) for the segment that starts at the knot and the same with
    ``_left`` for the segment that ends there (they differ where the process force steps or the slide turns).
    ``rest_*`` is what the full model gives beyond m a + c w^2 at the reference profile (gravity, balance,
    process force, friction, N m); ``slope`` the friction's derivative in the acceleration (N m per rad/s^2).
    ``drive``: Eq. 16 for this parameter set.
    """

    m: np.ndarray  # N m per rad/s^2 (linkage only; the gear inertia comes from ``drive``)
    c: np.ndarray  # N m per (rad/s)^2, the friction's slope in x included (rows_from_evaluation; ``rest_*`` taken with it)
    rest_right: np.ndarray
    rest_left: np.ndarray
    slope: np.ndarray
    u_right: np.ndarray  # rad/s^2: the reference profile's accelerations the rests were taken at
    u_left: np.ndarray
    drive: Drive
    # the segment that ends at a knot may take its m, c and slope from another parameter set than the one that starts
    # there (a worst-case member, planning.limits.WorstCase): the values for the segment ending at each knot (None: m, c, slope)
    m_left: np.ndarray | None = None
    c_left: np.ndarray | None = None
    slope_left: np.ndarray | None = None
    x: np.ndarray | None = None  # (rad/s)^2: the reference profile's theta_dot^2 (c holds the friction's slope in x, rest its value there)

    @property
    def left(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(m, c, slope) for the segment that ends at each knot."""
        return (self.m if self.m_left is None else self.m_left, self.c if self.c_left is None else self.c_left,
                self.slope if self.slope_left is None else self.slope_left)

    @property
    def fixed_right(self) -> np.ndarray:
        """rest_right - slope u_right: the part of the rest independent of the acceleration (N m)."""
        return self.rest_right - self.slope * self.u_right

    @property
    def fixed_left(self) -> np.ndarray:
        return self.rest_left - self.left[2] * self.u_left


def rows_from_evaluation(ev: Evaluation) -> TorqueRows:
    """:class:`TorqueRows` of a full-model evaluation along a profile: the friction linear in the acceleration (``slope``)
    and in x = theta_dot^2 (its slope added to ``c``, the rests taken with it), so that the fixed point's next friction is
    predicted to first order in both (the speed moves the reactions through the linkage's centripetal forces)."""
    slope = ev.friction_slopes[0] if ev.pd is not None else np.zeros_like(ev.x)
    c = np.asarray(ev.c, float) + (ev.friction_x_slopes if ev.pd is not None else 0.0)
    return TorqueRows(np.asarray(ev.m, float), c,
                      ev.crank_right - ev.m * ev.u_right - c * ev.x, ev.crank_left - ev.m * ev.u_left - c * ev.x,
                      np.asarray(slope, float), np.asarray(ev.u_right, float), np.asarray(ev.u_left, float), ev.drive,
                      x=np.asarray(ev.x, float))


@dataclass(frozen=True)
class SolverSettings:
    """IPOPT settings of the stage (the job's [planning.solver] optimal-control entries)."""

    tolerance: float = 1.0e-9  # IPOPT's relative KKT tolerance
    max_iterations: int = 500
    friction_tolerance_torque: float = 1.0  # N m of friction torque at the crank
    friction_max_iterations: int = 30
    friction_tolerance_time: float = 1.0e-6  # s: stroke times of a cycle over a friction kink that count as one (planning.jerk_stage.optimise)




# ------------------------------------------------------------------------------------------------
# the transcription


@dataclass(frozen=True)
class StrokeTime:
    """The stage's objective by default: the stroke time sum h_i (s). The stage calls its objective through these
    members without knowing which it is (the other: :class:`planning.energy.EnergyObjective`, the grid energy at a
    stated rate, carried by the grid limit's ``energy``)."""

    tolerance: float  # s: friction re-solves whose stroke times agree so closely reached one optimum (a friction kink)
    structure = ("time",)  # what a built solver depends on
    solver_options = {}  # IPOPT's options over the stage's (none: the stage's are for this objective)
    cycle = None  # no stated cycle: the thermal row's dwell is the job's

    def add_time_row(self, rows, v, h_ref: float):
        """No time row (the time is what is minimised); None."""
        return None

    def objective(self, seg: dict, Y0, v, problem):
        """The stroke time sum h_i (s)."""
        return ca.sum1(v.hs) * problem.h_ref

    def repeats(self, sol: "Solve", before: "Solve") -> bool:
        """Whether two friction re-solves reached the same optimum: stroke times within :attr:`tolerance`."""
        return abs(sol.profile.stroke_time - before.profile.stroke_time) < self.tolerance


class _Rows:
    """The problem's constraint rows as the build adds them: expressions, their bounds, and which are torque rows
    (their bounds are for |T_m| <= 1 N m and scale with the torque level at solve time)."""

    def __init__(self):
        self.g, self.lb, self.ub, self.torque = [], [], [], []

    def add(self, exprs: list, lb: np.ndarray, ub: np.ndarray, torque: bool = False) -> slice:
        """Add rows ``exprs`` with their bounds; ``torque``: bounds for |T_m| <= 1 N m. Returns their place in the rows."""
        start = sum(len(b) for b in self.lb)
        self.g.extend(exprs)
        self.lb.append(lb)
        self.ub.append(ub)
        self.torque.append(np.full(len(lb), torque, bool))
        return slice(start, start + len(lb))


@dataclass(frozen=True)
class _Segment:
    """One segment's symbols the rows are written in: ``zs`` = (w0, w1, a0, a1, h / h_ref), ``dth`` its angle; the knots'
    speeds and accelerations, its duration ``h`` (s), ``d`` = a1 - a0; ``checks`` (speed, acceleration, fraction of the
    angle) at each of CHECKS on the exact cubic; ``speeds`` the crank speed at the 5 points (knots, then checks)."""

    zs: object
    dth: object
    w0: object
    w1: object
    a0: object
    a1: object
    h: object
    d: object
    checks: tuple
    speeds: tuple


@dataclass(frozen=True)
class _Stroke:
    """The whole stroke's unknowns while the problem is built: knot speeds ``w`` and accelerations ``a`` (n each),
    segment durations ``hs`` (N, in units of h_ref); ``Z`` (5 x N) every segment's (w0, w1, a0, a1, h), ``DTH`` its
    angle (1 x N); ``P`` the members' torque parameters (TORQUE_PARAMS x N M, per member and segment; the friction
    terms, rows 4-7, change between solves); ``PL`` the drive-loss coefficients of the members with losses (4 x their
    number, :func:`press_model.motor.loss_coefficients`; None without)."""

    w: object
    a: object
    hs: object
    Z: object
    DTH: object
    P: object
    PL: object = None


class CollocationProblem:
    """The NLP of the module docstring for ``limits`` (:class:`planning.limits.Limits`) and the members' path dynamics,
    built once per plan.

    The transcription owns the unknowns, the segment's cubic in time (:class:`_Segment`), the members' crank torque at
    its points and the continuity rows; every limit adds its own rows (:attr:`planning.limits.Limits.items`, each in
    turn: its rows beside a segment's continuity, over the whole stroke, then those with unknowns of their own). The
    constraints of one segment are a small CasADi function of its two knots' states and duration, mapped over all
    segments: building the solver then differentiates that small function once, not an expression per knot, and IPOPT's
    constraint Jacobian is each segment's own Jacobian block in the unknowns (:func:`planning.segment_map.segment_map`:
    the same bits as CasADi's derivative of the map, without its seeds of the parameters; a row that takes the first
    member's torque, thermal or grid, has the torque inside its segment function, :meth:`of_first_torque`).
    Parameters of the built problem, changed between solves without rebuilding: per member the friction terms
    (:class:`TorqueRows`); the torque level enters through the bounds.
    """

    def __init__(self, limits: Limits, members: list[TorqueRows], settings: SolverSettings | None = None,
                 envelope=None, torque_segments=None):
        """``envelope``: crank speeds (rad/s per knot) no solution exceeds (toppra's jerk-free optimum: the
        time-optimal profile is the upper envelope of all admissible ones); the motor-speed rows are then
        kept only on segments that come within ``SPEED_SCREEN`` of the limit or of standstill, and
        :meth:`check_speeds` verifies the others on the solution. None: every segment's rows.
        ``torque_segments``: per member the segments whose torque rows enter the problem (None: all); a
        robust plan's members are screened so (:func:`planning.jerk_stage.screen_members`) and :meth:`check_torques` verifies.
        ``limits.thermal``: the cycle-RMS limit of the first member, one row of the problem (its bound is set per solve,
        :meth:`solve`'s ``rms_bound``); ``limits.grid``: the supply's peak-power limit on the first member, rows at every
        segment's knots and checks."""
        self.limits, self.settings, self.thermal, self.grid = limits, settings or SolverSettings(), limits.thermal, limits.grid
        # what is minimised: the stroke time, or the grid limit's energy objective (planning.energy)
        self.objective = (self.grid.energy if self.grid is not None and self.grid.energy is not None
                          else StrokeTime(self.settings.friction_tolerance_time))
        self.items = limits.items
        self.envelope = envelope
        self.drives = [r.drive for r in members]
        self.lossy = [d.has_losses for d in self.drives]  # Eq. 16 with the drive losses: smooth rows (planning.limits.TorqueMargin)
        self.branch_rows = [lossy and branch_can_bind(d, limits) for d, lossy in zip(self.drives, self.lossy)]
        self.members = [(np.asarray(r.m, float), np.asarray(r.c, float)) for r in members]
        self.n = limits.n
        N = self.n - 1
        self._scales()
        self._bs = [float(row_factors(d, [False])[1][0]) for d in self.drives]  # crank torque per N m of motor torque
        self.torque_bounds = [self._torque_bounds(k) for k in range(len(self.drives))]
        self.thermal_size = 5 if self.thermal is not None and self.lossy[0] else 2  # the thermal row's parameters (eta^2, 1 / T_rated (, q, v, d))
        self.torque_segments = [np.arange(N) if torque_segments is None else np.asarray(torque_segments[k], int) for k in range(len(self.drives))]
        self.base_key = self._cache_key()
        self.sym = self._segment()
        self.v = v = self._variables()
        self.rows = rows = _Rows()
        self.fns, self.grid_rows, self.running = {}, None, None
        self._add_collocation_rows()
        # the first member's torque on every segment for an objective that takes it (planning.energy's grid energy, whose
        # gradient CasADi takes in reverse mode: through the plain map, its sums in CasADi's order); the rows take the
        # torque inside their own segment functions (member_torque, of_first_torque)
        self.first_torque = (self._torque.map(N, "serial")(v.Z, v.DTH, v.P[:, :N])
                             if any(item.needs_torque for item in self.items) else None)
        for item in self.items:
            item.rows(self)
        self._add_periodic_rows()
        self.r2 = ca.MX.sym("r2")  # (the thermal limit's RMS bound / T_rated)^2
        self.TH = ca.MX.sym("TH", self.thermal_size)  # the first member's eta^2 and 1 / T_rated (N m) (, its loss coefficients q, v, d)
        self.z = ca.vertcat(v.w, v.a, v.hs)
        self.p = ca.vertcat(ca.reshape(v.P, -1, 1), self.r2, self.TH)
        if v.PL is not None:  # the drive losses' coefficients
            self.p = ca.vertcat(self.p, ca.reshape(v.PL, -1, 1))
        for item in self.items:
            extra = item.unknowns(self)
            if extra is not None:
                self.z = ca.vertcat(self.z, extra)
        self._time_row = self.objective.add_time_row(rows, v, self.h_ref)
        self._lbg, self._ubg = np.concatenate(rows.lb), np.concatenate(rows.ub)
        self._torque_rows = np.concatenate(rows.torque)
        f = self.objective.objective(self.fns, self.first_torque, v, self)
        nlp = {"x": self.z, "f": f, "g": ca.vertcat(*rows.g), "p": self.p}
        self._nlp, self._key = nlp, (self.base_key, tuple(int(i) for i in self.speed_segments))
        self.solver = self._solver(nlp, self._key)
        self._warm_solver = None  # built at the first re-solve with a previous solve's multipliers (_solver's warm)
        self._lbx, self._ubx = self._variable_bounds()
        self._last = None

    # -- building, in the order __init__ takes the steps ---------------------------------------------
    def _scales(self) -> None:
        """Reference values the rows are scaled by: crank speed ``w_ref`` (rad/s), segment duration ``h_ref`` (s),
        acceleration ``a_ref`` (rad/s^2)."""
        w_max = float(self.limits.crank_speed_max)
        self.w_ref = w_max if math.isfinite(w_max) else 1.0
        self.h_ref = float(np.mean(np.diff(self.limits.theta))) / self.w_ref * 2.0  # a typical segment duration, s
        self.a_ref = self.w_ref / self.h_ref / 10.0

    def _torque_bounds(self, k: int) -> tuple[np.ndarray, np.ndarray]:
        """Member k's torque rows' bounds (low, high) for |T_m| <= 1 N m at every segment's 5 points, in units of the
        rows' crank torque / bs (:func:`planning.limits.row_factors`; the standstill exponent at a resting knot)."""
        drv, n = self.drives[k], self.n
        lo_s, hi_s = row_factors(drv, self.limits.standstill)
        lo_m, hi_m = row_factors(drv, np.zeros(n, bool))
        tl = np.vstack([lo_s[:-1], lo_s[1:], lo_m[:-1], lo_m[:-1], lo_m[:-1]]) / self._bs[k]
        tu = np.vstack([hi_s[:-1], hi_s[1:], hi_m[:-1], hi_m[:-1], hi_m[:-1]]) / self._bs[k]
        return tl.ravel("F"), tu.ravel("F")

    def _cache_key(self) -> tuple:
        """Everything of the problem's structure a built solver depends on: everything of the press that differs
        between plans on the same knots (parameters, friction, drive, rated torque) is a parameter or a bound, so a
        later plan with the same limits and torque rows reuses a built solver."""
        limits = self.limits
        return (limits.theta.tobytes(), limits.height.tobytes(), limits.dh.tobytes(), np.asarray(limits.window, bool).tobytes(),
                np.asarray(limits.standstill, bool).tobytes(), float(limits.crank_speed_max), limits.forming_speed,
                float(limits.jerk), limits.periodic, self.settings, len(self.drives),
                tuple(tuple(int(i) for i in seg) for seg in self.torque_segments), self.thermal is not None, tuple(self.lossy),
                tuple(self.branch_rows), None if self.grid is None else self.grid.structure)

    def _segment(self) -> "_Segment":
        """The segment's symbols (:class:`_Segment`) and the functions of its members' torque kept for the rows and the
        checks on a solution: ``_torque`` (one member's crank torque / bs at the segment's 5 points) and
        ``point_speeds`` (the crank speed at those points, in their order). Each function's outputs go through ca.cse
        (shared subexpressions merged): fewer nodes in the expanded problem, whose Jacobian the build derives."""
        # -- one segment: z = (w0, w1, a0, a1, h scaled), p = dth
        zs = ca.SX.sym("z", 5)
        dt_ = ca.SX.sym("dth")
        w0, w1, a0, a1 = zs[0], zs[1], zs[2], zs[3]
        h = zs[4] * self.h_ref
        d = a1 - a0
        checks = []
        for q in CHECKS:  # the exact cubic at tau = q h (j = d / h)
            checks.append((w0 + a0 * q * h + d * q * q * h / 2.0, a0 + q * d,
                           (w0 * q * h + a0 * q * q * h * h / 2.0 + d * q**3 * h * h / 6.0) / dt_))
        # -- one member's torque on one segment: pt = (m0 m1 c0 c1 fr0 fl1 sl0 sl1 bs), crank torque / bs
        pt = ca.SX.sym("pt", TORQUE_PARAMS)
        m0, m1, c0, c1, fr0, fl1, sl0, sl1, b_s = (pt[i] for i in range(TORQUE_PARAMS))
        trows = [(m0 * a0 + c0 * w0 * w0 + fr0 + sl0 * a0) / b_s, (m1 * a1 + c1 * w1 * w1 + fl1 + sl1 * a1) / b_s]
        for wq, aq, f in checks:
            rest = (1.0 - f) * (fr0 + sl0 * aq) + f * (fl1 + sl1 * aq)
            trows.append(((m0 + f * (m1 - m0)) * aq + (c0 + f * (c1 - c0)) * wq * wq + rest) / b_s)
        self._torque = ca.Function("segment_torque", [zs, dt_, pt], [ca.cse(ca.vertcat(*trows))])
        speeds = [w0, w1, *(c[0] for c in checks)]
        self.point_speeds = ca.Function("segment_point_speeds", [zs], [ca.vertcat(*speeds)])
        return _Segment(zs, dt_, w0, w1, a0, a1, h, d, tuple(checks), tuple(speeds))

    def _variables(self) -> "_Stroke":
        """The unknowns of the whole stroke (:class:`_Stroke`)."""
        n = self.n
        w = ca.MX.sym("w", n)
        a = ca.MX.sym("a", n)
        hs = ca.MX.sym("h", n - 1)
        Z = ca.horzcat(w[:-1], w[1:], a[:-1], a[1:], hs).T  # 5 x N
        PL = ca.MX.sym("PL", LOSS_TERMS, sum(self.lossy)) if any(self.lossy) else None
        return _Stroke(w, a, hs, Z, ca.DM(np.diff(self.limits.theta)).T, ca.MX.sym("P", TORQUE_PARAMS, (n - 1) * len(self.drives)), PL)

    def _add_collocation_rows(self) -> None:
        """Angle and speed continuity (= 0) of every segment, with the limits' rows of one segment beside them (the
        jerk limit's)."""
        s, N = self.sym, self.n - 1
        rows = [((s.w0 * s.h + s.h * s.h * (2.0 * s.a0 + s.a1) / 6.0 - s.dth) / s.dth, 0.0, 0.0),  # angle continuity
                ((s.w1 - s.w0 - s.h * (s.a0 + s.a1) / 2.0) / self.w_ref, 0.0, 0.0)]  # speed continuity
        for item in self.items:
            rows += item.segment_rows(self)
        fn = ca.Function("segment", [s.zs, s.dth], [ca.cse(ca.vertcat(*(r[0] for r in rows)))])
        lb = np.repeat(np.array([[r[1]] for r in rows], float), N, axis=1)
        ub = np.repeat(np.array([[r[2]] for r in rows], float), N, axis=1)
        self.rows.add([ca.reshape(segment_map(fn, N)(self.v.Z, self.v.DTH), -1, 1)], lb.ravel("F"), ub.ravel("F"))

    def member_torque(self, k: int, keep: list):
        """Member k's crank torque / bs at the 5 points of its segments ``keep`` (5 x len(keep), CasADi)."""
        N, v = self.n - 1, self.v
        Pk = v.P[:, k * N:(k + 1) * N]
        return segment_map(self._torque, len(keep))(v.Z[:, keep], v.DTH[:, keep], Pk[:, keep])

    def of_first_torque(self, fn: ca.Function, extra: tuple = ()):
        """``fn(y, zs, *extra)`` of a segment (``y``: the first member's crank torque / bs at its 5 points, ``zs`` its
        unknowns, ``extra`` parameters) on every segment, the torque computed inside one function of the segment with
        it, so that its Jacobian block holds the torque's chain (:func:`planning.segment_map.segment_map`); ``extra``: MX
        columns given once for all segments. Returns fn's output by segment (its rows x N, CasADi)."""
        s, N = self.sym, self.n - 1
        pt = ca.SX.sym("pt", TORQUE_PARAMS)
        ex = [ca.SX.sym(f"extra{k}", e.shape[0]) for k, e in enumerate(extra)]
        composed = ca.Function(f"{fn.name()}_of_torque", [s.zs, s.dth, pt, *ex], [fn(self._torque(s.zs, s.dth, pt), s.zs, *ex)])
        return segment_map(composed, N)(self.v.Z, self.v.DTH, self.v.P[:, :N], *(ca.repmat(e, 1, N) for e in extra))

    def built_speed_segments(self) -> list:
        """The speed rows' segments of the built solvers with this problem's structure (:data:`SOLVER_CACHE`)."""
        return [segs for (bk, segs) in _SOLVERS if bk == self.base_key]

    def _add_periodic_rows(self) -> None:
        """Continuous mode: equal crank speed and acceleration at both ends."""
        if self.limits.periodic:
            w, a = self.v.w, self.v.a
            self.rows.add([(w[-1] - w[0]) / self.w_ref, (a[-1] - a[0]) / self.a_ref], np.zeros(2), np.zeros(2))

    def _solver(self, nlp: dict, key: tuple, warm: bool = False):
        """IPOPT for ``nlp``, built or taken from ``SOLVER_CACHE`` by ``key``; ``warm``: the one for a re-solve from a
        previous solve's point and multipliers (its barrier starts at ``WARM_MU_INIT``)."""
        # mu_init 1e-4 (IPOPT's default 0.1) and starts pushed only 1e-6 inside their bounds: from the moving-average
        # start 35 iterations instead of 103 (door panel). The Hessian by L-BFGS instead of CasADi's exact one: the
        # objective is linear and the constraints mildly curved, so it costs no iterations (39, then 14-24 per
        # friction re-solve against 38-42 exact), and the build skips the Hessian's derivation (3.6 s against
        # 4.6 s of CPU for the whole plan; the stroke time agrees to 2e-7 s). Its memory of 2 updates instead of
        # IPOPT's 6: each iteration's low-rank solve takes 2 x memory back-solves more, and the iterations stay about
        # the same (door panel 38-32-10-19, Table 4 35-28-29 against 39-27-17-9, 34-28-27; they vary by +-30 % with
        # any small change of the problem): compare's three plans (theoretical, calibrated, robust) at three box widths
        # took 6.2-7.4 s of CPU in the solves against 7.7-10.1 s; the stroke times agree to 5e-7 s (the friction fixed
        # point's tolerance). Not expanded to one SX graph: the L-BFGS problem needs only the Jacobian, which CasADi builds from
        # the mapped segment functions' own in 0.03 s instead of differentiating the expanded graph (0.8 s for a door-panel
        # plan, 1.0-1.8 s for a robust one); the evaluations cost less than that (the same iterates: door panel 1.6 s
        # against 2.2 s of CPU, stroke time identical to 1e-9 s)
        opts = {"ipopt.print_level": 0, "print_time": False, "ipopt.sb": "yes", "expand": False,
                "ipopt.tol": self.settings.tolerance, "ipopt.max_iter": self.settings.max_iterations,
                "ipopt.mu_init": 1e-4, "ipopt.warm_start_init_point": "yes",
                "ipopt.warm_start_bound_push": 1e-6, "ipopt.warm_start_mult_bound_push": 1e-6,
                "ipopt.hessian_approximation": "limited-memory", "ipopt.limited_memory_max_history": 2}
        opts.update(self.objective.solver_options)  # a curved objective (planning.energy) takes its own
        if warm:
            opts["ipopt.mu_strategy"], opts["ipopt.mu_init"] = "monotone", WARM_MU_INIT
            key = (key, "warm")
        solver = _SOLVERS.get(key)
        if solver is None:
            solver = _SOLVERS[key] = ca.nlpsol("jerk_limited_stroke", "ipopt", nlp, opts)
            while len(_SOLVERS) > SOLVER_CACHE:
                _SOLVERS.pop(next(iter(_SOLVERS)))
        return solver

    def _variable_bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """Bounds of the decision vector: speeds >= 0 (and <= the motor speed limit), durations > 0; stop-at-top: at
        rest with no acceleration at both ends; the thermal running sum free (its last value is bounded per solve)."""
        n, w_max = self.n, float(self.limits.crank_speed_max)
        N = n - 1
        lbx = np.concatenate([np.zeros(n), np.full(n, -np.inf), np.full(N, 1e-6)])
        ubx = np.full(3 * n - 1, np.inf)
        if self.thermal is not None:
            lbx, ubx = np.append(lbx, np.full(N, -np.inf)), np.append(ubx, np.full(N, np.inf))
        if math.isfinite(w_max):
            ubx[:n] = w_max
        if not self.limits.periodic:
            for k in (0, n - 1):
                ubx[k] = 0.0
                lbx[n + k] = ubx[n + k] = 0.0
        for k in np.flatnonzero(np.asarray(self.limits.standstill, bool)[1:-1]) + 1:  # a stop on the way (planning.hold)
            ubx[k] = 0.0
            lbx[n + k] = ubx[n + k] = 0.0
        return lbx, ubx

    # -- solving ------------------------------------------------------------------------------------
    def _bounds(self, level: float, rms_bound: float | None):
        """The bounds of a solve at torque level ``level`` (N m per motor; the torque rows' bounds are for 1 N m) with the
        thermal row's bound ``rms_bound`` (N m per motor; None: free): (lbg, ubg, ubx), each limit setting its own."""
        if rms_bound is not None and self.running is None:
            raise ValueError("an RMS bound for a problem built without its thermal row")
        lbg, ubg = self._lbg.copy(), self._ubg.copy()
        lbg[self._torque_rows] *= level
        ubg[self._torque_rows] *= level
        bounds = {"lbg": lbg, "ubg": ubg, "ubx": self._ubx, "level": level, "rms_bound": rms_bound}
        for item in self.items:
            item.bound(self, bounds)
        if self._time_row is not None:  # a minimum-energy stroke: its time bounds
            ubg[self._time_row] = self.objective.time_bounds() / self.h_ref
        return lbg, ubg, bounds["ubx"]

    def repeats(self, sol: "Solve", before: "Solve") -> bool:
        """Whether two friction re-solves reached the same optimum, as the objective judges (:class:`StrokeTime`: the
        stroke times; a grid-energy objective: its values, its stroke time on its bound)."""
        return self.objective.repeats(sol, before)

    def check_speeds(self, z) -> float:
        """Largest excess (rad/s) of the screened-out segments' speed rows over their bounds at decision vector
        ``z`` (<= 0: they hold; the kept rows are IPOPT's business)."""
        z = np.asarray(z, float).ravel()
        n = self.n
        out = np.setdiff1d(np.arange(n - 1), self.speed_segments)
        if not len(out):
            return -math.inf
        Z = np.vstack([z[:n - 1], z[1:n], z[n:2 * n - 1], z[n + 1:2 * n], z[2 * n:3 * n - 1]])[:, out]
        v = np.asarray(self.speed_fn.map(len(out))(Z, np.diff(self.limits.theta)[out][None, :])).ravel("F")
        sel = (5 * out[:, None] + np.arange(5)).ravel()
        return float(max(np.max(v - self.speed_ub[sel]), np.max(self.speed_lb[sel] - v))) * self.w_ref

    def _member_params(self, k: int, r: TorqueRows) -> np.ndarray:
        drv = self.drives[k]
        j = drv.gear_inertia * drv.gear_ratio**2
        m_eff, c = np.asarray(r.m, float) + j, np.asarray(r.c, float)
        m_l, c_l, sl_l = r.left
        return np.vstack([m_eff[:-1], np.asarray(m_l, float)[1:] + j, c[:-1], np.asarray(c_l, float)[1:], r.fixed_right[:-1], r.fixed_left[1:],
                          r.slope[:-1], np.asarray(sl_l, float)[1:],
                          np.full(len(c) - 1, self._bs[k])])

    def _params(self, rows: list[TorqueRows], rms_bound: float | None) -> np.ndarray:
        r2 = (rms_bound / self.thermal.rated) ** 2 if rms_bound is not None else 1.0
        if rms_bound is not None and self.objective.cycle is not None:  # the dwell fills the cycle: limits.Thermal
            r2 = (self.thermal.hold / self.thermal.rated) ** 2
        th = (braking_ratio(self.drives[0]), 1.0 / self.thermal.rated) if self.thermal is not None else (1.0, 1.0)
        if self.thermal_size == 5:  # the first member's drive losses in the thermal row
            th = (*th, *loss_coefficients(self.drives[0])[[1, 2, 4]])
        p = np.concatenate([np.hstack([self._member_params(k, r) for k, r in enumerate(rows)]).ravel("F"), [r2, *th]])
        if any(self.lossy):
            p = np.concatenate([p, *(loss_coefficients(d) for d, lossy in zip(self.drives, self.lossy) if lossy)])
        return p

    def _member_ratios(self, z, k: int, r: TorqueRows) -> np.ndarray:
        """Member k's torque rows on every segment at ``z`` as |T_m| per N m of level (5 x N)."""
        z = np.asarray(z, float).ravel()
        n, N = self.n, self.n - 1
        Z = np.vstack([z[:n - 1], z[1:n], z[n:2 * n - 1], z[n + 1:2 * n], z[2 * n:3 * n - 1]])
        Pk = self._member_params(k, r)
        v = np.asarray(self._torque.map(N)(Z, np.diff(self.limits.theta)[None, :], Pk))
        if self.lossy[k]:
            return lossy_torque_magnitude(r.drive, v * self._bs[k], np.asarray(self.point_speeds.map(N)(Z)))
        tl, tu = self.torque_bounds[k]
        return np.maximum(v / tu.reshape(N, 5).T, v / tl.reshape(N, 5).T)

    def broken_torque_segments(self, z, rows: list[TorqueRows], level: float, k: int) -> np.ndarray:
        """Segments where member k's torque breaks ``level`` (relative excess above TORQUE_TOLERANCE) at ``z``."""
        return np.flatnonzero(np.max(self._member_ratios(z, k, rows[k]), axis=0) / level - 1.0 > TORQUE_TOLERANCE)

    def check_torques(self, z, rows: list[TorqueRows], level: float) -> float:
        """Largest |T_m| / ``level`` - 1 over every member's torque rows on every segment at decision vector ``z``
        (the screened-out ones included; <= 0: all hold)."""
        return max(float(np.max(self._member_ratios(z, k, r))) for k, r in enumerate(rows)) / level - 1.0

    def pack(self, prof) -> np.ndarray:
        """Decision vector of a profile with knot speeds, knot accelerations and segment durations."""
        u = getattr(prof, "u_knots", None)
        if u is None:  # a toppra profile: piecewise-constant acceleration per segment -> knot averages
            uu = np.asarray(prof.u, float)
            u = np.concatenate([[uu[0]], 0.5 * (uu[:-1] + uu[1:]), [uu[-1]]])
            if not self.limits.periodic:
                u[0] = u[-1] = 0.0
        dt = np.asarray(prof.dt, float)
        dt = np.where(np.isfinite(dt), dt, 10.0 * self.h_ref)
        return np.concatenate([np.asarray(prof.sd, float), np.asarray(u, float), dt / self.h_ref])

    def unpack(self, z) -> JerkProfile:
        z = np.asarray(z, float).ravel()
        n = self.n
        return JerkProfile(self.limits.theta, np.maximum(z[:n], 0.0), z[n:2 * n], z[2 * n:3 * n - 1] * self.h_ref, self.limits.periodic)

    def solve(self, rows: list[TorqueRows], level: float, start, rms_bound: float | None = None) -> "Solve":
        """One IPOPT solve at torque level ``level`` (N m per motor) with friction held at ``rows``; ``rms_bound``
        (N m per motor): the first member's cycle RMS must stay within it (None: the thermal row is free).

        ``start``: a profile (the jerk-feasible start, or a previous solution) or a decision vector. IPOPT's
        own warm start is on: a decision vector ``start`` of a previous solve reuses that solve's multipliers.
        Raises :class:`OptimalControlError`.
        """
        if len(rows) != len(self.drives):
            raise ValueError(f"built for {len(self.drives)} members, got {len(rows)}")
        for item in self.items:
            item.before_solve(self, rows, level)
        p = self._params(rows, rms_bound)
        x0 = start if isinstance(start, np.ndarray) else self.pack(start)
        if self.running is not None and len(x0) == 3 * self.n - 1:  # the running sum at the start
            x0 = np.append(x0, np.asarray(self.running(x0, p)).ravel())
        lbg, ubg, ubx = self._bounds(level, rms_bound)
        t0 = time.perf_counter()
        args = dict(x0=x0, p=p, lbg=lbg, ubg=ubg, lbx=self._lbx, ubx=ubx)
        solver = self.solver
        if isinstance(start, np.ndarray) and self._last is not None and start is self._last[0]:
            args["lam_x0"], args["lam_g0"] = self._last[1], self._last[2]
            if self._warm_solver is None:
                self._warm_solver = self._solver(self._nlp, self._key, warm=True)
            solver = self._warm_solver
        res = call_solver(solver, **args)
        stats = solver.stats()
        secs = time.perf_counter() - t0
        status = stats.get("return_status", "unknown")
        if not (stats.get("success", False) or status in ("Solve_Succeeded", "Solved_To_Acceptable_Level")):
            raise OptimalControlError(f"IPOPT stopped with {status} after {stats.get('iter_count', '?')} iterations")
        z = np.asarray(res["x"]).ravel()
        self._last = (z, res["lam_x"], res["lam_g"])
        return Solve(self.unpack(z), z, status, int(stats.get("iter_count", 0)), secs, float(res["f"]))


@dataclass
class Solve:
    profile: JerkProfile
    z: np.ndarray
    status: str
    iterations: int
    seconds: float
    objective: float = math.nan  # the objective at z (s, or a grid-energy objective's units)
