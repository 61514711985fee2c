"""The 'simulate' command: one crank turn of a press under a motion and a load, written to a folder."""
from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from press_model.cycle import Cycle, gear_loss_power, simulate_cycle
from press_model.energy import energy_lines, stroke_energy
from press_model.forces import NO_PROCESS
from press_model.jobs import load_job, make_motion
from press_model.model import PressModel
from press_model.limits import check_spm, check_step_deg
from press_io.outputs import output_folder, versions, write_csv, write_json
from press_model.params import load_model
from press_model.plots import cycle_figure, power_figure, save_later
from press_model.readers import FieldReader
from press_model.torque_limits import TorqueLimits
from planning.settings import LimitsSection

RAD_S_TO_RPM = 60.0 / (2.0 * math.pi)
# RK4 steps per turn at least: a coarse --step-deg (10 deg: 36 steps) made the integration diverge (issue 14);
# 360 is the default grid's own count, so the default playback is unchanged
PLAYBACK_MIN_STEPS = 360
MOTIONS = {"cushion-test": "cushion-test"}  # motion name -> job file whose [motion] it is
LOADS = {"none": None, "cushion": "cushion-test", "door-panel": "door-panel"}


def cycle_columns(pm: PressModel, cycle: Cycle) -> dict:
    """The columns of cycle.csv, in order."""
    cols = {
        "time_s": cycle.time,
        "crank_angle_deg": np.degrees(cycle.theta),
        "crank_speed_rad_s": cycle.theta_dot,
        "crank_accel_rad_s2": cycle.theta_ddot,
        "slide_height_m": cycle.height,
        "slide_velocity_m_s": cycle.height_dot,
        "motor_torque_Nm": cycle.motor_torque,
        "motor_speed_rpm": cycle.theta_dot * pm.press.drive.gear_ratio * RAD_S_TO_RPM,
    }
    for k, name in enumerate(cycle.joint_names):
        cols[f"reaction_{name}_N"] = cycle.joint_reactions[:, k]
    cols["guide_normal_N"] = cycle.guide_normal
    return cols


def motor_limits(pm: PressModel, cycle: Cycle) -> dict:
    """The cycle against the press file's [motor] limits (per motor): peak torque / T_max, RMS (Eq. 24) / T_rated,
    top motor speed against the maximum, and which are broken (``broken``: one phrase each, empty when within)."""
    motor, drive = pm.press.motor, pm.press.drive
    peak, rms = cycle.peak_motor_torque(), cycle.rms_motor_torque()
    top_rpm = float(np.max(np.abs(cycle.theta_dot))) * drive.gear_ratio * RAD_S_TO_RPM
    max_rpm = motor.max_speed * RAD_S_TO_RPM
    broken = []
    if peak > motor.peak_torque:
        broken.append(f"peak torque {peak:.0f} N m is {peak / motor.peak_torque:.2f} x T_max = {motor.peak_torque:g} N m")
    if rms > motor.rated_torque:
        broken.append(f"RMS torque {rms:.0f} N m is {rms / motor.rated_torque:.2f} x the rated {motor.rated_torque:g} N m")
    if top_rpm > max_rpm:
        broken.append(f"motor speed {top_rpm:.0f} rpm exceeds the maximum {max_rpm:g} rpm")
    return {"peak_torque_ratio": peak / motor.peak_torque, "rms_torque_ratio": rms / motor.rated_torque,
            "top_motor_speed_rpm": top_rpm, "max_speed_rpm": max_rpm, "peak_torque_Nm": motor.peak_torque,
            "rated_torque_Nm": motor.rated_torque, "within_limits": not broken, "broken": broken}


def summary(pm: PressModel, cycle: Cycle, extra: dict) -> dict:
    press = pm.press
    return {
        **press.identity(),
        **extra,
        "cycle_time_s": cycle.period,
        "peak_motor_torque_Nm": cycle.peak_motor_torque(),
        "rms_motor_torque_Nm": cycle.rms_motor_torque(),
        "motor_work_per_motor_J": cycle.motor_work_per_motor(press.drive.gear_ratio),
        "motor_work_all_motors_J": press.drive.motors * cycle.motor_work_per_motor(press.drive.gear_ratio),
        "process_work_J": cycle.process_work(),
        "friction_dissipation_J": cycle.friction_work(),
        "motors": press.drive.motors,
        "stroke_m": pm.assembly.stroke,
        "bdc_crank_angle_deg": math.degrees(pm.assembly.theta_bdc),
        "tdc_crank_angle_deg": math.degrees(pm.assembly.theta_tdc),
        "friction_iterations_max": int(cycle.iterations.max()),
        "limits": motor_limits(pm, cycle),
        "parameters": press.parameter_values(),
        "versions": versions(),
    }


def cycle_energy(pm: PressModel, cycle: Cycle):
    """(power flow or None, the summary's ``energy``) of the cycle (:func:`press_model.energy.stroke_energy`), with the
    gear's loss, the joints' and guide's friction and the process work as its mechanical parts."""
    drive, w = pm.press.drive, cycle.dt_weights
    mechanical = {"gear_J": float(np.sum(gear_loss_power(pm, cycle) * w)), "friction_J": cycle.friction_work(),
                  "process_work_J": cycle.process_work()}
    return stroke_energy(pm.press, cycle.motor_torque, cycle.theta_dot * drive.gear_ratio, w, mechanical)


def playback(pm: PressModel, cycle: Cycle, motion, process) -> tuple[dict, dict]:
    """Forward-dynamics playback of the cycle's motor torque (a table over crank angle), RK4 + Baumgarte.

    Returns the playback columns and a summary: loop-closure gap and crank-angle drift against the plan.
    """
    from press_model.dynamics import slide_loads
    from press_model.forward import ForwardModel, integrate
    from press_model.kinematics import state_at
    from press_model.model import Workspace

    th = np.append(cycle.theta, 2 * math.pi)
    tm = np.append(cycle.motor_torque, cycle.motor_torque[0])
    st = state_at(pm, Workspace(pm), 0.0, float(cycle.theta_dot[0]), float(cycle.theta_ddot[0]))
    tr = integrate(ForwardModel(pm), st.q, st.v, lambda t, a, w: float(np.interp(a % (2 * math.pi), th, tm)),
                   slide_loads(pm, process), cycle.period, cycle.period / max(len(cycle.theta), PLAYBACK_MIN_STEPS))
    planned = np.interp(tr.time, np.append(cycle.time, cycle.period), th)
    cols = {
        "time_s": tr.time,
        "crank_angle_deg": np.degrees(tr.theta),
        "planned_crank_angle_deg": np.degrees(planned),
        "crank_speed_rad_s": tr.theta_dot,
        "motor_torque_Nm": tr.motor_torque,
        "loop_gap_m": tr.loop_residual,
    }
    drift = float(np.degrees(tr.theta[-1] - 2 * math.pi))
    info = {
        "method": "open-loop motor-torque table over crank angle; Pinocchio constraintDynamics, Baumgarte (Eq. 8), RK4",
        "max_loop_gap_m": float(tr.loop_residual.max()),
        "final_crank_angle_error_deg": drift,
        "warning": playback_warning(drift, float(np.degrees(cycle.theta[1] - cycle.theta[0]))),
    }
    return cols, info


def playback_warning(drift_deg: float, step_deg: float) -> str | None:
    """A warning text when the open-loop playback ends the turn further off than run_limits.toml allows, else None."""
    from press_model.limits import LIMITS_FILE, run_limits

    limit = run_limits().warn_playback_drift_deg
    if abs(drift_deg) <= limit:
        return None
    return (f"the open-loop playback ends the turn {drift_deg:+.1f} deg off the planned crank angle (more than {limit:g} deg, "
            f"{LIMITS_FILE}): at --step-deg {step_deg:g} the torque table's interpolation error drives it, not the model; "
            "rerun with --step-deg 0.25 (or finer) to check the inverse dynamics")


DEFAULT_SPM = 11.4  # strokes per minute of a built-in motion (the paper's experiment rate) when --spm is not given


@dataclass(frozen=True)
class SimulateCase:
    """One simulated turn as the 'simulate' command names it: the crank motion (a key of :data:`MOTIONS`), the load
    (a key of :data:`LOADS`), strokes per minute (None: the job's [motion] rate, else :data:`DEFAULT_SPM`), the
    crank-angle step in deg, whether the motor torque is also played back through the forward dynamics (playback.csv),
    and the user's ``job`` (a job file or built-in name; None: none): its [process] force is the load and its [motion],
    if it has one, the motion (``motion`` and ``load`` then unused)."""

    motion: str = "cushion-test"
    load: str = "cushion"
    spm: float | None = None
    step_deg: float = 1.0
    playback: bool = False
    job: str | None = None


def case_inputs(case: SimulateCase, jobs: dict | None = None) -> tuple[object, object, float, str, str]:
    """(motion, process force, strokes per minute, motion's name, load's name) of ``case``: from its job file when it
    names one (its [motion] if it has one, else ``case.motion``), else from the built-in jobs of :data:`MOTIONS` and
    :data:`LOADS` (``jobs``: those the caller read already, by built-in name)."""
    jobs = dict(jobs or {})
    user = load_job(case.job) if case.job is not None else None
    if user is not None and user.motion is not None:
        spm = case.spm if case.spm is not None else float(user.motion.get("strokes_per_min", DEFAULT_SPM))
        check_spm(spm)
        return (make_motion(user.motion, user.source, spm), user.process, spm, f"[motion] of {user.source}",
                f"[process] of {user.source}")
    spm = case.spm if case.spm is not None else DEFAULT_SPM
    check_spm(spm)
    for name in (MOTIONS.get(case.motion), None if user is not None else LOADS[case.load]):
        if name is not None and name not in jobs:
            jobs[name] = load_job(name)  # a job that gives both the motion and the load is read once
    if case.motion == "constant":
        motion = make_motion({"kind": "constant"}, "--motion constant", spm)
    else:
        job = jobs[MOTIONS[case.motion]]
        motion = make_motion(job.motion, job.source, spm)
    if user is not None:
        return motion, user.process, spm, case.motion, f"[process] of {user.source}"
    load_job_name = LOADS[case.load]
    return motion, jobs[load_job_name].process if load_job_name else NO_PROCESS, spm, case.motion, case.load


def case_margin(case: SimulateCase) -> float:
    """The torque margin (fraction of T_max) a plan of the case's job keeps: the job's [planning.limits]
    peak_torque_margin where it sets one, else the planner's default (the paper's 10 %)."""
    default = LimitsSection().peak_torque_margin
    if case.job is None:
        return default
    job = load_job(case.job)
    return FieldReader(job.source, job.raw).number(("planning", "limits", "peak_torque_margin"), gt=0.0, le=1.0, default=default)


def run_simulate(pm: PressModel, case: SimulateCase, out: Path, overrides: dict, figures=None,
                 jobs: dict | None = None, inputs: tuple | None = None) -> dict:
    """Simulate the turn ``case`` and write cycle.csv, summary.json and cycle.png into ``out``; returns the summary.

    ``figures``: a :func:`plots.figure_worker` that draws cycle.png while this writes the rest (the same bytes).
    ``jobs``: jobs the caller read already, by built-in name (the motion's and the load's are read here otherwise);
    ``inputs``: :func:`case_inputs` of ``case`` if the caller has them (read here otherwise).
    """
    step_deg = case.step_deg
    motion, process, spm, motion_name, load_name = inputs if inputs is not None else case_inputs(case, jobs)
    cycle = simulate_cycle(pm, motion, process, step_deg=step_deg)
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    limits = pm.press.motor
    title = f"{pm.press.name}: motion {motion_name}, load {load_name}, {spm:g} spm"
    # the margin a plan keeps (the job's [planning.limits] when it sets one, else the paper's 10 %): simulate plans nothing,
    # but an engineer reads the turn's torque against it
    lines = TorqueLimits(limits.peak_torque, case_margin(case))
    drawn = save_later(figures, cycle_figure, (cycle, lines, limits.rated_torque, title), out / "cycle.png")
    job = {"job_source": str(case.job)} if case.job is not None else {}
    info = summary(pm, cycle, {"motion": motion_name, "load": load_name, **job, "strokes_per_min": spm, "step_deg": step_deg,
                               "overrides": overrides})
    flow, info["energy"] = cycle_energy(pm, cycle)
    power_drawn = None
    if flow is not None:
        # the cycle's samples start at theta_c = 0 and stand for dtheta / theta_dot each: the time of each, as in cycle.csv
        cols = flow.columns(cycle.time)
        write_csv(out / "power.csv", cols)
        el = pm.press.electrical
        power_drawn = save_later(figures, power_figure, (cols, (el.dc_link.min_voltage_V, el.dc_link.max_voltage_V), title),
                                 out / "power.png")
    if case.playback:
        cols, info["playback"] = playback(pm, cycle, motion, process)
        write_csv(out / "playback.csv", cols)
    write_csv(out / "cycle.csv", cycle_columns(pm, cycle))
    drawn.result()
    if power_drawn is not None:
        power_drawn.result()
    write_json(out / "summary.json", info)  # last: a folder with a summary is a finished run
    return info


def simulate_job(press: str | None, params: str | None, case: SimulateCase, out: str, figures=None) -> tuple[list[str], list[str]]:
    """The 'simulate' command: :func:`run_simulate` of ``case`` into the folder ``out`` (written whole at the end).

    Returns (warnings, lines) for the command to print: the broken motor limits, and the summary.
    """
    check_step_deg(case.step_deg)
    inputs = case_inputs(case)  # the job, the motion and the rate read and checked before the output folder is made
    pm, overrides = load_model(press, params)
    with output_folder(out, [press, params, case.job], "simulate") as tmp:
        info = run_simulate(pm, case, tmp, overrides, figures, inputs=inputs)
    lim, spm = info["limits"], info["strokes_per_min"]
    warnings = [] if lim["within_limits"] else [
        f"the motor limits are broken at {spm:g} spm: {'; '.join(lim['broken'])} (summary.json 'limits'); "
        "simulate only analyses, the plan command keeps a stroke within the limits"]
    lines = [f"{pm.press.name}, motion {info['motion']}, load {info['load']}: peak motor torque {info['peak_motor_torque_Nm']:.0f} N m, RMS {info['rms_motor_torque_Nm']:.0f} N m, "
             f"motor work {info['motor_work_all_motors_J'] / 1e3:.1f} kJ per cycle -> {out}", *energy_lines(info["energy"])]
    if info["energy"].get("within_dc_link_window") is False:
        v = info["energy"]["dc_link_voltage_V"]
        warnings.append(f"the DC-link voltage leaves its window ({v['min']:.0f}-{v['max']:.0f} V, window {v['window'][0]:g}-{v['window'][1]:g} V): "
                        "the supply cannot follow the cycle ([drive.electrical] of the press file; summary.json 'energy')")
    if "playback" in info:
        pb = info["playback"]
        lines.append(f"forward-dynamics playback: max loop gap {pb['max_loop_gap_m']:.2e} m, crank angle at cycle end off by "
                     f"{pb['final_crank_angle_error_deg']:+.2f} deg")
        if pb["warning"]:
            warnings.append(pb["warning"])
    return warnings, lines
