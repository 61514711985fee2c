"""The full model along a knot profile: both one-sided accelerations at every knot, the static check, the cycle RMS.

:func:`evaluate_profile` runs the friction/reaction fixed point (:func:`planning.path_dynamics.full_crank_torque`)
and Eq. 16 on a :class:`planning.grid.Profile`; the planner re-checks its toppra solutions with it, and the
comparison and the robust plan evaluate a plan on another press with it.

Units: rad, s, N m inside; degrees only in messages.
"""
from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from functools import cached_property

import numpy as np

from press_io.errors import PlanningError
from press_model.model import PressModel
from press_model.motor import motor_torque
from press_model.press_data import Drive, Friction

from .grid import Profile
from .path_dynamics import PathDynamics, frictionless_crank_torque, full_crank_torque, full_crank_torques

CREEP_SPEED = 1.0e-6  # rad/s: "moving, but as slowly as possible" for the static check (Coulomb friction on, viscous nil)
DH_STILL = 1.0e-6  # m/rad: below this |dH/dtheta| the slide stands at the knot (TDC, BDC; round-off is ~1e-10)
X_SLOPE_STEP = 1.0e-4  # relative step in the crank speed of friction_x_slopes' central differences
X_SLOPE_MIN_SPEED = 1.0e-3  # rad/s: below this crank speed a knot's friction takes no slope in x (it is held at rest or starts from it)
CHECKS = (0.25, 0.5, 0.75)  # fractions of a segment's duration where the limits are checked besides its two knots
BOOLE = (7.0 / 90.0, 7.0 / 90.0, 32.0 / 90.0, 12.0 / 90.0, 32.0 / 90.0)  # Boole's rule on a segment: its two ends, then CHECKS


@dataclass(frozen=True, eq=False)
class Member:
    """One parameter set the torque limit must hold for: its path dynamics, drive (Eq. 16) and friction.

    A nominal plan has one member (the press as given); a robust plan (:mod:`planning.robust`) one per worst
    case of the parameter box. The first member is the press the plan's feed-forward and outputs are for.
    """

    pd: PathDynamics
    drive: Drive
    friction: Friction
    label: str = "nominal"


@dataclass
class Evaluation:
    """Full-model values on the knots for both one-sided accelerations (right: segment i, left: i-1)."""

    crank_right: np.ndarray  # N m
    crank_left: np.ndarray
    motor_right: np.ndarray  # N m per motor, Eq. 16
    motor_left: np.ndarray
    fric_right: np.ndarray  # N m at the crank: full minus frictionless affine
    fric_left: np.ndarray
    u_right: np.ndarray  # rad/s^2
    u_left: np.ndarray
    # for the torque between knots (planning.profile.reference): the profile's x = theta_dot^2 at the knots,
    # the path dynamics' m and c (N m per rad/s^2 and per (rad/s)^2) and the drive of the model evaluated
    x: np.ndarray | None = None
    m: np.ndarray | None = None
    c: np.ndarray | None = None
    drive: object = None

    pd: object = None  # the path dynamics and friction evaluated (for the friction's slopes, computed on demand)
    friction: object = None
    sides: tuple = None  # (process on right, on left, guide sign right, left): see _sides

    @cached_property
    def friction_slopes(self):
        """d(friction torque at the crank)/d theta_ddot at the knots (N m per rad/s^2, central differences on the
        full model, on the right side of each knot), and None for d/d x (not used)."""
        return _acceleration_slopes([self])[0], None

    @cached_property
    def friction_x_slopes(self):
        """d(friction torque at the crank)/d x at the knots, x = theta_dot^2 (N m per (rad/s)^2; central differences in
        the speed on the full model, right side of each knot, divided by 2 theta_dot): the reactions the friction acts on
        carry the linkage's centripetal forces. 0 where the crank creeps (a knot at rest: its speed is held at 0)."""
        return _speed_slopes([self])[0]

    def torque_between(self, theta_knots, theta, theta_dot, theta_ddot):
        """Motor torque per motor (N m, Eq. 16) at crank angles ``theta`` with their own speed and acceleration.

        The inertial part m u + c x uses the sample's u and x with m, c interpolated in crank angle; the rest of
        the crank torque (gravity, balance, process, friction), known at the two ends of each segment, is
        interpolated linearly in crank angle between them, the friction carried to the sample's own u and x by
        its slopes at each end (friction follows the reactions, which follow the acceleration and the speed).
        """
        seg = np.clip(np.searchsorted(theta_knots, theta, side="right") - 1, 0, len(theta_knots) - 2)
        frac = np.clip((theta - theta_knots[seg]) / (theta_knots[seg + 1] - theta_knots[seg]), 0.0, 1.0)
        x = np.asarray(theta_dot) ** 2
        u = np.asarray(theta_ddot, float)
        rest_r = self.crank_right - self.m * self.u_right - self.c * self.x
        rest_l = self.crank_left - self.m * self.u_left - self.c * self.x
        a, b = rest_r[seg], rest_l[seg + 1]
        if self.pd is not None:
            dfdu, _ = self.friction_slopes
            dfdx = self.friction_x_slopes  # as the jerk-limited stage's rows (planning.optimal.rows_from_evaluation)
            a = a + dfdu[seg] * (u - self.u_right[seg]) + dfdx[seg] * (x - self.x[seg])
            b = b + dfdu[seg + 1] * (u - self.u_left[seg + 1]) + dfdx[seg + 1] * (x - self.x[seg + 1])
        rest = (1.0 - frac) * a + frac * b
        m = (1.0 - frac) * self.m[seg] + frac * self.m[seg + 1]
        c = (1.0 - frac) * self.c[seg] + frac * self.c[seg + 1]
        crank = m * u + c * x + rest
        sd = np.where(np.asarray(theta_dot) > 0.0, theta_dot, CREEP_SPEED)
        return motor_torque(self.drive, crank, sd, u)


FRICTION_SLOPE_STEP = 1e-3  # rad/s^2: friction_slopes' central differences (friction is smooth in the acceleration, through the reactions)


def _friction_torques(evs: list, theta_dot, theta_ddot) -> list[np.ndarray]:
    """The friction torque at the crank (N m per knot) of each evaluation of ``evs`` (one path dynamics, one profile's
    sides) at ``theta_dot``, ``theta_ddot`` (rad/s, rad/s^2 per knot), each with its own friction: one fixed point
    per distinct friction, side by side (:func:`planning.path_dynamics.full_crank_torques`: the same values as apart)."""
    on_r, _, guide_r, _ = evs[0].sides
    frictions = list(dict.fromkeys(e.friction for e in evs))
    out = full_crank_torques(evs[0].pd, theta_dot, theta_ddot, frictions, process_on=on_r, guide_sign=guide_r)
    by = dict(zip(frictions, out))
    return [by[e.friction].friction_torque for e in evs]


def _acceleration_slopes(evs: list) -> list[np.ndarray]:
    """:attr:`Evaluation.friction_slopes`' d/d theta_ddot (N m per rad/s^2) of each of ``evs`` (one path dynamics and
    profile, the frictions side by side)."""
    e, du = evs[0], FRICTION_SLOPE_STEP
    sd = np.sqrt(e.x)
    up, down = _friction_torques(evs, sd, e.u_right + du), _friction_torques(evs, sd, e.u_right - du)
    return [(a - b) / (2 * du) for a, b in zip(up, down)]


def _speed_slopes(evs: list) -> list[np.ndarray]:
    """:attr:`Evaluation.friction_x_slopes` (N m per (rad/s)^2) of each of ``evs`` (one path dynamics and profile, the
    frictions side by side)."""
    e = evs[0]
    sd = np.sqrt(e.x)
    moving = sd > X_SLOPE_MIN_SPEED
    dw = X_SLOPE_STEP * np.maximum(sd, X_SLOPE_MIN_SPEED)
    up, down = _friction_torques(evs, sd + dw, e.u_right), _friction_torques(evs, np.maximum(sd - dw, CREEP_SPEED), e.u_right)
    step = sd + dw - np.maximum(sd - dw, CREEP_SPEED)
    return [np.where(moving, (a - b) / step / (2.0 * np.maximum(sd, X_SLOPE_MIN_SPEED)), 0.0) for a, b in zip(up, down)]


def share_friction_slopes(evs: list) -> None:
    """Compute the friction's slopes (:attr:`Evaluation.friction_slopes`, :attr:`Evaluation.friction_x_slopes`) of the
    evaluations ``evs`` of one profile (:func:`evaluate_members`') together: per path dynamics, one fixed point per distinct
    friction, run side by side (a robust plan's members: 5 path dynamics, 9 frictions on them); the values are the same as
    each evaluation's own. Evaluations without path dynamics, or whose slopes are known, are left as they are."""
    groups = {}
    for e in evs:
        if e.pd is not None and "friction_slopes" not in e.__dict__:
            groups.setdefault((id(e.pd), id(e.x)), []).append(e)  # one path dynamics along one profile
    for group in groups.values():
        for e, du, dx in zip(group, _acceleration_slopes(group), _speed_slopes(group)):
            e.__dict__["friction_slopes"], e.__dict__["friction_x_slopes"] = (du, None), dx  # functools.cached_property's own slots


def _sides(pd: PathDynamics):
    """Per knot, for the segment that starts there (right) and the one that ends there (left): the guide's
    direction of motion (+1 up, -1 down) where the slide stands at the knot itself (TDC, BDC: dH/dtheta = 0 up
    to round-off), and whether the process force acts (it steps at die contact and ends at BDC)."""
    still = np.abs(pd.dh) < DH_STILL
    dh = pd.dh if pd.reversed_inertia is None else -pd.dh  # a backward swing's slide moves against H's slope
    nxt = np.sign(np.append(dh[1:], dh[-1]))
    prv = np.sign(np.insert(dh[:-1], 0, dh[0]))
    guide_r = np.where(still, nxt, 0.0)
    guide_l = np.where(still, prv, 0.0)
    on = pd.process_force > 0
    on_r = on & ~(still & (nxt > 0))  # leaving BDC upwards: the force is gone inside the segment
    on_l = on.copy()
    k = np.flatnonzero(on[1:] & ~on[:-1]) + 1  # the first knot with the force: die contact, reached from above
    on_l[k] = False
    if pd.reversed_inertia is not None:  # a backward swing's die contact is its last knot with the force, reached from above on the right
        on_r[np.flatnonzero(on[:-1] & ~on[1:])] = False
    return guide_r, guide_l, on_r, on_l


def evaluate_profile(pm: PressModel, pd: PathDynamics, prof: Profile, member: Member | None = None) -> Evaluation:
    """Full model (friction fixed point, Eq. 16) along a knot profile, both sides of each acceleration step.

    Each side is the limit from inside its segment: where the crank stands (the ends of a stop-at-top stroke)
    theta_dot -> 0+, with Coulomb friction on and the efficiency by the sign of the power there (braking at
    the end; the torque constraint itself keeps the press file's standstill efficiency at those knots, the
    larger magnitude, so the limit holds at the instant of rest too); where the slide stands (TDC, BDC) the
    guide friction in the segment's direction of motion; the process force off on the left of die contact
    and on the right of BDC. ``fric_right/left`` is then everything the toppra rows' affine part (m u + c x
    + g + proc) leaves out: friction, and those process-force steps.
    """
    drive = pm.press.drive if member is None else member.drive
    friction = None if member is None else member.friction
    pd = pd if member is None else member.pd
    return _evaluate_frictions(pd, prof, [friction], [drive])[0]


def _evaluate_frictions(pd: PathDynamics, prof: Profile, frictions, drives) -> list[Evaluation]:
    """:func:`evaluate_profile` on one path dynamics for each (friction, drive) pair: the friction fixed points share their
    set-up and run side by side (:func:`planning.path_dynamics.full_crank_torques`)."""
    u_r, u_l = prof.knot_accels()
    sd = np.where(prof.sd > 0.0, prof.sd, CREEP_SPEED)
    guide_r, guide_l, on_r, on_l = _sides(pd)
    frs = full_crank_torques(pd, sd, u_r, frictions, process_on=on_r, guide_sign=guide_r)
    fls = full_crank_torques(pd, sd, u_l, frictions, process_on=on_l, guide_sign=guide_l)
    x = sd * sd
    aff_r, aff_l = frictionless_crank_torque(pd, sd, u_r), frictionless_crank_torque(pd, sd, u_l)
    return [Evaluation(fr.crank_torque, fl.crank_torque,
                       motor_torque(drive, fr.crank_torque, sd, u_r), motor_torque(drive, fl.crank_torque, sd, u_l),
                       fr.crank_torque - aff_r, fl.crank_torque - aff_l, u_r, u_l, x, pd.m, pd.c, drive, pd, friction,
                       (on_r, on_l, guide_r, guide_l))
            for fr, fl, friction, drive in zip(frs, fls, frictions, drives)]


def evaluate_members(pm: PressModel, members, prof) -> list[Evaluation]:
    """:func:`evaluate_profile` for each member; members sharing path dynamics and friction share the friction
    fixed point (the drive, Eq. 16, is applied per member), and members sharing path dynamics run their fixed points
    side by side (:func:`_evaluate_frictions`)."""
    cache, by_pd = {}, {}
    for m in members:
        key = (id(m.pd), m.friction)
        if key not in cache:
            cache[key] = None
            by_pd.setdefault(id(m.pd), (m.pd, []))[1].append(m)
    for pd, first in by_pd.values():
        for m, ev in zip(first, _evaluate_frictions(pd, prof, [m.friction for m in first], [m.drive for m in first])):
            cache[(id(pd), m.friction)] = ev
    out = []
    for m in members:
        ev = cache[(id(m.pd), m.friction)]
        if ev.drive is not m.drive:
            sd = np.sqrt(ev.x)
            ev = dataclasses.replace(ev, drive=m.drive,
                                     motor_right=motor_torque(m.drive, ev.crank_right, sd, ev.u_right),
                                     motor_left=motor_torque(m.drive, ev.crank_left, sd, ev.u_left))
        out.append(ev)
    return out


def segment_rms_integral(ev: Evaluation, prof: Profile) -> float:
    """Integral of T_m^2 dt over the stroke (N^2 m^2 s): on each segment Boole's rule on T_m at its two ends (the
    knots' one-sided values) and at 1/4, 1/2, 3/4 of its duration (:meth:`Evaluation.torque_between`, the written
    profile's torque), exact up to a quintic in time. The jerk-limited optimum's thermal row is the same sum."""
    dt = np.asarray(prof.dt, float)
    t0 = np.concatenate([[0.0], np.cumsum(dt)])[:-1]
    smp = prof.sample((t0[:, None] + np.asarray(CHECKS)[None, :] * dt[:, None]).ravel(), ev.pd.theta)
    mid = ev.torque_between(ev.pd.theta, smp["theta"], smp["theta_dot"], smp["theta_ddot"]).reshape(-1, len(CHECKS))
    sq = BOOLE[0] * ev.motor_right[:-1] ** 2 + BOOLE[1] * ev.motor_left[1:] ** 2 + (mid * mid) @ np.asarray(BOOLE[2:])
    return float(np.sum(dt * sq))


def creep_torque(pm: PressModel, pd: PathDynamics) -> np.ndarray:
    """Motor torque (N m per motor) at creeping speed and no acceleration at every knot of ``pd``: the least the motors
    must give anywhere on the stroke (gravity, balance, process force and Coulomb friction)."""
    creep = np.full(pd.n, CREEP_SPEED)
    fr = full_crank_torque(pd, creep, np.zeros(pd.n))
    return motor_torque(pm.press.drive, fr.crank_torque, creep, np.zeros(pd.n))


def static_check(pm: PressModel, pd: PathDynamics, limit: float, source: str, tm: np.ndarray | None = None) -> np.ndarray:
    """Motor torque (N m per motor) at creeping speed and no acceleration at every knot (:func:`creep_torque`, or ``tm``
    computed before for ``pd``); raises if any exceeds ``limit``: if the static loads break the margin, no speed profile
    can help.
    """
    tm = creep_torque(pm, pd) if tm is None else tm
    over = np.flatnonzero(np.abs(tm) > limit)
    if len(over):
        k = int(over[np.argmax(np.abs(tm[over]))])
        first = int(over[0])
        what = "the process force and the static loads" if pd.process_force[k] > 0 else "the static loads (gravity, balance)"
        raise PlanningError(
            f"{source}: infeasible job: at crank angle {math.degrees(pd.theta[k]) % 360:.2f} deg (slide height {pd.height[k]:.4f} m) "
            f"{what} alone need a motor torque of {abs(tm[k]):,.0f} N m per motor even at creeping speed, above the peak-torque "
            f"margin limit {limit:,.0f} N m ((planning.limits.peak_torque_margin - feedback_reserve) x motor.peak_torque_Nm); the margin is broken from "
            f"{math.degrees(pd.theta[first]) % 360:.2f} deg on. Lower the process force ([process] forces_N), or plan on a press "
            "with stronger motors or a higher gear ratio."
        )
    return tm


def cycle_rms(ev: Evaluation, prof: Profile, dwell: float, hold: float) -> float:
    """Cycle RMS of the motor torque (N m), Eq. 24: stroke segments plus the dwell at the holding torque ``hold``."""
    total = prof.stroke_time + dwell
    return math.sqrt((segment_rms_integral(ev, prof) + hold * hold * dwell) / total)
