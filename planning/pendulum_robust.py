"""A pendulum swing robust over a calibration's region: |T_m| within the limit at every corner of the box.

Each swing (planning/pendulum.py) is planned by :func:`planning.planner.plan_stroke` on its slice of the knots; here its
members are built on that slice (:class:`planning.robust._Builder`, :func:`planning.robust.worst_case_members`: the
monotone parameters at their worst side per row type, the others at every corner) and the backward swing's members are
time-reversed as its centre is (:func:`planning.path_dynamics.reversed_swing` with each member's own gear inertia, no
process force: the return is empty). The swing is planned with every member's rows (no per-segment grouping: a swing is
a small problem), then played through the full model at every corner of the box
(:func:`planning.robust.corner_torques`); a corner that breaks the limit joins the members and the swing is planned
again (at most :data:`planning.robust.MAX_CUTS` rounds; the robust tools passed in as
:class:`planning.robust.SwingRegion`: planning.robust imports the planner, which imports this module's caller), as :func:`planning.robust.plan_robust` does for a stroke.
Units: SI; torques N m per motor (the backward swing's in its reversal, minus the real ones: |T_m| is the real one).
"""
from __future__ import annotations

import numpy as np

from press_model.forces import NO_PROCESS

from .errors import PlanningError
from .evaluation import Member
from .path_dynamics import reversed_swing


class _ReversedBuilder:
    """A :class:`planning.robust._Builder`'s members in the time reversal of a backward swing (each member's path
    dynamics through :func:`reversed_swing` with its drive's gear inertia; shared where path dynamics and gear agree, so
    the corners still share their friction fixed points)."""

    def __init__(self, forward):
        self.forward, self.pm = forward, forward.pm
        self._reversed = {}

    def member(self, values: dict, label: str) -> Member:
        m = self.forward.member(values, label)
        key = (id(m.pd), m.drive.gear_inertia, m.drive.gear_ratio)
        if key not in self._reversed:
            self._reversed[key] = reversed_swing(m.pd, NO_PROCESS, None, m.drive.gear_inertia, m.drive.gear_ratio)
        return Member(self._reversed[key], m.drive, m.friction, label)


def plan_swing_robust(plan_stroke, pm, process, spec, dwell: float, pd_forward, grid, region, backward: bool):
    """One swing planned to hold the torque limit at every corner of ``region``'s box
    (:class:`planning.robust.SwingRegion`, passed in: planning.robust imports the planner, which plans this mode; its
    box's centre = ``pm``): ``pd_forward`` the forward path dynamics on the swing's knots (the backward swing's are its reversal),
    ``grid`` the swing's knots, ``dwell`` (s) at its end. Returns the swing's :class:`planning.planner.Plan`, its
    ``robust_torques`` set to :func:`corner_torques` (per corner, T_m per knot, N m per motor), ``robust_members`` and
    ``robust_cuts`` to the members (:class:`planning.evaluation.Member`) planned with and the corners added. Raises :class:`PlanningError` when a corner still
    breaks the limit after ``region.max_cuts`` rounds."""
    builder = region.builder(pm, process, grid, pd_forward)
    if backward:
        builder = _ReversedBuilder(builder)
    members, box, limit = region.members(builder), region.box, region.limit
    kw = {"hold_at": -1} if backward else {}
    for cuts in range(region.max_cuts + 1):
        plan = plan_stroke(pm, process, spec, dwell, members[0].pd, grid, members=members, **kw)
        torques = region.corner_torques(builder, plan)
        broken = [(c, t) for c, t in torques if np.max(np.abs(t)) > limit * (1.0 + 1e-9)]
        if not broken:
            plan.robust_torques = torques  # per corner (box.corners() order) the motor torque per knot, N m per motor
            plan.robust_members, plan.robust_cuts = members, cuts
            return plan
        members = members + [builder.member({**box.center, **c}, "corner that broke the limit") for c, _ in broken]
    worst = max(((c, float(np.max(np.abs(t)))) for c, t in torques), key=lambda ct: ct[1])
    raise PlanningError(f"{spec.source}: the robust pendulum's {'backward' if backward else 'forward'} swing still breaks the torque "
                        f"limit at a corner of the box after {region.max_cuts} rounds ({worst[1]:,.0f} N m against {limit:,.0f} N m at "
                        f"{worst[0]}); narrow the intervals")


def pendulum_corner_torques(plan) -> list[tuple[dict, np.ndarray]]:
    """Per corner of the box, the motor torque (N m per motor) at the knots of both swings of a robust
    :class:`planning.pendulum.PendulumPlan` (forward, then backward in its reversal: |T_m| is the real one)."""
    return [(c, np.concatenate([tf, tb])) for (c, tf), (_, tb) in zip(plan.forward.robust_torques, plan.backward.robust_torques)]
