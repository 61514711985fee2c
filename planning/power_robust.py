"""A robust plan under the job's supply limit ([planning.power] grid_peak_limit_W with a calibration's joint region): the
robust plan (:func:`planning.robust.plan_robust`) with the jerk-limited stage's grid rows on the centre's model, and the
grid limit verified at every corner of the box on the full model, the rows' bound tightened by the worst corner's
excess and the plan solved again until every corner holds.

Why the bound and not each corner's rows: the stage's grid rows are the first member's (the centre's); a corner draws
more where its torque is larger (low gear efficiency while motoring, high masses and gear inertia while accelerating), by
about the same share wherever the grid peaks bind (the approach's and the return's accelerations), so one scaled bound
reaches it in one or two extra plans. It is conservative (a corner that draws less elsewhere is held to the same bound),
not the optimum with every corner's grid power among the rows.

The check per corner is the written profile's: profile.csv's samples (:func:`planning.profile.reference` with the
corner's full-model evaluation of the knot profile, its holding torque in the dwell) through the power flow of
:func:`planning.energy.plan_energy` with the corner's drive, so the corners' grid peaks are what each of those presses
would draw running the plan."""
from __future__ import annotations

import dataclasses
import types

import numpy as np

from press_model.forces import ProcessForce
from press_model.model import PressModel
from press_model.motor import motor_torque

from .energy import plan_energy
from .evaluation import evaluate_profile
from .path_dynamics import full_crank_torque
from .planner import Plan
from .power import PowerLimit
from .profile import sample_plan
from .robust import Box, RobustResult, _Builder, plan_robust
from .settings import PlanningSpec

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
                           "corner's excess until every corner holds (planning/power_robust.py)"}
