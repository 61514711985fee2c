"""The 'plan' command in pendulum mode: plan the swing (:mod:`planning.pendulum`), the stop-at-top plan of the same job
and transfer for the gain, and write profile.csv, cam_table.csv, cam_master.csv (a swinging master cam), slide.png (the
slide height with the transfer window and the turning points), torque.png, speed.png and summary.json."""
from __future__ import annotations

import dataclasses
import math
from pathlib import Path

from press_model.jobs import Job
from press_model.model import PressModel
from press_io.outputs import versions, write_csv, write_json
from press_model.plots import save_later

from .cam_playback import PER_PERIOD, QUINTIC, cam_master_points, cam_table_points, peak_played, played_line
from .cams import CAM_FILE, CAM_MASTER_COLUMNS, CamSettings, master_cam, master_speed_deg_s, pendulum_master_header
from .figures import slide_height_figure, speed_figure, torque_figure
from .hold import stop_comments, stop_spans
from .pendulum import PendulumPlan, plan_pendulum
from .planner import Plan, plan_stroke
from .profile import CAM_COLUMNS, cam_table, cam_table_header, controller_cycle, sample_plan
from .settings import PlanningSpec


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


def run_pendulum_plan(pm: PressModel, job: Job, spec: PlanningSpec, out: Path, overrides: dict, progress=None, figures=None,
                      drawn: list | None = None, box=None) -> tuple[PendulumPlan, dict]:
    """Plan ``job`` in pendulum mode and the same job stop-at-top (the gain), write the outputs into ``out``; returns the
    pendulum plan and its summary. ``box``: a calibration's region (:class:`planning.robust.Box`) both plans hold the
    torque limit over (:func:`planning.robust.plan_robust`; summary ``robust``); None: the press as given."""
    from press_io.progress import Progress

    progress = progress or Progress("plan", enabled=False)
    CamSettings.from_job(job)
    sat_spec = dataclasses.replace(spec, mode="stop-at-top")
    extra = None
    if box is None:
        with progress.phase("pendulum plan: the working swing and the return (toppra, then the jerk-limited optimum each)"):
            plan = plan_pendulum(pm, job.process, spec)
        with progress.phase("the stop-at-top plan of the same job and transfer (the gain)"):
            sat = plan_stroke(pm, job.process, sat_spec)
    else:
        from .robust import plan_robust

        with progress.phase(f"robust pendulum plan over the calibration's {box.kind} ({2 ** len(box.bounds)} corners checked per swing)"):
            res = plan_robust(pm, job.process, spec, box, plan_nominal=False)
        plan, extra = res.plan, {"robust": res.summary(pm.press.motor.peak_torque)}
        with progress.phase("the robust stop-at-top plan of the same job and transfer (the gain)"):
            sat = plan_robust(pm, job.process, sat_spec, box, plan_nominal=False).plan
    gain = gain_over_stop_at_top(plan, sat)
    with progress.phase("outputs (profile.csv, cam_table.csv, cam_master.csv, figures, summary.json)"):
        info = write_pendulum_outputs(pm, job, plan, Path(out), overrides, gain, figures, drawn, extra)
    return plan, info


def write_pendulum_outputs(pm: PressModel, job: Job, plan: PendulumPlan, out: Path, overrides: dict, gain: dict | None,
                           figures=None, drawn: list | None = None, extra: dict | None = None) -> dict:
    """profile.csv, cam_table.csv, cam_master.csv (their played peaks in their headers and the summary), slide.png,
    torque.png, speed.png and summary.json of a pendulum plan (``extra``: further summary entries, mode = "auto"'s
    record); returns the summary."""
    out.mkdir(parents=True, exist_ok=True)
    press = pm.press
    gear, period = press.drive.gear_ratio, plan.spec.controller_period
    cols = sample_plan(plan, gear)
    info = {**pendulum_summary(pm, job, plan, overrides, gain), **(extra or {})}
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
    write_csv(out / CAM_FILE, cam, comments=pendulum_master_header(master_speed_deg_s(plan), swing_motor)
              + (played_line(played["cam_master_csv"], period, limits),) + stop_comments(plan))
    info["cam_table_csv"]["played_peak_torque_Nm"] = played["cam_table_csv"]
    info["cam_table_csv"]["cycle_periods"], info["cam_table_csv"]["time_scale"] = controller_cycle(plan, period)
    info["cam_master_csv"]["played_peak_torque_Nm"] = played["cam_master_csv"]
    t1, t2, t3, _ = plan.phases()
    h = {p["name"][0]: p["slide_height_m"] for p in info["pendulum"]["turning_points"]}
    marks = [("turning point A (rest, blank in)", 0.0, h["A"]), ("turning point B (rest, part out)", t1, h["B"]),
             ("turning point B, return starts", t2, h["B"]), ("turning point A (rest)", t3, h["A"])]
    marks += [(label, t0, st.height) for st, (t0, _, label) in zip(plan.stops, stop_spans(plan))]  # on the working swing
    title = f"{press.name}, {job.name}: pendulum {plan.strokes_per_min:.2f} spm"
    tr = plan.spec.transfer
    futures = [
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
    lines = [f"{job_name}: pendulum {info['strokes_per_min']:.3f} spm (working swing {p['forward_swing_s']:.3f} s + return "
             f"{p['backward_swing_s']:.3f} s + dwells {info['dwell_s']:.3f} s); turning points {a['crank_angle_deg']:.2f} deg "
             f"({a['slide_height_m']:.3f} m) and {b['crank_angle_deg']:.2f} deg ({b['slide_height_m']:.3f} m); peak torque "
             f"{info['peak_torque_Nm']:.0f} N m ({info['peak_torque_ratio']:.3f} T_max), RMS {info['rms_torque_Nm']:.0f} N m -> {out}"]
    if p.get("stops"):  # on the working swing, inside its time
        lines.append("stops on the working swing: " + ", ".join(
            f"{s['name']} {s['time_s']:g} s at {s['crank_angle_deg']:.2f} deg (slide {1000 * s['slide_height_m']:.1f} mm, holding "
            f"{s['holding_torque_Nm']:,.0f} N m)" for s in p["stops"]))
    g = info.get("gain_over_stop_at_top")
    if g:
        lines.append(f"against stop-at-top with the same transfer ({g['stop_at_top_strokes_per_min']:.3f} spm): "
                     f"{g['gain_spm']:+.3f} spm ({g['gain_percent']:+.1f} %)")
    if playback is not None:
        lines.append(playback["verdict"]["line"])
    return lines
