"""The [planning], [planning.limits], [planning.solver] and [playback] tables of a job file: the planner's and the playback's settings."""
from __future__ import annotations

import math
from dataclasses import dataclass

from press_model.jobs import JOB_FORMAT, Job
from press_model.readers import FieldReader
from press_model.torque_limits import TorqueLimits


@dataclass(frozen=True)
class PlanningSpec:
    """The [planning], [planning.limits], [planning.solver] and [playback] sections of a job file (SI units)."""

    source: str
    mode: str  # "stop-at-top" or "continuous"
    dwell: float  # s, transfer dwell at TDC (stop-at-top only)
    grid_step: float  # rad
    sample_time: float  # s
    torque_margin: float  # fraction of T_max allowed at every instant
    forming_speed: float  # m/s
    forming_window: float  # m above the contact height
    window_directions: str  # "both" or "down"
    friction_tolerance: float  # s of stroke time
    friction_tolerance_torque: float  # N m at the crank
    friction_max_iterations: int
    thermal_tolerance: float  # fraction of T_rated
    recheck_tightening: float
    recheck_max_rounds: int
    continuous_tolerance: float  # rad/s
    crank_jerk: float  # rad/s^3, the jerk limit (math.inf: none, bang-bang toppra profile)
    optimal_tolerance: float  # IPOPT's relative KKT tolerance of the jerk-limited stage
    optimal_max_iterations: int
    controller_period: float  # s, the cam table's sample time
    playback_bandwidth: float  # Hz, crank-angle loop of the verification controller
    playback_damping: float
    playback_dt: float  # s
    tracking_tolerance_deg: float  # deg of crank angle
    loop_gap_tolerance: float  # m
    feedback_reserve: float  # fraction of T_max kept free below the margin for the feedback
    thermal_reserve: float  # fraction of T_rated the feed-forward's cycle RMS keeps free for the feedback

    def torque_limits(self, peak_torque: float) -> TorqueLimits:
        """The plan's peak-torque limits (N m per motor) on a motor of T_max = ``peak_torque`` (N m): ``.verdict``
        margin x T_max, ``.feedforward`` (margin - feedback reserve) x T_max."""
        return TorqueLimits(peak_torque, self.torque_margin, self.feedback_reserve)


def read_planning(job: Job) -> PlanningSpec:
    """Validate and read the planning sections of ``job``; a job without [planning] cannot be planned."""
    rd = FieldReader(job.source, {k: job.raw[k] for k in ("planning", "playback") if k in job.raw})
    for old in ("kp_Nm_per_rad", "kd_Nm_s_per_rad"):
        if rd.node(("playback", old), required=False) is not None:
            rd.fail(("playback", old), job.raw["playback"][old], "is no longer read: the playback's gains come from the press's own inertia "
                    "at the crank; set playback.bandwidth_Hz and playback.damping_ratio instead (see door_panel.toml)")
    if rd.node(("planning",), required=False) is None:
        rd.fail(("planning",), "<missing>", "a job to plan needs a [planning] section (see the shipped door_panel.toml)")
    if "process" not in job.raw:
        rd.fail(("process",), "<missing>", "a job to plan needs a [process] section with contact_height_m, heights_m and forces_N")
    p, lim, sol, pb = ("planning",), ("planning", "limits"), ("planning", "solver"), ("playback",)
    mode = rd.string((*p, "mode"), choices=("stop-at-top", "continuous"))
    dwell = rd.number((*p, "dwell_s"), ge=0.0, unit="s", limit="max_dwell_s", what="any transfer's stop")
    if mode == "continuous" and dwell > 0:
        rd.fail((*p, "dwell_s"), dwell, "must be 0 in continuous mode (the dwell is a stop at TDC, stop-at-top only)")
    step = rd.number((*p, "grid_step_deg"), gt=0.0, le=5.0, unit="deg", limit="min_step_deg", what="the crank step any run needs")
    spec = PlanningSpec(
        source=job.source,
        mode=mode,
        dwell=dwell,
        grid_step=math.radians(step),
        sample_time=rd.number((*p, "sample_time_s"), gt=0.0, le=0.05, unit="s", limit="min_sample_time_s", what="any press controller's period"),
        torque_margin=rd.number((*lim, "peak_torque_margin"), gt=0.0, le=1.0),
        forming_speed=rd.number((*lim, "forming_slide_speed_m_s"), gt=0.0, unit="m/s"),
        forming_window=rd.number((*lim, "forming_window_above_contact_m"), ge=0.0, unit="m"),
        window_directions=rd.string((*lim, "forming_window_directions"), choices=("both", "down")),
        friction_tolerance=rd.number((*sol, "friction_tolerance_s"), gt=0.0, unit="s"),
        friction_tolerance_torque=rd.number((*sol, "friction_tolerance_Nm"), gt=0.0, unit="N m"),
        friction_max_iterations=rd.integer((*sol, "friction_max_iterations"), ge=1),
        thermal_tolerance=rd.number((*sol, "thermal_tolerance"), gt=0.0, lt=0.5),
        recheck_tightening=rd.number((*sol, "recheck_tightening"), gt=0.5, le=1.0),
        recheck_max_rounds=rd.integer((*sol, "recheck_max_rounds"), ge=1),
        continuous_tolerance=rd.number((*sol, "continuous_search_tolerance_rad_s"), gt=0.0, unit="rad/s"),
        crank_jerk=rd.number((*lim, "crank_jerk_rad_s3"), gt=0.0, unit="rad/s^3"),
        optimal_tolerance=rd.number((*sol, "optimal_tolerance"), gt=0.0, lt=1e-3),
        optimal_max_iterations=rd.integer((*sol, "optimal_max_iterations"), ge=1),
        controller_period=rd.number((*p, "controller_period_s"), gt=0.0, le=0.05, unit="s", limit="min_sample_time_s",
                                    what="any press controller's period"),
        playback_bandwidth=rd.number((*pb, "bandwidth_Hz"), ge=0.0, unit="Hz"),
        playback_damping=rd.number((*pb, "damping_ratio"), gt=0.0, unit=""),
        playback_dt=rd.number((*pb, "time_step_s"), gt=0.0, le=0.02, unit="s", limit="min_sample_time_s", what="any press controller's period"),
        tracking_tolerance_deg=rd.number((*pb, "tracking_tolerance_deg"), gt=0.0, unit="deg"),
        loop_gap_tolerance=rd.number((*pb, "loop_gap_tolerance_m"), gt=0.0, unit="m"),
        feedback_reserve=rd.number((*lim, "feedback_reserve"), ge=0.0, lt=0.5),
        thermal_reserve=rd.number((*lim, "thermal_feedback_reserve"), ge=0.0, lt=0.5),
    )
    rd.delegate((*p, "cam"))  # the master-position cam's settings: planning.cams.CamSettings reads them
    rd.delegate((*p, "power"))  # the supply limit: planning.power.read_power reads it
    rd.reject_unread(JOB_FORMAT)
    return spec
