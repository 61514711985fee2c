"""Verification: a plan played back through the forward dynamics with a feed-forward + PD crank controller.

The press is integrated with :func:`press_model.forward.integrate` (Pinocchio constrained dynamics of the
closed loops with Baumgarte stabilisation, Eq. 8, friction fixed point, classical RK4). The motor torque
per motor is

    T = T_ff(t) + kp (theta_ref - theta) + kd (theta_dot_ref - theta_dot),  clipped to +/- T_max,

with T_ff the plan's motor torque evaluated under the model being played (the plan's own model, or another
one for a cross-check). The clip is the drive's hard limit.

Gains (:func:`controller_gains`) come from the press's own inertia at the crank, not from fixed numbers: with
J_red(theta) = the linkage's inertia reduced to the crank (the path dynamics' m) + J_gear u^2, a motor torque
T gives n u eta T at the crank, so kp = J ω^2 / (n u eta) and kd = 2 ζ ω J / (n u eta) put the crank-angle
loop at the job's ``bandwidth_Hz`` (ω = 2 pi f) and ``damping_ratio`` where the inertia is largest (faster
elsewhere). A bandwidth the RK4 step cannot integrate is refused with the fix.

Verdict (:func:`verdict`): the playback fails when the commanded torque reaches T_max (the drive saturates),
the motor torque breaks the peak-torque margin, the crank angle leaves the job's ``tracking_tolerance_deg``
or a loop-closure gap exceeds ``loop_gap_tolerance_m``.
"""
from __future__ import annotations

import json
import math
from dataclasses import replace
from pathlib import Path

import numpy as np

from calibration.design.report import Design
from press_io.errors import PlanningError
from press_io.outputs import write_csv, write_json
from press_io.progress import Progress
from press_model.dynamics import slide_loads
from press_model.energy import stroke_energy
from press_model.forces import NO_PROCESS
from press_model.forward import ForwardModel, integrate
from press_model.jobs import Job
from press_model.kinematics import force_step_angles, state_at
from press_model.model import PressModel, Workspace
from press_model.motor import crank_gain
from press_model.power_flow import trapezoid_weights
from press_model.readers import FieldReader
from press_model.settings_fields import read_section

from .evaluation import Evaluation, evaluate_profile
from .grid import Grid, knot_profile
from .hold import stop_spans
from .path_dynamics import build_path_dynamics
from .planner import Plan
from .power import read_power
from .profile import reference
from .settings import PlanningSpec, PlaybackSection


def _wrap(a):
    """Angle difference folded into [-pi, pi) (rad)."""
    return (np.asarray(a) + math.pi) % (2.0 * math.pi) - math.pi


def _wrap_angle(a: float) -> float:
    """:func:`_wrap` of one float (rad): Python's float modulo is numpy's (the same floor rule, the same numbers), without
    numpy's cost per scalar."""
    return (a + math.pi) % (2.0 * math.pi) - math.pi


RK4_LIMIT = 0.5  # largest |closed-loop pole| x time step accepted (RK4's stability edge on the real axis is 2.8)


def controller_gains(pm: PressModel, spec: PlanningSpec, plan: Plan) -> dict:
    """PD gains (N m per rad and N m s per rad of crank error, per motor) from the press's inertia at the crank.

    Raises :class:`PlanningError` when the loop is too fast for the playback's RK4 step.
    """
    drive = pm.press.drive
    j_red = plan.pd.m + drive.gear_inertia * drive.gear_ratio**2  # kg m^2 at the crank, per knot
    j_max, j_min = float(np.max(j_red)), float(np.min(j_red))
    w = 2.0 * math.pi * spec.playback_bandwidth
    z = spec.playback_damping
    gain = crank_gain(drive, 1.0)  # crank torque per unit motor torque (motoring)
    kp = j_max * w * w / gain
    kd = 2.0 * z * w * j_max / gain
    # fastest pole where the inertia is smallest: roots of J s^2 + g kd s + g kp
    a = gain * kd / j_min
    b = gain * kp / j_min
    fastest = float(np.max(np.abs(np.roots([1.0, a, b]))))
    if fastest * spec.playback_dt > RK4_LIMIT:
        raise PlanningError(
            f"{spec.source}: playback.bandwidth_Hz = {spec.playback_bandwidth:g} with damping_ratio {z:g} gives a closed-loop pole of "
            f"{fastest:.0f} rad/s where the crank inertia is smallest ({j_min:,.0f} kg m^2), too fast for time_step_s = {spec.playback_dt:g} s "
            f"(|pole| x step must stay <= {RK4_LIMIT}); lower bandwidth_Hz or time_step_s")
    return {"kp_Nm_per_rad": kp, "kd_Nm_s_per_rad": kd, "bandwidth_Hz": spec.playback_bandwidth, "damping_ratio": z,
            "inertia_at_crank_kg_m2": {"max": j_max, "min": j_min}, "fastest_pole_rad_s": fastest,
            "rule": "kp = J_max w^2 / (n u eta), kd = 2 zeta w J_max / (n u eta), J = linkage inertia at the crank + J_gear u^2"}


def play_back(pm: PressModel, job: Job, spec: PlanningSpec, plan: Plan, ff: Evaluation | None = None, hold: float | None = None,
              t_end: float | None = None, progress=None):
    """Integrate the press on ``pm`` tracking ``plan``; returns (columns of playback.csv, summary dict).

    ``ff``, ``hold``: the plan's profile and the holding torque at TDC (N m) evaluated under ``pm`` (default:
    the plan's own evaluation and holding torque). ``t_end``:
    seconds to play (default: the whole cycle, dwell included).
    """
    ff = ff or plan.evaluation
    t_end = plan.cycle_time if t_end is None else float(t_end)
    t_max = pm.press.motor.peak_torque
    gains = controller_gains(pm, spec, plan)
    kp, kd = gains["kp_Nm_per_rad"], gains["kd_Nm_s_per_rad"]
    hold = plan.hold_torque if hold is None else float(hold)
    h = spec.playback_dt
    # the reference at every RK4 stage time (t, t + h/2, t + h), computed once: the controller only looks it up
    n_half = 2 * int(math.ceil(t_end / h - 1e-9)) + 1
    t_half = np.minimum(np.arange(n_half) * (h / 2.0), t_end)
    r_half = reference(plan, t_half, ff, hold)
    # as Python floats: the controller runs four times a step, and numpy's scalars cost several times a float's arithmetic
    th_half, sd_half, tq_half = (r_half[k].tolist() for k in ("theta", "theta_dot", "motor_torque"))
    half = [float(x) for x in t_half]

    loads = slide_loads(pm, job.process)
    phased = getattr(plan, "process_on_at", None)  # a pendulum: the process force only on its working swing
    if phased is not None:
        loads = phased_loads = _PhasedLoads(loads)
    spans = [(t0, t1) for t0, t1, _ in stop_spans(plan)] if getattr(plan, "stops", ()) else []
    if spans:
        loads = held_loads = _HeldLoads(loads)

    def controller(t, theta, theta_dot):
        # the controller is called at every stage's time just before the loads are
        if phased is not None:
            phased_loads.on = phased(t)
        if spans:
            held_loads.held = any(t0 <= t < t1 for t0, t1 in spans)
        i = min(int(round(t / (h / 2.0))), n_half - 1)
        if abs(half[i] - t) > 1e-9:  # the last, shorter step
            r = reference(plan, np.array([t]), ff, hold)
            th_r, sd_r, tq = float(r["theta"][0]), float(r["theta_dot"][0]), float(r["motor_torque"][0])
        else:
            th_r, sd_r, tq = th_half[i], sd_half[i], tq_half[i]
        cmd = tq + kp * _wrap_angle(th_r - theta) + kd * (sd_r - theta_dot)
        return min(max(cmd, -t_max), t_max)

    ws = Workspace(pm)
    start = plan.profile.sample(np.array([0.0]), plan.pd.theta)
    st = state_at(pm, ws, float(start["theta"][0]), float(start["theta_dot"][0]), float(start["theta_ddot"][0]))
    tr = integrate(ForwardModel(pm), st.q, st.v, controller, loads, t_end, h, progress=progress)
    # the recorded times are accumulated (t += h); take the reference at the grid instants the controller used
    idx = np.minimum(np.round(tr.time / (h / 2.0)).astype(int), n_half - 1)
    t_ref = np.where(np.abs(t_half[idx] - tr.time) < 1e-9, t_half[idx], tr.time)
    ref = reference(plan, t_ref, ff, hold)
    ff_t = ref["motor_torque"]
    err = _wrap(ref["theta"] - tr.theta)
    commanded = ff_t + kp * err + kd * (ref["theta_dot"] - tr.theta_dot)
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
    margin = spec.torque_limits(t_max).verdict
    info = {
        "method": "Pinocchio constraintDynamics with Baumgarte (Eq. 8), friction fixed point, RK4; feed-forward + PD on crank angle and speed",
        "model_parameters": pm.press.parameter_values(),
        "gains": {**gains, "time_step_s": h},
        "played_s": t_end,
        "max_tracking_error_deg": float(np.max(np.abs(np.degrees(err)))),
        "final_tracking_error_deg": float(np.degrees(err[-1])),
        "max_speed_error_rad_s": float(np.max(np.abs(ref["theta_dot"] - tr.theta_dot))),
        "peak_motor_torque_Nm": peak,
        "peak_torque_ratio": peak / t_max,
        "peak_torque_margin_Nm": margin,
        "within_margin": bool(peak <= margin),
        "max_pd_correction_Nm": float(np.max(np.abs(tr.motor_torque - ff_t))),
        "max_commanded_torque_Nm": float(np.max(np.abs(commanded))),
        "max_loop_gap_m": float(np.max(tr.loop_residual)),
    }
    # the motor's heating over the played cycle (dwell included), trapezoids on the RK4 samples: the feed-forward is
    # planned to (1 - reserve) T_rated, the feedback's share must fit in the rest
    sq = tr.motor_torque ** 2
    rms = float(np.sqrt(np.sum(0.5 * (sq[1:] + sq[:-1]) * np.diff(tr.time)) / (tr.time[-1] - tr.time[0])))
    info.update(cycle_rms_Nm=rms, rated_torque_Nm=pm.press.motor.rated_torque,
                thermal_ok=bool(rms <= pm.press.motor.rated_torque))
    # the power flow of the played motion: the torque the drive gave (feedback included) at the speed the press ran
    flow, info["energy"] = played_energy(pm, cols)
    dc_link = grid = None
    if flow is not None:
        link = pm.press.electrical.dc_link
        dc_link = (flow.dc_link_V, link.min_voltage_V, link.max_voltage_V)
        limit = read_power(job, pm.press.electrical)
        if limit.limited:
            grid = (flow.grid_W, limit.grid_peak_limit_W)
    info["verdict"] = verdict(spec, t_max, cols, commanded, (rms, pm.press.motor.rated_torque), dc_link, grid)
    return cols, info


class _PhasedLoads:
    """The slide's loads with the process force switched by the phase of the cycle (``on``, set by the controller)."""

    def __init__(self, loads):
        self.loads, self.on = loads, True

    def __call__(self, height, height_dot):
        balance, process = self.loads(height, height_dot)
        return balance, (process if self.on else 0.0 * process)


class _HeldLoads:
    """The slide's loads with the process force held while the plan stands at a stop (``held``, set by the controller):
    the die's force stays on the standing slide (planning/hold.py), where the process law alone would drop it the
    moment the slide backs up by a creep (its force acts on the slide moving down)."""

    def __init__(self, loads):
        self.loads, self.held = loads, False

    def __call__(self, height, height_dot):
        return self.loads(height, min(height_dot, 0.0) if self.held else height_dot)


def played_energy(pm: PressModel, cols: dict):
    """(power flow or None, energy summary) of a played cycle from playback.csv's columns: the torque the drive gave
    (feedback included) at the speed the press ran (:func:`press_model.energy.stroke_energy`, no mechanical parts)."""
    return stroke_energy(pm.press, cols["motor_torque_Nm"], np.asarray(cols["crank_speed_rad_s"]) * pm.press.drive.gear_ratio,
                         trapezoid_weights(cols["time_s"]), None)


def verdict(spec: PlanningSpec, t_max: float, cols: dict, commanded, thermal: tuple[float, float] | None = None,
            dc_link: tuple | None = None, grid: tuple | None = None) -> dict:
    """Pass/fail of a playback: T_max (commanded torque saturates), torque margin, tracking, loop closure, with
    ``thermal`` = (the played cycle's RMS motor torque, T_rated) in N m the motor's heating, and with ``dc_link`` =
    (the DC-link voltage at each played sample, its lowest and highest allowed) in V the supply's window
    ([drive.electrical]: a supply short of the demand sags the link, braking the supply cannot take lifts it), and with
    ``grid`` = (the grid power at each played sample in W, the job's planning.power.grid_peak_limit_W) the supply limit.

    Returns {"ok", "line" (one line: ``VERIFY OK: ...`` or ``VERIFY FAILED: <limit> at crank angle <deg> deg:
    <value> (<limit value>)``), "failures" (every broken limit, worst first within the order above)}.
    """
    angle = np.asarray(cols["crank_angle_deg"]) % 360.0
    margin = spec.torque_limits(t_max).verdict
    checks = (
        ("T_max", np.abs(np.asarray(commanded)), t_max, "N m", "{:,.0f}"),
        ("torque margin", np.abs(np.asarray(cols["motor_torque_Nm"])), margin, "N m", "{:,.0f}"),
        ("tracking tolerance", np.abs(np.asarray(cols["tracking_error_deg"])), spec.tracking_tolerance_deg, "deg", "{:.4f}"),
        ("loop-closure tolerance", np.asarray(cols["loop_gap_m"]), spec.loop_gap_tolerance, "m", "{:.3g}"),
    )
    failures = []
    for name, values, limit, unit, fmt in checks:
        k = int(np.argmax(values))
        if values[k] > limit:
            failures.append({"limit": name, "crank_angle_deg": float(angle[k]), "value": float(values[k]), "limit_value": float(limit),
                             "unit": unit, "line": f"VERIFY FAILED: {name} at crank angle {angle[k]:.2f} deg: "
                                                   f"{fmt.format(values[k])} {unit} ({fmt.format(limit)} {unit})"})
    if dc_link is not None:
        volts, v_lo, v_hi = np.asarray(dc_link[0]), float(dc_link[1]), float(dc_link[2])
        for name, k, bad, limit in (("DC-link undervoltage", int(np.argmin(volts)), lambda v: v < v_lo, v_lo),
                                    ("DC-link overvoltage", int(np.argmax(volts)), lambda v: v > v_hi, v_hi)):
            if bad(volts[k]):
                failures.append({"limit": name, "crank_angle_deg": float(angle[k]), "value": float(volts[k]), "limit_value": limit,
                                 "unit": "V", "line": f"VERIFY FAILED: {name} at crank angle {angle[k]:.2f} deg: {volts[k]:,.0f} V "
                                                      f"({limit:,.0f} V)"})
    if grid is not None:
        power, cap = np.asarray(grid[0]), float(grid[1])
        k = int(np.argmax(power))
        if power[k] > cap:
            failures.append({"limit": "grid peak power", "crank_angle_deg": float(angle[k]), "value": float(power[k]), "limit_value": cap,
                             "unit": "W", "line": f"VERIFY FAILED: grid peak power at crank angle {angle[k]:.2f} deg: {power[k] / 1e6:,.3f} MW "
                                                  f"({cap / 1e6:,.3f} MW)"})
    if thermal is not None and thermal[0] > thermal[1]:
        failures.append({"limit": "thermal RMS", "crank_angle_deg": None, "value": float(thermal[0]), "limit_value": float(thermal[1]),
                         "unit": "N m", "line": f"VERIFY FAILED: thermal RMS over the played cycle: {thermal[0]:,.1f} N m "
                                                f"(T_rated {thermal[1]:,.1f} N m)"})
    if failures:
        return {"ok": False, "line": failures[0]["line"], "failures": failures}
    t = np.abs(np.asarray(cols["motor_torque_Nm"]))
    line = (f"VERIFY OK: peak motor torque {np.max(t):,.0f} N m ({np.max(t) / t_max:.3f} T_max, margin {spec.torque_margin:g}), "
            f"max tracking error {np.max(np.abs(cols['tracking_error_deg'])):.4f} deg (tolerance {spec.tracking_tolerance_deg:g}), "
            f"max loop gap {np.max(cols['loop_gap_m']):.2g} m (tolerance {spec.loop_gap_tolerance:g})"
            + (f", cycle RMS {thermal[0]:,.0f} N m (T_rated {thermal[1]:,.0f})" if thermal is not None else "")
            + (f", DC link {np.min(dc_link[0]):,.0f}-{np.max(dc_link[0]):,.0f} V (window {dc_link[1]:,.0f}-{dc_link[2]:,.0f})"
               if dc_link is not None else "")
            + (f", grid peak {np.max(grid[0]) / 1e6:.3f} MW (limit {grid[1] / 1e6:.3f})" if grid is not None else ""))
    return {"ok": True, "line": line, "failures": []}


def run_playback(pm: PressModel, job: Job, spec: PlanningSpec, plan: Plan, out: Path, ff: Evaluation | None = None,
                 hold: float | None = None, progress=None) -> dict:
    """Play ``plan`` back on ``pm`` and write ``out``/playback.csv (and playback_power.csv, the played cycle's power
    flows, with [drive.electrical]); returns the summary (also written into summary.json), with its ``verdict`` and
    ``energy``."""
    cols, info = play_back(pm, job, spec, plan, ff, hold, progress=progress)
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    write_csv(out / "playback.csv", cols)
    flow, _ = played_energy(pm, cols)
    if flow is not None:
        write_csv(out / "playback_power.csv", flow.columns(cols["time_s"]))
    summary = out / "summary.json"
    if summary.is_file():
        rec = json.loads(summary.read_text(encoding="utf-8"))
        rec["playback"] = info
        write_json(summary, rec)
    return info


# ----------------------------------------------------------------------------------------------------------------------
# The designed calibration runs checked as `plan --verify` checks a plan, and the 'design-experiment' command's work.
#
# Each run of :func:`calibration.design.report.design_experiment` is a continuous crank rotation: on knots every
# ``KNOT_STEP_DEG`` plus die contact and BDC it becomes a planner profile (theta_dot^2 linear in theta between knots,
# the constant-acceleration segments of a toppra profile), evaluated by the planner's full model
# (:func:`planning.evaluation.evaluate_profile`) and played back through the forward dynamics with that feed-forward
# and the PD loop of :mod:`planning.playback`, for one turn. The verdict is the playback's: the commanded torque below
# T_max, the motor torque within the design's peak-torque margin, the crank angle within the tracking tolerance, the
# loops closed. The playback's settings are the job's ``[design.playback]`` table (door_panel.toml's [playback] keys).


KNOT_STEP_DEG = 0.5  # knots of the run's profile: the crank speed is smooth, 0.5 deg keeps the constant-acceleration segments' error far below the PD's corrections


def playback_spec(job: Job, torque_margin: float) -> PlanningSpec:
    """A PlanningSpec carrying the job's [design.playback] settings (absent keys: :class:`PlaybackSection`'s defaults)
    and the design's torque margin; the planner-only fields are unused by the playback and set to NaN or neutral values."""
    rd = FieldReader(job.source, {"design": {"playback": (job.raw.get("design") or {}).get("playback")}})
    pb = read_section(rd, ("design", "playback"), PlaybackSection)
    nan = math.nan
    spec = PlanningSpec(
        source=job.source, mode="continuous", dwell=0.0, grid_step=math.radians(KNOT_STEP_DEG), sample_time=nan, torque_margin=torque_margin,
        forming_speed=nan, forming_window=nan, window_directions="both", friction_tolerance=nan, friction_tolerance_torque=nan,
        friction_max_iterations=0, thermal_tolerance=nan, recheck_tightening=nan, recheck_max_rounds=0, continuous_tolerance=nan,
        crank_jerk=math.inf, optimal_tolerance=nan, optimal_max_iterations=0, controller_period=nan,
        playback_bandwidth=pb.bandwidth_Hz, playback_damping=pb.damping_ratio, playback_dt=pb.time_step_s,
        tracking_tolerance_deg=pb.tracking_tolerance_deg, loop_gap_tolerance=pb.loop_gap_tolerance_m,
        feedback_reserve=0.0, thermal_reserve=0.0,
    )
    rd.reject_unread()
    return spec


def run_plan(pm: PressModel, spec: PlanningSpec, motion, process) -> Plan:
    """One turn of a continuous run (``motion``, ``process`` or None) from crank angle 0 as a planner :class:`Plan`."""
    process = process or NO_PROCESS
    n = round(360.0 / KNOT_STEP_DEG)
    uniform = np.linspace(0.0, 2.0 * math.pi, n + 1)
    steps = [a % (2.0 * math.pi) for a in force_step_angles(pm, process)]
    theta = np.unique(np.concatenate([uniform, steps]))
    contact = int(np.argmin(np.abs(theta - steps[0]))) if steps else None
    pd = build_path_dynamics(pm, theta, process, contact)
    x = motion.theta_dot(theta) ** 2
    u = np.diff(x) / (2.0 * np.diff(theta))  # constant acceleration per segment: x linear in theta
    prof = knot_profile(theta, x, u, float(motion.theta_dot(np.array([0.0]))[0]))
    ev = evaluate_profile(pm, pd, prof)
    peak = float(max(np.max(np.abs(ev.motor_right)), np.max(np.abs(ev.motor_left))))
    grid = Grid(theta, contact if contact is not None else 0, {}, np.zeros(len(theta), bool))
    sd = prof.sd
    return Plan(spec=spec, grid=grid, pd=pd, profile=prof, evaluation=ev, dwell=0.0, hold_torque=0.0, torque_level=math.nan,
                peak_torque=peak, rms_torque=math.nan, max_motor_speed=float(np.max(sd)) * pm.press.drive.gear_ratio,
                max_window_slide_speed=math.nan, thermal_binding=False, friction_iterations=0, recheck_rounds=0,
                thermal_iterations=0, jerk_free_stroke_time=math.nan)


def verify_runs(design: Design, out: Path | None = None, progress: Progress | None = None) -> list[dict]:
    """Play every designed run back (module docstring) under the theoretical parameters; returns each playback's summary
    with its ``verdict``, and writes run_N/playback.csv into ``out`` when given. ``progress``: one phase line per run."""
    pm = design.family.pm
    spec = playback_spec(design.job, design.settings.peak_torque_margin)
    progress = progress or Progress("design-experiment", enabled=False)
    results = []
    n = len(design.result.runs)
    for i, c in enumerate(design.result.runs, start=1):
        process = c.run.process()
        with progress.phase(f"playback of run {i}/{n} through the forward dynamics (FF + PD)"):
            plan = run_plan(pm, spec, c.run.motion(), process)
            job = replace(design.job, process=process or NO_PROCESS)
            cols, info = play_back(pm, job, spec, plan, progress=progress.bar(f"run {i}/{n}"))
        info.pop("model_parameters", None)
        results.append(info)
        if out is not None:
            (Path(out) / f"run_{i}").mkdir(parents=True, exist_ok=True)
            write_csv(Path(out) / f"run_{i}" / "playback.csv", cols)
    return results
