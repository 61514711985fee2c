"""The minimum-energy plan at a stated production rate ([planning.power] ``target_strokes_per_min``): the jerk-limited
stage with the stroke's grid energy as its objective instead of its time, the stroke time bounded by the rate's cycle
less the job's dwell, every limit of the time-optimal plan kept (torque, speed, forming window, jerk, thermal, the grid
peak limit if the job sets one).

The objective is what the grid gives over one cycle, from the same grid power the grid rows use
(:class:`planning.optimal.GridRow`: k s with s = T w + a T^2 + b w + c w^2 the motors' terminal power, Eq. 16's smooth
form for T): while the drives draw, k s; while they regenerate, what reaches the grid is s times the converters'
efficiency instead of over it (a regenerative supply), or nothing (a diode supply: the brake resistor takes it), both in
one smooth form. Over a segment it is integrated by Boole's rule over its knots and checks (the thermal row's
quadrature), and the dwell the cycle's rest adds at the holding torque's grid power: minimising
sum_i h_i (P_i - P_hold) + P_hold T_cycle gives the cycle's energy at T_cycle = 60 / spm. The time-optimal stroke with
its dwell stretched to the same cycle is one admissible point of this problem, so the optimum draws no more.
A capacitor bank (storage) is left out of the objective: the written plan's energy (summary ``energy``) has it.
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import casadi as ca
import numpy as np

from press_model.forces import ProcessForce
from press_model.model import PressModel

from .energy import plan_energy
from .errors import PlanningError
from .evaluation import BOOLE, cycle_rms
from .modes import plan_in_mode
from .planner import Plan, grid_row
from .power import PowerLimit, grid_bound_coefficients
from .profile import sample_plan
from .settings import PlanningSpec

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
    plan = plan_in_mode(pm, process, spec, pd=fastest.pd, grid=fastest.grid, start=fastest.profile, row=row)
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
                  "(planning/power_energy.py)",
    }


def min_energy_line(rec: dict) -> str:
    """One line the 'plan' command prints of a minimum-energy plan (summary ``min_energy``)."""
    return (f"minimum energy at {rec['target_strokes_per_min']:.3f} spm: {rec['energy_per_stroke_J'] / 1e6:.4f} MJ per stroke "
            f"against {rec['time_optimal_energy_per_stroke_J'] / 1e6:.4f} MJ for the time-optimal stroke with a longer dwell "
            f"({rec['saving_J'] / 1e3:,.1f} kJ less; stroke {rec['stroke_time_s']:.3f} s)")

