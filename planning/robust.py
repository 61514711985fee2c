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
  braking row at low friction. The drive losses of [drive.losses] (k_load, c_drive) likewise: Eq. 16 gains
  k_load (B / nu)^2 + c_drive u theta_dot, never negative while the crank turns forward, so the motoring row is worst
  at their high side and the braking row at their low side. These take one side of the box per row type, not both.
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
(a cutting-plane loop; the corner joins the worst-case group of the row type it broke and the plan is re-solved in its
own stage from the last solution, :meth:`_RobustRun.cut`). Such a corner is mostly seen before the stage: along toppra's stroke the
corners whose row beats their group's where the limit binds join the group up front (:func:`screen_corners`; on a
calibration of a SYNTHETIC clean cushion-test log, seed 101, mu_s at the top of its box braked harder near the end of the
stroke than at the bottom, and its cut re-solved the stage twice more). Where the per-segment worst-case stage does not converge within
``PER_SEGMENT_MAX_ITERATIONS``, every member's rows are planned instead (:meth:`_RobustRun.plan_members`). A test checks the
robust plan at every corner with the per-point Pinocchio model.
Intervals reaching outside a parameter's range in the press file (e.g. eta_gear above 0.99) are clipped to
it (the range is the press file's statement of where the parameter can lie; a box reaching past it asks the plan to
hold for presses that cannot exist) and each clipping is a `warning:` line naming the parameter, the box and the range. A bootstrap interval need not contain the point estimate; the centre
(the calibrated values) is one of the LP's members anyway, so the plan holds there as well as in the box.
"""
from __future__ import annotations

import copy
import dataclasses
import functools
import itertools
import logging
import weakref
from dataclasses import dataclass

import numpy as np

from press_io.errors import PlanningError
from press_model.forces import ProcessForce
from press_model.model import PressModel
from press_model.press_data import PressData

from .evaluation import Member, evaluate_members, evaluate_profile
from .modes import plan_in_mode
from .limits import Limits, OptimalControlError
from .jerk_stage import Robust
from .path_dynamics import PathDynamics, build_path_dynamics
from .pendulum import pendulum_corner_torques, plan_pendulum
from .planner import Plan, StrokePlanner, StrokeProblem, plan_stroke, planning_limit
from .settings import PlanningSpec

log = logging.getLogger(__name__)

DRIVE_FIELDS = {"load_loss": "load_loss_at_rated"}  # a drive parameter's target field -> the Drive attribute it sets, where they differ
DRIVE_LOSS_FIELDS = ("load_loss", "viscous", "coulomb_drag")  # [drive.losses]' parameters: they raise T_m on both rows, as friction does
MAX_CUTS = 8  # rounds of adding a corner that breaks the limit before the robust plan is refused
PER_SEGMENT_MAX_ITERATIONS = 150  # IPOPT iterations per solve of the per-segment worst-case stage before every member's rows take over: its solves take 13-45 on the boxes measured; on one SYNTHETIC calibration (J_gear's region the whole range) it stalled at the optimum's value without meeting the tolerance for 500, where every member's rows converge in 40
SCREENED = "corner that beats its worst-case group"  # the label of a member screen_corners adds
BINDING_BAND = 0.01  # the cost driver's binding knots: the worst corner's |T_m| within this fraction of the feed-forward limit (the torque-limited phases; elsewhere the margin costs nothing)
ROW_TYPES = ("motoring", "braking")  # the two row types of a worst-case group, in the order of the rows' columns below


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
        eta_gear above 0.99), with a warning line per clipped parameter; refused where nothing of it lies in the range.
        ``press``: the press file as read, not the calibrated press (whose ranges are re-centred on the calibrated values)."""
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

    def _drive_and_friction(self, values: dict) -> tuple | None:
        """The centre's drive and friction with the values of their scalar parameters in ``values`` set (the fields
        :data:`press_model.press_data.SCALAR_TARGETS` names, SI, as the press reader sets them); None if a value of
        those sections is not such a scalar (the press file is then read again with the values)."""
        fields = {"drive": {}, "friction": {}}
        for n, v in values.items():
            t = self.pm.press.parameters[n].target
            if t.section in fields:
                if not t.field:
                    return None
                fields[t.section][DRIVE_FIELDS.get(t.field, t.field) if t.section == "drive" else t.field] = float(v)
        press = self.pm.press
        return dataclasses.replace(press.drive, **fields["drive"]), dataclasses.replace(press.friction, **fields["friction"])

    def member(self, values: dict, label: str) -> Member:
        # a drive and friction are the centre's with their scalars set (reading the press file again costs ~20 ms, 16
        # times for the 64 corners of the paper's six parameters); the press file is read again only for path
        # dynamics not built before (4 for those corners) or a drive or friction value that is not a scalar
        key, df_key = self._key(values), self._drive_friction_key(values)
        press = None
        if df_key not in self._drive_friction:
            df = self._drive_and_friction(values)
            if df is None:
                press = self.pm.press.with_overrides(values, "robust box")
                df = (press.drive, press.friction)
            self._drive_friction[df_key] = df
        if key not in self._pds:
            if not key:
                self._pds[key] = self._pd_center
            else:
                press = press or self.pm.press.with_overrides(values, "robust box")
                pm_c = PressModel(press, check_assembly=False)  # same geometry: no parameter moves a joint
                pm_c.assembly = self.pm.assembly
                self._pds[key] = build_path_dynamics(pm_c, self.theta, self.process, self.contact, like=self._pd_center)
        return Member(self._pds[key], *self._drive_friction[df_key], label)


_SHARED: "weakref.WeakKeyDictionary[PressModel, list]" = weakref.WeakKeyDictionary()
SHARED_KEPT = 4  # per press model: centre problems and corner builders kept (a grid-limited robust plan's rounds share one of each)


def _shared(pm: PressModel, same: tuple, equal: tuple, make):
    """``make()``'s result for ``pm``, the objects ``same`` (compared by identity) and the values ``equal`` (by ==), made
    once while ``pm`` lives; the last ``SHARED_KEPT`` are kept."""
    seen = _SHARED.setdefault(pm, [])
    for s, e, value in seen:
        if len(s) == len(same) and all(a is b for a, b in zip(s, same)) and e == equal:
            return value
    value = make()
    seen.append((same, equal, value))
    del seen[:-SHARED_KEPT]
    return value


def centre_problem(pm: PressModel, process: ProcessForce, spec: PlanningSpec) -> StrokeProblem:
    """:meth:`StrokeProblem.build` of the centre ``pm`` (knots and path dynamics), built once per press model, process force
    and settings: a robust plan planned again on them (the grid limit's rounds at a tightened row bound,
    :func:`planning.energy.plan_robust_under_grid_limit`) takes the knots and path dynamics built before."""
    return _shared(pm, ("problem", process), (spec,), lambda: StrokeProblem.build(pm, process, spec))


def corner_builder(pm: PressModel, process: ProcessForce, grid, pd: PathDynamics, center: dict) -> _Builder:
    """The :class:`_Builder` of the box's members on ``grid``'s knots around the centre's path dynamics ``pd``, made once per
    ``pd`` and centre values: the corners' path dynamics (and drives and frictions) it builds serve every robust plan and
    corner check on these knots (the grid limit's rounds and their corners' grid peaks)."""
    return _shared(pm, ("builder", process, pd), (dict(center),),
                   lambda: _Builder(pm, process, grid.theta, grid.contact_index, pd, center))


def worst_case_members(builder: _Builder, box: Box) -> tuple[list[Member], list[tuple[str, list[int]]]]:
    """The members of the module docstring: monotone parameters at their worst side per row type, the rest at every corner.

    Returns (members: the centre first, then per corner of the affine parameters its motoring and its braking worst
    case; the groups [("motoring", indices), ("braking", indices)] whose worst case per segment the optimal-control
    stage takes, :class:`planning.limits.WorstCase`)."""
    pm = builder.pm
    target = {n: pm.press.parameters[n].target for n in box.bounds}
    monotone = [n for n in box.bounds if target[n].field == "efficiency" or target[n].section == "friction"
                or (target[n].section == "drive" and target[n].field in DRIVE_LOSS_FIELDS)]
    others = sorted(n for n in box.bounds if n not in monotone)
    eff = [n for n in monotone if target[n].field == "efficiency"]
    fric = [n for n in monotone if n not in eff]
    # motoring worst: low efficiency, high friction; braking worst: high efficiency, low friction
    motoring = {**{n: box.bounds[n][0] for n in eff}, **{n: box.bounds[n][1] for n in fric}}
    braking = {**{n: box.bounds[n][1] for n in eff}, **{n: box.bounds[n][0] for n in fric}}
    members = [builder.member(box.center, "centre")]
    groups = {"motoring": [], "braking": []}
    for pick in itertools.product(*(box.bounds[n] for n in others)):
        corner = dict(zip(others, pick))
        for side, worst in (("motoring", motoring), ("braking", braking)):
            values = {**box.center, **corner, **worst}
            groups[side].append(len(members))
            members.append(builder.member(values, f"{side} worst, " + ", ".join(f"{n}={v:.6g}" for n, v in values.items())))
    return members, list(groups.items())


def screen_corners(builder: _Builder, box: Box, members: list[Member], groups: list, prof, level: float) -> list[tuple[Member, set]]:
    """The corners of the box that the monotone rule of :func:`worst_case_members` misses along ``prof``: per row type,
    every corner whose drive is its group's (the efficiency at that row type's worst side) and whose row (motoring: T_m,
    braking: -T_m, N m per motor, the knot's larger side) beats the largest row of the group's members at a knot where
    it comes within ``BINDING_BAND`` of ``level`` (N m per motor). The friction's monotonicity is exact for the friction
    alone, not through the reactions it shifts (the guide's friction moves the joints' normals): such a corner would
    break the limit on the full model and cost a cut (the stage re-solved); taken up front it joins the group, whose
    worst case per segment stays one row set. Returns [(member, {row type})] for :meth:`planning.jerk_stage.JerkStage.join`."""
    corners = [builder.member({**box.center, **c}, SCREENED) for c in box.corners()]
    # the members are corners themselves: one evaluation shares their friction fixed points (planning.evaluation)
    evs = evaluate_members(builder.pm, corners + list(members), prof)
    rows = np.array([[np.maximum(ev.motor_right, ev.motor_left), np.maximum(-ev.motor_right, -ev.motor_left)] for ev in evs])
    corner_rows, member_rows = rows[:len(corners)], rows[len(corners):]
    out = {}
    for kind, idx in groups:
        k = ROW_TYPES.index(kind)
        worst = np.max(member_rows[idx, k], axis=0)
        drive = dataclasses.replace(members[idx[0]].drive, gear_inertia=0.0)
        for c, (m, r) in enumerate(zip(corners, corner_rows[:, k])):
            if (np.any((r > worst) & (r >= (1.0 - BINDING_BAND) * level))
                    and dataclasses.replace(m.drive, gear_inertia=0.0) == drive):
                out.setdefault(c, (m, set()))[1].add(kind)
    return list(out.values())


def corner_torques(builder: _Builder, box: Box, plan: Plan) -> list[tuple[dict, np.ndarray]]:
    """Per corner of the box, the plan's motor torque at every knot (N m per motor, the side of the knot with the larger
    |T_m|) on the full model (the planner's re-check, :func:`planning.evaluation.evaluate_profile`)."""
    corners = box.corners()
    # corners that share their path dynamics and friction share the full model's friction fixed point (16 of 64 for the
    # paper's six), Eq. 16 applied per corner
    evs = evaluate_members(builder.pm, [builder.member({**box.center, **c}, "corner") for c in corners], plan.profile)
    return [(c, np.where(np.abs(ev.motor_right) >= np.abs(ev.motor_left), ev.motor_right, ev.motor_left)) for c, ev in zip(corners, evs)]


def corner_peaks(builder: _Builder, box: Box, plan: Plan) -> list[tuple[dict, float]]:
    """Peak |T_m| (N m per motor) of the plan's knot profile under every corner of the box (:func:`corner_torques`)."""
    return [(c, float(np.max(np.abs(t)))) for c, t in corner_torques(builder, box, plan)]


def region_peak(pm: PressModel, process: ProcessForce, spec: PlanningSpec, box: Box, plan: Plan) -> dict:
    """The largest |T_m| a plan (made for the centre) reaches over the box's corners, on the full model: summary
    ``nominal_over_region`` of `plan --nominal` ({"worst_corner", "peak_torque_Nm", "peak_ratio" (of T_max), "margin",
    "corners_checked", "box_kind"})."""
    builder = _Builder(pm, process, plan.grid.theta, plan.grid.contact_index, plan.pd, box.center)
    peaks = corner_peaks(builder, box, plan)
    corner, peak = max(peaks, key=lambda cp: cp[1])
    t_max = pm.press.motor.peak_torque
    return {"worst_corner": corner, "peak_torque_Nm": peak, "peak_ratio": peak / t_max, "margin": spec.torque_margin,
            "corners_checked": len(peaks), "box_kind": box.kind,
            "method": "the plan's knot profile through the full model (friction fixed point, Eq. 16) at every corner of the box"}


def cost_driver(box: Box, torques: list[tuple[dict, np.ndarray]], limit: float) -> dict:
    """Which parameter the robust plan's margin pays for: per parameter, its half-width's share of the torque spread at
    the binding knots.

    ``torques``: :func:`corner_torques` of the robust plan; the binding knots are those where the worst corner's |T_m|
    is within ``BINDING_BAND`` of ``limit`` (N m per motor). A parameter's spread at a knot is the mean, over the corner
    pairs that differ in it alone, of |T_m(high) - T_m(low)| (= |dT/dp| x the box's width for the affine parameters,
    i.e. twice |dT/dp| x its half-width); summed over the binding knots. Returns {"parameter": the largest, "shares":
    {name: share}, "spread_Nm": {name: summed spread}, "binding_knots": count, "method": ...}."""
    names = sorted(box.bounds)
    T = np.array([t for _, t in torques])  # (corners, knots) in box.corners() order: itertools.product over sorted names
    worst = np.max(np.abs(T), axis=0)
    knots = np.flatnonzero(worst >= (1.0 - BINDING_BAND) * limit)
    shape = (2,) * len(names)
    Tk = T[:, knots].reshape(*shape, len(knots))
    spread = {n: float(np.sum(np.mean(np.abs(np.take(Tk, 1, axis=j) - np.take(Tk, 0, axis=j)), axis=tuple(range(len(names) - 1)))))
              for j, n in enumerate(names)}
    total = sum(spread.values())
    shares = {n: (v / total if total > 0 else 0.0) for n, v in spread.items()}
    return {"parameter": max(shares, key=shares.get) if total > 0 else None, "shares": shares, "spread_Nm": spread,
            "binding_knots": int(len(knots)),
            "method": f"per parameter, |T_m(high) - T_m(low)| of the robust plan's knot profile over the corner pairs of the box that "
                      f"differ in it alone (mean over the pairs), summed over the knots where the worst corner's |T_m| is within "
                      f"{100 * BINDING_BAND:g} % of the feed-forward limit; share of the sum over the parameters"}


@dataclass
class RobustResult:
    plan: Plan  # the robust plan (feed-forward and outputs for the centre model)
    nominal: Plan | None  # the jerk-limited plan for the centre (calibrated) values alone, when it was planned
    box: Box
    members: list
    corner_peaks: list  # [(corner, peak N m)]
    cuts: int  # corners added because they broke the limit
    driver: dict  # :func:`cost_driver`
    nominal_estimate: dict  # how the nominal plan's rate was found: {"strokes_per_min", "method"}
    per_segment: bool  # the optimal-control stage took each group's worst case per segment (else every member)

    @property
    def nominal_strokes_per_min(self) -> float:
        return self.nominal_estimate["strokes_per_min"]

    def summary(self, t_max: float) -> dict:
        worst_corner, worst = max(self.corner_peaks, key=lambda cp: cp[1])
        spm_nominal = self.nominal_strokes_per_min
        return {
            "method": ("torque rows at the box's worst cases: efficiency and friction at their worst side per row type (monotone), "
                       "the other parameters at every corner in toppra's LP and, in the jerk-limited optimum, per segment the corner "
                       "whose motoring (braking) row is largest, chosen again at every friction re-solve (planning/limits.py, WorstCase); "
                       if self.per_segment else
                       "torque rows at the box's worst cases per knot: efficiency and friction at their worst side per row type "
                       "(monotone), the other parameters at every corner; ")
                      + "corners that beat their group along toppra's stroke where the limit binds joined to it before the "
                        "jerk-limited stage; verified at all 2^n corners on the full model, a corner that breaks the limit added and the "
                        "plan re-solved (planning/robust.py)",
            "box": {n: list(b) for n, b in self.box.bounds.items()},
            "box_kind": self.box.kind,
            "clipped_to_parameter_ranges": self.box.clipped,
            "warnings": list(self.box.warnings),
            "center": self.box.center,
            "center_outside_box": sorted(n for n, (lo, hi) in self.box.bounds.items() if not lo <= self.box.center[n] <= hi),
            "members_in_lp": len(self.members),
            "corners_joined_before_the_stage": sum(m.label == SCREENED for m in self.members),
            "worst_case_per_segment": self.per_segment,
            "corners_checked": len(self.corner_peaks),
            "corners_added": self.cuts,
            "worst_corner": worst_corner,
            "worst_corner_peak_torque_Nm": worst,
            "worst_corner_peak_ratio": worst / t_max,
            "strokes_per_min_robust": self.plan.strokes_per_min,
            "strokes_per_min_nominal_calibrated": spm_nominal,
            "nominal_calibrated_is": self.nominal_estimate["method"],
            "spm_cost": spm_nominal - self.plan.strokes_per_min,
            "rate_cost_percent": 100.0 * (1.0 - self.plan.strokes_per_min / spm_nominal),
            "cost_driver": self.driver,
            "buy_back": "a calibration run that narrows the cost driver's interval: `servo-press design-experiment`",
        }


def nominal_estimate(pm: PressModel, spec: PlanningSpec, plan: Plan) -> dict:
    """The nominal (centre-only) plan's production rate without planning it: the robust jerk-limited cycle shortened by
    the difference of toppra's jerk-free strokes (the robust one's, and the centre's alone at the same level on the
    same knots: one friction fixed point of the LP). Returns {"strokes_per_min", "method"}."""
    pd = plan.pd
    still = np.zeros(pd.n, bool)
    if plan.spec.mode == "stop-at-top":  # the plan's mode (mode = "auto": the one it kept)
        still[0] = still[-1] = True
    for st in plan.stops:  # the stops on the way (planning.hold)
        still[st.index] = True
    spec = plan.spec
    centre = [Member(pd, pm.press.drive, pm.press.friction)]
    # the fixed point starts from the centre's friction along the robust plan's jerk-free stroke (a few re-solves fewer
    # than from none; the same fixed point to its tolerance)
    ev = evaluate_profile(pm, pd, plan.jerk_free_profile, centre[0])
    prof, _, _ = StrokePlanner(pm, centre, Limits.declare(pm, spec, plan.grid, pd, still), spec).fixed_point(plan.torque_level, [(ev.fric_right, ev.fric_left)],
                                                                              np.sqrt(ev.x))
    cycle = plan.cycle_time - (plan.jerk_free_stroke_time - prof.stroke_time)
    return {"strokes_per_min": 60.0 / cycle,
            "method": "estimated, not planned: the robust plan's cycle shortened by toppra's jerk-free stroke of the box's worst cases "
                      "minus that of the calibrated values alone (on the door panel with a 6-parameter joint region around Table 4 this over-stated the cost: 0.54 % against the "
                      "0.46 % of the two jerk-limited plans; `compare` plans both)"}


def _join_groups(members: list[Member], groups: list, new: list[tuple[Member, set]]) -> list | None:
    """The worst-case groups with each added corner in the group of every row type it broke (a :class:`Member` and its
    broken row types, {"motoring", "braking"}); None if a corner cannot join one (its drive differs from the group's in more
    than the gear inertia, which :func:`planning.limits._combine` carries over: it then enters the stage as itself)."""
    def alike(a, b):
        return dataclasses.replace(a, gear_inertia=0.0) == dataclasses.replace(b, gear_inertia=0.0)

    out = [(kind, list(idx)) for kind, idx in groups]
    for k, (m, kinds) in enumerate(new):
        for kind, idx in out:
            if kind in kinds:
                if not alike(m.drive, members[idx[0]].drive):
                    return None
                idx.append(len(members) + k)
    return out


def _modes_after_cut(modes: dict | None, plan) -> dict | None:
    """Auto's record of every mode (planning.modes) carried to ``plan``, the kept mode's re-solve after a cut, with that
    mode's rate and cycle time as re-solved (the other modes' rows are as auto planned them)."""
    if not modes:
        return modes
    out = copy.deepcopy(modes)
    row = out["modes"].get(plan.spec.mode)
    if row is not None:
        row.update(strokes_per_min=plan.strokes_per_min, cycle_time_s=plan.cycle_time)
    return out


def stage_spec(spec: PlanningSpec) -> PlanningSpec:
    """``spec`` for a solve of the per-segment worst-case stage: at most ``PER_SEGMENT_MAX_ITERATIONS`` IPOPT iterations."""
    return dataclasses.replace(spec, optimal_max_iterations=min(spec.optimal_max_iterations, PER_SEGMENT_MAX_ITERATIONS))


def _with_spec(plan: Plan, spec: PlanningSpec) -> Plan:
    """The plan with the job's own settings (it was solved with :func:`stage_spec`'s), in the mode planned (``mode =
    "auto"``: the one kept)."""
    return dataclasses.replace(plan, spec=dataclasses.replace(spec, mode=plan.spec.mode))


@dataclass
class _RobustRun:
    """What every plan of one robust plan shares: the centre's problem (press, process, job, knots and path dynamics),
    each mode's start (the nominal plan or its plan per mode, :attr:`planning.planner.Plan.mode_plans`; None: none), the supply limit the stage holds (None: none) and the calibration's
    region (:class:`SwingRegion`, for mode = "auto"'s pendulum, which builds its members on its swings' knots)."""

    problem: StrokeProblem
    start: object = None  # the nominal plan, or name -> the nominal plan of each mode (planning.modes.plan_modes' start)
    power: object = None
    region: object = None

    def plan_members(self, members, groups, warm=None, screen=None):
        """The robust plan of ``members``: with ``groups`` the per-segment worst cases (:class:`planning.limits.WorstCase`) and,
        where that stage does not converge (:data:`PER_SEGMENT_MAX_ITERATIONS`), every member's rows, which do. Returns
        (members, groups as planned (None: every member's rows), plan). ``warm``: an evaluation per member toppra's friction
        starts from; ``screen(base, level, members=, groups=)``: :func:`screen_corners` on the box, whose corners join the
        groups before the stage starts (members and groups returned with them; None: none)."""
        problem, spec = self.problem, self.problem.spec
        if groups:
            if screen is not None and spec.mode != "auto":  # auto plans each mode on its own knots, not the builder's
                screen = functools.partial(screen, members=members, groups=groups)
            else:
                screen = None
            try:
                rows = Robust(members, groups, screen, warm, fallback=False)
                plan = _with_spec(plan_in_mode(problem.using(stage_spec(spec)), start=self.start, power=self.power, robust=rows,
                                               region=self.region), spec)
                stage = getattr(plan, "stage", None)
                if stage is not None and stage.worst is not None:  # with the corners the screen added
                    members, groups = stage.members, [(kind, list(idx)) for kind, idx in stage.worst.groups]
                return members, groups, plan
            except OptimalControlError as err:
                log.info("%s: the per-segment worst-case stage did not converge (%s); every member's rows instead", spec.source, err)
        return members, None, plan_in_mode(problem, start=self.start, power=self.power, robust=Robust(members, warm=warm),
                                           region=self.region)

    def cut(self, builder, center: dict, plan: Plan, members, groups, broken, limit: float):
        """The robust plan re-solved with the corners that broke the limit (``broken``: [(corner, torque per knot)]) added.

        The re-solve starts where the plan stopped: toppra's friction fixed point from every member's friction along the
        plan's jerk-free profile, IPOPT from the plan's optimum; and, where each added corner can join the worst-case group
        of the row type it broke (:func:`_join_groups`), in the plan's own stage, whose built problem keeps its row sets (a
        group's worst case per segment is one row set however many members it has): no rebuild. ``builder``: the box's
        members (each corner completes its centre values); ``limit``: N m per motor. Returns (members, groups (None: every
        member's rows), plan)."""
        spec = self.problem.spec
        new = [(builder.member({**center, **c}, "corner that broke the limit"),
                {"motoring" if v > 0 else "braking" for v in t[np.abs(t) > limit * (1.0 + 1e-9)]}) for c, t in broken]
        members = members + [m for m, _ in new]
        joined = _join_groups(members[:len(members) - len(new)], groups, new) if groups else None
        warm = evaluate_members(builder.pm, members, plan.jerk_free_profile) if plan.jerk_free_profile is not None else None
        stage = getattr(plan, "stage", None)  # a pendulum plan has none: its swings are re-planned whole
        if joined is not None and stage is not None and stage.worst is not None and plan.optimiser.get("status") != "fallback":
            stage.members = members
            stage.start = stage.problem._last[0] if stage.problem is not None and stage.problem._last is not None else plan.profile
            stage.worst.groups = [(kind, list(idx)) for kind, idx in joined]
            # the stage is the kept mode's (mode = "auto": the re-solve refines that mode; auto's own path would re-plan
            # every mode without the stage's members)
            kept = dataclasses.replace(spec, mode=plan.spec.mode)
            try:
                again = _with_spec(plan_stroke(StrokeProblem(builder.pm, builder.process, stage_spec(kept), plan.grid, plan.pd),
                                               robust=Robust(stage.members, warm=warm, stage=stage, fallback=False)), spec)
                return members, joined, dataclasses.replace(again, modes=_modes_after_cut(plan.modes, again))
            except OptimalControlError as err:  # every member's rows then (they converge where the per-segment stage may not)
                log.info("%s: the per-segment worst-case stage did not converge (%s); every member's rows instead", spec.source, err)
                return self.on(plan).plan_members(members, None, warm)
        # a corner that cannot join a group enters the stage as itself, beside the groups
        return self.on(plan).plan_members(members, joined or groups, warm)

    def on(self, plan) -> "_RobustRun":
        """This run on ``plan``'s knots and path dynamics."""
        return dataclasses.replace(self, problem=StrokeProblem(self.problem.pm, self.problem.process, self.problem.spec,
                                                               plan.grid, plan.pd))


@dataclass(frozen=True)
class SwingRegion:
    """A calibration's box as a pendulum swing holds it (:func:`planning.pendulum.plan_swing_robust`, below this module): the members and the corner check of this module on the swing's knots."""

    box: Box
    limit: float  # N m per motor: the feed-forward torque limit every corner must keep (planning_limit)
    max_cuts: int = MAX_CUTS

    def builder(self, pm: PressModel, process: ProcessForce, grid, pd: PathDynamics) -> _Builder:
        """Members built on ``grid``'s knots around ``pd`` (the centre's forward path dynamics there), made once per ``pd``
        (:func:`corner_builder`): the backward swing's members are the forward's path dynamics in their time reversal,
        which puts the return's process force in place of theirs (:func:`planning.path_dynamics.reversed_swing`), so both
        swings take the corners built for the first."""
        return corner_builder(pm, process, grid, pd, self.box.center)

    def members(self, builder) -> list[Member]:
        """:func:`worst_case_members` (the centre first)."""
        return worst_case_members(builder, self.box)[0]

    def corner_torques(self, builder, plan) -> list[tuple[dict, np.ndarray]]:
        """:func:`corner_torques` of the swing ``plan``."""
        return corner_torques(builder, self.box, plan)


def _pendulum_result(pm, process, spec, box: Box, plan, nominal) -> RobustResult:
    """The :class:`RobustResult` of a robust pendulum plan (its swings' corner checks, :func:`planning.pendulum.plan_swing_robust`);
    the rate against the calibrated values alone from the pendulum planned at them (``nominal`` if it is one)."""
    torques = pendulum_corner_torques(plan)
    if nominal is None or nominal.spec.mode != "pendulum":
        nominal = plan_pendulum(pm, process, plan.spec)
    est = {"strokes_per_min": nominal.strokes_per_min, "method": "planned: the pendulum of the calibrated values alone"}
    peaks = [(c, float(np.max(np.abs(t)))) for c, t in torques]
    cuts = plan.forward.robust_cuts + plan.backward.robust_cuts
    members = plan.forward.robust_members + plan.backward.robust_members  # both swings', each built on its own knots
    return RobustResult(plan, nominal, box, members, peaks, cuts, cost_driver(box, torques, planning_limit(pm, spec)), est, False)


def plan_robust(pm: PressModel, process: ProcessForce, spec: PlanningSpec, box: Box, nominal: Plan | None = None,
                plan_nominal: bool = True, per_segment: bool = True, power=None) -> RobustResult:
    """The robust plan on ``pm`` (the centre model) for ``box``, and the rate it costs against the centre alone.

    ``nominal``: the centre's jerk-limited plan if the caller has it (the robust optimum is started from it);
    otherwise it is planned when ``plan_nominal``, else its rate is estimated (:func:`nominal_estimate`; the `plan`
    command: planning it would add a second jerk-limited solve). ``per_segment``: the optimal-control stage takes per segment
    the worst motoring and braking case of the corners (:class:`planning.limits.WorstCase`) instead of every corner's rows (not
    for a drive with the press file's losses: every corner's rows then). ``power``: a supply limit whose grid rows the stage
    holds on the centre's model (:mod:`planning.energy` checks the corners and tightens them; None: none)."""
    if spec.mode == "pendulum":  # each swing robust on its own knots (planning.pendulum.plan_swing_robust)
        region = SwingRegion(box, planning_limit(pm, spec))
        return _pendulum_result(pm, process, spec, box, plan_pendulum(pm, process, spec, region=region), nominal)
    if nominal is None and plan_nominal:
        nominal = plan_in_mode(centre_problem(pm, process, spec))
    problem = StrokeProblem(pm, process, spec, nominal.grid, nominal.pd) if nominal is not None else centre_problem(pm, process, spec)
    builder = corner_builder(pm, process, problem.grid, problem.pd, box.center)
    members, groups = worst_case_members(builder, box)
    # the worst case per segment reads Eq. 16's two linear rows; a drive with the losses Eq. 16 leaves out has smooth rows
    # in the crank torque and the speed (planning/optimal.py), for which the stage takes every member
    per_segment = per_segment and not any(m.drive.has_losses for m in members)
    limit = planning_limit(pm, spec)
    # each mode started from the nominal plan of that mode (if planned; mode = "auto": every mode's, Plan.mode_plans): IPOPT
    # from its optimum, the robust one differing only where a worst case binds, and toppra's friction from its jerk-free stroke
    starts = (nominal.mode_plans or nominal) if nominal is not None else None
    run = _RobustRun(problem, starts, power, SwingRegion(box, limit))
    members, groups, plan = run.plan_members(members, groups if per_segment else None,
                                             screen=lambda base, level, members, groups: screen_corners(builder, box, members, groups, base, level))
    if hasattr(plan, "swings"):  # mode = "auto" kept the pendulum, whose swings hold the box on their own knots
        return _pendulum_result(pm, process, spec, box, plan, nominal)
    for cuts in range(MAX_CUTS + 1):
        per_segment = groups is not None
        torques = corner_torques(builder, box, plan)
        peaks = [(c, float(np.max(np.abs(t)))) for c, t in torques]
        broken = [(c, t) for c, t in torques if np.max(np.abs(t)) > limit * (1.0 + 1e-9)]
        if not broken:
            est = ({"strokes_per_min": nominal.strokes_per_min, "method": "planned: the jerk-limited plan of the calibrated values alone"}
                   if nominal is not None else nominal_estimate(pm, spec, plan))
            return RobustResult(plan, nominal, box, members, peaks, cuts, cost_driver(box, torques, limit), est, per_segment)
        if cuts == MAX_CUTS:
            break
        members, groups, plan = run.cut(builder, box.center, plan, members, groups, broken, limit)
        if hasattr(plan, "swings"):  # mode = "auto" re-planned kept the pendulum
            return _pendulum_result(pm, process, spec, box, plan, nominal)
    worst = max(peaks, key=lambda cp: cp[1])
    raise PlanningError(f"{spec.source}: the robust plan still breaks the torque limit at a corner of the box after {MAX_CUTS} rounds "
                        f"({worst[1]:,.0f} N m against {limit:,.0f} N m at {worst[0]}); narrow the intervals")
