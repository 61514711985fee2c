"""The friction's slopes of several members computed together (planning.evaluation.share_friction_slopes: per path dynamics,
the frictions' fixed points side by side) are the values each member's own evaluation gives, bit for bit."""
import dataclasses

import numpy as np

from planning.evaluation import Member, evaluate_members, share_friction_slopes


def _members(plan):
    pm = plan.pd.pm
    fr = pm.press.friction
    other = dataclasses.replace(fr, mu_s=fr.mu_s * 1.3, mu_r=fr.mu_r * 0.7)
    stiff = dataclasses.replace(pm.press.drive, gear_inertia=pm.press.drive.gear_inertia * 1.1)
    return pm, [Member(plan.pd, pm.press.drive, fr), Member(plan.pd, pm.press.drive, other, "other"),
                Member(plan.pd, stiff, other, "other, stiffer gear")]


def test_slopes_computed_together_equal_each_members_own(door_panel_plan):
    pm, members = _members(door_panel_plan)
    together = evaluate_members(pm, members, door_panel_plan.profile)
    share_friction_slopes(together)
    apart = [evaluate_members(pm, [m], door_panel_plan.profile)[0] for m in members]
    for t, a in zip(together, apart):
        assert np.array_equal(t.friction_slopes[0], a.friction_slopes[0])
        assert np.array_equal(t.friction_x_slopes, a.friction_x_slopes)
    # the frictions differ, so do their slopes: the test compares different numbers per member
    assert not np.array_equal(together[0].friction_slopes[0], together[1].friction_slopes[0])

