"""The press's physical limits as toppra constraint objects, one object per limit.

Path: s = theta_c (rad), x = theta_dot^2, u = theta_ddot, so q(s) = s with q' = 1 and q'' = 0 and each
constraint gives its coefficients per knot directly (no Python inverse dynamics inside toppra).

* :class:`MotorTorqueLimit`: |T_m| <= L per motor with Eq. 16, T = B / (n u eta^sgn(B theta_dot)),
  B = tau + J_gear u^2 theta_ddot, as the two linear inequalities of :func:`press_model.motor.torque_row_factors`
  (one binds when motoring, the other when braking; the press file's standstill exponent at a knot where the
  crank stands still, the ends of a stop-at-top stroke).
  With the press file's drive losses ([drive.losses]) |T_m| <= L is still an exact interval of B at a given crank
  speed (:func:`press_model.motor.torque_bracket_interval`): the same two rows, shifted to its ends, with the
  speed of the viscous loss held from the previous profile, as the friction is (the planner's fixed point).
* :class:`SpeedLimit`: x <= x_max per knot; used for the motor speed (theta_dot <= omega_max / u) and for
  the slide speed in the forming window (theta_dot <= v_max / |dH/dtheta|).

Discretisation: toppra's interpolation scheme. Stage i holds the constraint at knot i with (u_i, x_i) and at
knot i+1 with (u_i, x_i + 2 Delta_i u_i), so the profile's piecewise-constant acceleration is checked at both
ends of every segment. The torque rows carry their own knot-i and knot-(i+1) constant terms, so the friction
torque (taken from the full model at exactly those two states) is consistent at the fixed point.
"""
from __future__ import annotations

import importlib
import math
import sys
import types

import numpy as np

from press_model.model import PressModel
from press_model.motor import torque_bracket_interval, torque_row_factors
from press_model.press_data import Drive

# ----------------------------------------------------------------------------------------------------------------------
# toppra, imported without matplotlib.
#
# toppra's package imports matplotlib.pyplot (in ``toppra.algorithm.algorithm`` and ``toppra.parametrizer``) for
# plotting methods the planner never calls: ~0.3 s of every ``plan`` and ``compare`` process, whose figures are
# drawn in a figure worker (:func:`planning.figures.figure_worker`) that imports matplotlib itself. While toppra
# loads, ``matplotlib`` and ``matplotlib.pyplot`` are stand-in modules; a stand-in imports the real module at the
# first use of one of its names (toppra's ``plt.plot`` would still work), and after the import they are gone from
# ``sys.modules``, so a later ``import matplotlib.pyplot`` gets the real one. Where matplotlib is loaded already
# (a test session), toppra is imported plainly.


class _StandIn(types.ModuleType):
    """A module that imports the real one of its name at the first use of a name it lacks."""

    def __getattr__(self, name: str):
        if name.startswith("__"):  # the import system's own look-ups (__path__, ...): not a use
            raise AttributeError(name)
        if sys.modules.get(self.__name__) is self:
            del sys.modules[self.__name__]
        return getattr(importlib.import_module(self.__name__), name)


def _load():
    if "matplotlib" in sys.modules or "toppra" in sys.modules:
        import toppra
        import toppra.algorithm

        return toppra
    mpl, pyplot = _StandIn("matplotlib"), _StandIn("matplotlib.pyplot")
    mpl.pyplot = pyplot  # `import matplotlib.pyplot as plt` takes the attribute of the package
    stand_ins = {"matplotlib": mpl, "matplotlib.pyplot": pyplot}
    sys.modules.update(stand_ins)
    try:
        import toppra
        import toppra.algorithm
    finally:
        for name, mod in stand_ins.items():
            if sys.modules.get(name) is mod:
                del sys.modules[name]
    return toppra


toppra = _load()



DiscretizationType, LinearConstraint = toppra.constraint.DiscretizationType, toppra.constraint.LinearConstraint

_NO_LIMIT = 1.0e12  # (rad/s)^2: stands for 'no limit' (toppra's LP solver wants finite bounds)


class MotorTorqueLimit(LinearConstraint):
    """|T_m| <= limit (N m per motor) through Eq. 16, as 2 rows per end of each segment.

    ``m, c``: crank torque per unit u and per unit x (N m s^2/rad); ``const_right[i]`` the rest of the crank
    torque at knot i for the segment that starts there, ``const_left[i]`` for the segment that ends there
    (N m; they differ by the friction taken at the two accelerations). ``standstill[i]``: the crank is at
    rest at knot i (x fixed to 0 there). ``speed``: crank speed per knot (rad/s) the drive's viscous loss is taken
    at (the previous profile's; None: at rest); used only when the drive has losses.
    """

    name = "motor_torque"
    name_motoring = "motor_torque_motoring"
    name_braking = "motor_torque_braking"

    def __init__(self, drive: Drive, m, c, const_right, const_left, limit: float, standstill, speed=None):
        super().__init__()
        self.discretization_type = DiscretizationType.Interpolation
        self.identical = True
        self.drive = drive
        self.limit = float(limit)
        u = drive.gear_ratio
        m_eff = np.asarray(m, float) + drive.gear_inertia * u * u  # the gear inertia at the crank
        k_mot, k_brk = torque_row_factors(drive, standstill)  # per knot: T_motoring = B * k_mot, -T_braking = -B * k_brk
        if len(k_mot) != len(m_eff):
            raise ValueError(f"{type(self).__name__}: {len(k_mot)} standstill flags for {len(m_eff)} knots")
        self.k = np.stack([k_mot, -k_brk], axis=1)  # (N+1, 2): rows = +T <= L and -T <= L
        self.m_eff, self.c_x = m_eff, np.asarray(c, float)
        self.const_right, self.const_left = np.asarray(const_right, float), np.asarray(const_left, float)
        self.shift = self._loss_shift(standstill, speed) if drive.has_losses else None

    def _loss_shift(self, standstill, speed) -> np.ndarray:
        """With the drive's losses: per knot and row, what each row's value gains (N m) so that it reaches the limit at
        the end of the exact interval of B (:func:`press_model.motor.torque_bracket_interval`) instead of at the linear
        rows' B = L / k: L - k_mot B_hi and L + k_brk B_lo, (N+1, 2)."""
        still = np.asarray(standstill, bool)
        w = np.zeros(len(still)) if speed is None else np.asarray(speed, float)
        b_lo, b_hi = torque_bracket_interval(self.drive, self.limit, w, still)
        return self.limit - self.k * np.stack([b_hi, b_lo], axis=1)

    def rows_at(self, i, u, x, side: str = "right"):
        """Values of the two rows (+T, -T; N m) at knot i for acceleration u and x (arrays broadcast)."""
        const = self.const_right[i] if side == "right" else self.const_left[i]
        B = self.m_eff[i] * u + self.c_x[i] * x + const
        rows = np.stack([self.k[i, 0] * B, self.k[i, 1] * B], axis=-1)
        return rows if self.shift is None else rows + self.shift[i]

    def compute_constraint_params(self, path, gridpoints, *args, **kwargs):
        n1 = len(self.m_eff)
        if len(gridpoints) != n1:
            raise ValueError(f"{type(self).__name__} was built for {n1} knots, toppra asked for {len(gridpoints)}")
        k = self.k
        a0 = k * self.m_eff[:, None]
        b0 = k * self.c_x[:, None]
        c0 = k * self.const_right[:, None]
        deltas = np.diff(np.asarray(gridpoints, float))
        a1, b1, c1 = a0.copy(), b0.copy(), c0.copy()
        # end of segment i: knot i+1 with u_i and x_{i+1} = x_i + 2 Delta_i u_i
        a1[:-1] = k[1:] * self.m_eff[1:, None] + 2.0 * deltas[:, None] * k[1:] * self.c_x[1:, None]
        b1[:-1] = k[1:] * self.c_x[1:, None]
        c1[:-1] = k[1:] * self.const_left[1:, None]
        if self.shift is not None:  # the drive's losses: the rows end at the exact interval of B
            c0 = c0 + self.shift
            c1[:-1] += self.shift[1:]
            c1[-1] += self.shift[-1]
        a = np.hstack([a0, a1])
        b = np.hstack([b0, b1])
        c = np.hstack([c0, c1])
        F = np.eye(4)
        h = np.full(4, self.limit)
        return a, b, c, F, h, None, None


class SpeedLimit(LinearConstraint):
    """x = theta_dot^2 <= x_max[i] at each knot (inf: no limit there). ``name`` says which limit it is."""

    def __init__(self, name: str, x_max):
        super().__init__()
        self.name = name
        self.x_max = np.asarray(x_max, float)

    def compute_constraint_params(self, path, gridpoints, *args, **kwargs):
        if len(gridpoints) != len(self.x_max):
            raise ValueError(f"{self.name} was built for {len(self.x_max)} knots, toppra asked for {len(gridpoints)}")
        xbound = np.zeros((len(self.x_max), 2))
        xbound[:, 1] = np.where(np.isfinite(self.x_max), self.x_max, _NO_LIMIT)
        return None, None, None, None, None, None, xbound


class StackedTorqueLimit(LinearConstraint):
    """Several :class:`MotorTorqueLimit` s on the same knots as one toppra constraint (all their rows).

    A robust plan gives one per parameter set of the box that can be the worst case (:mod:`planning.robust`).
    """

    name = "motor_torque"

    def __init__(self, parts):
        super().__init__()
        self.discretization_type = DiscretizationType.Interpolation
        self.identical = True
        self.parts = list(parts)

    def compute_constraint_params(self, path, gridpoints, *args, **kwargs):
        got = [p.compute_constraint_params(path, gridpoints) for p in self.parts]
        a = np.hstack([g[0] for g in got])
        b = np.hstack([g[1] for g in got])
        c = np.hstack([g[2] for g in got])
        F = np.eye(a.shape[1])
        h = np.concatenate([g[4] for g in got])
        return a, b, c, F, h, None, None


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
