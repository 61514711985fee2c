"""One toppra solve with the friction torque held fixed: the constraint objects, the crank path, the boundary speeds.

stop-at-top: sd = 0 at both ends; continuous: the same crank speed v at both ends, v found by a 1-D search
(toppra has no periodic boundary), see :func:`_solve_continuous`. The friction fixed point around these
solves is :meth:`planning.planner.StrokePlanner.fixed_point`.

Units: rad, s, N m inside; degrees only in messages.
"""
from __future__ import annotations

import logging
import math
from contextlib import contextmanager

import numpy as np

from press_io.errors import PlanningError
from press_model.model import PressModel

from .constraints import MotorTorqueLimit, SpeedLimit, StackedTorqueLimit, toppra
from .grid import Grid, Profile, knot_profile
from .path_dynamics import PathDynamics
from .settings import PlanningSpec

STOP_X = 1.0e-12  # (rad/s)^2: x = theta_dot^2 allowed at a stop on the way in toppra's LP (a speed of 1e-6 rad/s)


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


def stroke_constraints(pm: PressModel, members, grid: Grid, spec: PlanningSpec, level: float, frics, still, speed=None):
    """The toppra constraint objects; ``frics``: per member the friction torque (right, left) at the knots; ``speed``:
    the crank speed per knot (rad/s) a drive's viscous loss is taken at, the previous profile's (None: at rest)."""
    limits = pm.press.motor
    drive = members[0].drive
    pd = members[0].pd
    rows = [MotorTorqueLimit(m.drive, m.pd.m, m.pd.c, m.pd.g + m.pd.proc + fr, m.pd.g + m.pd.proc + fl, level, still, speed)
            for m, (fr, fl) in zip(members, frics)]
    torque = rows[0] if len(rows) == 1 else StackedTorqueLimit(rows)
    x_motor = np.full(pd.n, (limits.max_speed / drive.gear_ratio) ** 2)
    # a stop on the way (planning.hold): the crank at rest at that knot, to within STOP_X: with x <= 0 exactly, toppra's
    # backward pass can round the stop's controllable set to [1e-17, 0] (empty) and the knot before to NaN (seen in a
    # robust plan with a hold at BDC); the jerk-limited stage then sets the speed there to 0 exactly
    x_motor[1:-1][np.asarray(still, bool)[1:-1]] = STOP_X
    with np.errstate(divide="ignore"):
        x_win = np.where(grid.in_window & (np.abs(pd.dh) > 0), (spec.forming_speed / np.abs(pd.dh)) ** 2, np.inf)
    speed = SpeedLimit("motor_speed", x_motor)
    slide = SpeedLimit("forming_slide_speed", x_win)
    return [torque, speed, slide]


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
