"""A plan under the job's supply limit ([planning.power] grid_peak_limit_W): the jerk-limited stage carries the grid
power at its knots and checks as rows (:class:`planning.optimal.GridRow`); between the checks the written profile's
power can bulge above them (power is torque x speed, more curved than either), so the written profile (profile.csv's
samples through :mod:`planning.energy`) is re-checked and the row's bound tightened by the excess until it holds."""
from __future__ import annotations

import dataclasses

from press_model.forces import ProcessForce
from press_model.model import PressModel

from .energy import plan_energy
from .modes import plan_in_mode
from .planner import Plan
from .power import PowerLimit
from .profile import sample_plan
from .settings import PlanningSpec

RECHECK_ROUNDS = 4  # plans at a tightened row bound at most (one or two suffice on the door panel)
RECHECK_TIGHTENING = 1.0e-5  # the tightened bound is limit x (bound / peak) x (1 - this)


def plan_under_grid_limit(pm: PressModel, process: ProcessForce, spec: PlanningSpec, power: PowerLimit, start=None,
                          **kw) -> tuple[Plan, dict]:
    """The time-optimal plan whose written profile draws at most ``power.grid_peak_limit_W`` from the grid (W); returns
    (plan, record: the limit, the feed-forward's share of it (``grid_feedback_reserve`` kept free), the rows' bounds tried,
    the written peak). ``start``, ``kw``: :func:`plan_stroke`'s."""
    limit = power.grid_peak_limit_W
    target = power.feedforward_limit_W
    bound, tried = target, []
    for _ in range(RECHECK_ROUNDS):
        plan = plan_in_mode(pm, process, spec, start=start, power=dataclasses.replace(power, grid_peak_limit_W=bound), **kw)
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
