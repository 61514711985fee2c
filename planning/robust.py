"""Robust plan: |T_m| <= the torque limit for every parameter set in the calibration's joint 95 % region.

The box is calibrated.json's joint region (``joint_region.box``, {name: [low, high]}: every parameter's truth
inside it at once at the 95 % level, what a plan that must hold for the press needs; a result written before the
joint region existed gives its per-parameter ``intervals``; read by :func:`press_model.params.read_joint_box`),
around its ``parameters`` (the centre, whose model the
feed-forward and the outputs are for).

Which parameter sets the torque rows are taken at (the choice the issue asks for):

* **Monotone parameters, exact by sign.** The gear efficiency enters Eq. 16 as 1 / eta while the motors drive
  and as eta while they brake, so for a given crank torque the motoring row |T| is largest at the box's low
  eta and the braking row at its high eta. Friction (mu_r, mu_s, and the viscous c_r, c_s) always opposes the
  motion, so it raises the crank torque the motors must give: the motoring row is worst at high friction, the
  braking row at low friction. These take one side of the box per row type, not both.
* **All other parameters, every corner.** Masses, inertias, the balance coefficient and the gear inertia
  enter the crank torque affinely at fixed friction (RNEA is linear in the inertial parameters, Eq. 13 is
  affine in the supply pressure, J_gear u^2 theta_ddot is linear), so the largest |T| over their box is at
  one of its corners, but which corner depends on the sign of the acceleration at each knot: all 2^k corners
  go into the LP (k = 3 for the paper's six: m8, psi, J_gear -> 8 corners x 2 row types = 16 members).

Only the corners of the inertial/balance parameters need their own path dynamics (4 for m8 x psi); the
drive and friction parameters do not enter them. So the worst case per knot costs 16 row sets in toppra's
LP and 8 friction evaluations per re-solve, not 64 path dynamics.

The claim is verified, not assumed: the final profile is evaluated on the full model (friction fixed point,
Eq. 16) at **all 2^n corners** of the box; a corner that breaks the limit (the coupling of friction and
reactions could in principle break the monotonicity) is added to the members and the plan is re-solved
(a cutting-plane loop). A test checks the robust plan at every corner with the per-point Pinocchio model.
Intervals reaching outside a parameter's range in the press file (e.g. eta_gear above 0.99) are clipped to
it (the range is the press file's statement of where the parameter can lie; a box reaching past it asks the plan to
hold for presses that cannot exist) and each clipping is a `warning:` line naming the parameter, the box and the range. A bootstrap interval need not contain the point estimate; the centre
(the calibrated values) is one of the LP's members anyway, so the plan holds there as well as in the box.
"""
from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np

from press_model.forces import ProcessForce
from press_model.model import PressModel
from press_model.press_data import PressData

from .errors import PlanningError
from .evaluation import Member, evaluate_profile
from .grid import planning_grid
from .path_dynamics import PathDynamics, build_path_dynamics
from .planner import Plan, plan_stroke, planning_limit
from .settings import PlanningSpec

MAX_CUTS = 8  # rounds of adding a corner that breaks the limit before the robust plan is refused


@dataclass(frozen=True)
class Box:
    """The parameter box: centre values and [low, high] per parameter (SI), with what was clipped to the ranges."""

    center: dict  # may lie outside the box (a bootstrap interval need not contain the estimate): planned for too
    bounds: dict  # name -> (low, high)
    clipped: dict  # name -> the interval as given, where it was clipped
    kind: str  # which box of calibrated.json: "joint region" (all parameters at once) or "per-parameter intervals"
    warnings: tuple = ()  # one line per clipped parameter: its box as given, the press file's range, the box planned over

    @classmethod
    def from_calibration(cls, press: PressData, center: dict, intervals: dict, source: str, kind: str) -> "Box":
        """The box of a calibration result's ``intervals`` (name -> (low, high), SI) around ``center``, each side clipped
        to the parameter's sensitivity range in the press file (a bootstrap box can reach past a physical bound, e.g.
        eta_gear above 0.99), with a warning line per clipped parameter; refused where nothing of it lies in the range."""
        bounds, clipped, warnings = {}, {}, []
        for name, (lo, hi) in intervals.items():
            p = press.parameters.get(name)
            if p is None:
                raise PlanningError(f"{source}: intervals names {name!r}, not a parameter of this press; known: {', '.join(press.parameters)}")
            if name not in center:
                raise PlanningError(f"{source}: intervals.{name} has no calibrated value in \"parameters\"; a robust plan needs both")
            c_lo, c_hi = max(lo, p.low), min(hi, p.high)
            if c_lo > c_hi:
                raise PlanningError(f"{source}: intervals.{name} = [{lo:g}, {hi:g}] lies outside the parameter's range "
                                    f"[{p.low:g}, {p.high:g}] of the press file; recalibrate or widen the range")
            if (c_lo, c_hi) != (lo, hi):
                clipped[name] = [lo, hi]
                warnings.append(f"{source}: the {kind} box of {name}, [{lo:g}, {hi:g}], reaches outside the press file's sensitivity "
                                f"range [{p.low:g}, {p.high:g}]: the robust plan holds over [{c_lo:g}, {c_hi:g}] only (widen the range "
                                "in the press file if the parameter can lie there)")
            bounds[name] = (float(c_lo), float(c_hi))
        if not bounds:
            raise PlanningError(f"{source}: \"intervals\" is empty: nothing to be robust against")
        return cls(dict(center), bounds, clipped, kind, tuple(warnings))

    def corners(self) -> list[dict]:
        """Every corner of the box (2^n parameter sets), in a fixed order."""
        names = sorted(self.bounds)
        return [dict(zip(names, pick)) for pick in itertools.product(*(self.bounds[n] for n in names))]


class _Builder:
    """Members (path dynamics, drive, friction) for parameter sets, path dynamics shared where they agree."""

    def __init__(self, pm: PressModel, process: ProcessForce, theta, contact_index, pd_center: PathDynamics, center: dict | None = None):
        self.pm, self.process, self.theta, self.contact = pm, process, theta, contact_index
        self._pd_center = pd_center
        self._pds = {} if center is None else {self._key(center): pd_center}  # ``pm`` is the centre model, ``pd_center`` its path dynamics
        self._drive_friction = {}  # drive and friction per values of their parameters

    def _key(self, values: dict) -> tuple:
        """The values that enter the path dynamics (not friction or drive, which enter per member)."""
        return tuple(sorted((n, v) for n, v in values.items() if self._section(n) not in ("friction", "drive")))

    def _section(self, name):
        return self.pm.press.parameters[name].target.section

    def _drive_friction_key(self, values: dict) -> tuple:
        """The values that enter the drive and the friction (the rest of a member)."""
        return tuple(sorted((n, v) for n, v in values.items() if self._section(n) in ("friction", "drive")))

    def member(self, values: dict, label: str) -> Member:
        # the press file is read again (~10 ms) only for a drive and friction or path dynamics not built before: the
        # 64 corners and 17 members of the paper's six parameters share 16 of the one and 4 of the other
        key, df_key = self._key(values), self._drive_friction_key(values)
        press = None
        if df_key not in self._drive_friction:
            press = self.pm.press.with_overrides(values, "robust box")
            self._drive_friction[df_key] = (press.drive, press.friction)
        if key not in self._pds:
            if not key:
                self._pds[key] = self._pd_center
            else:
                press = press or self.pm.press.with_overrides(values, "robust box")
                pm_c = PressModel(press, check_assembly=False)  # same geometry: no parameter moves a joint
                pm_c.assembly = self.pm.assembly
                self._pds[key] = build_path_dynamics(pm_c, self.theta, self.process, self.contact, like=self._pd_center)
        return Member(self._pds[key], *self._drive_friction[df_key], label)


def worst_case_members(builder: _Builder, box: Box) -> list[Member]:
    """The members of the module docstring: monotone parameters at their worst side per row type, the rest at every corner."""
    pm = builder.pm
    target = {n: pm.press.parameters[n].target for n in box.bounds}
    monotone = [n for n in box.bounds if target[n].field == "efficiency" or target[n].section == "friction"]
    others = sorted(n for n in box.bounds if n not in monotone)
    eff = [n for n in monotone if target[n].field == "efficiency"]
    fric = [n for n in monotone if n not in eff]
    # motoring worst: low efficiency, high friction; braking worst: high efficiency, low friction
    motoring = {**{n: box.bounds[n][0] for n in eff}, **{n: box.bounds[n][1] for n in fric}}
    braking = {**{n: box.bounds[n][1] for n in eff}, **{n: box.bounds[n][0] for n in fric}}
    members = [builder.member(box.center, "centre")]
    for pick in itertools.product(*(box.bounds[n] for n in others)):
        corner = dict(zip(others, pick))
        for side, worst in (("motoring", motoring), ("braking", braking)):
            values = {**box.center, **corner, **worst}
            members.append(builder.member(values, f"{side} worst, " + ", ".join(f"{n}={v:.6g}" for n, v in values.items())))
    return members


def corner_peaks(builder: _Builder, box: Box, plan: Plan) -> list[tuple[dict, float]]:
    """Peak |T_m| (N m per motor) of the plan's knot profile under every corner of the box, on the full model
    (the same evaluation as the planner's re-check: :func:`planning.evaluation.evaluate_profile`)."""
    out = []
    for corner in box.corners():
        m = builder.member({**box.center, **corner}, "corner")
        ev = evaluate_profile(builder.pm, m.pd, plan.profile, m)
        out.append((corner, float(max(np.max(np.abs(ev.motor_right)), np.max(np.abs(ev.motor_left))))))
    return out


@dataclass
class RobustResult:
    plan: Plan  # the robust plan (feed-forward and outputs for the centre model)
    nominal: Plan  # the plan for the centre (calibrated) values alone
    box: Box
    members: list
    corner_peaks: list  # [(corner, peak N m)]
    cuts: int  # corners added because they broke the limit

    def summary(self, t_max: float) -> dict:
        worst_corner, worst = max(self.corner_peaks, key=lambda cp: cp[1])
        return {
            "method": "torque rows at the box's worst cases per knot: efficiency and friction at their worst side per row type "
                      "(monotone), the other parameters at every corner; verified at all 2^n corners on the full model "
                      "(planning/robust.py)",
            "box": {n: list(b) for n, b in self.box.bounds.items()},
            "box_kind": self.box.kind,
            "clipped_to_parameter_ranges": self.box.clipped,
            "warnings": list(self.box.warnings),
            "center": self.box.center,
            "center_outside_box": sorted(n for n, (lo, hi) in self.box.bounds.items() if not lo <= self.box.center[n] <= hi),
            "members_in_lp": len(self.members),
            "corners_checked": len(self.corner_peaks),
            "corners_added": self.cuts,
            "worst_corner": worst_corner,
            "worst_corner_peak_torque_Nm": worst,
            "worst_corner_peak_ratio": worst / t_max,
            "strokes_per_min_robust": self.plan.strokes_per_min,
            "strokes_per_min_nominal_calibrated": self.nominal.strokes_per_min,
            "rate_cost_percent": 100.0 * (1.0 - self.plan.strokes_per_min / self.nominal.strokes_per_min),
        }


def plan_robust(pm: PressModel, process: ProcessForce, spec: PlanningSpec, box: Box, nominal: Plan | None = None) -> RobustResult:
    """The robust plan on ``pm`` (the centre model) for ``box``; also the nominal plan of the centre (for the rate cost)."""
    if nominal is None:
        grid = planning_grid(pm, process, spec)
        nominal = plan_stroke(pm, process, spec, pd=build_path_dynamics(pm, grid.theta, process, grid.contact_index), grid=grid)
    grid, pd = nominal.grid, nominal.pd
    builder = _Builder(pm, process, grid.theta, grid.contact_index, pd, box.center)
    members = worst_case_members(builder, box)
    limit = planning_limit(pm, spec)
    for cuts in range(MAX_CUTS + 1):
        # IPOPT started from the nominal optimum: the robust one differs only where a worst case binds
        plan = plan_stroke(pm, process, spec, pd=pd, grid=grid, members=members, start=nominal.profile)
        peaks = corner_peaks(builder, box, plan)
        broken = [c for c, p in peaks if p > limit * (1.0 + 1e-9)]
        if not broken:
            return RobustResult(plan, nominal, box, members, peaks, cuts)
        members = members + [builder.member({**box.center, **c}, "corner that broke the limit") for c in broken]
    worst = max(peaks, key=lambda cp: cp[1])
    raise PlanningError(f"{spec.source}: the robust plan still breaks the torque limit at a corner of the box after {MAX_CUTS} rounds "
                        f"({worst[1]:,.0f} N m against {limit:,.0f} N m at {worst[0]}); narrow the intervals")

