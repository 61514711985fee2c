"""The jerk-limited profiles: :class:`JerkProfile`, the collocation's solution (constant jerk per segment), and
:class:`SmoothProfile`, a jerk-limited profile near toppra's optimum: its knot profile filtered by a moving average of
width w in time.

What it is for. This is the start of the optimal-control stage (:func:`planning.jerk_stage.solve_jerk_limited`),
not a plan: the filter makes toppra's bang-bang stroke jerk-limited by construction, which starts IPOPT close
to the jerk-limited optimum (about a third of the iterations it needs from the bang-bang profile itself). Used
as the plan, as before, it cost the filter's width once plus the rounds that re-tightened the limits the
averaging broke: on the door panel 3.52 s of stroke against the optimum's 3.26 s.

The filter: theta_f(t) = (1 / w) * integral of theta_base over [t - w, t]. Its derivatives are differences of
the base profile's, so everything is exact and closed-form: theta_dot_f = (theta_base(t) - theta_base(t - w)) / w,
theta_ddot_f = (theta_dot_base(t) - theta_dot_base(t - w)) / w, jerk_f = (u_base(t) - u_base(t - w)) / w. With
w = (largest - smallest crank acceleration, 0 included for a stop-at-top stroke) / J the jerk is bounded by J
everywhere, the acceleration is continuous, the filtered stroke still starts and ends at rest at TDC and covers
exactly one turn, and the speed never exceeds the base profile's largest speed (it is an average of it). A
stop-at-top stroke gets longer by exactly w; a continuous (periodic) one keeps its period (the filter is
circular). The torque margin and the forming-window speed are not guaranteed; the optimal-control stage
imposes them. (A box filter of width w has spectral zeros at k / w: at the door panel's w = 0.151 s those are
6.6, 13.2 and 19.9 Hz, not at the linkage's 15 Hz mode; the optimum's jerk limit does not claim a notch either.)
"""
from __future__ import annotations

import math

import numpy as np

BISECTION_STEPS = 64  # halvings of the time bracket when inverting theta_f(t) = knot: below 1e-15 s on a 10 s stroke


class SmoothProfile:
    """A knot profile (:class:`planning.grid.Profile`) on ``theta`` filtered to jerk <= ``jerk`` (rad/s^3).

    ``periodic``: continuous mode (the stroke repeats, theta advancing 2 pi per period); otherwise the
    crank rests at theta[0] before the stroke and at theta[-1] after it. Times of this profile start at 0
    when the filtered crank leaves theta[0]. Same interface as the base profile: ``sd`` (rad/s at the
    knots), ``dt`` (s between knots), ``stroke_time``, ``boundary_speed``, :meth:`knot_accels`, :meth:`sample`.
    """

    def __init__(self, base, theta, jerk: float, periodic: bool):
        self.base = base
        self.theta = np.asarray(theta, float)
        self.jerk = float(jerk)
        self.periodic = bool(periodic)
        u = np.asarray(base.u, float)
        hi, lo = float(np.max(u)), float(np.min(u))
        if not periodic:
            hi, lo = max(hi, 0.0), min(lo, 0.0)
        self.accel_swing = hi - lo  # rad/s^2
        self.width = self.accel_swing / self.jerk if self.accel_swing > 0 else 0.0  # s
        self._tk = np.concatenate([[0.0], np.cumsum(base.dt)])
        self.base_time = float(self._tk[-1])
        if self.periodic and self.width >= self.base_time:
            raise ValueError("jerk filter wider than the stroke")  # planner turns this into a PlanningError
        th, sd = self.theta, np.asarray(base.sd, float)
        d = np.diff(self._tk)
        self._P = np.concatenate([[0.0], np.cumsum(th[:-1] * d + sd[:-1] * d * d / 2.0 + u * d**3 / 6.0)])
        self._u = u
        self._sd = sd
        self.start = self._find_start()
        self.knot_times_abs = self._invert(self.theta)
        t = self.knot_times_abs - self.start
        t[0] = 0.0
        self.knot_times = t
        self.dt = np.diff(t)
        _, self.sd, self.u_knots, _ = self._filtered(self.knot_times_abs)
        if not periodic:  # at rest at both ends by construction: exact zeros, not round-off
            self.sd[0], self.sd[-1] = base.sd[0], base.sd[-1]
            self.u_knots[0] = self.u_knots[-1] = 0.0
        else:  # both ends are the same instant of the periodic motion
            self.sd[-1], self.u_knots[-1] = self.sd[0], self.u_knots[0]
        self.boundary_speed = float(self.sd[0])

    # -- the base profile, extended before and after the stroke --------------------------------------
    def _base(self, t):
        """Base crank angle, speed, acceleration and time integral of the angle at base times ``t`` (arrays)."""
        t = np.asarray(t, float)
        T, th = self.base_time, self.theta
        if self.periodic:
            n = np.floor(t / T)
            r = t - n * T
        else:
            r = np.clip(t, 0.0, T)
        seg = np.clip(np.searchsorted(self._tk, r, side="right") - 1, 0, len(self._u) - 1)
        tau = r - self._tk[seg]
        u = self._u[seg]
        s = th[seg] + self._sd[seg] * tau + 0.5 * u * tau * tau
        v = self._sd[seg] + u * tau
        P = self._P[seg] + th[seg] * tau + self._sd[seg] * tau * tau / 2.0 + u * tau**3 / 6.0
        if self.periodic:
            turn = 2.0 * math.pi
            P = n * self._P[-1] + turn * T * n * (n - 1.0) / 2.0 + P + turn * n * r
            s = s + turn * n
        else:
            before, after = t < 0.0, t > T
            s = np.where(before, th[0], np.where(after, th[-1], s))
            v = np.where(before | after, 0.0, v)
            u = np.where(before | after, 0.0, u)
            P = np.where(before, th[0] * t, np.where(after, self._P[-1] + th[-1] * (t - T), P))
        return s, v, u, P

    def _filtered(self, t):
        """theta, theta_dot, theta_ddot, jerk of the filtered motion at window-end times ``t`` (base clock)."""
        t = np.asarray(t, float)
        w = self.width
        s1, v1, a1, P1 = self._base(t)
        if w == 0.0:
            return s1, v1, a1, np.zeros_like(t)
        s0, v0, a0, P0 = self._base(t - w)
        return (P1 - P0) / w, (s1 - s0) / w, (v1 - v0) / w, (a1 - a0) / w

    def _invert(self, angles):
        """Window-end times at which the filtered crank angle equals ``angles`` (vectorised bisection)."""
        angles = np.asarray(angles, float)
        if self.periodic:
            lo = np.full(angles.shape, self.start - self.base_time * 0.01)
            hi = np.full(angles.shape, self.start + self.base_time * 1.01)
        else:
            lo = np.zeros(angles.shape)
            hi = np.full(angles.shape, self.base_time + self.width)
        for _ in range(BISECTION_STEPS):
            mid = 0.5 * (lo + hi)
            below = self._filtered(mid)[0] < angles
            lo = np.where(below, mid, lo)
            hi = np.where(below, hi, mid)
        out = 0.5 * (lo + hi)
        if not self.periodic:
            out[0], out[-1] = 0.0, self.base_time + self.width
        return out

    def _find_start(self) -> float:
        """Base-clock time at which the filtered stroke starts (0 for stop-at-top; theta_f = theta[0] if periodic)."""
        if not self.periodic:
            return 0.0
        lo, hi = 0.0, self.base_time
        for _ in range(BISECTION_STEPS):
            mid = 0.5 * (lo + hi)
            if self._filtered(np.array([mid]))[0][0] < self.theta[0]:
                lo = mid
            else:
                hi = mid
        return 0.5 * (lo + hi)

    # -- the profile interface ------------------------------------------------------------------------
    @property
    def stroke_time(self) -> float:
        return float(self.knot_times[-1])

    def knot_accels(self):
        """Crank acceleration at each knot from the right and from the left (rad/s^2): equal, it is continuous."""
        return self.u_knots, self.u_knots

    def sample(self, t, theta=None) -> dict:
        """Crank angle (rad, unwrapped), speed, acceleration and jerk at profile times ``t`` (s); at rest after the stroke."""
        t = np.atleast_1d(np.asarray(t, float))
        T = self.stroke_time
        tc = np.clip(t, 0.0, T)
        th, sd, a, j = self._filtered(tc + self.start)
        th = np.clip(th, self.theta[0], self.theta[-1])
        end = t >= T
        th[end], sd[end] = self.theta[-1], self.sd[-1]
        a = np.where(end, self.u_knots[-1], a)
        if not self.periodic:
            a = np.where(t > T, 0.0, a)
            j = np.where(t > T, 0.0, j)
        return {"theta": th, "theta_dot": np.maximum(sd, 0.0), "theta_ddot": a, "jerk": j}

    def max_jerk(self) -> float:
        """Largest |jerk| of the filtered motion (rad/s^3): the base acceleration's largest jump over one window / w."""
        if self.width == 0.0:
            return 0.0
        t = np.concatenate([self._tk, self._tk + self.width])
        t = np.concatenate([t - 1e-9, t + 1e-9])
        return float(np.max(np.abs(self._filtered(t)[3])))


class JerkProfile:
    """The collocation's solution: crank speed ``sd`` (rad/s) and acceleration ``u_knots`` (rad/s^2) at the
    knots, segment durations ``dt`` (s), constant jerk on each segment. Same interface as the toppra stage's
    ``Profile``: ``stroke_time``, ``boundary_speed``, :meth:`knot_accels`, :meth:`sample`, :meth:`max_jerk`."""

    def __init__(self, theta, sd, u_knots, dt, periodic: bool):
        self.theta = np.asarray(theta, float)
        self.sd = np.asarray(sd, float)
        self.u_knots = np.asarray(u_knots, float)
        self.dt = np.asarray(dt, float)
        self.periodic = bool(periodic)
        self.jerk = np.diff(self.u_knots) / self.dt  # rad/s^3 per segment
        self.boundary_speed = float(self.sd[0])
        self._tk = np.concatenate([[0.0], np.cumsum(self.dt)])

    @property
    def stroke_time(self) -> float:
        return float(self._tk[-1])

    def knot_accels(self):
        """Crank acceleration at each knot from the right and from the left (rad/s^2): equal, it is continuous."""
        return self.u_knots, self.u_knots

    def max_jerk(self) -> float:
        """Largest |crank jerk| (rad/s^3); the jerk is constant on each segment."""
        return float(np.max(np.abs(self.jerk)))

    def sample(self, t, theta=None) -> dict:
        """Crank angle (rad, unwrapped), speed, acceleration and jerk at times ``t`` (s); the segment's exact cubic.

        After the stroke the crank holds the end state (at rest for stop-at-top: acceleration and jerk 0).
        """
        t = np.atleast_1d(np.asarray(t, float))
        T = self.stroke_time
        seg = np.clip(np.searchsorted(self._tk, t, side="right") - 1, 0, len(self.dt) - 1)
        tau = np.clip(t, 0.0, T) - self._tk[seg]
        w0, a0, j = self.sd[seg], self.u_knots[seg], self.jerk[seg]
        th = self.theta[seg] + tau * (w0 + tau * (a0 / 2.0 + tau * j / 6.0))
        th = np.clip(th, self.theta[seg], self.theta[seg + 1])  # the knot itself is met to the solver's tolerance
        sd = w0 + tau * (a0 + tau * j / 2.0)
        a = a0 + tau * j
        end = t >= T
        th[end], sd[end], a[end] = self.theta[-1], self.sd[-1], self.u_knots[-1]
        jj = np.where(end, 0.0, j)
        return {"theta": th, "theta_dot": np.maximum(sd, 0.0), "theta_ddot": a, "jerk": jj}
