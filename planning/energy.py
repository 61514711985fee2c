"""What a plan is optimised for and measured by beside the minimum time of :mod:`planning.planner`: a plan's grid energy
per stroke (:func:`plan_energy`), the time optimum under a grid peak-power limit (:func:`plan_under_grid_limit`; robust
over a calibration's region: :func:`plan_robust_under_grid_limit`), the minimum-energy plan at a stated rate
(:func:`plan_min_energy`, with :class:`EnergyObjective` as the jerk-limited stage's objective) and the front of rate
against the grid's peak (:func:`pareto_front`). Each section below says how. Units: SI (W, J, s, N m per motor).
"""
from __future__ import annotations

import dataclasses
import math
import types
from dataclasses import dataclass

import casadi as ca
import numpy as np

from press_io.errors import PlanningError
from press_model.energy import stroke_energy
from press_model.forces import ProcessForce
from press_model.model import PressModel
from press_model.motor import crank_input_torque, motor_torque
from press_model.power_flow import trapezoid_weights

from .evaluation import BOOLE, cycle_rms, evaluate_profile
from .modes import plan_in_mode
from .path_dynamics import full_crank_torque
from .planner import Plan, StrokeProblem, grid_row
from .power import PowerLimit, grid_bound_coefficients
from .profile import sample_plan
from .robust import Box, RobustResult, _Builder, plan_robust
from .settings import PlanningSpec

# ----------------------------------------------------------------------------------------------------------------------
# A plan's energy per stroke (summary.json ``energy``, power.csv, power.png): the motor torque and speed of
# profile.csv's samples through :func:`press_model.energy.stroke_energy`, the dwell's holding torque included.
#
# The mechanical parts: the process work (the job's force on the slide over its motion), the gear's loss (the shaft's
# power less what the gear passes to the crank, :func:`press_model.motor.crank_input_torque`), and the rest of the
# shaft's work as the joints' and guide's friction (the linkage's kinetic, potential and balance energy return to
# their start over the periodic stroke).

RPM_TO_RAD_S = 2.0 * math.pi / 60.0


def plan_energy(pm: PressModel, process: ProcessForce, cols: dict):
    """(power flow or None, the summary's ``energy``) of a plan sampled as profile.csv's columns ``cols`` (one
    periodic cycle: the first and last samples are its start and end)."""
    drive = pm.press.drive
    t = np.asarray(cols["time_s"], float)
    w = trapezoid_weights(t)
    torque = np.asarray(cols["motor_torque_Nm"], float)
    crank_speed = np.asarray(cols["crank_speed_rad_s"], float)
    shaft_net = float(np.sum(drive.motors * drive.gear_ratio * torque * crank_speed * w))
    h, hd = np.asarray(cols["slide_height_m"], float), np.asarray(cols["slide_velocity_m_s"], float)
    process_work = float(np.sum(-process(h, hd) * hd * w))
    crank_side = crank_input_torque(drive, torque, crank_speed) * crank_speed
    gear = float(np.sum((drive.motors * drive.gear_ratio * torque * crank_speed - crank_side) * w))
    mechanical = {"gear_J": gear, "friction_J": shaft_net - gear - process_work, "process_work_J": process_work}
    flow, en = stroke_energy(pm.press, torque, crank_speed * drive.gear_ratio, w, mechanical)
    en["friction_is"] = ("the shaft's net work less the gear's loss and the process work: joint and guide friction (the "
                         "linkage's kinetic, potential and balance energy return over the periodic stroke)")
    return flow, en


# ----------------------------------------------------------------------------------------------------------------------
# A plan under the job's supply limit ([planning.power] grid_peak_limit_W): the jerk-limited stage carries the grid
# power at its knots and checks as rows (:class:`planning.limits.GridRow`); between the checks the written profile's
# power can bulge above them (power is torque x speed, more curved than either), so the written profile (profile.csv's
# samples through :mod:`planning.energy`) is re-checked and the row's bound tightened by the excess until it holds.


RECHECK_ROUNDS = 4  # plans at a tightened row bound at most (one or two suffice on the door panel)
RECHECK_TIGHTENING = 1.0e-5  # the tightened bound is limit x (bound / peak) x (1 - this)


def plan_under_grid_limit(problem: StrokeProblem, power: PowerLimit, start=None) -> tuple[Plan, dict]:
    """The time-optimal plan whose written profile draws at most ``power.grid_peak_limit_W`` from the grid (W); returns
    (plan, record: the limit, the feed-forward's share of it (``grid_feedback_reserve`` kept free), the rows' bounds tried,
    the written peak). ``problem``: the job on its press (:class:`planning.planner.StrokeProblem`); ``start``: a profile on
    its knots IPOPT starts from (:func:`planning.planner.plan_stroke`'s)."""
    pm, process = problem.pm, problem.process
    limit = power.grid_peak_limit_W
    target = power.feedforward_limit_W
    bound, tried = target, []
    for _ in range(RECHECK_ROUNDS):
        plan = plan_in_mode(problem, start=start, power=dataclasses.replace(power, grid_peak_limit_W=bound))
        _, en = plan_energy(pm, process, sample_plan(plan, pm.press.drive.gear_ratio))
        tried.append(bound)
        peak = en["grid_peak_W"]
        if peak <= target or plan.optimiser.get("status") == "fallback":
            break
        bound *= target / peak * (1.0 - RECHECK_TIGHTENING)
        start = plan.profile
    return plan, {"grid_peak_limit_W": limit, "feedforward_limit_W": target, "row_bounds_W": tried, "grid_peak_W": peak,
                  "held": bool(peak <= target),
                  "optimiser": plan.optimiser.get("status")}


# ----------------------------------------------------------------------------------------------------------------------
# The minimum-energy plan at a stated production rate ([planning.power] ``target_strokes_per_min``): the jerk-limited
# stage with the stroke's grid energy as its objective instead of its time, the stroke time bounded by the rate's cycle
# less the job's dwell, every limit of the time-optimal plan kept (torque, speed, forming window, jerk, thermal, the grid
# peak limit if the job sets one).
#
# The objective is what the grid gives over one cycle, from the same grid power the grid rows use
# (:class:`planning.limits.GridRow`: k s with s = T w + a T^2 + b w + c w^2 the motors' terminal power, Eq. 16's smooth
# form for T): while the drives draw, k s; while they regenerate, what reaches the grid is s times the converters'
# efficiency instead of over it (a regenerative supply), or nothing (a diode supply: the brake resistor takes it), both in
# one smooth form. Over a segment it is integrated by Boole's rule over its knots and checks (the thermal row's
# quadrature), and the dwell the cycle's rest adds at the holding torque's grid power: minimising
# sum_i h_i (P_i - P_hold) + P_hold T_cycle gives the cycle's energy at T_cycle = 60 / spm. The time-optimal stroke with
# its dwell stretched to the same cycle is one admissible point of this problem, so the optimum draws no more.
# A capacitor bank (storage) is left out of the objective: the written plan's energy (summary ``energy``) has it.


SOLVER_OPTIONS = {"ipopt.limited_memory_max_history": 6, "ipopt.mu_init": 1e-3, "ipopt.tol": 1e-6, "ipopt.acceptable_tol": 1e-4, "ipopt.acceptable_iter": 10, "ipopt.obj_scaling_factor": 0.1}
REPEAT_TOLERANCE = 1.0e-3  # relative: friction re-solves whose energies agree so closely are one optimum (optimal.optimise): the door panel's minimum-energy stroke sits on friction kinks (mu |reaction|), its re-solves cycle within 6e-4 of the energy
SMOOTHING = 1.0e-2  # of the rows' unit (both motors at peak torque and top speed, ~5.4 MW): |s| as sqrt(s^2 + this^2); the energy over-stated by at most (1 - regen) x this x the unit / 2, ~2 kW at the reference press


@dataclass(frozen=True)
class EnergyObjective:
    """The stroke's grid energy as the jerk-limited stage's objective, with the stroke time <= ``stroke_time`` (s)."""

    regen: float  # grid power per unit of the motoring form while the drives regenerate: (inverter x infeed)^2, 0 for a diode supply
    hold_power: float  # W: the grid power while the press dwells at its holding torque
    stroke_time: float  # s: the stroke time's bound (a bound of the built problem, set per solve)

    @property
    def structure(self) -> tuple:
        return ("energy", self.regen, self.hold_power)

    @property
    def solver_options(self) -> dict:
        """IPOPT's options for this objective over the time-optimal stage's (``planning.optimal``)."""
        return dict(SOLVER_OPTIONS)

    def repeats(self, objective: float, before: float) -> bool:
        """Whether two friction re-solves' objective values count as one optimum (a cycle over a friction kink)."""
        return abs(objective - before) <= REPEAT_TOLERANCE * abs(before)

    def add_time_row(self, rows, v, h_ref: float) -> slice:
        """The stroke time sum h_i (in units of ``h_ref``) <= the bound (set per solve); returns its row's slice."""
        start = sum(len(lb) for lb in rows.lb)
        rows.add([ca.sum1(v.hs)], np.array([-np.inf]), np.array([np.inf]))
        return slice(start, start + 1)

    def objective(self, grid_fn, Y0, v, problem):
        """The cycle's grid energy less its constant part, in units of the grid rows' scale x h_ref (J / (W s))."""
        N = problem.n - 1
        R = grid_fn.map(N, "serial")(Y0, v.Z)  # 5 x N: k s / scale at the knots and checks
        P = 0.5 * ((1.0 + self.regen) * R + (1.0 - self.regen) * ca.sqrt(R * R + SMOOTHING**2))
        seg = ca.mtimes(ca.DM(np.asarray(BOOLE)).T, P)  # 1 x N: each segment's mean grid power
        return ca.mtimes(seg - self.hold_power / problem.grid.scale, v.hs)


def energy_objective(pm: PressModel, hold_torque: float, stroke_time: float) -> EnergyObjective:
    """The objective for ``pm``'s press ([drive.electrical]) with the holding torque ``hold_torque`` (N m per motor)."""
    el = pm.press.electrical
    a, b, c, k = grid_bound_coefficients(el, pm.press.drive.motors)
    k_inv, k_infeed = el.inverter.efficiency, el.supply.efficiency  # the converters' (not the gear's of Eq. 16)
    regen = (k_inv * k_infeed) ** 2 if el.supply.kind == "regenerative" else 0.0
    return EnergyObjective(regen, k * a * hold_torque**2, stroke_time)


def _with_cycle(plan: Plan, cycle: float) -> Plan:
    """``plan`` with its dwell stretched to make the cycle ``cycle`` s (its RMS over that cycle)."""
    dwell = cycle - plan.stroke_time
    return dataclasses.replace(plan, dwell=dwell, rms_torque=cycle_rms(plan.evaluation, plan.profile, dwell, plan.hold_torque))


def plan_min_energy(pm: PressModel, process: ProcessForce, spec: PlanningSpec, power: PowerLimit, fastest: Plan,
                    target_spm: float) -> tuple[Plan, dict]:
    """The plan drawing the least grid energy per cycle at ``target_spm`` strokes per minute, under every limit of
    ``fastest`` (the time-optimal plan of the same job and ``power``; its stroke starts the solve); returns (plan with
    the cycle 60 / ``target_spm`` s, record: the target, both plans' energy per stroke and the saving). Raises
    :class:`PlanningError` for a target above the time-optimal rate."""
    cycle = 60.0 / target_spm
    if cycle < fastest.cycle_time * (1.0 - 1e-9):
        raise PlanningError(f"{spec.source}: planning.power.target_strokes_per_min = {target_spm:g} is not valid: the "
                            f"time-optimal plan makes {fastest.strokes_per_min:.3f} spm at most; give a target at or below it")
    stroke = cycle - fastest.dwell
    # the grid limit's rows (if the job sets one) at the feed-forward's share of it, as the time-optimal plan's start
    row = grid_row(pm, dataclasses.replace(power, grid_peak_limit_W=power.feedforward_limit_W), always=True)
    row = dataclasses.replace(row, energy=energy_objective(pm, fastest.hold_torque, stroke))
    plan = plan_in_mode(StrokeProblem(pm, process, spec, fastest.grid, fastest.pd), start=fastest.profile, row=row)
    if plan.optimiser.get("status") == "fallback":
        raise PlanningError(f"{spec.source}: the minimum-energy plan at {target_spm:g} spm did not converge "
                            f"({plan.optimiser.get('fallback_reason')}); remove planning.power.target_strokes_per_min for the time-optimal plan")
    plan = _with_cycle(plan, cycle)
    fast = _with_cycle(fastest, cycle)
    gear = pm.press.drive.gear_ratio
    _, en = plan_energy(pm, process, sample_plan(plan, gear))
    _, en_fast = plan_energy(pm, process, sample_plan(fast, gear))
    return plan, {
        "target_strokes_per_min": target_spm, "cycle_time_s": cycle, "stroke_time_s": plan.stroke_time,
        "stroke_time_bound_s": stroke, "energy_per_stroke_J": en["net_J"], "drawn_J": en["drawn_J"],
        "time_optimal_energy_per_stroke_J": en_fast["net_J"], "time_optimal_drawn_J": en_fast["drawn_J"],
        "time_optimal_strokes_per_min": fastest.strokes_per_min,
        "saving_J": en_fast["net_J"] - en["net_J"],
        "time_optimal_is": "the time-optimal stroke with its dwell stretched to the same cycle",
        "optimiser": plan.optimiser.get("status"),
        "method": "the jerk-limited stage with the cycle's grid energy as its objective and the stroke time bounded "
                  "(planning/energy.py)",
    }


def min_energy_line(rec: dict) -> str:
    """One line the 'plan' command prints of a minimum-energy plan (summary ``min_energy``)."""
    return (f"minimum energy at {rec['target_strokes_per_min']:.3f} spm: {rec['energy_per_stroke_J'] / 1e6:.4f} MJ per stroke "
            f"against {rec['time_optimal_energy_per_stroke_J'] / 1e6:.4f} MJ for the time-optimal stroke with a longer dwell "
            f"({rec['saving_J'] / 1e3:,.1f} kJ less; stroke {rec['stroke_time_s']:.3f} s)")


# ----------------------------------------------------------------------------------------------------------------------
# A robust plan under the job's supply limit ([planning.power] grid_peak_limit_W with a calibration's joint region): the
# robust plan (:func:`planning.robust.plan_robust`) with the jerk-limited stage's grid rows on the centre's model, and the
# grid limit verified at every corner of the box on the full model, the rows' bound tightened by the worst corner's
# excess and the plan solved again until every corner holds.
#
# Why the bound and not each corner's rows: the stage's grid rows are the first member's (the centre's); a corner draws
# more where its torque is larger (low gear efficiency while motoring, high masses and gear inertia while accelerating), by
# about the same share wherever the grid peaks bind (the approach's and the return's accelerations), so one scaled bound
# reaches it in one or two extra plans. It is conservative (a corner that draws less elsewhere is held to the same bound),
# not the optimum with every corner's grid power among the rows.
#
# The check per corner is the written profile's: profile.csv's samples (:func:`planning.profile.reference` with the
# corner's full-model evaluation of the knot profile, its holding torque in the dwell) through the power flow of
# :func:`planning.energy.plan_energy` with the corner's drive, so the corners' grid peaks are what each of those presses
# would draw running the plan.


ROBUST_RECHECK_ROUNDS = 6  # robust plans at a tightened row bound at most (two suffice on the door panel)
ROBUST_TIGHTENING = 1.0e-3  # the tightened bound is bound x (target / worst corner's peak) x (1 - this): the worst corner moves
# a little with the plan (2e-5 of the bound on the door panel), and one more robust plan to take that back costs a third of the
# command; 1e-3 of the grid bound costs about 2e-5 of the stroke time


def corner_grid_peaks(pm: PressModel, process: ProcessForce, box: Box, plan: Plan, builder=None) -> list[tuple[dict, float]]:
    """Per corner of ``box`` (:meth:`Box.corners`, and the centre first as ``{}``), the grid peak (W) of ``plan``'s written
    profile run on that corner's press: the corner's full-model torque along the knot profile, sampled as profile.csv,
    through its drive and the press file's [drive.electrical]. ``builder``: a :class:`planning.robust._Builder` on the
    plan's knots whose corners' path dynamics are reused (None: one is made)."""
    builder = builder or _Builder(pm, process, plan.grid.theta, plan.grid.contact_index, plan.pd, box.center)
    presses = {}
    out = []
    zeros = np.zeros(plan.pd.n)
    for corner in [{}] + box.corners():
        values = {**box.center, **corner}
        m = builder.member(values, "corner")
        ev = evaluate_profile(pm, m.pd, plan.profile, m)
        hold = float(motor_torque(m.drive, full_crank_torque(m.pd, zeros, zeros, friction=m.friction).crank_torque[0], 0.0, 0.0))
        key = builder._drive_friction_key(values)
        if key not in presses:
            presses[key] = pm.press.with_overrides(values, "robust box")
        cols = sample_plan(dataclasses.replace(plan, evaluation=ev, pd=m.pd, hold_torque=hold), pm.press.drive.gear_ratio)
        _, en = plan_energy(types.SimpleNamespace(press=presses[key]), process, cols)
        out.append((corner, float(en["grid_peak_W"])))
    return out


def plan_robust_under_grid_limit(pm: PressModel, process: ProcessForce, spec: PlanningSpec, box: Box,
                                 power: PowerLimit) -> tuple[RobustResult, dict]:
    """The robust plan over ``box`` whose written profile draws at most ``power``'s feed-forward share of
    ``grid_peak_limit_W`` (W) at every corner of the box and at the centre; returns (the robust result, the summary's
    ``grid_limit`` record: the limit, the rows' bounds tried, the worst corner and its grid peak, the corners checked)."""
    target = power.feedforward_limit_W
    bound, tried, builder = target, [], None
    for _ in range(ROBUST_RECHECK_ROUNDS):
        # each from toppra's smoothed stroke: a start from the previous round's plan screens other rows in, and the
        # rebuilt solver costs what the fewer iterations save (24.6 against 23.8 s of CPU on the door panel)
        res = plan_robust(pm, process, spec, box, plan_nominal=False, power=dataclasses.replace(power, grid_peak_limit_W=bound))
        builder = builder or _Builder(pm, process, res.plan.grid.theta, res.plan.grid.contact_index, res.plan.pd, box.center)
        peaks = corner_grid_peaks(pm, process, box, res.plan, builder)
        tried.append(bound)
        worst_corner, worst = max(peaks, key=lambda cp: cp[1])
        if worst <= target or res.plan.optimiser.get("status") == "fallback":
            break
        bound *= target / worst * (1.0 - ROBUST_TIGHTENING)
    return res, {"grid_peak_limit_W": power.grid_peak_limit_W, "feedforward_limit_W": target, "row_bounds_W": tried,
                 "grid_peak_W": peaks[0][1], "worst_corner": worst_corner or "centre", "worst_corner_grid_peak_W": worst,
                 "corners_checked": len(peaks) - 1, "held": bool(worst <= target),
                 "optimiser": res.plan.optimiser.get("status"),
                 "method": "the centre's grid rows in the robust plan's jerk-limited stage, the written profile's grid peak "
                           "checked at every corner of the box on the full model and the rows' bound tightened by the worst "
                           "corner's excess until every corner holds (planning/energy.py)"}


# ----------------------------------------------------------------------------------------------------------------------
# `plan --pareto`: the front of production rate against the supply's peak power. The job is planned at a row of grid
# peak limits from the unconstrained plan's own grid peak down to ``lowest_fraction`` of it
# ([planning.power] ``pareto_points``, ``pareto_lowest_fraction``), each the jerk-limited time optimum under that limit
# (the plan before is its start), and the energy per stroke of each is reported: pareto.csv and pareto.png.


COLUMNS = ["grid_peak_limit_W", "strokes_per_min", "grid_peak_W", "energy_per_stroke_J", "drawn_J", "returned_J",
           "stroke_time_s", "cycle_time_s", "within_limit", "optimiser"]


def pareto_limits(peak: float, points: int, lowest_fraction: float) -> np.ndarray:
    """``points`` grid limits (W) from ``peak`` (the unconstrained plan's grid peak) down to ``lowest_fraction`` of it."""
    return peak * np.linspace(1.0, lowest_fraction, points)


def _row(pm: PressModel, process: ProcessForce, plan: Plan, limit: float) -> dict:
    _, en = plan_energy(pm, process, sample_plan(plan, pm.press.drive.gear_ratio))
    opt = plan.optimiser or {}
    return {"grid_peak_limit_W": limit, "strokes_per_min": plan.strokes_per_min, "grid_peak_W": en["grid_peak_W"],
            "energy_per_stroke_J": en["net_J"], "drawn_J": en["drawn_J"], "returned_J": en["returned_J"],
            "stroke_time_s": plan.stroke_time, "cycle_time_s": plan.cycle_time,
            "within_limit": "yes" if en["grid_peak_W"] <= limit * (1.0 + 1e-6) else "NO", "optimiser": opt.get("status", "-")}


def pareto_front(pm: PressModel, process: ProcessForce, spec: PlanningSpec, base: Plan, power: PowerLimit,
                 progress=None) -> list[dict]:
    """The front's rows (pareto.csv's columns): ``base`` the unconstrained plan, then one plan per lower limit, each
    started from its neighbour's optimum on ``base``'s knots and path dynamics (built once; the jerk-limited stage's
    IPOPT solver is built at the first limit and reused, the limit being a bound: :data:`planning.optimal.SOLVER_CACHE`)."""
    _, en = plan_energy(pm, process, sample_plan(base, pm.press.drive.gear_ratio))
    limits = pareto_limits(en["grid_peak_W"], power.pareto_points, power.pareto_lowest_fraction)
    rows = [_row(pm, process, base, float(limits[0]))]
    start = base.profile
    for limit in limits[1:]:
        try:
            plan, _ = plan_under_grid_limit(StrokeProblem(pm, process, spec, base.grid, base.pd),
                                            dataclasses.replace(power, grid_peak_limit_W=float(limit)), start=start)
        except PlanningError as exc:
            rows.append({**{k: float("nan") for k in COLUMNS}, "grid_peak_limit_W": float(limit), "within_limit": "NO",
                         "optimiser": f"infeasible: {exc}"})
            break
        rows.append(_row(pm, process, plan, float(limit)))
        if progress is not None:
            progress(len(rows) / len(limits))
        start = plan.profile
    return rows
