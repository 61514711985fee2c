"""The stroke's limits, declared once: a :class:`Limits` of small limit objects, each with two faces.

A limit is one object (the torque margin, the motor speed, the forming window's slide speed, the crank jerk, the cycle
RMS, the grid peak) that yields

* **toppra's face** (:meth:`Limit.toppra`): its constraint objects on the knots (:mod:`planning.toppra_solve`) at the
  friction fixed point's state (:class:`ToppraPoint`), or none where toppra cannot take it (a jerk: third order; the
  cycle RMS: an integral, met by the thermal loop around toppra; the grid peak: toppra's own formulation with its
  tangent points is :func:`planning.power.toppra_under_grid_limit`);
* **IPOPT's face** (:meth:`Limit.segment_rows`, :meth:`Limit.rows`, :meth:`Limit.unknowns`): its rows of the
  jerk-limited stage's transcription (:class:`planning.optimal.CollocationProblem`), built from the segment's cubic
  in time the transcription gives, and their bounds at solve time (:meth:`Limit.bound`).

toppra's fixed point (:meth:`Limits.toppra`) and the transcription iterate over :attr:`Limits.items` without
knowing which limit each is. The press file's drive losses ([drive.losses]) are the torque margin's: Eq. 16 with the
losses, per member whose drive has them, on both faces (toppra: the exact interval of the crank torque at the held
speed; IPOPT: the smooth rows and the physical branch).

Units: rad, s, m, N m (per motor where a motor torque), W.
"""
from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import casadi as ca
import numpy as np

from press_model.model import PressModel
from press_model.motor import (LOSS_TERMS, loss_coefficients, lossy_torque_rows, motor_torque, smooth_lossy_motor_torque,
                               smooth_motor_torque, torque_row_factors)
from press_model.press_data import Drive

from .evaluation import BOOLE, CHECKS
from .segment_map import segment_map
from .toppra_solve import MotorTorqueLimit, SpeedLimit, StackedTorqueLimit

STOP_X = 1.0e-12  # (rad/s)^2: x = theta_dot^2 allowed at a stop on the way in toppra's LP (a speed of 1e-6 rad/s)
SPEED_SCREEN = 0.1  # motor-speed rows only where the envelope is above (1 - this) x the limit or below this x the limit
GAP = 1.0 / 128.0  # |j| h^2 x this: largest rise of a speed between two checks h/4 apart (a quadratic with |w''| = |j|: |j| (h/4)^2 / 8)
GAP_SMOOTHING = 1.0e-3  # rad/s^2: |a_{i+1} - a_i| taken as sqrt(d^2 + this^2) in that bound (differentiable at d = 0)
RMS_SMOOTHING = 1.0  # N m per motor: |T| as sqrt(T^2 + this^2) where Eq. 16 switches eta (differentiable; T^2 over-estimated by < this^2)


class OptimalControlError(RuntimeError):
    """The optimal-control stage did not reach an optimum; the message says why (the planner falls back)."""


@dataclass(frozen=True)
class ThermalLimit:
    """The cycle-RMS (thermal) limit of Eq. 24 on the plan's press (the first member): the motor torque's
    mean square over the cycle, the stroke plus a dwell at the holding torque, within ``rated`` squared."""

    rated: float  # N m per motor, T_rated
    hold: float  # N m per motor, the static holding torque at TDC during the dwell
    dwell: float  # s


@dataclass(frozen=True)
class GridRow:
    """The supply's peak-power limit ([planning.power], :mod:`planning.power`) as rows of the problem, on the first
    member at the knots and the checks: k (T w + a T^2 + b w + c w^2) <= limit, T the motor torque (Eq. 16's smooth form
    from the crank torque, ``braking`` its braking ratio) and w = ``gear_ratio`` x the crank speed the motor speed
    (:func:`planning.power.grid_bound_coefficients`); rows in units of ``scale`` W, the limit their bound at solve time."""

    a: float  # W per (N m)^2: the copper loss 3 R / k_t^2
    b: float  # W per rad/s: the iron loss growing with speed
    c: float  # W per (rad/s)^2: the iron loss growing with its square
    k: float  # motors / (inverter x infeed efficiency)
    gear_ratio: float
    braking: float  # Eq. 16's braking ratio of the first member (press_model.motor.braking_ratio)
    scale: float  # W: the rows' unit
    limit: float  # W: the grid peak the rows keep to
    energy: object = None  # planning.energy.EnergyObjective: the stroke's grid energy as the objective instead of its time
    losses: tuple | None = None  # the first member's drive losses (r, q, v, b, d) of press_model.motor.loss_coefficients; None: none

    @property
    def structure(self) -> tuple:
        """What a built solver depends on (the limit is a bound, set per solve)."""
        return (self.a, self.b, self.c, self.k, self.gear_ratio, self.braking, self.scale,
                None if self.energy is None else self.energy.structure, self.losses)


@dataclass(frozen=True)
class ToppraPoint:
    """The state toppra's faces are taken at, one friction re-solve of the fixed point: ``members``
    (:class:`planning.evaluation.Member` s, the first the plan's press), the torque ``level`` (N m per motor), per member
    the friction torque at the crank (right, left) per knot (N m) and the crank speed per knot a drive's viscous loss is
    held at (rad/s; None: at rest)."""

    members: list
    level: float
    frics: list
    speed: np.ndarray | None = None


# ----------------------------------------------------------------------------------------------------------------------
# helpers of the rows


def hermite_slopes(h0, h1, d0, d1, dth, f):
    """dH/dtheta (m/rad) and its first and second angle derivatives (m/rad^2, m/rad^3) at fraction ``f`` of a
    segment's angle on the cubic Hermite interpolation of the slide height H (the written profile's spline)."""
    dq = (h0 - h1) / dth
    D = (6.0 * f * f - 6.0 * f) * dq + (3.0 * f * f - 4.0 * f + 1.0) * d0 + (3.0 * f * f - 2.0 * f) * d1
    D1 = ((12.0 * f - 6.0) * dq + (6.0 * f - 4.0) * d0 + (6.0 * f - 2.0) * d1) / dth
    D2 = (12.0 * dq + 6.0 * d0 + 6.0 * d1) / (dth * dth)
    return D, D1, D2


def smooth_abs(x, eps):
    """|x| made differentiable at 0: sqrt(x^2 + eps^2) >= |x|."""
    return ca.sqrt(x * x + eps * eps)


def row_factors(drive: Drive, standstill):
    """Per knot, the crank-torque bounds (low, high) of |T_m| <= 1 N m through Eq. 16 without the drive's losses:
    B in [-1/k_brk, 1/k_mot] (N m)."""
    k_mot, k_brk = torque_row_factors(drive, standstill)
    return -1.0 / k_brk, 1.0 / k_mot


def lossy_torque_magnitude(drive: Drive, bracket, theta_dot) -> np.ndarray:
    """|T_m| (N m per motor) of Eq. 16 with the drive's losses for crank-side brackets B (N m) at crank speeds
    ``theta_dot`` (rad/s; 0: at rest, the standstill exponent), inf where B lies beyond the physical branch while the
    crank turns (the rows of :func:`press_model.motor.lossy_torque_rows` refuse it)."""
    tm = np.abs(motor_torque(drive, bracket, theta_dot, 0.0))
    y = np.asarray(bracket) / row_factors(drive, [False])[1][0]
    off = (np.asarray(theta_dot) > 0.0) & (lossy_torque_rows(y, theta_dot, loss_coefficients(drive))[2] < 0.0)
    return np.where(off, np.inf, tm)


def branch_can_bind(drive: Drive, limits: "Limits") -> bool:
    """Whether the braking form of Eq. 16 with the drive's losses can reach the end of its physical branch within the
    limits: its lowest value, -eta^2 / (4 k) (N m per motor), at or above -(torque cap + the viscous loss at the
    motor's top speed). Else the braking row's bound leaves a band around the branch's end infeasible, and an
    optimum on the physical side of it needs no branch row (they took about a tenth of a door-panel plan's CPU)."""
    r, q, v, b, d = loss_coefficients(drive)
    turn = r / (2.0 * b) if b else math.inf  # eta^2 / (4 k) = r / (2 b)
    return turn <= limits.torque_cap + v * limits.crank_speed_max + d


# ----------------------------------------------------------------------------------------------------------------------
# the limits


class Limit:
    """One limit of the stroke with its two faces; a face a limit lacks yields nothing. ``name``: which limit it is
    (the toppra constraint's name, a message's)."""

    name = ""
    needs_torque = False  # the first member's crank torque on every segment for an objective (the transcription's ``first_torque``)

    def toppra(self, at: ToppraPoint) -> list:
        """toppra's constraint objects at the fixed point's state ``at`` (none: toppra cannot take the limit)."""
        return []

    def segment_rows(self, tr) -> list:
        """Rows of one segment beside its continuity, from the segment's symbols ``tr.sym``: [(expression, lb, ub)]."""
        return []

    def rows(self, tr) -> None:
        """Add the limit's rows over the whole stroke to the transcription ``tr`` under build."""

    def unknowns(self, tr):
        """Rows with unknowns of their own, added after every other row; returns those unknowns (None: none)."""
        return None

    def bound(self, tr, bounds: dict) -> None:
        """Set the limit's bounds of a solve in ``bounds`` (lbg, ubg, ubx arrays; level, rms_bound)."""

    def before_solve(self, tr, rows, level: float) -> None:
        """Refuse a solve the limit cannot hold (raise :class:`OptimalControlError`)."""


@dataclass(frozen=True, eq=False)
class TorqueMargin(Limit):
    """|T_m| <= the torque level for every member (Eq. 16, the drive's losses where its press file has them). toppra:
    :class:`planning.toppra_solve.MotorTorqueLimit` per member; IPOPT: per member its rows on the segments the
    transcription keeps, at the knots and the checks, bounds for 1 N m scaled by the level at solve time."""

    standstill: np.ndarray
    cap: float  # N m per motor: no solve's level is above it (where a drive loss's branch bound can bind)
    name = "motor_torque"

    def toppra(self, at: ToppraPoint) -> list:
        rows = [MotorTorqueLimit(m.drive, m.pd.m, m.pd.c, m.pd.g + m.pd.proc + fr, m.pd.g + m.pd.proc + fl, at.level, self.standstill, at.speed)
                for m, (fr, fl) in zip(at.members, at.frics)]
        return [rows[0] if len(rows) == 1 else StackedTorqueLimit(rows)]

    def rows(self, tr) -> None:
        for k in range(len(tr.drives)):
            keep = [int(i) for i in tr.torque_segments[k]]
            if not keep:
                continue
            Yk = tr.member_torque(k, keep)
            if tr.lossy[k]:
                self._loss_rows(tr, k, keep, Yk)
                continue
            tl, tu = tr.torque_bounds[k]
            sel = (5 * np.asarray(keep)[:, None] + np.arange(5)).ravel()
            tr.rows.add([ca.reshape(Yk, -1, 1)], tl[sel], tu[sel], torque=True)

    def _loss_rows(self, tr, k: int, keep: list, Yk) -> None:
        """Member k's torque rows with its drive losses on its segments ``keep`` (``Yk``: y = B / (n u eta) at their 5
        points): motoring form <= 1, braking form in [-1, 1] (N m, scaled by the level at solve time) and the branch
        >= 0 (:func:`press_model.motor.lossy_torque_rows`); the branch rows only where the braking form's bound can reach
        the branch's end (the transcription's ``branch_rows``), elsewhere a band around it is infeasible already, which
        keeps a solution on the physical side (the transcription's torque check verifies). Where the crank rests (the
        ends of a stop-at-top stroke) the state is fixed and Eq. 16 takes the standstill exponent: no rows there,
        :meth:`before_solve` checks it."""
        v = tr.v
        W = segment_map(tr.point_speeds, len(keep))(v.Z[:, keep])
        col = sum(tr.lossy[:k])
        motoring, braking, branch = lossy_torque_rows(Yk, W, [v.PL[i, col] for i in range(LOSS_TERMS)])
        still = np.asarray(self.standstill, bool)
        moving = np.ones((5, tr.n - 1), bool)
        moving[0], moving[1] = ~still[:-1], ~still[1:]
        moving = moving[:, keep].ravel("F")
        inf = np.full(len(moving), np.inf)
        tr.rows.add([ca.reshape(motoring, -1, 1)], -inf, np.where(moving, 1.0, np.inf), torque=True)
        tr.rows.add([ca.reshape(braking, -1, 1)], np.where(moving, -1.0, -np.inf), np.where(moving, 1.0, np.inf), torque=True)
        if tr.branch_rows[k]:
            tr.rows.add([ca.reshape(branch, -1, 1)], np.where(moving, 0.0, -np.inf), inf)

    def before_solve(self, tr, rows, level: float) -> None:
        """With drive losses: the level within :attr:`cap`, and every member with losses within ``level`` (N m per motor)
        where the crank rests: its torque there is fixed (no speed, no acceleration), Eq. 16 at the standstill exponent."""
        if not any(tr.lossy):
            return
        if level > self.cap:
            raise ValueError(f"torque level {level:g} N m above the problem's cap {self.cap:g} N m")
        still = np.flatnonzero(np.asarray(self.standstill, bool))
        for r in (r for r, lossy in zip(rows, tr.lossy) if lossy):
            crank = np.where(still == 0, r.fixed_right[still], r.fixed_left[still])
            tm = np.abs(motor_torque(r.drive, crank, 0.0, 0.0))
            if np.any(tm > level):
                raise OptimalControlError(f"the torque at rest, {float(np.max(tm)):,.0f} N m, is above the level {level:,.0f} N m")


@dataclass(frozen=True, eq=False)
class GridPeak(Limit):
    """The supply's peak power (:class:`GridRow`) on the first member at every segment's knots and checks. toppra: none
    here (its tangent formulation is :func:`planning.power.toppra_under_grid_limit`); IPOPT: the rows, their bound the
    limit at solve time; the grid power function stays with the transcription (``tr.fns["grid"]``) for a grid-energy
    objective."""

    grid: GridRow
    name = "grid_power"
    needs_torque = True

    def rows(self, tr) -> None:
        g, s = self.grid, tr.sym
        # T_m by Eq. 16's smooth form from y = B / (n u eta), the motor speed u w; k (T w + a T^2 + b w + c w^2) / scale
        yg = ca.SX.sym("yg", len(s.speeds))
        prow = []
        for q, wq in enumerate(s.speeds):
            if g.losses is not None:  # the drive losses' terms at the point's own speed, as the thermal row's
                tm = smooth_lossy_motor_torque(yg[q], wq, g.losses, RMS_SMOOTHING)
            else:
                tm = smooth_motor_torque(yg[q], g.braking, RMS_SMOOTHING)
            om = g.gear_ratio * wq
            prow.append(g.k * (tm * om + g.a * tm * tm + g.b * om + g.c * om * om) / g.scale)
        fn = tr.fns["grid"] = ca.Function("segment_grid", [yg, s.zs], [ca.cse(ca.vertcat(*prow))])
        N = tr.n - 1
        tr.grid_rows = tr.rows.add([ca.reshape(tr.of_first_torque(fn), -1, 1)],
                                   np.full(5 * N, -np.inf), np.full(5 * N, np.inf))

    def bound(self, tr, bounds: dict) -> None:
        bounds["ubg"][tr.grid_rows] = self.grid.limit / self.grid.scale


@dataclass(frozen=True, eq=False)
class MotorSpeed(Limit):
    """The motor speed at the crank, theta_dot <= ``crank_speed_max`` (rad/s), and theta_dot >= 0; the crank at rest
    where ``standstill`` says so. toppra: x <= its square per knot (STOP_X at a stop on the way); IPOPT: the speed at
    every segment's checks with the rise between them kept free, on the segments the envelope screening keeps."""

    crank_speed_max: float
    standstill: np.ndarray
    name = "motor_speed"

    def toppra(self, at: ToppraPoint) -> list:
        x_motor = np.full(len(self.standstill), self.crank_speed_max ** 2)
        # a stop on the way (planning.hold): the crank at rest at that knot, to within STOP_X: with x <= 0 exactly, toppra's
        # backward pass can round the stop's controllable set to [1e-17, 0] (empty) and the knot before to NaN (seen in a
        # robust plan with a hold at BDC); the jerk-limited stage then sets the speed there to 0 exactly
        x_motor[1:-1][np.asarray(self.standstill, bool)[1:-1]] = STOP_X
        return [SpeedLimit(self.name, x_motor)]

    def rows(self, tr) -> None:
        """Crank speeds >= 0 inside a segment (the knots have variable bounds) and <= the motor speed limit, on the
        segments the envelope screening keeps (a built solver's rows may be more than this plan's screening keeps: more
        rows, the same optimum)."""
        s, N, w_max = tr.sym, tr.n - 1, float(self.crank_speed_max)
        gap = smooth_abs(s.d, GAP_SMOOTHING) * s.h * GAP  # >= |j| h^2 / 128, smooth in d
        tr.speed_fn = ca.Function("segment_speed", [s.zs, s.dth], [ca.cse(ca.vertcat(*[(wq + gap) / tr.w_ref for wq in (s.w0, *(c[0] for c in s.checks), s.w1)]))])
        tr.speed_lb = np.tile([-np.inf, 0.0, 0.0, 0.0, -np.inf], N)
        tr.speed_ub = np.full(5 * N, w_max / tr.w_ref if math.isfinite(w_max) else np.inf)
        if tr.envelope is None:
            keep = np.arange(N)
        else:
            env = np.asarray(tr.envelope, float)
            lo_env, hi_env = np.minimum(env[:-1], env[1:]), np.maximum(env[:-1], env[1:])
            keep = np.flatnonzero((hi_env >= (1.0 - SPEED_SCREEN) * w_max) | (lo_env <= SPEED_SCREEN * tr.w_ref))
        built = tr.built_speed_segments()
        cover = [segs for segs in built if set(keep) <= set(segs)]
        if cover:
            keep = np.array(min(cover, key=len), int)
        elif built:  # the union: the next plan of this kind more likely finds its rows in it
            keep = np.union1d(keep, built[-1]).astype(int)
        tr.speed_segments = keep
        if len(keep):
            idx = [int(k) for k in keep]
            sel = (5 * keep[:, None] + np.arange(5)).ravel()
            tr.rows.add([ca.reshape(segment_map(tr.speed_fn, len(keep))(tr.v.Z[:, idx], tr.v.DTH[:, idx]), -1, 1)],
                        tr.speed_lb[sel], tr.speed_ub[sel])


@dataclass(frozen=True, eq=False)
class FormingSpeed(Limit):
    """The slide speed |dH/dtheta| theta_dot <= ``forming_speed`` (m/s) where ``window`` (per knot) says so. toppra: x <=
    (v / |dH/dtheta|)^2 per knot; IPOPT: the slide speed at the window's segments' knots and checks, on the Hermite cubic
    of the slide height, with its rise between checks kept free."""

    theta: np.ndarray
    height: np.ndarray
    dh: np.ndarray
    window: np.ndarray
    forming_speed: float
    name = "forming_slide_speed"

    def toppra(self, at: ToppraPoint) -> list:
        with np.errstate(divide="ignore"):
            x_win = np.where(self.window & (np.abs(self.dh) > 0), (self.forming_speed / np.abs(self.dh)) ** 2, np.inf)
        return [SpeedLimit(self.name, x_win)]

    def rows(self, tr) -> None:
        """The slide speed <= the forming speed on the segments inside the forming window (both ends in it). The slide
        speed v = D(theta) w has d2v/dt2 = D j + 3 D' w a + D'' w^3 (D = dH/dtheta and its angle derivatives from the
        Hermite cubic), so the rise kept free between checks is (h/4)^2 / 8 times that, in smooth absolute values."""
        s = tr.sym
        pw = ca.SX.sym("pw", 6)  # dth, H0, H1, D0, D1, direction
        dtw = pw[0]
        hq_rows = []
        for wq, aq, f in ((s.w0, s.a0, 0.0), *s.checks, (s.w1, s.a1, 1.0)):
            if not isinstance(f, float):
                f = ca.substitute(f, s.dth, dtw)
            D, D1, D2 = hermite_slopes(pw[1], pw[2], pw[3], pw[4], dtw, f)
            curv = (smooth_abs(D * s.d, GAP_SMOOTHING * 1e-2) * s.h + s.h * s.h * (3.0 * smooth_abs(D1 * wq * aq, GAP_SMOOTHING * 1e-2)
                                                                                 + smooth_abs(D2 * wq**3, GAP_SMOOTHING * 1e-2))) * GAP
            hq_rows.append(pw[5] * D * wq + curv)
        fn = ca.Function("window_segment", [s.zs, pw], [ca.cse(ca.vertcat(*hq_rows) / self.forming_speed)])
        dth = np.diff(self.theta)
        win = np.asarray(self.window, bool)
        seg_win = np.flatnonzero(win[:-1] & win[1:] & (np.abs(self.dh[:-1]) + np.abs(self.dh[1:]) > 0))
        if len(seg_win):
            idx = [int(k) for k in seg_win]
            PW = np.vstack([dth[idx], self.height[:-1][idx], self.height[1:][idx], self.dh[:-1][idx], self.dh[1:][idx],
                            np.sign(self.dh[:-1][idx] + self.dh[1:][idx])])  # the slide keeps its direction in a segment (BDC is a knot)
            nw = 5 * len(idx)
            tr.rows.add([ca.reshape(segment_map(fn, len(idx))(tr.v.Z[:, idx], ca.DM(PW)), -1, 1)], np.full(nw, -np.inf), np.ones(nw))


@dataclass(frozen=True, eq=False)
class Jerk(Limit):
    """|crank jerk| <= ``jerk`` (rad/s^3). toppra: none (no third-order constraint, upstream issue #133; its profile is
    the jerk-free lower bound); IPOPT: |a_{i+1} - a_i| <= J h_i per segment (two linear rows beside its continuity)."""

    jerk: float
    name = "crank_jerk"

    def segment_rows(self, tr) -> list:
        s, J = tr.sym, float(self.jerk)
        return [((s.d - J * s.h) / (J * tr.h_ref), -np.inf, 0.0), ((s.d + J * s.h) / (J * tr.h_ref), 0.0, np.inf)]


@dataclass(frozen=True, eq=False)
class Thermal(Limit):
    """The cycle RMS of Eq. 24 on the first member (:class:`ThermalLimit`). toppra: none (an integral; the thermal loop
    around toppra bisects the torque level, :meth:`planning.planner.StrokePlanner.bisect_thermal`); IPOPT: one row,
    sum_i h_i Q_i + T_hold^2 t_dwell <= T_bound^2 (sum_i h_i + t_dwell) with Q_i Boole's rule of T_m^2 over the
    segment's knots and checks, carried as a running sum (N unknowns of its own) with the bound on its last value."""

    thermal: ThermalLimit
    name = "thermal_rms"

    def unknowns(self, tr):
        """The running sum C (N unknowns, C_{i+1} = C_i + segment i's term / N) and its rows; one dense row would make the
        Jacobian's colouring touch every segment at once (the build took 3x longer)."""
        s, N = tr.sym, tr.n - 1
        # the row's integrand on one segment: h x Boole's rule of (T_m / T_rated)^2 over the knots and the checks, the
        # planner's quadrature (evaluation.segment_rms_integral); T_m from the crank torque by Eq. 16 in its smooth form
        # (press_model.motor.smooth_motor_torque) from y = B / (n u eta)
        ys, th2 = ca.SX.sym("y", len(BOOLE)), ca.SX.sym("eta2_inv_rated", tr.thermal_size)  # eta^2, 1 / T_rated (, q, v, d): parameters (solver cache)
        sq = 0.0
        for q, wq in enumerate(BOOLE):
            if tr.lossy[0]:  # the drive losses' terms at the point's own speed
                tm = smooth_lossy_motor_torque(ys[q], s.speeds[q], (th2[0], th2[2], th2[3], 0.0, th2[4]), RMS_SMOOTHING) * th2[1]
            else:
                tm = smooth_motor_torque(ys[q], th2[0], RMS_SMOOTHING) * th2[1]
            sq = sq + wq * tm * tm
        square = ca.Function("segment_square", [ys, s.zs, th2], [ca.cse(s.zs[4] * sq)])
        # sum_i h_i (T_m^2 - bound^2) + (hold^2 - bound^2) dwell <= 0, in units of T_rated^2 and h_ref
        S = (tr.of_first_torque(square, (tr.TH,)) - tr.r2 * tr.v.hs.T) / N
        C = ca.MX.sym("C", N)
        tr.rows.add([C - ca.vertcat(0.0, C[:-1]) - S.T], np.zeros(N), np.zeros(N))
        tr.running = ca.Function("running_sum", [tr.z, tr.p], [ca.cumsum(S.T)])
        # a stroke at a stated rate (planning.energy): the dwell is what the cycle leaves of the stroke, so the row is
        # sum_i h_i (T_m^2 - hold^2) <= (bound^2 - hold^2) cycle (r2 set to (hold / T_rated)^2, CollocationProblem._params)
        cycle = tr.objective.cycle
        tr.dwell_term = (self.thermal.dwell if cycle is None else cycle) / tr.h_ref / N
        return C

    def bound(self, tr, bounds: dict) -> None:
        rms_bound = bounds["rms_bound"]
        if rms_bound is None:
            return
        ubx = bounds["ubx"] = bounds["ubx"].copy()
        th = self.thermal
        ubx[-1] = ((rms_bound / th.rated) ** 2 - (th.hold / th.rated) ** 2) * tr.dwell_term


@dataclass(frozen=True)
class Limits:
    """What the stroke must keep, on the knots ``theta`` (rad, increasing, one turn), declared once per plan
    (:meth:`planning.planner.StrokeProblem.limits`): the data below and, from it, :attr:`items`, the limit objects
    toppra's fixed point and the jerk-limited stage iterate over.

    ``window``: per knot, the forming-window slide-speed limit applies (a segment is in the window when both
    its ends are); ``height``, ``dh``: slide height (m) and dH/dtheta (m/rad) at the knots;
    ``standstill``: per knot, the crank rests there (the ends of a stop-at-top stroke, a stop on the way).
    """

    theta: np.ndarray
    height: np.ndarray
    dh: np.ndarray
    window: np.ndarray
    standstill: np.ndarray
    crank_speed_max: float  # rad/s: the motor speed limit at the crank
    forming_speed: float  # m/s
    jerk: float  # rad/s^3
    periodic: bool  # continuous mode: equal speed and acceleration at both ends
    torque_cap: float = math.inf  # N m per motor: no solve's torque level is above it (where a drive loss's branch bound can bind)
    thermal: ThermalLimit | None = None  # the cycle-RMS limit, a row of the problem (None: none)
    grid: GridRow | None = None  # the supply's peak-power rows, or the grid energy as the objective (None: none)
    region: Region | None = None  # the members the torque margin holds for (None: not given yet, :meth:`over`)

    @classmethod
    def declare(cls, pm, spec, grid, pd, still, thermal: ThermalLimit | None = None, grid_row: GridRow | None = None) -> "Limits":
        """The limits of the job ``spec`` on the press ``pm`` (a :class:`press_model.model.PressModel`) along the knots
        ``grid`` (:class:`planning.grid.Grid`) with their path dynamics ``pd``; ``still``: per knot, the crank rests there;
        ``thermal``, ``grid_row``: the cycle-RMS row and the grid rows of the jerk-limited stage (None: without)."""
        win = grid.in_window & (np.abs(pd.dh) > 0)
        return cls(grid.theta, pd.height, pd.dh, win, np.asarray(still, bool), pm.press.motor.max_speed / pm.press.drive.gear_ratio,
                   spec.forming_speed, spec.crank_jerk, spec.mode == "continuous", spec.torque_limits(pm.press.motor.peak_torque).verdict,
                   thermal=thermal, grid=grid_row)

    @property
    def n(self) -> int:
        return len(self.theta)

    @property
    def items(self) -> tuple[Limit, ...]:
        """The limit objects, in the order their rows enter the transcription (a built solver's rows keep that order)."""
        out = [TorqueMargin(self.standstill, self.torque_cap)]
        if self.grid is not None:
            out.append(GridPeak(self.grid))
        out += [MotorSpeed(self.crank_speed_max, self.standstill),
                FormingSpeed(self.theta, self.height, self.dh, self.window, self.forming_speed)]
        if math.isfinite(self.jerk):
            out.append(Jerk(self.jerk))
        if self.thermal is not None:
            out.append(Thermal(self.thermal))
        return tuple(out)

    def toppra(self, at: ToppraPoint) -> list:
        """toppra's constraint objects of every limit at the fixed point's state ``at``."""
        return [c for item in self.items for c in item.toppra(at)]

    def over(self, region: Region) -> "Limits":
        """The same limits held over ``region``: the torque margin for each of its members (toppra: every member's rows;
        the jerk-limited stage: its worst-case groups' worst member per segment and the ungrouped members), the cycle RMS
        and the grid peak on its first member, the press the plan is for. A robust plan under a grid limit, with the
        drive's losses, is these limits with a grid row over a box's members: no limit needs to know of the others."""
        return dataclasses.replace(self, region=region)


# ----------------------------------------------------------------------------------------------------------------------
# over a region: the torque margin held for every member of a calibrated box, and a group's worst member per segment
#
# The worst corner of a parameter box per segment: two torque-row sets (motoring, braking) instead of every corner.
#
# A robust plan (:mod:`planning.robust`) must keep |T_m| <= L for every corner of the calibration's box. Its
# members come in two groups that share their drive's efficiency and their friction side (the monotone rule:
# low eta and high friction where the motors drive, high eta and low friction where they brake) and differ in
# the affine parameters (masses, balance, gear inertia). At fixed friction the crank torque B is affine in
# those, so on a segment the largest motoring row B k_mot (and the largest braking row -B k_brk) over the group
# is at one of its members, the one on the side of each parameter that the sign of dB/dp there picks. Which
# one is read off the members' own rows at the current profile (the sign rule without differencing: the
# member whose row is largest is the corner the signs point at); so the optimal-control stage carries per
# segment one motoring and one braking worst case, not 2^k corners x 2 row sets, and the choice is made again
# at every friction re-solve (:class:`WorstCase`); the fixed point's residual is taken on the corners a solve used. A choice is kept unless another member's row beats it by
# more than ``HYSTERESIS`` of the largest row (a tie would otherwise flip between re-solves). After the
# friction fixed point the stage checks every member's rows at the solution (:meth:`WorstCase.holds`) and
# re-solves while one is broken; the robust plan then verifies all 2^n corners on the full model (its
# cutting-plane loop).
#
# Units: N m (crank torque B, motor torque per motor), rad, s.


@dataclass
class Region:
    """A calibrated region as the limits hold it (:meth:`Limits.over`; :mod:`planning.robust` builds it from a box):
    ``members`` (:class:`planning.evaluation.Member` s, the first the press the plan is for), on every one of which the
    torque margin holds (the cycle RMS and the grid peak on the first); ``worst_case``: groups of member indices
    [(row type, indices)] whose worst case per segment enters the jerk-limited stage instead of each member (toppra's LP
    takes every member; None: every member's rows); ``screen(base, level) -> [(Member, row types)]``: with
    ``worst_case``, the members to add to the groups at the stage's first solve (:func:`planning.robust.screen_corners`;
    None: none)."""

    members: list
    worst_case: list | None = None
    screen: object = None

    def worst(self, theta, standstill) -> "WorstCase | None":
        """The groups' worst cases on the knots ``theta`` with the crank at rest at ``standstill`` (None: no groups)."""
        return WorstCase(self.worst_case, theta, standstill) if self.worst_case else None


HYSTERESIS = 1.0e-7  # relative to the largest row: a member replaces the one chosen on a segment only if its row is larger by more (the stage's TORQUE_TOLERANCE is 1e-6)


def _states(prof, theta):
    """Per segment the crank speed w, acceleration a and angle fraction f at its two knots and its 1/4, 1/2, 3/4
    checks (5 x N each), on the profile's cubic in time (the stage's own transcription, planning.optimal)."""
    sd = np.asarray(prof.sd, float)
    u_r, u_l = prof.knot_accels()
    a0, a1 = np.asarray(u_r, float)[:-1], np.asarray(u_l, float)[1:]
    w0, w1 = sd[:-1], sd[1:]
    h = np.asarray(prof.dt, float)
    h = np.where(np.isfinite(h), h, 0.0)
    dth = np.diff(np.asarray(theta, float))
    d = a1 - a0
    W, A, F = [w0], [a0], [np.zeros_like(w0)]
    for q in CHECKS:
        W.append(w0 + a0 * q * h + d * q * q * h / 2.0)
        A.append(a0 + q * d)
        F.append(np.clip((w0 * q * h + a0 * q * q * h * h / 2.0 + d * q**3 * h * h / 6.0) / dth, 0.0, 1.0))
    W.append(w1), A.append(a1), F.append(np.ones_like(w0))
    return np.array(W), np.array(A), np.array(F)


def segment_torques(r, prof, theta) -> np.ndarray:
    """The crank-side bracket B = tau + J_gear u^2 theta_ddot (N m) of the rows ``r`` (:class:`planning.optimal.TorqueRows`)
    at every segment's two knots and three checks along ``prof`` (5 x N: knot i, the checks, knot i+1), with the
    stage's interpolation of m, c and the rest between the segment's ends."""
    W, A, F = _states(prof, theta)
    j = r.drive.gear_inertia * r.drive.gear_ratio**2
    m_l, c_l, sl_l = r.left
    m0, m1 = r.m[:-1] + j, np.asarray(m_l)[1:] + j
    c0, c1 = r.c[:-1], np.asarray(c_l)[1:]
    fr0, fl1 = r.fixed_right[:-1], r.fixed_left[1:]
    s0, s1 = r.slope[:-1], np.asarray(sl_l)[1:]
    return ((m0 + F * (m1 - m0)) * A + (c0 + F * (c1 - c0)) * W * W
            + (1.0 - F) * (fr0 + s0 * A) + F * (fl1 + s1 * A))


def row_values(r, prof, theta, standstill) -> tuple[np.ndarray, np.ndarray]:
    """(motoring row B k_mot, braking row -B k_brk) in N m per motor at the 5 x N points of :func:`segment_torques`
    (the press file's standstill factors at the knots where the crank rests, as the stage's bounds)."""
    B = segment_torques(r, prof, theta)
    ks_m, ks_b = torque_row_factors(r.drive, standstill)
    km, kb = torque_row_factors(r.drive, np.zeros(len(standstill), bool))
    k_mot = np.vstack([ks_m[:-1], km[:-1], km[:-1], km[:-1], ks_m[1:]])
    k_brk = np.vstack([ks_b[:-1], kb[:-1], kb[:-1], kb[:-1], ks_b[1:]])
    return B * k_mot, -B * k_brk


ROW_OF_KIND = {"motoring": 0, "braking": 1}  # which of row_values' two rows a group's worst case is taken on

class WorstCase:
    """Per segment, the group's worst member for one row type, as one :class:`planning.optimal.TorqueRows`.

    ``groups``: [(row type "motoring" or "braking", member indices)]; the members of a group share their drive's
    efficiency, ratio, motors and standstill rule (they may differ in the gear inertia, carried into m here).
    Members in no group enter the stage as themselves, before the worst cases (the first member, the press the plan
    is for, stays first)."""

    def __init__(self, groups, theta, standstill):
        self.groups = [(kind, list(idx)) for kind, idx in groups]
        self.theta, self.standstill = np.asarray(theta, float), np.asarray(standstill, bool)
        self.choice = [None] * len(self.groups)  # per group, the member index chosen per segment
        self.full = None  # every member's rows at the last profile composed
        self.kept = None  # the stage's rows at the last profile with the choice made before it (the fixed point's residual)

    def ungrouped(self, n_members: int) -> list[int]:
        grouped = {i for _, idx in self.groups for i in idx}
        return [i for i in range(n_members) if i not in grouped]

    def compose(self, rows: list, prof) -> list:
        """The stage's rows: the ungrouped members' own, then per group its worst case along ``prof``."""
        self.full = rows
        out = [rows[i] for i in self.ungrouped(len(rows))]
        kept = list(out)
        for g, (kind, idx) in enumerate(self.groups):
            vals = np.array([np.max(row_values(rows[i], prof, self.theta, self.standstill)[ROW_OF_KIND[kind]], axis=0)
                             for i in idx])  # (members, N)
            best = np.argmax(vals, axis=0)
            prev = self.choice[g]
            kept.append(_combine([rows[i] for i in idx], best if prev is None else prev))
            if prev is not None:
                cols = np.arange(vals.shape[1])
                keep = vals[best, cols] <= vals[prev, cols] + HYSTERESIS * np.max(np.abs(vals))
                best = np.where(keep, prev, best)
            self.choice[g] = best
            out.append(_combine([rows[i] for i in idx], best))
        self.kept = kept
        return out

    def holds(self, prof, level: float, tolerance: float) -> bool:
        """Whether every member's rows (of the last :meth:`compose`) keep ``level`` (N m per motor) within the relative
        ``tolerance`` at every segment's knots and checks along ``prof``."""
        for r in self.full:
            mot, brk = row_values(r, prof, self.theta, self.standstill)
            if max(float(np.max(mot)), float(np.max(brk))) > level * (1.0 + tolerance):
                return False
        return True

    def counts(self) -> dict:
        """Per group, how many segments each member is the worst case on (member index -> segments)."""
        return {f"{kind} {g}": {int(i): int(n) for i, n in zip(*np.unique(np.asarray(idx)[self.choice[g]], return_counts=True))}
                for g, (kind, idx) in enumerate(self.groups) if self.choice[g] is not None}


def _combine(rows: list, pick: np.ndarray):
    """One TorqueRows whose segment s is ``rows[pick[s]]``'s (its knot-s right side and knot-(s+1) left side); the
    gear inertia of each carried into m (the drive's set to 0), the drives otherwise alike."""
    d0 = rows[0].drive
    for r in rows[1:]:
        d = r.drive
        if (d.efficiency, d.gear_ratio, d.motors, d.standstill) != (d0.efficiency, d0.gear_ratio, d0.motors, d0.standstill):
            raise ValueError("worst-case group: its members' drives differ in more than the gear inertia")
    n = len(rows[0].m)
    right = np.concatenate([pick, [pick[-1]]])  # the last knot starts no segment: any member's values
    left = np.concatenate([[pick[0]], pick])  # the first knot ends no segment
    K = np.arange(n)

    def take(name, side):
        return np.array([getattr(r, name) for r in rows])[side, K]

    jr = np.array([r.drive.gear_inertia * r.drive.gear_ratio**2 for r in rows])
    lefts = [r.left for r in rows]
    m_l = np.array([lf[0] for lf in lefts])[left, K] + jr[left]
    c_l = np.array([lf[1] for lf in lefts])[left, K]
    s_l = np.array([lf[2] for lf in lefts])[left, K]
    return dataclasses.replace(
        rows[0], m=take("m", right) + jr[right], c=take("c", right), rest_right=take("rest_right", right),
        rest_left=take("rest_left", left), slope=take("slope", right), u_right=take("u_right", right), u_left=take("u_left", left),
        drive=dataclasses.replace(d0, gear_inertia=0.0), m_left=m_l, c_left=c_l, slope_left=s_l)


# ----------------------------------------------------------------------------------------------------------------------
# Which limit binds where: per phase of the stroke (approach, forming window, return, dwell), the share of its time each limit is active.


ACTIVE = 1.0e-2  # a limit counts as active on a segment when within this fraction of its bound (the jerk-limited profile rides just under its limits)
# a phase's binding limit is the one active for the largest share of its time, if that share reaches MIN_SHARE. The
# time without any active limit ("none") is not a competitor: a smoothed profile spends much of each phase moving
# between its limits, and "none" then outvoted a motor speed held at its limit for half the approach
MIN_SHARE = 0.05


def active_limits(pm: PressModel, plan) -> dict[str, np.ndarray]:
    """Per segment of ``plan`` (a :class:`planning.planner.Plan`, whose ``binding`` this module gives: it does not import
    the planner), whether each limit is active (within ACTIVE of its bound at either end of the segment)."""
    ev, prof, pd = plan.evaluation, plan.profile, plan.pd
    L = plan.torque_level
    drive, motor = pm.press.drive, pm.press.motor
    a, b = ev.motor_right[:-1], ev.motor_left[1:]
    thr = 1.0 - ACTIVE
    sd_max = motor.max_speed / drive.gear_ratio
    win = plan.grid.in_window
    v_slide = np.where(win, np.abs(pd.dh) * prof.sd, 0.0) / plan.spec.forming_speed
    return {
        MotorTorqueLimit.name_motoring: (np.maximum(a, b) >= thr * L),
        MotorTorqueLimit.name_braking: (np.minimum(a, b) <= -thr * L),
        "motor_speed": np.maximum(prof.sd[:-1], prof.sd[1:]) >= thr * sd_max,
        "forming_slide_speed": np.maximum(v_slide[:-1], v_slide[1:]) >= thr,
    }


def phases(plan) -> dict[str, np.ndarray]:
    """Segments of each phase: before the forming window, inside it, after it (bool arrays over segments)."""
    win = plan.grid.in_window
    seg_win = win[:-1] & win[1:]
    idx = np.flatnonzero(seg_win)
    n = len(seg_win)
    first, last = (idx[0], idx[-1]) if len(idx) else (n, n - 1)
    k = np.arange(n)
    return {"approach": k < first, "forming_window": (k >= first) & (k <= last), "return": k > last}


def binding_report(pm: PressModel, plan) -> dict:
    """For each phase: the dominant limit (the one active longest, "none" when none is active for MIN_SHARE of the
    phase's time), its share, and the share of the phase's time each limit (and no limit) is active."""
    act = active_limits(pm, plan)
    dt = plan.profile.dt
    out = {}
    for name, mask in phases(plan).items():
        t = float(np.sum(dt[mask]))
        shares = {k: (float(np.sum(dt[mask & v])) / t if t > 0 else 0.0) for k, v in act.items()}
        free = mask & ~np.any(np.array(list(act.values())), axis=0)
        shares["none"] = float(np.sum(dt[free])) / t if t > 0 else 0.0
        top = max(act, key=lambda k: shares[k]) if t > 0 else None
        dominant = top if top is not None and shares[top] >= MIN_SHARE else "none"
        out[name] = {"dominant": dominant, "dominant_time_share": shares[dominant] if t > 0 else 0.0, "time_s": t,
                     "active_time_share": shares}
    if plan.spec.mode == "stop-at-top":
        out["dwell"] = {"dominant": "thermal_rms" if plan.thermal_binding else "none", "time_s": plan.dwell}
    out["thermal_rms"] = (("binding: the cycle RMS is at the thermal limit, a limit of the jerk-limited optimum" if plan.max_jerk < math.inf
                           else "binding: the torque level was lowered to meet the thermal limit") if plan.thermal_binding else "not binding")
    return out
