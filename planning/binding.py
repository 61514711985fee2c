"""Which limit binds where: per phase of the stroke (approach, forming window, return, dwell), the share of its time each limit is active."""
from __future__ import annotations

import math
import numpy as np

from press_model.model import PressModel

from .constraints import MotorTorqueLimit

ACTIVE = 1.0e-2  # a limit counts as active on a segment when within this fraction of its bound (the jerk-limited profile rides just under its limits)
# a phase's binding limit is the one active for the largest share of its time, if that share reaches MIN_SHARE. The
# time without any active limit ("none") is not a competitor: a smoothed profile spends much of each phase moving
# between its limits, and "none" then outvoted a motor speed held at its limit for half the approach
MIN_SHARE = 0.05


def active_limits(pm: PressModel, plan) -> dict[str, np.ndarray]:
    """Per segment of ``plan`` (a :class:`planning.planner.Plan`, whose ``binding`` this module gives: it does not import
    the planner), whether each limit is active (within ACTIVE of its bound at either end of the segment)."""
    ev, prof, pd = plan.evaluation, plan.profile, plan.pd
    L = plan.torque_level
    drive, motor = pm.press.drive, pm.press.motor
    a, b = ev.motor_right[:-1], ev.motor_left[1:]
    thr = 1.0 - ACTIVE
    sd_max = motor.max_speed / drive.gear_ratio
    win = plan.grid.in_window
    v_slide = np.where(win, np.abs(pd.dh) * prof.sd, 0.0) / plan.spec.forming_speed
    return {
        MotorTorqueLimit.name_motoring: (np.maximum(a, b) >= thr * L),
        MotorTorqueLimit.name_braking: (np.minimum(a, b) <= -thr * L),
        "motor_speed": np.maximum(prof.sd[:-1], prof.sd[1:]) >= thr * sd_max,
        "forming_slide_speed": np.maximum(v_slide[:-1], v_slide[1:]) >= thr,
    }


def phases(plan) -> dict[str, np.ndarray]:
    """Segments of each phase: before the forming window, inside it, after it (bool arrays over segments)."""
    win = plan.grid.in_window
    seg_win = win[:-1] & win[1:]
    idx = np.flatnonzero(seg_win)
    n = len(seg_win)
    first, last = (idx[0], idx[-1]) if len(idx) else (n, n - 1)
    k = np.arange(n)
    return {"approach": k < first, "forming_window": (k >= first) & (k <= last), "return": k > last}


def binding_report(pm: PressModel, plan) -> dict:
    """For each phase: the dominant limit (the one active longest, "none" when none is active for MIN_SHARE of the
    phase's time), its share, and the share of the phase's time each limit (and no limit) is active."""
    act = active_limits(pm, plan)
    dt = plan.profile.dt
    out = {}
    for name, mask in phases(plan).items():
        t = float(np.sum(dt[mask]))
        shares = {k: (float(np.sum(dt[mask & v])) / t if t > 0 else 0.0) for k, v in act.items()}
        free = mask & ~np.any(np.array(list(act.values())), axis=0)
        shares["none"] = float(np.sum(dt[free])) / t if t > 0 else 0.0
        top = max(act, key=lambda k: shares[k]) if t > 0 else None
        dominant = top if top is not None and shares[top] >= MIN_SHARE else "none"
        out[name] = {"dominant": dominant, "dominant_time_share": shares[dominant] if t > 0 else 0.0, "time_s": t,
                     "active_time_share": shares}
    if plan.spec.mode == "stop-at-top":
        out["dwell"] = {"dominant": "thermal_rms" if plan.thermal_binding else "none", "time_s": plan.dwell}
    out["thermal_rms"] = (("binding: the cycle RMS is at the thermal limit, a limit of the jerk-limited optimum" if plan.max_jerk < math.inf
                           else "binding: the torque level was lowered to meet the thermal limit") if plan.thermal_binding else "not binding")
    return out
