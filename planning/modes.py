"""The motion modes a stroke can be planned in, and `mode = "auto"`: every mode the job allows, the fastest kept.

:data:`MODES` is a small registry, name -> :class:`Mode`: how to plan the job in that mode (``plan``) and whether the
job allows it (``why_not``: None when it does, else the reason in one line). "stop-at-top" (rest at TDC, one turn,
rest at TDC, then the job's dwell or its transfer's), "continuous" (the crank never stops at TDC: not allowed with a
fixed dwell there, planning.dwell_s > 0; with [planning.transfer] planned, and kept only where its stroke alone keeps
the slide above the opening for time_s, else recorded with the reason) and "pendulum" (planning/pendulum.py: allowed
with [planning.transfer], its stops on the working swing; robust over a calibration's region swing by swing); a
further mode registers itself with :func:`register`. :func:`plan_in_mode` plans a job in the mode its settings name.

:func:`plan_fastest` plans each allowed mode on the same knots and path dynamics and keeps the fastest plan that
keeps every limit (the peak torque within the margin, the cycle RMS within the rating, the jerk limit kept: a plan
whose jerk-limited stage fell back to toppra does not count); its :attr:`planning.planner.Plan.modes` records every
mode: allowed or why not, its strokes per minute, whether it keeps every limit, or why it could not be planned, and
its rate against the stop-at-top plan's (``vs_stop_at_top_spm``, ``vs_stop_at_top_percent``).

Units: SI inside; strokes per minute in the record.
"""
from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Callable

from press_io.errors import PlanningError

from .pendulum import plan_pendulum
from .jerk_stage import Robust
from .planner import RefusedPlan, StrokeProblem, plan_stroke


@dataclass(frozen=True)
class Mode:
    """One motion mode, a strategy above the planner: ``why_not(spec) -> str | None``: None when the job (its spec in auto
    mode) allows the mode, else why not; ``plan(problem, **kw) -> Plan`` with the
    :class:`planning.planner.StrokeProblem`'s settings already in this mode (:func:`mode_spec`) and the keywords of
    :data:`AUTO_KEYWORDS`. The planner (:mod:`planning.planner`) knows no mode
    but the stroke's ends (at rest or periodic); this module chooses among them."""

    name: str
    plan: Callable
    why_not: Callable
    periodic: bool = False  # the crank's speed and acceleration equal at both ends (not at rest): a start profile must be too


class NotSupported(PlanningError):
    """A mode that cannot plan this kind of request (a robust plan over a region, a grid limit): recorded as not
    supported, not as infeasible."""


def _continuous_why_not(spec) -> str | None:
    # with [planning.transfer] the dwell is 0: the stroke is planned and its time above the opening checked
    # (planning.transfer.continuous_check), which only the planned stroke can tell
    if spec.dwell > 0:
        return (f"the job needs the crank at rest at TDC for planning.dwell_s = {spec.dwell:g} s (its transfer); continuous "
                "rotation never stops there")
    return None


def _pendulum_why_not(spec) -> str | None:
    if spec.transfer is None:
        return ("the job states no [planning.transfer] (opening_height_m, time_s): the pendulum's turning points lie at the "
                "transfer's opening, and a fixed planning.dwell_s at TDC is not a window a swing can hold")
    return None


def _plan_stroke(problem: StrokeProblem, region=None, **kw):
    """:func:`planning.planner.plan_stroke` of a turning mode (stop-at-top, continuous): one stroke TDC to TDC on the
    job's knots; a robust plan's ``region`` is not read (its members stand for it on these knots)."""
    return plan_stroke(problem, **kw)


def _plan_pendulum(problem: StrokeProblem, robust: Robust | None = None, power=None, region=None, start=None, **kw):
    """:func:`planning.pendulum.plan_pendulum` in auto mode; a robust plan's ``region``
    (:class:`planning.robust.SwingRegion`) is held by each swing (its members built on the swing's knots,
    :func:`planning.pendulum.plan_swing_robust`), started from ``start``'s swings where it is a pendulum plan of the same
    job (another row's); members without their region and a grid limit are not supported (raises
    :class:`NotSupported`)."""
    if robust is not None and len(robust.members) > 1 and region is None:
        raise NotSupported("pendulum mode builds a robust plan's members on its swings' knots: members without the calibration's "
                           "region are not supported")
    if power is not None and power.limited:
        raise NotSupported("pendulum mode plans without a grid limit (planning.power.grid_peak_limit_W): not supported")
    return plan_pendulum(problem.pm, problem.process, problem.spec, region=region,
                         start=start if hasattr(start, "swings") else None)


MODES: dict[str, Mode] = {}


def register(mode: Mode) -> None:
    """Add ``mode`` to :data:`MODES` (a later mode of the same name replaces it)."""
    MODES[mode.name] = mode


register(Mode("stop-at-top", _plan_stroke, lambda spec: None))
register(Mode("continuous", _plan_stroke, _continuous_why_not, periodic=True))
register(Mode("pendulum", _plan_pendulum, _pendulum_why_not))


def mode_spec(spec, name: str):
    """``spec`` (the job's, in auto mode) in mode ``name``: the dwell at TDC only where the crank stops there."""
    return dataclasses.replace(spec, mode=name, dwell=spec.dwell if name == "stop-at-top" else 0.0)


def keeps_limits(pm, plan) -> tuple[bool, str]:
    """(whether ``plan`` keeps every limit, which one it breaks): the peak torque within the margin, the cycle RMS
    within the rating, the jerk limit kept (the jerk-limited stage did not fall back: each swing's, for a pendulum plan)."""
    limit = plan.spec.torque_limits(pm.press.motor.peak_torque).verdict
    if plan.peak_torque > limit * (1.0 + 1e-9):
        return False, f"peak torque {plan.peak_torque:,.0f} N m above the margin {limit:,.0f} N m"
    if plan.rms_torque > pm.press.motor.rated_torque:
        return False, f"cycle RMS {plan.rms_torque:,.0f} N m above T_rated {pm.press.motor.rated_torque:,.0f} N m"
    for rec in optimiser_records(plan):
        if math.isfinite(plan.spec.crank_jerk) and rec.get("status") == "fallback":
            return False, f"the jerk limit is not kept (the jerk-limited stage fell back: {rec.get('fallback_reason')})"
    return True, ""


def optimiser_records(plan) -> list[dict]:
    """The jerk-limited stage's records of ``plan``: its own, or each swing's of a pendulum plan."""
    swings = getattr(plan, "swings", None)
    return [p.optimiser for p in swings] if swings is not None else [plan.optimiser]


# what auto mode plans every mode with: a jerk-limited stage, a warm start, a screen or grid rows belong to one mode's
# knots and problem and are left out (of a Robust, its members and worst-case groups are taken)
AUTO_KEYWORDS = ("dwell", "start", "power", "robust", "region")


def plan_in_mode(problem: StrokeProblem, **kw):
    """The job of ``problem`` in the mode its settings name: mode = "auto" by :func:`plan_fastest` (of ``kw`` only
    :data:`AUTO_KEYWORDS`), a turning mode by :func:`planning.planner.plan_stroke` with ``kw`` (a robust plan's
    ``region`` not read there). Returns the plan; raises :class:`PlanningError` for an infeasible job or mode =
    "pendulum" (its own command, :func:`planning.pendulum.plan_pendulum`)."""
    if problem.spec.mode == "auto":
        kw = {k: v for k, v in kw.items() if k in AUTO_KEYWORDS}
        if kw.get("robust") is not None:
            kw["robust"] = Robust(kw["robust"].members, kw["robust"].worst_case)
        return plan_fastest(problem, **kw)
    return _plan_stroke(problem, **kw)


def plan_fastest(problem: StrokeProblem, **kw):
    """The job of ``problem`` in every mode of :data:`MODES` it allows (``spec.mode == "auto"``), the fastest plan that
    keeps every limit, with the record of every mode as its ``modes`` (see the module) and every mode's plan, kept or
    refused, as its ``mode_plans`` (name -> plan: another row's starts, :func:`plan_modes`' ``start``). ``kw``: the modes'
    keywords (dwell, start, robust members ...), the same for every mode, all planned on ``problem``'s knots and path
    dynamics. Raises :class:`PlanningError` when no mode gives a plan that keeps every limit, with each mode's reason."""
    record, kept, planned = _plan_each(problem, None, kw)
    best = keep_fastest(problem.spec, record, kept)
    best.mode_plans = planned
    return best


def plan_modes(problem: StrokeProblem, names=None, **kw) -> tuple[dict, dict]:
    """The modes of :data:`MODES` named in ``names`` (None: every one), each planned as :func:`plan_fastest` plans it,
    on ``problem`` (the knots and the path dynamics do not depend on the mode: built once):
    (each mode's record, each mode's plan that keeps every limit, by name). Modes planned apart (in other processes) give
    :func:`keep_fastest` the same as planned together: no mode's plan reads another's. ``start``: a plan (or its
    profile) to start each mode of its kind from, or name -> another row's plan of that mode
    (:attr:`planning.planner.Plan.mode_plans`), each mode started from its own."""
    return _plan_each(problem, names, kw)[:2]


def _plan_each(problem: StrokeProblem, names, kw: dict) -> tuple[dict, dict, dict]:
    """:func:`plan_modes`' (record, kept) and every mode's plan, kept or refused after planning (name -> plan)."""
    spec, pm = problem.spec, problem.pm
    record, kept, planned = {}, {}, {}
    for name, mode in MODES.items():
        if names is not None and name not in names:
            continue
        why = mode.why_not(spec)
        if why is not None:
            record[name] = {"allowed": False, "why_not": why, "strokes_per_min": None}
            continue
        # another plan's optimum to start from (compare's calibrated plan from the theoretical one) only where it is a
        # stroke of this mode's kind: a rest-to-rest start is no start for a periodic stroke, nor the other way round
        start = kw.get("start")
        if isinstance(start, dict):  # another row's plan of each mode: this mode's own
            start = start.get(name)
        profile = getattr(start, "profile", start)
        mkw = kw if "start" not in kw else {**kw, "start": start if getattr(profile, "periodic", None) == mode.periodic else None}
        try:
            plan = mode.plan(problem.using(mode_spec(spec, name)), **mkw)
        except NotSupported as err:
            record[name] = {"allowed": True, "supported": False, "strokes_per_min": None, "keeps_every_limit": False,
                            "infeasible": str(err)}
            continue
        except PlanningError as err:
            record[name] = {"allowed": True, "strokes_per_min": None, "keeps_every_limit": False, "infeasible": str(err)}
            if isinstance(err, RefusedPlan):  # planned, then refused by the job's check: still a start for another row
                planned[name] = err.plan
            continue
        planned[name] = plan
        ok, broken = keeps_limits(pm, plan)
        record[name] = {"allowed": True, "strokes_per_min": plan.strokes_per_min, "cycle_time_s": plan.cycle_time,
                        "dwell_at_tdc_s": plan.dwell, "keeps_every_limit": ok, **({"infeasible": broken} if not ok else {})}
        if ok:
            kept[name] = plan
    return record, kept, planned


def keep_fastest(spec, record: dict, kept: dict):
    """:func:`plan_fastest`'s plan from :func:`plan_modes`' ``record`` and ``kept`` (of every mode of :data:`MODES`,
    planned together or apart): the fastest kept plan (the first in :data:`MODES` of equal rate), its ``modes`` the
    record in :data:`MODES`' order with each mode's rate against the stop-at-top plan's."""
    record = {name: record[name] for name in MODES if name in record}
    best = None
    for name in record:
        plan = kept.get(name)
        if plan is not None and (best is None or plan.strokes_per_min > best.strokes_per_min):
            best = plan
    base = record.get("stop-at-top", {}).get("strokes_per_min")
    for name, r in record.items():  # each mode's gain (or loss) against the stop-at-top plan of the same job and transfer
        if base and r.get("strokes_per_min") is not None and name != "stop-at-top":
            r["vs_stop_at_top_spm"] = r["strokes_per_min"] - base
            r["vs_stop_at_top_percent"] = 100.0 * (r["strokes_per_min"] / base - 1.0)
    if best is None:
        reasons = "; ".join(f"{n}: {r.get('why_not') or r.get('infeasible')}" for n, r in record.items())
        raise PlanningError(f"{spec.source}: planning.mode = \"auto\": no mode gives a plan that keeps every limit ({reasons})")
    best.modes = {"planned": best.spec.mode, "rule": "the fastest mode the job allows that keeps every limit", "modes": record}
    return best
