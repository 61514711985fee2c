"""The 'plan' command: plan the job's stroke and write profile.csv, cam_table.csv, cam_master.csv (+ its ISG ASCII copy),
summary.json and the Figure 6 / 7 analogues."""
from __future__ import annotations

import dataclasses
import json
import math
from concurrent.futures import wait
from pathlib import Path

import numpy as np

from press_io.errors import PlanningError, PressDataError, ServoPressError
from press_io.outputs import atomic_write_text, check_output_folder, output_folder, versions, write_csv, write_json, write_table
from press_io.progress import Progress
from press_model.energy import energy_lines
from press_model.jobs import Job, load_job
from press_model.model import PressModel
from press_model.params import apply_overrides, joint_box_of, overrides_of, read_json
from press_model.plots import power_figure, save_later
from press_model.press_data import load_press

from .cams import (CAM_FILE, CAM_MASTER_COLUMNS, CamSettings, ISG_COLUMNS, ISG_FILE, PER_PERIOD, QUINTIC,
                   cam_master_header, cam_master_points, cam_table_header, cam_table_points, checked_cam_error,
                   isg_cam_table, isg_points, master_cam, master_points, master_speed_deg_s, peak_played,
                   pendulum_master_header, played_line, read_isg_cam_table, slave_axis_line)
from .energy import objective_of, plan_energy, refuse_unmet
from .figures import Drawing, figure_worker, slide_height_figure, speed_figure, torque_figure
from .hold import stop_comments, stop_spans
from .pendulum import PendulumPlan, plan_pendulum
from .planner import Plan, StrokeProblem, plan_stroke
from .power import read_power
from .profile import CAM_COLUMNS, cam_table, controller_cycle, rate_text, sample_plan
from .settings import PlanningSpec, read_planning
from .settings import limiting_line, motor_sharing


def plan_summary(pm: PressModel, job: Job, plan: Plan, overrides: dict) -> dict:
    """summary.json of a plan: production rate, torque figures, binding limits, limits, parameters, versions."""
    press, spec = pm.press, plan.spec
    cam = CamSettings.from_job(job)
    motor = press.motor
    torque = spec.torque_limits(motor.peak_torque)
    return {
        "job": job.name,
        "job_source": job.source,
        **press.identity(),
        "mode": spec.mode,
        "strokes_per_min": plan.strokes_per_min,
        "cycle_time_s": plan.cycle_time,
        "stroke_time_s": plan.stroke_time,
        "dwell_s": plan.dwell,
        "peak_torque_Nm": plan.peak_torque,
        "peak_torque_ratio": plan.peak_torque / motor.peak_torque,
        "limiting_motor": spec.sharing.record(plan.peak_torque, motor.peak_torque),  # the motor the margin holds (planning/settings.py)
        "rms_torque_Nm": plan.rms_torque,
        "rms_torque_ratio_to_rated": plan.rms_torque / motor.rated_torque,
        "holding_torque_at_tdc_Nm": plan.hold_torque,
        **({"stops": [st.record() for st in plan.stops]} if plan.stops else {}),  # planning.hold: at rest on the way, within stroke_time_s
        **({"mode_requested": "auto", "modes": plan.modes} if plan.modes is not None else {}),
        "max_motor_speed_rpm": plan.max_motor_speed * 60.0 / (2.0 * math.pi),
        "max_slide_speed_in_forming_window_m_s": plan.max_window_slide_speed,
        "boundary_crank_speed_rad_s": plan.profile.boundary_speed,
        "binding_constraints": plan.binding,
        "transfer": plan.transfer,  # [planning.transfer]: the opening, the time required and the dwell that tops it up (None: dwell_s)
        "limits": {
            "peak_torque_limit_Nm": torque.verdict,
            "peak_torque_margin": spec.torque_margin,
            "feedback_reserve": spec.feedback_reserve,
            "feedforward_torque_limit_Nm": torque.feedforward,
            "torque_level_planned_to_Nm": plan.torque_level,
            "rated_torque_Nm": motor.rated_torque,
            "thermal_feedback_reserve": spec.thermal_reserve,
            "feedforward_rms_limit_Nm": (1.0 - spec.thermal_reserve) * motor.rated_torque,
            "max_motor_speed_rpm": motor.max_speed * 60.0 / (2.0 * math.pi),
            "forming_slide_speed_m_s": spec.forming_speed,
            "forming_window_below_height_m": job.process.contact_height + spec.forming_window,
            "forming_window_directions": spec.window_directions,
            "crank_jerk_rad_s3": spec.crank_jerk if math.isfinite(spec.crank_jerk) else None,
        },
        "jerk_limit": {
            "crank_jerk_rad_s3": spec.crank_jerk if math.isfinite(spec.crank_jerk) else None,
            "max_crank_jerk_rad_s3": plan.max_jerk if math.isfinite(plan.max_jerk) else None,
            "kept": bool(math.isfinite(plan.max_jerk) and plan.max_jerk <= spec.crank_jerk * (1.0 + 1e-6)),
            "strokes_per_min_with_jerk_limit": plan.strokes_per_min,
            "strokes_per_min_without_jerk_limit": plan.jerk_free_strokes_per_min if math.isfinite(plan.jerk_free_stroke_time) else None,
            "stroke_time_without_jerk_limit_s": plan.jerk_free_stroke_time + plan.stop_time if math.isfinite(plan.jerk_free_stroke_time) else None,
            "stroke_time_without_jerk_limit_is": "toppra's jerk-free optimum on the same knots and limits: a lower bound of the jerk-limited stroke "
                                                 "(without the thermal limit too: toppra takes no RMS limit)",
            "method": "time optimum under every limit, the thermal RMS and the jerk limit: direct collocation (constant jerk per segment, "
                      "limits at the knots and at 1/4, 1/2, 3/4 of each segment, the cycle RMS by Boole's rule on them), IPOPT via CasADi, "
                      "started from toppra's optimum; friction fixed point outside (planning/optimal.py, planning/jerk_stage.py)",
            "optimiser": plan.optimiser,
        },
        "grid": {
            "knots": int(plan.pd.n),
            "step_deg": math.degrees(spec.grid_step),
            "special_angles_deg": {k: math.degrees(v) % 360.0 for k, v in plan.grid.special.items()},
            "die_contact_height_m": float(plan.pd.height[plan.grid.contact_index]),
        },
        "solver": {
            "method": "toppra 1-dof path s = theta_c, seidel LP, interpolation discretisation; friction fixed point; "
                      "then the jerk-limited optimum with the thermal limit among its limits (see jerk_limit); without a jerk limit or "
                      "when that stage falls back, thermal bisection on toppra's torque level",
            "friction_re_solves": plan.friction_iterations,
            "recheck_rounds": plan.recheck_rounds,
            "thermal_iterations": plan.thermal_iterations,
        },
        "cam_table_csv": {
            "sample_time_s": spec.controller_period,
            "columns": list(CAM_COLUMNS),
            "motor_position": "deg at the motor shaft (gear ratio applied), unwrapped, 0 at the start of the stroke",
            "feedforward_torque": "per motor, Eq. 16, full model with friction",
            "interpolation": PER_PERIOD,
        },
        "cam_master_csv": {
            "master_step_deg": cam.master_step_deg,
            "points": master_points(cam.master_step_deg) + 1,
            "columns": list(CAM_MASTER_COLUMNS),
            "master": "virtual master axis, one turn (0 to 360 deg) per cycle (stroke and dwell) at constant speed",
            "master_speed_deg_s": master_speed_deg_s(plan),
            "master_speed_rpm": 60.0 / plan.cycle_time,
            "cycle_time_s": plan.cycle_time,
            "motor_position": "deg at the motor shaft (gear ratio applied), unwrapped, 0 at the start of the stroke",
            "interpolation": QUINTIC,
            "isg_file": {"name": ISG_FILE, "format": "ISG/Beckhoff ASCII cam table keywords, Functiontype 6 (TABLE_DEFINED), one "
                         "MC_MotionFunctionPoint per line (" + " ".join(ISG_COLUMNS) + "), quintic segments (POLYNOM5_MM), "
                         "equidistant master 0-360 deg, the point at 360 implied (endless positive)",
                         "slave": "crank (eccentric-shaft) axis position from the start of the stroke, deg, one turn a cycle",
                         "interpolation": QUINTIC, "wrap": "endless positive (ISG: MC_CamIn.StartMode OR HLI_CI_ENDLESS_POSITIVE)",
                         "table_id": cam.isg_table_id, "lines": master_points(cam.master_step_deg)},
        },
        "profile_csv": {
            "sample_time_s": spec.sample_time,
            "crank_angle": "theta_c in deg, unwrapped: from TDC to TDC + 360 (subtract 360 above 360 for the 0-360 range)",
            "motor_torque": "per motor, Eq. 16, full model with friction",
        },
        "parameters": press.parameter_values(),
        "overrides": overrides,
        "versions": versions(),
    }


def write_plan_outputs(pm: PressModel, job: Job, plan: Plan, out: Path, overrides: dict, title: str, extra: dict | None = None,
                       drawing: Drawing | None = None) -> dict:
    """Write profile.csv, cam_table.csv, cam_master.csv, cam_master_isg.txt, summary.json, torque.png (Figure 6) and
    speed.png (Figure 7) into ``out``; returns the summary.

    ``drawing``: where the figures are drawn (:class:`planning.figures.Drawing`; None: here, waited for here). The same
    bytes either way."""
    figures, drawn = (drawing.worker, drawing.drawn) if drawing is not None else (None, None)
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    press = pm.press
    cam_cfg = CamSettings.from_job(job)
    cam_err = checked_cam_error(plan, press.drive.gear_ratio, press.motor.peak_torque, cam_cfg, job.source)  # refused before writing
    cols = sample_plan(plan, press.drive.gear_ratio)
    # the figures are handed to the worker as soon as their data exist: it draws them while the cam tables are made
    futures = [
        save_later(figures, torque_figure, ([("motor torque", cols["time_s"], cols["motor_torque_Nm"], plan.rms_torque)],
                                            plan.spec.torque_limits(press.motor.peak_torque), press.motor.rated_torque, title,
                                            stop_spans(plan)), out / "torque.png"),
        save_later(figures, speed_figure, ([("plan", cols["time_s"], cols["crank_speed_rad_s"], cols["crank_accel_rad_s2"])],
                                           press.drive.gear_ratio, press.motor.max_speed * 60.0 / (2.0 * math.pi), title,
                                           stop_spans(plan)), out / "speed.png")]
    if drawn is not None:  # the caller waits for them, also when a step below fails (before the folder is removed)
        drawn.extend(futures)
    info = {**plan_summary(pm, job, plan, overrides), **(extra or {})}
    info["cam_master_csv"]["linear_interpolation"] = cam_err.record()  # not what the files declare: a positions-only import
    info["energy"], power_png = write_energy(pm, job, cols, out, title, figures)
    futures += power_png
    if drawn is not None:
        drawn.extend(power_png)
    limit = read_power(job, press.electrical)
    if limit.limited:
        info["energy"]["grid_peak_limit_W"] = limit.grid_peak_limit_W
        info["energy"]["within_grid_limit"] = bool(info["energy"]["grid_peak_W"] <= limit.grid_peak_limit_W * (1.0 + 1e-9))
        if press.electrical.storage.enabled:  # the grid rows bound the drives' own draw (planning.power.grid_bound_coefficients)
            info["energy"]["grid_limit_leaves_out_storage_W"] = press.electrical.storage.power_limit_W
    write_csv(out / "profile.csv", cols)
    gear, period = press.drive.gear_ratio, plan.spec.controller_period
    tab = cam_table(plan, gear)
    cam = master_cam(plan, gear, cam_cfg.master_step_deg)
    isg = isg_cam_table(
        cam, gear, job.name, cam_cfg.isg_table_id, cam_cfg.isg_max_lines,
        (f"{job.name} on {press.name}: {rate_text(plan.strokes_per_min)}, cycle {plan.cycle_time:.6f} s; master = one turn per cycle",
         slave_axis_line(gear, ISG_FILE), f"written by servo-press-twin {versions()['servo-press-twin']} (servo-press plan)",
         "not this file's interpolation: what a controller that took the positions alone and joined them linearly would do "
         "(planning/cams.py):", *cam_err.lines(), *stop_comments(plan)))
    limits = plan.spec.torque_limits(press.motor.peak_torque)
    tab_points = cam_table_points(tab)
    played = {"cam_table_csv": max(peak_played(plan, PER_PERIOD, tab_points, period, gear),  # its columns, and differenced
                                   peak_played(plan, PER_PERIOD, tab_points, period, gear, use_columns=False)),
              "cam_master_csv": peak_played(plan, QUINTIC, cam_master_points(cam), period, gear),
              "isg_file": peak_played(plan, QUINTIC, isg_points(read_isg_cam_table(isg)[1]), period, 1.0)}
    write_csv(out / "cam_table.csv", tab, comments=cam_table_header(period, plan) + (played_line(played["cam_table_csv"], period, limits),)
              + stop_comments(plan))
    write_csv(out / CAM_FILE, cam, comments=cam_master_header(plan, gear) + (played_line(played["cam_master_csv"], period, limits),)
              + stop_comments(plan))
    atomic_write_text(out / ISG_FILE, isg.replace("Tablename =", f"# {played_line(played['isg_file'], period, limits)}\nTablename =", 1))
    info["cam_table_csv"]["played_peak_torque_Nm"] = played["cam_table_csv"]
    info["cam_table_csv"]["cycle_periods"], info["cam_table_csv"]["time_scale"] = controller_cycle(plan, period)
    info["cam_master_csv"]["played_peak_torque_Nm"] = played["cam_master_csv"]
    info["cam_master_csv"]["isg_file"]["played_peak_torque_Nm"] = played["isg_file"]
    write_json(out / "summary.json", info)  # a folder with a summary is a finished plan (output_folder moves it in place whole)
    if drawn is None:
        for f in futures:
            f.result()
    return info


def write_energy(pm: PressModel, job: Job, cols: dict, out: Path, title: str, figures=None, working=None) -> tuple[dict, list]:
    """A plan's energy per stroke from profile.csv's columns ``cols`` (:func:`planning.energy.plan_energy`, the process
    force acting on the samples ``working``: None, all) and, for a press file with [drive.electrical], power.csv written
    into ``out`` and power.png handed to ``figures`` (the figure worker; None: drawn here); returns (the summary's
    ``energy``, the figure's futures)."""
    flow, energy = plan_energy(pm, job.process, cols, working)
    if flow is None:
        return energy, []
    power = flow.columns(cols["time_s"])
    write_csv(out / "power.csv", power)
    link = pm.press.electrical.dc_link
    return energy, [save_later(figures, power_figure, (power, (link.min_voltage_V, link.max_voltage_V), title), out / "power.png")]


def run_plan(pm: PressModel, job: Job, spec: PlanningSpec, out: Path, overrides: dict, box=None, progress=None,
             drawing: Drawing | None = None, nominal: bool = False, verdict: dict | None = None) -> tuple[Plan, dict]:
    """Plan the stroke of ``job`` on ``pm`` and write the outputs; returns the plan and its summary.

    ``box`` (a :class:`planning.robust.Box`): plan robustly over it (summary ``robust``: the rate it costs against the
    calibrated values alone, estimated, and which parameter drives it); with ``nominal`` plan at the centre alone
    instead and report the peak torque the plan reaches at the box's worst corner (summary ``nominal_over_region``).
    ``verdict``: the calibration's own (:mod:`press_model.calibration_verdict`), recorded as ``calibration_verdict``.
    ``progress``: a :class:`press_io.progress.Progress`. ``drawing``: where the figures are drawn
    (:func:`write_plan_outputs`).
    """
    progress = progress or Progress("plan", enabled=False)
    CamSettings.from_job(job)  # the cam's settings checked before the planning, not after it
    extra = {} if verdict is None else {"calibration_verdict": verdict}
    power = read_power(job, pm.press.electrical)
    if spec.mode == "pendulum":
        if power.limited:
            raise ServoPressError(f"{job.source}: planning.mode = \"pendulum\" plans without a grid limit: "
                                  "leave out planning.power.grid_peak_limit_W")
        if power.min_energy:  # the swings are planned for time: a target rate would be dropped without a word
            raise PressDataError(job.source, "planning.power.target_strokes_per_min", power.target_strokes_per_min,
                                 "is planned on one turning stroke, not in pendulum mode; set planning.mode = \"stop-at-top\" "
                                 "or remove the target")
        return run_pendulum_plan(pm, job, spec, out, overrides, progress, drawing, None if nominal else box, extra)
    if box is None or nominal:
        objective = objective_of(power)
        with progress.phase(objective.what):
            plan, rec = objective.plan(StrokeProblem.build(pm, job.process, spec))
        extra.update(rec)
        kind = "overrides" if overrides else "nominal parameters"
        if box is not None:
            from .robust import region_peak

            with progress.phase(f"the plan at the {2 ** len(box.bounds)} corners of the calibration's {box.kind}"):
                extra["nominal_over_region"] = region_peak(pm, job.process, spec, box, plan)
            kind = "calibrated values alone (--nominal)"
    else:
        from .robust import plan_robust

        with progress.phase(f"robust plan over the calibration's {box.kind}, {len(box.bounds)} parameters ({2 ** len(box.bounds)} corners checked)"
                            + (f" within the grid limit {power.grid_peak_limit_W / 1e6:.3f} MW at every corner" if power.limited else "")):
            if power.limited:
                from .energy import plan_robust_under_grid_limit

                res, extra["grid_limit"] = plan_robust_under_grid_limit(pm, job.process, spec, box, power)
            else:
                res = plan_robust(pm, job.process, spec, box, plan_nominal=False)
        plan = res.plan
        extra["robust"] = res.summary(pm.press.motor.peak_torque)
        kind = f"robust over the calibration's {box.kind}"
    refuse_unmet(pm, plan, extra, job.source)  # a plan that breaks a stated limit is no result: nothing is written
    if plan.spec.mode == "pendulum":  # mode = "auto" kept the pendulum: its own outputs, the modes and the gain from auto's record
        extra.update(mode_requested="auto", modes=plan.modes)
        with progress.phase("outputs (profile.csv, cam_table.csv, cam_master.csv, figures, summary.json)"):
            info = write_pendulum_outputs(pm, job, plan, out, overrides, gain_from_modes(plan.modes), drawing, extra)
        return plan, info
    title = f"{pm.press.name}, {job.name}: {rate_text(plan.strokes_per_min)} ({kind})"
    with progress.phase("outputs (profile.csv, cam_table.csv, cam_master.csv, figures, summary.json)"):
        info = write_plan_outputs(pm, job, plan, out, overrides, title, extra, drawing)
    return plan, info


def plan_job(press: str, job: str, params: str | None, out: str, robust: bool = False, verify: bool = False,
             nominal: bool = False, pareto: bool = False) -> tuple[str, dict, dict | None]:
    """The 'plan' command: plan ``job`` (file or built-in name) on ``press`` with the overrides ``params`` into the
    folder ``out`` (written whole at the end); returns (job name, summary, playback record or None).

    A calibration result ``params`` with a joint region (or intervals) is planned robustly over it unless ``nominal``
    (then at its values alone, with the peak the plan reaches over the region reported); overrides without a region are
    planned as given. ``robust``: the region is required (an error without one); ``verify``: also play the plan back
    through the forward dynamics (:func:`planning.playback.run_playback`); ``pareto``: also the front of rate against
    the grid's peak power (:mod:`planning.energy`: pareto.csv, pareto.png, summary ``pareto``; the press at its values,
    not a robust plan). Everything is checked before the output folder is made.
    """
    from press_model.calibration_verdict import calibration_verdict

    job_ = load_job(job)
    spec = read_planning(job_)
    press_ = load_press(press)
    power = read_power(job_, press_.electrical)  # refused here, before any output folder exists
    if (power.limited or pareto or power.min_energy) and not math.isfinite(spec.crank_jerk):
        raise ServoPressError(f"{job_.source}: planning.limits.crank_jerk_rad_s3 is not set: a plan within a grid limit "
                              "(planning.power.grid_peak_limit_W, plan --pareto) or at the least energy (target_strokes_per_min) "
                              "needs the jerk-limited stage, which carries the grid power; set a crank jerk limit (see door_panel.toml)")
    if pareto and spec.mode == "pendulum":  # its swings are planned without grid rows: there is no front to sweep
        raise PressDataError(job_.source, "planning.mode", spec.mode, "plan --pareto sweeps grid peak-power limits, which pendulum "
                             "mode does not plan under; set mode = \"stop-at-top\" (or \"continuous\") for the front, or leave out --pareto")
    if pareto and press_.electrical is None:
        raise ServoPressError(f"plan --pareto needs a press file with [drive.electrical] (the grid power it sweeps); {press_.source} has none")
    if pareto and robust:
        raise ServoPressError("plan --pareto plans the press at its values: leave out --robust (give --nominal with a calibration "
                              "that has a joint region)")
    doc = read_json(params, press_) if params is not None else None  # read once: the overrides and the robust box
    overrides = overrides_of(doc) if doc is not None else {}
    # the heaviest motor is held to the margin: the calibration's measured shares, else the press file's
    spec = dataclasses.replace(spec, sharing=motor_sharing(press_, *((doc.value, doc.source) if doc is not None else ())))
    pm = PressModel(apply_overrides(press_, overrides))
    if robust and nominal:
        raise ServoPressError("plan: --robust and --nominal contradict each other: --nominal plans at the calibrated values alone, "
                              "--robust (the default for a calibration with a joint region) over its region; give one")
    if robust and params is None:
        raise ServoPressError("plan --robust needs --params calibrated.json (the calibration's values and 95 % intervals)")
    box = None
    verdict = calibration_verdict(doc.value, doc.source) if doc is not None else None
    if params is not None:
        from .robust import Box

        center, intervals, kind = joint_box_of(doc, required=robust)  # --robust: the box is required
        if intervals is not None:
            box = Box.from_calibration(press_, center, intervals, str(params), kind)  # the file's ranges, not re-centred
    if box is not None and not nominal and power.min_energy:
        raise ServoPressError(f"{job_.source}: planning.power.target_strokes_per_min is planned on one parameter set: the "
                              "jerk-limited stage's energy objective takes the plan's own model, while a robust plan's torque rows "
                              f"range over the {box.kind}'s corners, whose grid energy is not among its objective or its corner "
                              "check; add --nominal (planned at the calibrated values) or remove the key for the robust plan")
    if pareto and box is not None and not nominal:
        raise ServoPressError("plan --pareto plans the press at its values: a calibration with a joint region is planned robustly "
                              "over it by default; add --nominal")
    pb = None
    # the figures are drawn in a process forked now: matplotlib's import runs beside the planning, the drawing beside
    # the playback
    check_output_folder(out, [press, job, params], "plan")  # a refused --out before the worker's fork (~1 s of CPU in a fresh process)
    with figure_worker() as figures, output_folder(out, [press, job, params], "plan") as tmp:
        progress = Progress("plan")
        drawn = []
        try:
            plan, info = run_plan(pm, job_, spec, tmp, overrides, box, progress, Drawing(figures, drawn), nominal, verdict)
            if pareto:
                with progress.phase("the front of rate against grid peak power (plan --pareto)"):
                    info["pareto"] = run_pareto(pm, job_, spec, plan, power, tmp, Drawing(figures, drawn), progress.bar("pareto"))
            if verify:
                from .playback import run_playback

                with progress.phase("playback through the forward dynamics (FF + PD)"):
                    pb = run_playback(pm, job_, spec, plan, tmp, progress=progress.bar("playback"))
        finally:
            wait(drawn)  # no figure is still being written when the folder is swapped in (or removed after an error)
        for f in drawn:
            f.result()
    return job_.name, info, pb


def run_pareto(pm: PressModel, job: Job, spec: PlanningSpec, plan: Plan, power, out: Path, drawing: Drawing | None = None,
               progress=None) -> dict:
    """The front of ``plan --pareto`` into ``out`` (pareto.csv, pareto.png; summary.json's ``pareto``), from ``plan``
    (the unconstrained plan; a plan under the job's own grid limit is planned again without it); returns the record.
    ``drawing``: where pareto.png is drawn (:class:`planning.figures.Drawing`; None: here); ``progress``: a callback of
    the fraction of the front planned (None: none)."""
    from .energy import COLUMNS, MinimumTime, pareto_front

    if isinstance(plan, PendulumPlan):  # auto mode chose the pendulum, whose swings carry no grid rows
        raise PlanningError(f"{job.source}: planning.mode = \"{spec.mode}\" planned a pendulum stroke, which plan --pareto cannot "
                            "sweep under grid limits; set mode = \"stop-at-top\" (or \"continuous\") for the front")
    from .figures import pareto_figure

    figures, drawn = (drawing.worker, drawing.drawn) if drawing is not None else (None, None)
    base = plan if not (power.limited or power.min_energy) else MinimumTime().plan(
        StrokeProblem(pm, job.process, spec, plan.grid, plan.pd), start=plan.profile)[0]
    rows = pareto_front(pm, job.process, spec, base, power, progress)
    write_table(Path(out) / "pareto.csv", COLUMNS, rows)
    done = save_later(figures, pareto_figure, (rows, f"{pm.press.name}, {job.name}: rate and energy against the grid's peak power"),
                      out / "pareto.png")
    if drawn is not None:
        drawn.append(done)
    else:
        done.result()
    rec = pareto_record(rows)
    summary = Path(out) / "summary.json"
    rec_all = json.loads(summary.read_text(encoding="utf-8"))
    rec_all["pareto"] = rec
    write_json(summary, rec_all)
    return rec


def robust_line(r: dict) -> str:
    """One line on a robust plan (summary ``robust``): its rate, its cost against the calibrated values alone, the worst
    corner, the parameter that drives the cost and where to buy it back."""
    d = r["cost_driver"]
    driver = (f"; cost driver {d['parameter']} ({100 * d['shares'][d['parameter']]:.0f} % of the torque spread at the binding knots): "
              "`servo-press design-experiment` designs the runs that narrow it" if d["parameter"] else "")
    if r["nominal_calibrated_is"].startswith("planned"):
        against = (f"against {rate_text(r['strokes_per_min_nominal_calibrated'])} for the calibrated values alone (cost "
                   f"{r['spm_cost']:.3f} spm, {r['rate_cost_percent']:+.2f} %)")
    else:  # an estimate is no plan: no rate of its own beside the plan's (`compare` plans it and prints its rate)
        against = (f"the calibrated values alone would plan about {r['rate_cost_percent']:.1f} % faster (estimated from toppra's "
                   "jerk-free strokes, not planned: `servo-press compare` plans it)")
    sep = "; " if against.startswith("the") else " "
    return (f"robust over the calibration's {r['box_kind']}: {rate_text(r['strokes_per_min_robust'])}{sep}{against}; worst of "
            f"{r['corners_checked']} corners {r['worst_corner_peak_ratio']:.4f} T_max{driver}")


def plan_lines(job_name: str, info: dict, playback: dict | None, out: Path) -> list[str]:
    """The lines the 'plan' command prints: rate, torques and binding limits, the jerk limit's cost, the robust
    plan's cost, the playback's verdict."""
    if info.get("mode") == "pendulum":
        lines = pendulum_lines(job_name, info, playback, out)
        return lines[:1] + [modes_line(info["modes"])] + lines[1:] if "modes" in info else lines
    b = {k: v["dominant"] + (f" ({100 * v['dominant_time_share']:.0f} % of its time)" if v["dominant"] != "none" else "")
         for k, v in info["binding_constraints"].items() if isinstance(v, dict) and k != "dwell"}
    jl = info["jerk_limit"]
    lines = [f"{job_name}: {rate_text(info['strokes_per_min'])} (stroke {info['stroke_time_s']:.3f} s + dwell {info['dwell_s']:.3f} s); "
             f"peak torque {info['peak_torque_Nm']:.0f} N m ({info['peak_torque_ratio']:.3f} T_max), RMS {info['rms_torque_Nm']:.0f} N m; "
             f"binding: {', '.join(f'{k} {v}' for k, v in b.items())}; thermal {info['binding_constraints']['thermal_rms']} -> {out}"]
    if "modes" in info:
        lines.append(modes_line(info["modes"]))
    if limiting_line(info.get("limiting_motor", {})):
        lines.append(limiting_line(info["limiting_motor"]))
    if info.get("stops"):
        lines.append("stops on the way: " + ", ".join(f"{s['name']} {s['time_s']:g} s at {s['crank_angle_deg']:.2f} deg "
                                                      f"(slide {1000 * s['slide_height_m']:.1f} mm, holding {s['holding_torque_Nm']:,.0f} N m)"
                                                      for s in info["stops"]))
    if jl["crank_jerk_rad_s3"] is not None and jl["kept"]:
        without = jl["strokes_per_min_without_jerk_limit"]
        lines.append(f"jerk limit {jl['crank_jerk_rad_s3']:g} rad/s^3 (largest {jl['max_crank_jerk_rad_s3']:.0f}): {jl['strokes_per_min_with_jerk_limit']:.3f} spm; "
                     + (f"{without:.3f} spm without it" if without is not None else "without it the stroke breaks the thermal limit"))
    if "energy" in info:
        lines.extend(energy_lines(info["energy"]))
    if "grid_limit" in info:
        g = info["grid_limit"]
        who = "the time-optimal start" if "of" in g else "the plan"
        lines.append(f"grid limit {g['grid_peak_limit_W'] / 1e6:.3f} MW: {who} draws {g['grid_peak_W'] / 1e6:.3f} MW at its peak "
                     f"({'held' if g['held'] else 'NOT held'}; {len(g['row_bounds_W'])} plan(s) to hold it on the written profile)"
                     + (f"; worst of {g['corners_checked']} corners {g['worst_corner_grid_peak_W'] / 1e6:.3f} MW"
                        if "corners_checked" in g else ""))
    if "min_energy" in info:
        from .energy import min_energy_line

        lines.append(min_energy_line(info["min_energy"]))
    if "pareto" in info:
        lines.append(pareto_line(info["pareto"]))
    if "robust" in info:
        lines.append(robust_line(info["robust"]))
    if playback is not None:
        lines.append(playback["verdict"]["line"])
    return lines


def pareto_record(rows: list[dict]) -> dict:
    """summary.json's ``pareto`` of the front's rows (pareto.csv's): the limits, the rates, which limit each plan meets
    and the limits no plan met (with why: fell back to toppra's stroke, drew more, could not be planned)."""
    from .energy import COLUMNS

    return {"csv": "pareto.csv", "columns": COLUMNS, "points": len(rows),
            "limits_W": [r["grid_peak_limit_W"] for r in rows], "strokes_per_min": [r["strokes_per_min"] for r in rows],
            "within_limit": [r["within_limit"] == "yes" for r in rows],
            "not_met": [{"grid_peak_limit_W": r["grid_peak_limit_W"], "grid_peak_W": r["grid_peak_W"], "why": r["optimiser"]}
                        for r in rows if r["within_limit"] != "yes"],
            "method": "each limit the jerk-limited time optimum with the grid power as rows of its problem (planning/energy.py), "
                      "started from the plan at the limit before; the first row is the plan without a limit; a limit whose plan "
                      "fell back to toppra's jerk-free stroke or drew more is not met (within_limit NO) and ends the front"}


def pareto_line(p: dict) -> str:
    """One line of ``plan --pareto`` (summary ``pareto``): the front's span over the limits its plans meet, and the
    limits no plan met (a plan that fell back to toppra's stroke, drew more, or could not be planned)."""
    met = [i for i, ok in enumerate(p["within_limit"]) if ok]
    line = (f"pareto.csv: {p['points']} plans from {p['limits_W'][met[0]] / 1e6:.2f} MW ({p['strokes_per_min'][met[0]]:.3f} spm) to "
            f"{p['limits_W'][met[-1]] / 1e6:.2f} MW ({p['strokes_per_min'][met[-1]]:.3f} spm) of grid peak") if met else \
        f"pareto.csv: {p['points']} plans, none within its limit"
    if p["not_met"]:
        low = p["not_met"][-1]
        line += (f"; {len(p['not_met'])} limit(s) NOT met, the front ends there (down to {low['grid_peak_limit_W'] / 1e6:.2f} MW: "
                 f"{low['why']})")
    return line


def modes_line(modes: dict) -> str:
    """One line of mode = "auto" (summary ``modes``): each mode's rate, or why it was not allowed or kept, and the one planned."""
    parts = []
    for name, r in modes["modes"].items():
        if not r["allowed"]:
            parts.append(f"{name} not allowed ({r['why_not']})")
        elif r["strokes_per_min"] is None:
            parts.append(f"{name} {'not supported' if r.get('supported') is False else 'infeasible'} ({r['infeasible']})")
        else:
            vs = f", {r['vs_stop_at_top_percent']:+.1f} % vs stop-at-top" if "vs_stop_at_top_percent" in r else ""
            parts.append(f"{name} {r['strokes_per_min']:.3f} spm{vs}" + ("" if r["keeps_every_limit"] else f" (breaks a limit: {r['infeasible']})"))
    return f"mode auto -> {modes['planned']}: " + "; ".join(parts)


def plan_warnings(info: dict) -> list[str]:
    """What the 'plan' command warns about: a DC-link voltage out of its window and a grid limit broken
    ([drive.electrical], [planning.power]); a jerk-limited stage that fell back to toppra's jerk-free stroke; a cam file
    that, played as it declares, breaks the torque margin; a plan at the calibrated values alone (--nominal) and the
    peak it reaches over the calibration's region; a calibration that is not adequate or warned (a robust box clipped
    to the press file's ranges: ``robust.warnings``). What the master cam's positions joined linearly would give (an
    import that ignores the files' declared segments) is stated in the ISG header and the summary, not warned: no file
    declares it."""
    from press_model.calibration_verdict import verdict_warning

    out = []
    en = info.get("energy") or {}
    if en.get("within_dc_link_window") is False:
        out.append(f"the DC-link voltage leaves its window over the planned cycle ({en['dc_link_voltage_V']['min']:.0f}-"
                   f"{en['dc_link_voltage_V']['max']:.0f} V, window {en['dc_link_voltage_V']['window']}): the supply of the press "
                   "file's [drive.electrical] cannot follow this plan (summary.json 'energy')")
    if en.get("within_grid_limit") is False:
        out.append(f"the plan draws {en['grid_peak_W'] / 1e6:.3f} MW from the grid at its peak, above planning.power.grid_peak_limit_W = "
                   f"{en['grid_peak_limit_W'] / 1e6:.3f} MW (summary.json 'energy')")
    if "grid_limit_leaves_out_storage_W" in en:
        out.append(f"planning.power.grid_peak_limit_W = {en['grid_peak_limit_W'] / 1e6:.3f} MW is planned on the drives' own draw: "
                   f"the storage ([drive.electrical.storage], up to {en['grid_limit_leaves_out_storage_W'] / 1e6:.3f} MW) is left out, "
                   "so the plan may be slower than the supply with the bank allows (summary.json 'energy')")
    opt = info["jerk_limit"].get("optimiser") or {}
    for swing, o in (opt.items() if info.get("mode") == "pendulum" else [(None, opt)]):  # a pendulum: one per swing
        if o.get("status") == "fallback":
            what = f" of the {swing} swing" if swing else ""
            out.append(f"the jerk-limited optimisation{what} failed ({o['fallback_reason']}); the plan is toppra's jerk-free stroke and "
                       "does NOT keep planning.limits.crank_jerk_rad_s3")
    out += played_cam_warnings(info)
    if "nominal_over_region" in info:
        r = info["nominal_over_region"]
        verb = "BREAKS" if r["peak_ratio"] > r["margin"] * (1 + 1e-9) else "keeps"
        out.append(f"--nominal: the plan keeps the margin at the calibrated values alone; at the worst corner of the calibration's "
                   f"{r['box_kind']} it reaches {r['peak_ratio']:.3f} T_max and {verb} the margin {r['margin']:g} T_max "
                   "(without --nominal the plan keeps it over the whole region)")
    w = verdict_warning(info.get("calibration_verdict"))
    if w:
        out.append(w)
    return out


def played_cam_warnings(info: dict) -> list[str]:
    """One line per cam file of a plan's summary whose played peak (``played_peak_torque_Nm``) is above the margin."""
    if "cam_table_csv" not in info:  # a plan summary before its outputs are written has no cam files yet
        return []
    lim = info["limits"]
    t_max = info["peak_torque_Nm"] / info["peak_torque_ratio"]  # the motor's T_max (summary.json holds the ratio, not T_max)
    master = info.get("cam_master_csv", {})
    files = (("cam_table.csv", info.get("cam_table_csv", {})), (CAM_FILE, master), (ISG_FILE, master.get("isg_file", {})))
    return [f"{name} played as it declares ({entry.get('interpolation')}) every {info['cam_table_csv']['sample_time_s']:g} s reaches "
            f"{entry['played_peak_torque_Nm']:,.0f} N m per motor = {entry['played_peak_torque_Nm'] / t_max:.4f} T_max, above the margin "
            f"{lim['peak_torque_limit_Nm']:,.0f} N m: lower [planning.cam] master_step_deg (its segments are too long for the motion)"
            for name, entry in files if entry.get("played_peak_torque_Nm", 0.0) > lim["peak_torque_limit_Nm"]]


# ----------------------------------------------------------------------------------------------------------------------
# The 'plan' command in pendulum mode: plan the swing (:mod:`planning.pendulum`), the stop-at-top plan of the same job
# and transfer for the gain, and write profile.csv, cam_table.csv, cam_master.csv (a swinging master cam), slide.png (the
# slide height with the transfer window and the turning points), torque.png, speed.png and summary.json.


def gain_over_stop_at_top(pendulum: PendulumPlan, stop_at_top: Plan) -> dict:
    """The pendulum plan's rate against the stop-at-top plan of the same job and transfer requirement (spm and %)."""
    p, s = pendulum.strokes_per_min, stop_at_top.strokes_per_min
    return {"pendulum_strokes_per_min": p, "stop_at_top_strokes_per_min": s, "gain_spm": p - s, "gain_percent": 100.0 * (p / s - 1.0),
            "stop_at_top_dwell_at_tdc_s": stop_at_top.dwell, "stop_at_top_stroke_time_s": stop_at_top.stroke_time,
            "same_requirement": "the stop-at-top plan's dwell at TDC tops its time above the opening up to the same time_s (planning/transfer.py)"}


def gain_from_modes(modes: dict) -> dict | None:
    """:func:`gain_over_stop_at_top`'s rates from mode = "auto"'s record (``Plan.modes``; planning.modes): the pendulum's
    and the stop-at-top plan's, which auto planned beside it (None when the stop-at-top plan gave no rate)."""
    rec = modes["modes"]
    p, s = rec["pendulum"]["strokes_per_min"], rec.get("stop-at-top", {}).get("strokes_per_min")
    if s is None:
        return None
    sat = rec["stop-at-top"]
    return {"pendulum_strokes_per_min": p, "stop_at_top_strokes_per_min": s, "gain_spm": p - s, "gain_percent": 100.0 * (p / s - 1.0),
            "stop_at_top_dwell_at_tdc_s": sat.get("dwell_at_tdc_s"), "stop_at_top_stroke_time_s": sat["cycle_time_s"] - sat.get("dwell_at_tdc_s", 0.0),
            "same_requirement": "the stop-at-top plan's dwell at TDC tops its time above the opening up to the same time_s (planning/transfer.py)"}


def pendulum_summary(pm: PressModel, job: Job, plan: PendulumPlan, overrides: dict, gain: dict | None) -> dict:
    """summary.json of a pendulum plan: rate, torques, the swings and turning points, the transfer, the gain, limits,
    parameters, versions."""
    press, spec = pm.press, plan.spec
    motor = press.motor
    torque = spec.torque_limits(motor.peak_torque)
    cam = CamSettings.from_job(job)
    f, b = plan.forward, plan.backward
    jerk = max(f.max_jerk, b.max_jerk)
    return {
        "job": job.name, "job_source": job.source, **press.identity(),
        "mode": "pendulum",
        "strokes_per_min": plan.strokes_per_min,
        "cycle_time_s": plan.cycle_time,
        "stroke_time_s": f.stroke_time + b.stroke_time,
        "dwell_s": plan.dwell_a + plan.dwell_b,
        "peak_torque_Nm": plan.peak_torque,
        "peak_torque_ratio": plan.peak_torque / motor.peak_torque,
        "limiting_motor": spec.sharing.record(plan.peak_torque, motor.peak_torque),
        "rms_torque_Nm": plan.rms_torque,
        "rms_torque_ratio_to_rated": plan.rms_torque / motor.rated_torque,
        "max_motor_speed_rpm": plan.max_motor_speed * 60.0 / (2.0 * math.pi),
        "max_slide_speed_in_forming_window_m_s": plan.max_window_slide_speed,
        "pendulum": plan.summary(),
        "transfer": plan.transfer,
        "gain_over_stop_at_top": gain,
        "limits": {
            "peak_torque_limit_Nm": torque.verdict, "peak_torque_margin": spec.torque_margin, "feedback_reserve": spec.feedback_reserve,
            "feedforward_torque_limit_Nm": torque.feedforward, "rated_torque_Nm": motor.rated_torque,
            "thermal_feedback_reserve": spec.thermal_reserve, "feedforward_rms_limit_Nm": (1.0 - spec.thermal_reserve) * motor.rated_torque,
            "max_motor_speed_rpm": motor.max_speed * 60.0 / (2.0 * math.pi), "forming_slide_speed_m_s": spec.forming_speed,
            "forming_window_below_height_m": job.process.contact_height + spec.forming_window,
            "forming_window_directions": spec.window_directions,
            "crank_jerk_rad_s3": spec.crank_jerk if math.isfinite(spec.crank_jerk) else None,
        },
        "jerk_limit": {"crank_jerk_rad_s3": spec.crank_jerk if math.isfinite(spec.crank_jerk) else None,
                       "max_crank_jerk_rad_s3": jerk if math.isfinite(jerk) else None,
                       "kept": bool(math.isfinite(jerk) and jerk <= spec.crank_jerk * (1.0 + 1e-6)),
                       "optimiser": {"forward": f.optimiser, "backward": b.optimiser}},
        "cam_table_csv": {"sample_time_s": spec.controller_period, "columns": list(CAM_COLUMNS), "interpolation": PER_PERIOD,
                          "motor_position": "deg at the motor shaft from turning point A: rises on the working swing, falls back to 0 on the return"},
        "cam_master_csv": {"master_step_deg": cam.master_step_deg, "columns": list(CAM_MASTER_COLUMNS), "interpolation": QUINTIC,
                           "master_speed_deg_s": master_speed_deg_s(plan), "cycle_time_s": plan.cycle_time,
                           "wrap": "pendulum: the slave swings back to its start every cycle (not endless)",
                           "isg_file": {"written": False, "why": "the ISG table is written endless positive; a pendulum's slave swings back"}},
        "profile_csv": {"sample_time_s": spec.sample_time,
                        "crank_angle": "theta_c in deg as the stop-at-top grid's (unwrapped from TDC): rises from A to B, falls back to A"},
        "parameters": press.parameter_values(),
        "overrides": overrides,
        "versions": versions(),
    }


def run_pendulum_plan(pm: PressModel, job: Job, spec: PlanningSpec, out: Path, overrides: dict, progress=None,
                      drawing: Drawing | None = None, box=None, extra: dict | None = None) -> tuple[PendulumPlan, dict]:
    """Plan ``job`` in pendulum mode and the same job stop-at-top (the gain), write the outputs into ``out``; returns the
    pendulum plan and its summary. ``box``: a calibration's region (:class:`planning.robust.Box`) both plans hold the
    torque limit over (:func:`planning.robust.plan_robust`; summary ``robust``); None: the press as given. ``drawing``: where
    the figures are drawn (:func:`write_pendulum_outputs`); ``extra``: further summary entries (the calibration's verdict).
    Raises :class:`PlanningError` (nothing written) for a plan that breaks a stated limit (:func:`planning.energy.refuse_unmet`)."""
    from press_io.progress import Progress

    progress = progress or Progress("plan", enabled=False)
    CamSettings.from_job(job)
    sat_spec = dataclasses.replace(spec, mode="stop-at-top")
    extra = dict(extra or {})
    if box is None:
        with progress.phase("pendulum plan: the working swing and the return (toppra, then the jerk-limited optimum each)"):
            plan = plan_pendulum(pm, job.process, spec)
        with progress.phase("the stop-at-top plan of the same job and transfer (the gain)"):
            sat = plan_stroke(StrokeProblem.build(pm, job.process, sat_spec))
    else:
        from .robust import plan_robust

        with progress.phase(f"robust pendulum plan over the calibration's {box.kind} ({2 ** len(box.bounds)} corners checked per swing)"):
            res = plan_robust(pm, job.process, spec, box, plan_nominal=False)
        plan, extra["robust"] = res.plan, res.summary(pm.press.motor.peak_torque)
        with progress.phase("the robust stop-at-top plan of the same job and transfer (the gain)"):
            sat = plan_robust(pm, job.process, sat_spec, box, plan_nominal=False).plan
    refuse_unmet(pm, plan, extra, job.source)
    gain = gain_over_stop_at_top(plan, sat)
    with progress.phase("outputs (profile.csv, cam_table.csv, cam_master.csv, figures, summary.json)"):
        info = write_pendulum_outputs(pm, job, plan, Path(out), overrides, gain, drawing, extra)
    return plan, info


def write_pendulum_outputs(pm: PressModel, job: Job, plan: PendulumPlan, out: Path, overrides: dict, gain: dict | None,
                           drawing: Drawing | None = None, extra: dict | None = None) -> dict:
    """profile.csv, cam_table.csv, cam_master.csv (their played peaks in their headers and the summary), slide.png,
    torque.png, speed.png and summary.json of a pendulum plan (``extra``: further summary entries, mode = "auto"'s
    record; ``drawing``: where the figures are drawn, :class:`planning.figures.Drawing`); returns the summary."""
    figures, drawn = (drawing.worker, drawing.drawn) if drawing is not None else (None, None)
    out.mkdir(parents=True, exist_ok=True)
    press = pm.press
    gear, period = press.drive.gear_ratio, plan.spec.controller_period
    cols = sample_plan(plan, gear)
    info = {**pendulum_summary(pm, job, plan, overrides, gain), **(extra or {})}
    title = f"{press.name}, {job.name}: pendulum {rate_text(plan.strokes_per_min)}"
    t1, t2, t3, _ = plan.phases()
    # as a stop-at-top plan's, the process force on the working swing alone (the return runs with the die empty)
    info["energy"], power_png = write_energy(pm, job, cols, out, title, figures, np.asarray(cols["time_s"]) <= t1)
    write_csv(out / "profile.csv", cols)
    limits = plan.spec.torque_limits(press.motor.peak_torque)
    tab = cam_table(plan, gear)
    cam = master_cam(plan, gear, CamSettings.from_job(job).master_step_deg)
    tab_points = cam_table_points(tab)
    played = {"cam_table_csv": max(peak_played(plan, PER_PERIOD, tab_points, period, gear, turn_deg=0.0),
                                   peak_played(plan, PER_PERIOD, tab_points, period, gear, use_columns=False, turn_deg=0.0)),
              "cam_master_csv": peak_played(plan, QUINTIC, cam_master_points(cam), period, gear, turn_deg=0.0)}
    pend = ("PENDULUM: the motor turns forward on the working swing and BACK on the return; position from turning point A, "
            "back to 0 at the end of every cycle (not endless)",)
    write_csv(out / "cam_table.csv", tab, comments=cam_table_header(period, plan) + pend + (played_line(played["cam_table_csv"], period, limits),)
              + stop_comments(plan))
    swing_motor = math.degrees(plan.turning[1] - plan.turning[0]) * gear
    write_csv(out / CAM_FILE, cam, comments=pendulum_master_header(plan, gear, swing_motor)
              + (played_line(played["cam_master_csv"], period, limits),) + stop_comments(plan))
    info["cam_table_csv"]["played_peak_torque_Nm"] = played["cam_table_csv"]
    info["cam_table_csv"]["cycle_periods"], info["cam_table_csv"]["time_scale"] = controller_cycle(plan, period)
    info["cam_master_csv"]["played_peak_torque_Nm"] = played["cam_master_csv"]
    h = {p["name"][0]: p["slide_height_m"] for p in info["pendulum"]["turning_points"]}
    marks = [("turning point A (rest, blank in)", 0.0, h["A"]), ("turning point B (rest, part out)", t1, h["B"]),
             ("turning point B, return starts", t2, h["B"]), ("turning point A (rest)", t3, h["A"])]
    marks += [(label, t0, st.height) for st, (t0, _, label) in zip(plan.stops, stop_spans(plan))]  # on the working swing
    tr = plan.spec.transfer
    futures = power_png + [
        save_later(figures, slide_height_figure, (cols["time_s"], cols["slide_height_m"], tr.opening_height, tr.time, marks, title),
                   out / "slide.png"),
        save_later(figures, torque_figure, ([("motor torque", cols["time_s"], cols["motor_torque_Nm"], plan.rms_torque)], limits,
                                            press.motor.rated_torque, title, stop_spans(plan)), out / "torque.png"),
        save_later(figures, speed_figure, ([("plan", cols["time_s"], cols["crank_speed_rad_s"], cols["crank_accel_rad_s2"])], gear,
                                           press.motor.max_speed * 60.0 / (2.0 * math.pi), title, stop_spans(plan)), out / "speed.png")]
    write_json(out / "summary.json", info)
    if drawn is None:
        for fu in futures:
            fu.result()
    else:
        drawn.extend(futures)
    return info


def pendulum_lines(job_name: str, info: dict, playback: dict | None, out: Path) -> list[str]:
    """The lines the 'plan' command prints for a pendulum plan."""
    p = info["pendulum"]
    a, b = p["turning_points"]
    lines = [f"{job_name}: pendulum {rate_text(info['strokes_per_min'])} (working swing {p['forward_swing_s']:.3f} s + return "
             f"{p['backward_swing_s']:.3f} s + dwells {info['dwell_s']:.3f} s); turning points {a['crank_angle_deg']:.2f} deg "
             f"({a['slide_height_m']:.3f} m) and {b['crank_angle_deg']:.2f} deg ({b['slide_height_m']:.3f} m); peak torque "
             f"{info['peak_torque_Nm']:.0f} N m ({info['peak_torque_ratio']:.3f} T_max), RMS {info['rms_torque_Nm']:.0f} N m -> {out}"]
    if p.get("stops"):  # on the working swing, inside its time
        lines.append("stops on the working swing: " + ", ".join(
            f"{s['name']} {s['time_s']:g} s at {s['crank_angle_deg']:.2f} deg (slide {1000 * s['slide_height_m']:.1f} mm, holding "
            f"{s['holding_torque_Nm']:,.0f} N m)" for s in p["stops"]))
    if "energy" in info:  # as a stop-at-top plan's
        lines.extend(energy_lines(info["energy"]))
    g = info.get("gain_over_stop_at_top")
    if g:
        lines.append(f"against stop-at-top with the same transfer ({g['stop_at_top_strokes_per_min']:.3f} spm): "
                     f"{g['gain_spm']:+.3f} spm ({g['gain_percent']:+.1f} %)")
    if playback is not None:
        lines.append(playback["verdict"]["line"])
    return lines
