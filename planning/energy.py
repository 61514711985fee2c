"""What a plan is optimised for and measured by beside the minimum time of :mod:`planning.planner`: a plan's grid energy
per stroke (:func:`plan_energy`), the time optimum under a grid peak-power limit (:func:`plan_under_grid_limit`; robust
over a calibration's region: :func:`plan_robust_under_grid_limit`), the minimum-energy plan at a stated rate under the
job's transfer window (:func:`plan_min_energy`, with :class:`EnergyObjective` as the jerk-limited stage's objective) and
the front of rate against the grid's peak (:func:`pareto_front`). The objectives as objects the `plan` command takes
without knowing which (:class:`MinimumTime`, :class:`GridLimited`, :class:`MinimumEnergy`, :class:`ParetoRow`;
:func:`objective_of`), and :func:`refuse_unmet` for a plan that breaks a stated limit. Each section below says how.
Units: SI (W, J, s, N m per motor).
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
from .modes import optimiser_records, plan_in_mode
from .path_dynamics import full_crank_torque
from .planner import Plan, StrokeProblem, grid_row, plan_stroke
from .power import PowerLimit, grid_bound_coefficients
from .profile import sample_plan
from .robust import Box, RobustResult, corner_builder, plan_robust
from .settings import PlanningSpec
from .transfer import segments_below, window_kept

# ----------------------------------------------------------------------------------------------------------------------
# A plan's energy per stroke (summary.json ``energy``, power.csv, power.png): the motor torque and speed of
# profile.csv's samples through :func:`press_model.energy.stroke_energy`, the dwell's holding torque included.
#
# The mechanical parts: the process work (the job's force on the slide over its motion), the gear's loss (the shaft's
# power less what the gear passes to the crank, :func:`press_model.motor.crank_input_torque`), and the rest of the
# shaft's work as the joints' and guide's friction (the linkage's kinetic, potential and balance energy return to
# their start over the periodic stroke).

RPM_TO_RAD_S = 2.0 * math.pi / 60.0


def plan_energy(pm: PressModel, process: ProcessForce, cols: dict, working=None):
    """(power flow or None, the summary's ``energy``) of a plan sampled as profile.csv's columns ``cols`` (one
    periodic cycle: the first and last samples are its start and end). ``working``: per sample, whether the process
    force acts (a pendulum's working swing; its return runs with the die empty); None: wherever the force curve has it."""
    drive = pm.press.drive
    t = np.asarray(cols["time_s"], float)
    w = trapezoid_weights(t)
    torque = np.asarray(cols["motor_torque_Nm"], float)
    crank_speed = np.asarray(cols["crank_speed_rad_s"], float)
    shaft_net = float(np.sum(drive.motors * drive.gear_ratio * torque * crank_speed * w))
    h, hd = np.asarray(cols["slide_height_m"], float), np.asarray(cols["slide_velocity_m_s"], float)
    process_work = float(np.sum(-process(h, hd) * hd * w * (1.0 if working is None else np.asarray(working, float))))
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
STROKE_BACKOFF = 1.0e-7  # relative: the stroke's time row bound below the cycle, which IPOPT meets to ~3e-9 (the door panel at 11 spm under its window: 1.7e-8 s over), so the dwell the cycle leaves is never negative
SMOOTHING = 1.0e-2  # of the rows' unit (both motors at peak torque and top speed, ~5.4 MW): |s| as sqrt(s^2 + this^2); the energy over-stated by at most (1 - regen) x this x the unit / 2, ~2 kW at the reference press


@dataclass(frozen=True)
class EnergyObjective:
    """The stroke's grid energy as the jerk-limited stage's objective, with the moving stroke's time <= ``stroke_time``
    (s) and, with a transfer window, its time with the slide below the opening <= ``below_time`` (s) over the segments
    ``below`` (:func:`planning.transfer.segments_below`); the thermal row takes the dwell as ``cycle`` (s) less the stroke
    (:class:`planning.optimal.CollocationProblem`)."""

    regen: float  # grid power per unit of the motoring form while the drives regenerate: (inverter x infeed)^2, 0 for a diode supply
    hold_power: float  # W: the grid power while the press dwells at its holding torque
    stroke_time: float  # s: the stroke time's bound (a bound of the built problem, set per solve)
    below: tuple | None = None  # per segment, whether the slide is below the transfer's opening in it (None: no window)
    below_time: float = math.inf  # s: the bound of those segments' time (set per solve)
    cycle: float | None = None  # s: the cycle at the stated rate; the thermal row counts the dwell as what it leaves of the stroke

    @property
    def structure(self) -> tuple:
        return ("energy", self.regen, self.hold_power, self.below)

    @property
    def solver_options(self) -> dict:
        """IPOPT's options for this objective over the time-optimal stage's (``planning.optimal``)."""
        return dict(SOLVER_OPTIONS)

    def repeats(self, sol, before) -> bool:
        """Whether two friction re-solves (:class:`planning.optimal.Solve`) count as one optimum: their objective values
        within :data:`REPEAT_TOLERANCE` (a cycle over a friction kink)."""
        return abs(sol.objective - before.objective) <= REPEAT_TOLERANCE * abs(before.objective)

    def add_time_row(self, rows, v, h_ref: float) -> slice:
        """The stroke time sum h_i (in units of ``h_ref``) <= the bound, and with a window the time below the opening
        <= its bound (both set per solve, :meth:`time_bounds`); returns their rows' slice."""
        start = sum(len(lb) for lb in rows.lb)
        g = [ca.sum1(v.hs)]
        if self.below is not None:
            g.append(ca.sum1(v.hs[[int(i) for i in np.flatnonzero(self.below)]]))
        rows.add(g, np.full(len(g), -np.inf), np.full(len(g), np.inf))
        return slice(start, start + len(g))

    def time_bounds(self) -> np.ndarray:
        """The time rows' bounds (s): the stroke's, and the time below the opening's with a window."""
        return np.array([self.stroke_time] + ([self.below_time] if self.below is not None else []))

    def objective(self, seg: dict, Y0, v, problem):
        """The cycle's grid energy less its constant part, in units of the grid rows' scale x h_ref (J / (W s)), from the
        stage's segment functions ``seg`` (their grid power)."""
        N = problem.n - 1
        R = seg["grid"].map(N, "serial")(Y0, v.Z)  # 5 x N: k s / scale at the knots and checks
        P = 0.5 * ((1.0 + self.regen) * R + (1.0 - self.regen) * ca.sqrt(R * R + SMOOTHING**2))
        seg = ca.mtimes(ca.DM(np.asarray(BOOLE)).T, P)  # 1 x N: each segment's mean grid power
        return ca.mtimes(seg - self.hold_power / problem.grid.scale, v.hs)


def energy_objective(pm: PressModel, hold_torque: float, cycle: float, stroke_time: float, below=None,
                     below_time: float = math.inf) -> EnergyObjective:
    """The objective for ``pm``'s press ([drive.electrical]) with the holding torque ``hold_torque`` (N m per motor), the
    cycle ``cycle`` (s), the stroke's time bound ``stroke_time`` (s) and, with a transfer window, the segments ``below``
    its opening and the bound ``below_time`` (s) of their time."""
    el = pm.press.electrical
    a, b, c, k = grid_bound_coefficients(el, pm.press.drive.motors)
    k_inv, k_infeed = el.inverter.efficiency, el.supply.efficiency  # the converters' (not the gear's of Eq. 16)
    regen = (k_inv * k_infeed) ** 2 if el.supply.kind == "regenerative" else 0.0
    below = None if below is None else tuple(bool(x) for x in below)
    return EnergyObjective(regen, k * a * hold_torque**2, stroke_time, below, below_time, cycle)


def _with_cycle(plan: Plan, cycle: float) -> Plan:
    """``plan`` with its dwell stretched to make the cycle ``cycle`` s (its RMS over that cycle)."""
    dwell = cycle - plan.stroke_time
    return dataclasses.replace(plan, dwell=dwell, rms_torque=cycle_rms(plan.evaluation, plan.profile, dwell, plan.hold_torque))


def _window(pm: PressModel, fastest: Plan, cycle: float) -> tuple:
    """(segments below the opening, the bound of their time in s) of a stop-at-top job with [planning.transfer] at the
    cycle ``cycle`` s: the slide may be below the opening for the cycle less the transfer's time, stops below it included;
    (None, inf) without a window."""
    tr = fastest.spec.transfer
    if tr is None or fastest.spec.mode != "stop-at-top":
        return None, math.inf
    resting_below = sum(st.time for st in fastest.stops if st.height < tr.opening_height)
    return segments_below(pm, fastest.grid, tr.opening_height), cycle - tr.time - resting_below


def plan_min_energy(pm: PressModel, process: ProcessForce, spec: PlanningSpec, power: PowerLimit, fastest: Plan,
                    target_spm: float) -> tuple[Plan, dict]:
    """The plan drawing the least grid energy per cycle at ``target_spm`` strokes per minute, under every limit of
    ``fastest`` (the time-optimal plan of the same job and ``power``, in the mode it was planned in; its stroke starts the
    solve) and the job's transfer window; returns (plan with the cycle 60 / ``target_spm`` s, record: the target, both
    plans' energy per stroke and the saving). Raises :class:`PlanningError` for a target above the time-optimal rate.

    The dwell is what the cycle leaves of the stroke (the thermal row counts it so). A fixed ``dwell_s`` bounds the stroke
    by the cycle less it. With [planning.transfer] the window is a row of the problem instead: the slide below the opening
    for at most the cycle less ``time_s`` (the segments holding the two crossings counted whole, a few ms too much), the
    stroke at most the cycle; a slower stroke spends longer above the opening and needs less dwell."""
    cycle = 60.0 / target_spm
    if cycle < fastest.cycle_time * (1.0 - 1e-9):
        raise PlanningError(f"{spec.source}: planning.power.target_strokes_per_min = {target_spm:g} is not valid: the "
                            f"time-optimal plan makes {fastest.strokes_per_min:.3f} spm at most; give a target at or below it")
    if fastest.spec.mode not in ("stop-at-top", "continuous"):
        raise PlanningError(f"{spec.source}: planning.power.target_strokes_per_min = {target_spm:g} is planned on one turning stroke, "
                            f"not in mode \"{fastest.spec.mode}\"; set planning.mode = \"stop-at-top\" or remove the target")
    below, below_time = _window(pm, fastest, cycle)
    # the crank's moving time (the stops on the way are fixed): the cycle less the job's fixed dwell, or with a window
    # the whole cycle (the window's row bounds it)
    stroke = (cycle - (fastest.dwell if below is None else 0.0) - fastest.stop_time) * (1.0 - STROKE_BACKOFF)
    # the grid limit's rows (if the job sets one) at the feed-forward's share of it, as the time-optimal plan's start
    row = grid_row(pm, dataclasses.replace(power, grid_peak_limit_W=power.feedforward_limit_W), always=True)
    row = dataclasses.replace(row, energy=energy_objective(pm, fastest.hold_torque, cycle, stroke, below, below_time))
    # in the time-optimal plan's own mode (auto: the one it kept); its dwell is the planner's thermal check's (the
    # stage's row takes the cycle's), the written dwell the cycle's rest (_with_cycle)
    problem = StrokeProblem(pm, process, fastest.spec, fastest.grid, fastest.pd)
    plan = plan_stroke(problem, dwell=fastest.dwell, start=fastest.profile, row=row)
    if plan.optimiser.get("status") == "fallback":
        raise PlanningError(f"{spec.source}: the minimum-energy plan at {target_spm:g} spm did not converge "
                            f"({plan.optimiser.get('fallback_reason')}); remove planning.power.target_strokes_per_min for the time-optimal plan")
    plan = _with_cycle(plan, cycle)
    if below is not None:
        plan.transfer = {**window_kept(pm, plan, fastest.spec, plan.dwell),
                         "rule": "the cycle 60 / target_strokes_per_min; dwell = the cycle less the stroke, the slide below "
                                 "opening_height_m for at most the cycle less time_s (a row of the minimum-energy problem)"}
    fast = _with_cycle(fastest, cycle)
    gear = pm.press.drive.gear_ratio
    _, en = plan_energy(pm, process, sample_plan(plan, gear))
    _, en_fast = plan_energy(pm, process, sample_plan(fast, gear))
    return plan, {
        "target_strokes_per_min": target_spm, "cycle_time_s": cycle, "stroke_time_s": plan.stroke_time,
        "stroke_time_bound_s": stroke / (1.0 - STROKE_BACKOFF) + fastest.stop_time, "energy_per_stroke_J": en["net_J"], "drawn_J": en["drawn_J"],
        **({"time_below_opening_bound_s": below_time} if below is not None else {}),
        "time_optimal_energy_per_stroke_J": en_fast["net_J"], "time_optimal_drawn_J": en_fast["drawn_J"],
        "time_optimal_strokes_per_min": fastest.strokes_per_min,
        "saving_J": en_fast["net_J"] - en["net_J"],
        "time_optimal_is": "the time-optimal stroke with its dwell stretched to the same cycle",
        "optimiser": plan.optimiser.get("status"),
        "method": "the jerk-limited stage with the cycle's grid energy as its objective, the stroke time bounded and the "
                  "transfer window (if any) a row (planning/energy.py)",
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
    builder = builder or corner_builder(pm, process, plan.grid, plan.pd, box.center)
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
        builder = builder or corner_builder(pm, process, res.plan.grid, res.plan.pd, box.center)  # plan_robust's own: its corners built
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
    fell_back = opt.get("status") == "fallback"  # toppra's jerk-free stroke: it breaks the jerk limit, whatever it draws
    within = en["grid_peak_W"] <= limit * (1.0 + 1e-6) and not fell_back
    return {"grid_peak_limit_W": limit, "strokes_per_min": plan.strokes_per_min, "grid_peak_W": en["grid_peak_W"],
            "energy_per_stroke_J": en["net_J"], "drawn_J": en["drawn_J"], "returned_J": en["returned_J"],
            "stroke_time_s": plan.stroke_time, "cycle_time_s": plan.cycle_time, "within_limit": "yes" if within else "NO",
            "optimiser": f"fallback: {opt.get('fallback_reason')}" if fell_back else opt.get("status", "-")}


def pareto_front(pm: PressModel, process: ProcessForce, spec: PlanningSpec, base: Plan, power: PowerLimit,
                 progress=None) -> list[dict]:
    """The front's rows (pareto.csv's columns): ``base`` the unconstrained plan, then one plan per lower limit
    (:class:`ParetoRow`), each started from its neighbour's optimum on ``base``'s knots and path dynamics (built once; the
    jerk-limited stage's IPOPT solver is built at the first limit and reused, the limit being a bound:
    :data:`planning.optimal.SOLVER_CACHE`). A limit whose plan fell back to toppra's stroke or could not be planned ends
    the front with its row marked (``within_limit`` NO, ``optimiser`` why): the limits below it are lower still."""
    _, en = plan_energy(pm, process, sample_plan(base, pm.press.drive.gear_ratio))
    limits = pareto_limits(en["grid_peak_W"], power.pareto_points, power.pareto_lowest_fraction)
    rows = [_row(pm, process, base, float(limits[0]))]
    problem = StrokeProblem(pm, process, spec, base.grid, base.pd)
    start = base.profile
    for limit in limits[1:]:
        plan, rec = ParetoRow(power, float(limit)).plan(problem, start=start)
        rows.append(rec["pareto_row"])
        if progress is not None:
            progress(len(rows) / len(limits))
        if plan is None or rows[-1]["within_limit"] != "yes":
            break
        start = plan.profile
    return rows


def pareto_met(rows: list[dict]) -> list[dict]:
    """The rows of the front whose plan meets its limit (``within_limit`` yes): the front as it may be reported."""
    return [r for r in rows if r["within_limit"] == "yes"]


# ----------------------------------------------------------------------------------------------------------------------
# What the plan is optimised for, as objects the command takes without knowing which: each ``plan(problem, start)``
# returns (the plan, the summary's records of what it was planned for); :func:`objective_of` picks one from the job's
# [planning.power]. Below them the jerk-limited stage takes the time sum or :class:`EnergyObjective` as its objective;
# above them :func:`refuse_unmet` turns a plan that does not keep a stated limit into an error (nothing is written).


@dataclass(frozen=True)
class MinimumTime:
    """The time-optimal plan in the job's mode: no supply limit, no target rate."""

    what = "time-optimal plan (toppra, then the jerk-limited optimum; friction fixed points)"  # the progress line's phase

    def plan(self, problem: StrokeProblem, start=None) -> tuple[Plan, dict]:
        """(the time-optimal plan of ``problem``, no records)."""
        return plan_in_mode(problem, start=start), {}


@dataclass(frozen=True)
class GridLimited:
    """The time-optimal plan whose written profile draws at most ``power.grid_peak_limit_W`` (W) from the grid."""

    power: PowerLimit

    @property
    def what(self) -> str:
        """What is planned, as the progress line names the phase."""
        return (f"time-optimal plan within the grid limit {self.power.grid_peak_limit_W / 1e6:.3f} MW (toppra, then the "
                "jerk-limited optimum with the grid rows; friction fixed points)")

    def plan(self, problem: StrokeProblem, start=None) -> tuple[Plan, dict]:
        """(the plan, {"grid_limit": :func:`plan_under_grid_limit`'s record, ``held`` whether the plan keeps it})."""
        plan, rec = plan_under_grid_limit(problem, self.power, start=start)
        return plan, {"grid_limit": rec}


@dataclass(frozen=True)
class MinimumEnergy:
    """The least grid energy per cycle at ``power.target_strokes_per_min``, under every limit of the time-optimal plan
    ``first`` plans (:class:`MinimumTime` or :class:`GridLimited`)."""

    power: PowerLimit
    first: object

    @property
    def what(self) -> str:
        """What is planned, as the progress line names the phase."""
        return (f"{self.first.what}; then the minimum-energy plan at {self.power.target_strokes_per_min:g} spm (the "
                "jerk-limited stage with the grid energy as its objective)")

    def plan(self, problem: StrokeProblem, start=None) -> tuple[Plan, dict]:
        """(the minimum-energy plan, ``first``'s records and {"min_energy": :func:`plan_min_energy`'s record})."""
        fastest, rec = self.first.plan(problem, start=start)
        refuse_unmet(problem.pm, fastest, rec, problem.spec.source)  # the start must keep every limit it is to keep
        plan, rec["min_energy"] = plan_min_energy(problem.pm, problem.process, problem.spec, self.power, fastest,
                                                  self.power.target_strokes_per_min)
        if "grid_limit" in rec:  # the written plan's own grid peak is the summary's energy.grid_peak_W
            rec["grid_limit"]["of"] = "the time-optimal plan the minimum-energy plan started from"
        return plan, rec


@dataclass(frozen=True)
class ParetoRow:
    """One row of ``plan --pareto``'s front: the time-optimal plan under the grid peak ``limit`` (W)."""

    power: PowerLimit
    limit: float

    def plan(self, problem: StrokeProblem, start=None) -> tuple[Plan | None, dict]:
        """(the plan or None if none could be planned, {"pareto_row": the row of pareto.csv, marked NO with the reason
        where the plan fell back to toppra's stroke, breaks the limit or could not be planned})."""
        try:
            plan, _ = plan_under_grid_limit(problem, dataclasses.replace(self.power, grid_peak_limit_W=self.limit), start=start)
        except PlanningError as exc:
            return None, {"pareto_row": {**{k: float("nan") for k in COLUMNS}, "grid_peak_limit_W": self.limit,
                                         "within_limit": "NO", "optimiser": f"infeasible: {exc}"}}
        return plan, {"pareto_row": _row(problem.pm, problem.process, plan, self.limit)}


def objective_of(power: PowerLimit):
    """The objective the job's [planning.power] asks for: :class:`MinimumEnergy` with a target rate (over
    :class:`GridLimited` with a grid limit), else :class:`GridLimited` or :class:`MinimumTime`."""
    first = GridLimited(power) if power.limited else MinimumTime()
    return MinimumEnergy(power, first) if power.min_energy else first


def refuse_unmet(pm: PressModel, plan: Plan, records: dict, source: str) -> None:
    """Raise :class:`PlanningError` naming the first stated limit ``plan`` does not keep (the job's grid peak limit in
    ``records["grid_limit"]``, the jerk limit, the thermal limit, the torque margin) and what the plan reaches there;
    a plan that keeps them all passes."""
    g = records.get("grid_limit")
    spec = plan.spec
    reason = next((o.get("fallback_reason") for o in optimiser_records(plan) if (o or {}).get("status") == "fallback"), None)
    if g is not None and not g["held"]:
        worst = g.get("worst_corner_grid_peak_W", g["grid_peak_W"])
        raise PlanningError(
            f"{source}: planning.power.grid_peak_limit_W = {g['grid_peak_limit_W']:g} cannot be met: the best stroke found draws "
            f"{worst / 1e6:.3f} MW from the grid at its peak ({g['feedforward_limit_W'] / 1e6:.3f} MW planned for)"
            + (f"; the jerk-limited stage failed ({reason})" if reason else "")
            + "; no plan written: raise the limit (in W, not MW) or lower the process force")
    if reason is not None and math.isfinite(spec.crank_jerk):
        raise PlanningError(f"{source}: planning.limits.crank_jerk_rad_s3 = {spec.crank_jerk:g} cannot be met: the jerk-limited stage "
                            f"failed ({reason}) and toppra's jerk-free stroke steps its acceleration (unbounded jerk); no plan "
                            "written: raise planning.solver.optimal_max_iterations or relax the limit that conflicts with it")
    rated = pm.press.motor.rated_torque
    if plan.rms_torque > rated * (1.0 + 1e-9):
        raise PlanningError(f"{source}: the thermal limit cannot be met: the cycle RMS is {plan.rms_torque:,.0f} N m, above T_rated "
                            f"{rated:,.0f} N m; no plan written: lengthen planning.dwell_s or lower the process force")
    margin = spec.torque_limits(pm.press.motor.peak_torque).verdict
    if plan.peak_torque > margin * (1.0 + 1e-9):
        raise PlanningError(f"{source}: planning.limits.peak_torque_margin = {spec.torque_margin:g} cannot be met: the plan reaches "
                            f"{plan.peak_torque:,.0f} N m, above {margin:,.0f} N m; no plan written: lower the process force")
