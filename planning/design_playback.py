"""The designed calibration runs checked as `plan --verify` checks a plan, and the 'design-experiment' command's work.

Each run of :func:`calibration.design.report.design_experiment` is a continuous crank rotation: on knots every
``KNOT_STEP_DEG`` plus die contact and BDC it becomes a planner profile (theta_dot^2 linear in theta between knots,
the constant-acceleration segments of a toppra profile), evaluated by the planner's full model
(:func:`planning.evaluation.evaluate_profile`) and played back through the forward dynamics with that feed-forward
and the PD loop of :mod:`planning.playback`, for one turn. The verdict is the playback's: the commanded torque below
T_max, the motor torque within the design's peak-torque margin, the crank angle within the tracking tolerance, the
loops closed. The playback's settings are the job's ``[design.playback]`` table (door_panel.toml's [playback] keys).
"""
from __future__ import annotations

import math
from dataclasses import replace
from pathlib import Path

import numpy as np

from calibration.design.report import Design
from press_model.forces import NO_PROCESS
from press_model.jobs import Job
from press_model.kinematics import force_step_angles
from press_model.model import PressModel
from press_io.outputs import write_csv
from press_io.progress import Progress
from press_model.readers import FieldReader
from press_model.settings_fields import read_section

from .evaluation import evaluate_profile
from .grid import Grid, knot_profile
from .path_dynamics import build_path_dynamics
from .planner import Plan
from .playback import play_back
from .settings import PlanningSpec, PlaybackSection

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
    return Plan(spec, grid, pd, prof, ev, 0.0, 0.0, math.nan, peak, math.nan, float(np.max(sd)) * pm.press.drive.gear_ratio,
                math.nan, False, 0, 0, 0, math.nan)


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
