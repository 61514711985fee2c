"""The planning knots (:class:`Grid`) and a solution on them (:class:`Profile`): crank speed and acceleration per knot.

Units: rad, s inside; the grid's special angles (die contact, forming window, process breakpoints, BDC) are
solved, not rounded.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from press_io.errors import PlanningError
from press_model.forces import ProcessForce
from press_model.kinematics import height_crossing
from press_model.model import PressModel, Workspace

from .settings import PlanningSpec


@dataclass(frozen=True)
class Grid:
    """Planning knots (rad, increasing from TDC to TDC + 2 pi) and the special angles inserted into them."""

    theta: np.ndarray
    contact_index: int
    special: dict  # name -> angle (rad)
    in_window: np.ndarray  # bool per knot: the forming-window slide-speed limit applies


def planning_grid(pm: PressModel, process: ProcessForce, spec: PlanningSpec) -> Grid:
    """Uniform knots of ``spec.grid_step`` plus die contact, window entry/exit, process breakpoints, BDC and the stops
    on the way (``spec.stops``: named "hold", "pause", :mod:`planning.hold`).

    Die contact (H = H_p on the downstroke) and the other special angles are solved (brentq to 1e-13 rad),
    not rounded; a uniform knot closer than 1 % of a step to one of them is dropped.
    """
    asm = pm.assembly
    s0 = asm.theta_tdc
    s1 = s0 + 2.0 * math.pi
    bdc = asm.theta_bdc + 2.0 * math.pi * math.ceil((s0 - asm.theta_bdc) / (2.0 * math.pi))
    n = max(8, round(2.0 * math.pi / spec.grid_step))
    uniform = s0 + np.arange(n + 1) * (2.0 * math.pi / n)
    uniform[-1] = s1
    hp = process.contact_height
    top = asm.stroke
    if not 0.0 < hp < top:
        raise PlanningError(f"{spec.source}: process.contact_height_m = {hp} is not valid: must lie inside the stroke (0, {top:.4f}) m")
    eps = 1e-9
    ws = Workspace(pm)
    special = {"bdc": bdc, "die_contact": height_crossing(pm, ws, hp, s0 + eps, bdc - eps)}
    h_win = hp + spec.forming_window
    if h_win < top:
        special["window_entry"] = height_crossing(pm, ws, h_win, s0 + eps, bdc - eps)
        if spec.window_directions == "both":
            special["window_exit"] = height_crossing(pm, ws, h_win, bdc + eps, s1 - eps)
    for k, h in enumerate(sorted(set(process.heights))):
        if 0.0 < h < hp:
            special[f"process_breakpoint_{k}"] = height_crossing(pm, ws, h, s0 + eps, bdc - eps)
    for req in spec.stops:  # the stroke's stops on the way (planning.hold): knots of their own
        from .hold import stop_angle

        special[req.name] = stop_angle(pm, ws, req, s0, bdc, spec.source)
    step = 2.0 * math.pi / n
    keep = np.ones(len(uniform), bool)
    for ang in special.values():
        near = np.abs(uniform - ang) < 0.01 * step
        near[0] = near[-1] = False  # the stroke's ends stay
        keep &= ~near
    theta = np.unique(np.concatenate([uniform[keep], list(special.values())]))
    contact_index = int(np.argmin(np.abs(theta - special["die_contact"])))
    # the forming window by angle (the knots between entry and exit), so its ends are knots of it
    lo = special.get("window_entry", s0)
    hi = special.get("window_exit", s1 if spec.window_directions == "both" else bdc)
    in_window = (theta >= lo - 1e-12) & (theta <= hi + 1e-12)
    return Grid(theta, contact_index, special, in_window)


@dataclass
class Profile:
    """A solution on the knots: sd (rad/s, n), u (rad/s^2, n - 1 segments), times (s)."""

    sd: np.ndarray
    u: np.ndarray
    dt: np.ndarray  # segment durations, s
    boundary_speed: float  # rad/s at both ends

    @property
    def stroke_time(self) -> float:
        return float(np.sum(self.dt))

    def knot_accels(self):
        """Crank acceleration at each knot (rad/s^2) from the right (segment i) and from the left (segment i - 1)."""
        return np.append(self.u, self.u[-1]), np.insert(self.u, 0, self.u[0])

    def sample(self, t, theta) -> dict:
        """Crank angle (rad, unwrapped), speed and acceleration at times ``t`` (s) on knots ``theta``; at rest after the end.

        Between knots the acceleration is constant, so theta = theta_i + sd_i tau + u_i tau^2 / 2 exactly.
        """
        t = np.atleast_1d(np.asarray(t, float))
        t_knots = np.concatenate([[0.0], np.cumsum(self.dt)])
        T = t_knots[-1]
        seg = np.clip(np.searchsorted(t_knots, t, side="right") - 1, 0, len(self.u) - 1)
        tau = np.minimum(t, T) - t_knots[seg]
        u = self.u[seg]
        sd = np.maximum(self.sd[seg] + u * tau, 0.0)
        th = np.minimum(theta[seg] + self.sd[seg] * tau + 0.5 * u * tau * tau, theta[seg + 1])  # round-off at the segment end
        end = t >= T
        th[end], sd[end] = theta[-1], self.sd[-1]
        if self.boundary_speed == 0.0:
            u = np.where(t > T, 0.0, u)
        return {"theta": th, "theta_dot": sd, "theta_ddot": u}


def knot_profile(theta, x, u, v) -> Profile:
    """The :class:`Profile` of toppra's x = sd^2 ((rad/s)^2 per knot) and u (rad/s^2 per segment), boundary speed ``v`` (rad/s)."""
    sd = np.sqrt(np.maximum(np.asarray(x, float), 0.0))
    ds = np.diff(theta)
    with np.errstate(divide="ignore"):
        dt = 2.0 * ds / (sd[:-1] + sd[1:])
    return Profile(sd, np.asarray(u, float), dt, float(v))


def graded_ends(grid: Grid, levels: int) -> Grid:
    """``grid`` with ``levels`` more knots toward each end of the stroke: the first and the last segment halved
    ``levels`` times (knots at theta_0 + d / 2^k and theta_N - d / 2^k, k = 1 .. levels, d the end segments' length).

    Where the crank starts and ends at rest (stop-at-top) the jerk-limited stage's first segment is a cubic from
    standstill and toppra's a constant acceleration; on the uniform knots the two differ by a share of the end
    segment's time, on graded ends both converge to the same stroke (docs/validation.md, "Planning within the supply")."""
    th = np.asarray(grid.theta, float)
    d0, d1 = th[1] - th[0], th[-1] - th[-2]
    k = 2.0 ** -np.arange(1, levels + 1)
    theta = np.unique(np.concatenate([th, th[0] + d0 * k, th[-1] - d1 * k]))
    inside = th[grid.in_window]
    in_window = ((theta >= inside.min() - 1e-12) & (theta <= inside.max() + 1e-12)) if inside.size else np.zeros(len(theta), bool)
    contact_index = int(np.argmin(np.abs(theta - grid.special["die_contact"])))
    return Grid(theta, contact_index, dict(grid.special), in_window)
