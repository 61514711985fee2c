"""toppra's face of the limits and one toppra solve with the friction torque held fixed.

Path: s = theta_c (rad), x = theta_dot^2, u = theta_ddot, so q(s) = s with q' = 1 and q'' = 0 (:class:`CrankPath`) and
each constraint object gives its coefficients per knot directly (no Python inverse dynamics inside toppra); the limits
yield them (:meth:`planning.limits.Limits.toppra`):

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

The solve (:func:`solve_toppra`): stop-at-top: sd = 0 at both ends; continuous: the same crank speed v at both ends,
v found by a 1-D search (toppra has no periodic boundary), see :func:`_solve_continuous`. The friction fixed point
around these solves is :meth:`planning.planner.StrokePlanner.fixed_point`.

Units: rad, s, N m inside; degrees only in messages.
"""
from __future__ import annotations

import importlib
import logging
import math
import sys
import types
from contextlib import contextmanager

import numpy as np

from press_io.errors import PlanningError
from press_model.motor import torque_bracket_interval, torque_row_factors
from press_model.press_data import Drive

from .grid import Profile, knot_profile
from .path_dynamics import PathDynamics
from .settings import PlanningSpec

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
# one solve


class CrankPath(toppra.interpolator.AbstractGeometricPath):
    """q(s) = s on [s0, s1]: the crank angle is its own path parameter (one degree of freedom)."""

    def __init__(self, s0: float, s1: float):
        self._interval = np.array([s0, s1], float)

    def __call__(self, path_positions, order=0):
        s = np.atleast_1d(np.asarray(path_positions, float))
        val = s if order == 0 else (np.ones_like(s) if order == 1 else np.zeros_like(s))
        return val.reshape(-1, 1) if np.ndim(path_positions) else val.reshape(1)

    @property
    def dof(self):
        return 1

    @property
    def path_interval(self):
        return self._interval

    @property
    def waypoints(self):
        return None


@contextmanager
def _quiet_toppra():
    """toppra logs warnings for infeasible problems; the planner turns those into PlanningError instead."""
    lg = logging.getLogger("toppra")
    old = lg.level
    lg.setLevel(logging.CRITICAL)
    try:
        yield
    finally:
        lg.setLevel(old)


def _algorithm(constraints, theta):
    return toppra.algorithm.TOPPRA(constraints, CrankPath(theta[0], theta[-1]), gridpoints=theta, solver_wrapper="seidel")


def solve_toppra(constraints, theta, spec: PlanningSpec, pd: PathDynamics, hint: float | None = None) -> Profile:
    with _quiet_toppra():
        algo = _algorithm(constraints, theta)
        if spec.mode == "stop-at-top":
            sdd, sd, _, K = algo.compute_parameterization(0.0, 0.0, return_data=True)
            if sdd is None:
                _raise_uncontrollable(pd, K, constraints)
            return knot_profile(theta, np.asarray(sd) ** 2, sdd, 0.0)
        return _solve_continuous(algo, theta, spec, pd, constraints, hint)


def _solve_continuous(algo, theta, spec: PlanningSpec, pd: PathDynamics, constraints, hint: float | None = None) -> Profile:
    """Equal crank speed v at start and end: golden-section search of v for the least stroke time.

    The admissible v are those whose square lies in the feasible sets of both end knots; a coarse scan
    brackets the best one, then golden-section refines it to ``continuous_search_tolerance_rad_s``. ``hint``
    (the previous friction re-solve's v) narrows the scan to 1/8 of the range around it, unless the best
    lands on that narrow scan's edge.
    """
    X = algo.compute_feasible_sets()
    if np.isnan(X).any():
        _raise_uncontrollable(pd, X, constraints)
    v_max = math.sqrt(max(0.0, min(X[0, 1], X[-1, 1])))
    cache = {}

    def time_at(v):
        if v not in cache:
            sdd, sd, _ = algo.compute_parameterization(v, v)
            if sdd is None:
                cache[v] = (math.inf, None)
            else:
                prof = knot_profile(theta, np.asarray(sd) ** 2, sdd, v)
                cache[v] = (prof.stroke_time, prof)
        return cache[v][0]

    vs = np.linspace(0.0, v_max, 17)
    if hint is not None and 0.0 <= hint <= v_max:
        narrow = np.linspace(max(0.0, hint - v_max / 16), min(v_max, hint + v_max / 16), 5)
        ts = [time_at(float(v)) for v in narrow]
        k = int(np.argmin(ts))
        inner = (0 < k < len(narrow) - 1) or narrow[k] in (0.0, v_max)  # a bracket, or the range's own end
        if inner and math.isfinite(ts[k]):
            vs = narrow
    if len(vs) == 17:
        ts = [time_at(float(v)) for v in vs]
    k = int(np.argmin(ts))
    if not math.isfinite(ts[k]):
        *_, K = algo.compute_parameterization(0.0, 0.0, return_data=True)
        _raise_uncontrollable(pd, K, constraints)
    # the best at an end of the admissible range (e.g. the motor speed limit): done if one tolerance inside is worse
    if k == len(vs) - 1 and vs[k] == v_max and time_at(float(v_max - spec.continuous_tolerance)) >= ts[k]:
        return cache[float(v_max)][1]
    if k == 0 and vs[0] == 0.0 and time_at(float(spec.continuous_tolerance)) >= ts[0]:
        return cache[0.0][1]
    lo, hi = float(vs[max(k - 1, 0)]), float(vs[min(k + 1, len(vs) - 1)])
    gr = (math.sqrt(5.0) - 1.0) / 2.0
    a, b = hi - gr * (hi - lo), lo + gr * (hi - lo)
    while hi - lo > spec.continuous_tolerance:
        if time_at(a) <= time_at(b):
            hi, b = b, a
            a = hi - gr * (hi - lo)
        else:
            lo, a = a, b
            b = lo + gr * (hi - lo)
    best = min(cache, key=lambda v: cache[v][0])
    return cache[best][1]


def _raise_uncontrollable(pd: PathDynamics, K, constraints):
    """PlanningError at the knot where the controllable (or feasible) set of crank speeds becomes empty."""
    K = np.asarray(K, float)
    bad = np.flatnonzero(np.isnan(K).any(axis=1) | (K[:, 0] > K[:, 1] + 1e-12))
    k = int(bad[-1]) if len(bad) else 0
    names = ", ".join(getattr(c, "name", type(c).__name__) for c in constraints)
    raise PlanningError(
        f"no admissible stroke: at crank angle {math.degrees(pd.theta[k]) % 360:.2f} deg (slide height {pd.height[k]:.4f} m) "
        f"no crank speed keeps every limit ({names}) and still reaches the end of the stroke. "
        "Relax the limit that binds there (the job's [planning.limits], the press's [motor]) or lower the process force."
    )
