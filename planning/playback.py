"""Verification: a plan played back through the forward dynamics with a feed-forward + PD crank controller.

The press is integrated with :func:`press_model.forward.integrate` (Pinocchio constrained dynamics of the
closed loops with Baumgarte stabilisation, Eq. 8, friction fixed point, classical RK4). The motor torque
per motor is

    T = T_ff(t) + kp (theta_ref - theta) + kd (theta_dot_ref - theta_dot),  clipped to +/- T_max,

with T_ff the plan's motor torque evaluated under the model being played (the plan's own model, or another
one for a cross-check) and the gains from the job's [playback] section. The clip is the drive's hard
limit; the report says how close the commanded torque came to the 10 % margin.
"""
from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

from press_model.dynamics import slide_loads
from press_model.forward import ForwardModel, integrate
from press_model.jobs import Job, PlanningSpec
from press_model.kinematics import state_at
from press_model.model import PressModel, Workspace
from press_model.outputs import write_csv, write_json

from .planner import Evaluation, Plan
from .profile import reference


def _wrap(a):
    """Angle difference folded into [-pi, pi) (rad)."""
    return (np.asarray(a) + math.pi) % (2.0 * math.pi) - math.pi


def play_back(pm: PressModel, job: Job, spec: PlanningSpec, plan: Plan, ff: Evaluation | None = None, hold: float | None = None,
              t_end: float | None = None):
    """Integrate the press on ``pm`` tracking ``plan``; returns (columns of playback.csv, summary dict).

    ``ff``, ``hold``: the plan's profile and the holding torque at TDC (N m) evaluated under ``pm`` (default:
    the plan's own evaluation and holding torque). ``t_end``:
    seconds to play (default: the whole cycle, dwell included).
    """
    ff = ff or plan.evaluation
    t_end = plan.cycle_time if t_end is None else float(t_end)
    t_max = pm.press.motor.peak_torque
    kp, kd = spec.playback_kp, spec.playback_kd
    hold = plan.hold_torque if hold is None else float(hold)

    def ref_at(t):
        r = reference(plan, np.array([t]), ff.motor_right, ff.motor_left, hold)
        return r["theta"][0], r["theta_dot"][0], r["motor_torque"][0]

    def controller(t, theta, theta_dot):
        th_r, sd_r, tq = ref_at(t)
        cmd = tq + kp * float(_wrap(th_r - theta)) + kd * (sd_r - theta_dot)
        return float(np.clip(cmd, -t_max, t_max))

    ws = Workspace(pm)
    st = state_at(pm, ws, float(plan.pd.theta[0]), float(plan.profile.sd[0]), float(plan.profile.u[0]))
    tr = integrate(ForwardModel(pm), st.q, st.v, controller, slide_loads(pm, job.process), t_end, spec.playback_dt)
    ref = reference(plan, tr.time, ff.motor_right, ff.motor_left, hold)
    ff_t = ref["motor_torque"]
    err = _wrap(ref["theta"] - tr.theta)
    cols = {
        "time_s": tr.time,
        "crank_angle_deg": np.degrees(ref["theta"] - err),  # unwrapped like profile.csv
        "planned_crank_angle_deg": np.degrees(ref["theta"]),
        "tracking_error_deg": np.degrees(err),
        "crank_speed_rad_s": tr.theta_dot,
        "planned_crank_speed_rad_s": ref["theta_dot"],
        "motor_torque_Nm": tr.motor_torque,
        "feedforward_torque_Nm": ff_t,
        "loop_gap_m": tr.loop_residual,
    }
    peak = float(np.max(np.abs(tr.motor_torque)))
    margin = spec.torque_margin * t_max
    info = {
        "method": "Pinocchio constraintDynamics with Baumgarte (Eq. 8), friction fixed point, RK4; feed-forward + PD on crank angle and speed",
        "model_parameters": pm.press.parameter_values(),
        "gains": {"kp_Nm_per_rad": kp, "kd_Nm_s_per_rad": kd, "time_step_s": spec.playback_dt},
        "played_s": t_end,
        "max_tracking_error_deg": float(np.max(np.abs(np.degrees(err)))),
        "final_tracking_error_deg": float(np.degrees(err[-1])),
        "max_speed_error_rad_s": float(np.max(np.abs(ref["theta_dot"] - tr.theta_dot))),
        "peak_motor_torque_Nm": peak,
        "peak_torque_ratio": peak / t_max,
        "peak_torque_margin_Nm": margin,
        "within_margin": bool(peak <= margin),
        "max_pd_correction_Nm": float(np.max(np.abs(tr.motor_torque - ff_t))),
        "max_loop_gap_m": float(np.max(tr.loop_residual)),
    }
    return cols, info


def run_playback(pm: PressModel, job: Job, spec: PlanningSpec, plan: Plan, out: Path, ff: Evaluation | None = None,
                 hold: float | None = None) -> dict:
    """Play ``plan`` back on ``pm`` and write ``out``/playback.csv; returns the summary (also written into summary.json)."""
    cols, info = play_back(pm, job, spec, plan, ff, hold)
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    write_csv(out / "playback.csv", cols)
    summary = out / "summary.json"
    if summary.is_file():
        rec = json.loads(summary.read_text(encoding="utf-8"))
        rec["playback"] = info
        write_json(summary, rec)
    return info
