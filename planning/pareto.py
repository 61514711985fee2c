"""`plan --pareto`: the front of production rate against the supply's peak power. The job is planned at a row of grid
peak limits from the unconstrained plan's own grid peak down to ``lowest_fraction`` of it
([planning.power] ``pareto_points``, ``pareto_lowest_fraction``), each the jerk-limited time optimum under that limit
(the plan before is its start), and the energy per stroke of each is reported: pareto.csv and pareto.png."""
from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np

from press_model.forces import ProcessForce
from press_model.model import PressModel
from press_io.outputs import write_table

from .energy import plan_energy
from .errors import PlanningError
from .planner import Plan
from .power import PowerLimit
from .power_plan import plan_under_grid_limit
from .profile import sample_plan
from .settings import PlanningSpec

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
            plan, _ = plan_under_grid_limit(pm, process, spec, dataclasses.replace(power, grid_peak_limit_W=float(limit)), start=start,
                                            pd=base.pd, grid=base.grid)
        except PlanningError as exc:
            rows.append({**{k: float("nan") for k in COLUMNS}, "grid_peak_limit_W": float(limit), "within_limit": "NO",
                         "optimiser": f"infeasible: {exc}"})
            break
        rows.append(_row(pm, process, plan, float(limit)))
        if progress is not None:
            progress(len(rows) / len(limits))
        start = plan.profile
    return rows


def write_pareto(rows: list[dict], out: Path) -> None:
    """pareto.csv of the front's rows."""
    write_table(Path(out) / "pareto.csv", COLUMNS, rows)
