"""The [planning], [planning.limits], [planning.solver] and [playback] tables of a job file: the planner's and the playback's settings.

Each table is a settings dataclass (:class:`PlanningSection`, :class:`LimitsSection`, :class:`SolverSection`,
:class:`PlaybackSection`) whose defaults are the door-panel job's values, with unit and reason; a job file gives
only what differs (and, in stop-at-top mode, its transfer's dwell). :func:`read_planning` reads them into the
planner's :class:`PlanningSpec` (SI units).

The motors' load sharing a plan takes (:class:`MotorSharing`, :func:`motor_sharing`): the heaviest motor, its torque
per unit of the mean motor torque the model computes, and where that came from. A calibration of a log with one torque channel per motor records the motors' shares (calibrated.json
``motor_shares``, :mod:`calibration.traces.motor_shares`), with the heaviest motor's factor at the upper 95 % bound of
its share; a plan with ``--params`` takes it. Without one, the press file's ``[motor] load_shares`` (absent: an even
load, factor 1). The planner holds the mean motor torque to the torque limits over the factor
(:class:`press_model.torque_limits.TorqueLimits`), so that the heaviest motor keeps the margin.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

from press_io.errors import PressDataError
from press_model.jobs import JOB_FORMAT, Job
from press_model.press_data import PressData
from press_model.readers import FieldReader
from press_model.settings_fields import read_section, setting
from press_model.torque_limits import TorqueLimits

from .hold import HoldSection, PauseSection, StopRequest, read_stops

# --- the motors' load sharing ---------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class MotorSharing:
    """``factor``: the heaviest motor's torque per unit of the mean motor torque (>= 1; 1: an even load); ``motor`` its
    number (from 1; 0: none heavier); ``source`` where the shares come from, for the summary."""

    factor: float = 1.0
    motor: int = 0
    source: str = "an even load (no shares measured or stated)"

    def record(self, peak_torque_Nm: float, t_max: float) -> dict:
        """summary.json's ``limiting_motor``: the heaviest motor and its peak torque (N m and / T_max) at the plan's peak
        mean motor torque ``peak_torque_Nm``."""
        return {"motor": self.motor or None, "torque_factor": self.factor, "shares_from": self.source,
                "peak_torque_Nm": self.factor * peak_torque_Nm, "peak_torque_ratio": self.factor * peak_torque_Nm / t_max}



def limiting_line(rec: dict) -> str:
    """One line naming the limiting motor of a summary's ``limiting_motor`` (:meth:`MotorSharing.record`) and its peak;
    "" for an even load."""
    if rec.get("motor") is None:
        return ""
    return (f"limiting motor: motor {rec['motor']}, {rec['torque_factor']:.3f} x the mean motor torque ({rec['shares_from']}): "
            f"peak {rec['peak_torque_Nm']:,.0f} N m ({rec['peak_torque_ratio']:.3f} T_max)")


def motor_sharing(press: PressData, calibration: dict | None = None, source: str = "--params") -> MotorSharing:
    """The :class:`MotorSharing` of a plan: the calibration's ``motor_shares`` (a parsed calibrated.json, ``source``
    its file) where it has them, else the press file's ``[motor] load_shares``."""
    rec = calibration.get("motor_shares") if isinstance(calibration, dict) else None
    if rec is not None:
        h = rec.get("heaviest") if isinstance(rec, dict) else None
        f = h.get("torque_factor") if isinstance(h, dict) else None
        m = h.get("motor") if isinstance(h, dict) else None
        if not (isinstance(f, (int, float)) and not isinstance(f, bool) and math.isfinite(f) and f >= 1.0
                and isinstance(m, int) and not isinstance(m, bool) and 1 <= m <= press.drive.motors):
            raise PressDataError(source, "motor_shares.heaviest", h, "must hold torque_factor (a number >= 1) and motor (1 to "
                                 f"{press.drive.motors}) as `servo-press calibrate` wrote them: pass calibrated.json as written")
        return MotorSharing(float(f), m, f"{source} motor_shares: motor {m} at up to {100 * f / press.drive.motors:.1f} % "
                                         "of the total (upper 95 % bound)")
    shares = press.motor.load_shares
    if shares:
        m = max(range(len(shares)), key=lambda i: shares[i]) + 1
        f = press.motor.heaviest_factor(press.drive.motors)
        return MotorSharing(f, m if f > 1.0 else 0, f"{press.source} [motor] load_shares: motor {m} at {100 * shares[m - 1]:.1f} %")
    return MotorSharing()


_PERIOD = dict(unit="s", limit="min_sample_time_s", what="any press controller's period")


@dataclass(frozen=True)
class PlanningSection:
    """[planning] of a job file (units in the key names)."""

    mode: str = setting("stop-at-top", "", "start at rest at TDC, one turn, stop at rest at TDC, then the transfer dwell "
                        "(\"continuous\": the crank never stops; \"pendulum\": the crank swings through BDC between two "
                        "turning points at or above [planning.transfer] opening_height_m, forward on the working stroke, back on "
                        "the empty return; \"auto\": every mode the job allows, the fastest kept, planning/modes.py)",
                        choices=("stop-at-top", "continuous", "pendulum", "auto"))
    dwell_s: float = setting(0.0, "s", "the transfer's dwell at TDC is the job's own: required in stop-at-top and auto mode "
                             "without [planning.transfer] (which plans the dwell; both are refused), 0 in continuous mode", ge=0.0, unit="s", limit="max_dwell_s",
                             what="any transfer's stop")
    grid_step_deg: float = setting(1.0, "deg", "uniform crank step of toppra's grid; 0.5 deg shortens the door-panel "
                                   "stroke by 0.085 %, 1 deg plans in 0.3 s", gt=0.0, le=5.0, unit="deg",
                                   limit="min_step_deg", what="the crank step any run needs")
    sample_time_s: float = setting(0.002, "s", "profile.csv sample time: a 500 Hz press-controller set-point rate",
                                   gt=0.0, le=0.05, **_PERIOD)
    controller_period_s: float = setting(0.002, "s", "cam_table.csv sample time: the controller's position-loop / cam "
                                         "interpolation period (500 Hz)", gt=0.0, le=0.05, **_PERIOD)


@dataclass(frozen=True)
class TransferSection:
    """[planning.transfer] of a job file: what the part transfer needs of the slide each stroke. A job with this
    table plans its dwell from it (stop-at-top: the dwell at TDC tops the time the moving slide spends above the
    opening up to ``time_s``; pendulum: the same at each turning point); a job without it keeps ``dwell_s``."""

    opening_height_m: float = setting(0.0, "m", "slide height above BDC the transfer needs to move the part in and out "
                                      "(the part's depth plus the fingers' clearance): the job's own, 0 = no requirement",
                                      ge=0.0, unit="m")
    time_s: float = setting(0.0, "s", "time per stroke the slide must be at or above opening_height_m for the transfer "
                            "(its in-die part of the cycle): the job's own, 0 = no requirement", ge=0.0, unit="s",
                            limit="max_dwell_s", what="any transfer's stop")


@dataclass(frozen=True)
class Transfer:
    """The transfer window of a job (SI units): the slide at or above ``opening_height`` (m above BDC) for at least
    ``time`` (s) per stroke."""

    opening_height: float
    time: float


@dataclass(frozen=True)
class LimitsSection:
    """[planning.limits] of a job file."""

    peak_torque_margin: float = setting(0.9, "fraction of T_max", "paper Section 4.3: |T_m| <= 0.9 T_max per motor at "
                                        "every instant (10 % safety margin)", gt=0.0, le=1.0)
    forming_slide_speed_m_s: float = setting(0.30, "m/s", "reference page: slide speed limit in the contact and forming "
                                             "window", gt=0.0, unit="m/s")
    forming_window_above_contact_m: float = setting(0.05, "m", "reference page: the window is H <= H_p + 0.05 m",
                                                    ge=0.0, unit="m")
    forming_window_directions: str = setting("both", "", "the reference page limits the speed by height alone, so the die "
                                             "also opens slowly (\"down\": downstroke only)", choices=("both", "down"))
    crank_jerk_rad_s3: float = setting(330.0, "rad/s^3", "the door-panel stroke's largest crank acceleration (~22 rad/s^2) "
                                       "built up in no less than one period of the linkage's lowest mode (15 Hz): 22 x 15",
                                       gt=0.0, unit="rad/s^3")
    feedback_reserve: float = setting(0.01, "fraction of T_max", "left free below the margin for the feedback's "
                                      "corrections (250 N m per motor; door-panel playbacks need at most ~220 N m)",
                                      ge=0.0, lt=0.5)
    thermal_feedback_reserve: float = setting(0.001, "fraction of T_rated", "of the cycle RMS left free for the "
                                              "feedback's share (a door-panel playback's PD adds ~1e-4)", ge=0.0, lt=0.5)


@dataclass(frozen=True)
class SolverSection:
    """[planning.solver] of a job file."""

    friction_tolerance_s: float = setting(1.0e-6, "s", "the friction fixed point stops when the stroke time changes "
                                          "less than this (far below the 2 ms sampling) ...", gt=0.0, unit="s")
    friction_tolerance_Nm: float = setting(1.0, "N m", "... and the friction torque at the crank less than this "
                                           "anywhere (1e-6 of the crank torque capacity)", gt=0.0, unit="N m")
    friction_max_iterations: int = setting(30, "", "the fixed point converges linearly, 8-9 re-solves on the door "
                                           "panel; 30 flags a non-converging case", ge=1)
    thermal_tolerance: float = setting(1.0e-4, "fraction of T_rated", "the bisection on the peak-torque level stops "
                                       "when the RMS is within this below T_rated", gt=0.0, lt=0.5)
    recheck_tightening: float = setting(0.99999, "", "a full-model re-check above the torque limit scales the level by "
                                        "(limit / peak) x this and re-solves", gt=0.5, le=1.0)
    recheck_max_rounds: int = setting(5, "", "rounds of that tightening before the plan is refused", ge=1)
    optimal_tolerance: float = setting(1.0e-9, "", "IPOPT's relative KKT tolerance of the jerk-limited stroke: the "
                                       "stroke time settles to ~1e-9 s", gt=0.0, lt=1e-3)
    optimal_max_iterations: int = setting(500, "", "IPOPT iterations per solve before the plan falls back to toppra's "
                                          "jerk-free stroke with a WARNING (35-55 needed on the door panel)", ge=1)
    continuous_search_tolerance_rad_s: float = setting(1.0e-4, "rad/s", "golden-section tolerance on the common "
                                                       "start/end crank speed (continuous mode)", gt=0.0, unit="rad/s")


@dataclass(frozen=True)
class PlaybackSection:
    """[playback] of a job file, and [design.playback] (the designed runs' verification): the forward-dynamics
    playback with feed-forward torque + PD on crank angle and speed, its gains from the press's inertia at the crank."""

    bandwidth_Hz: float = setting(3.0, "Hz", "crank-angle loop bandwidth 5x below the linkage's lowest mode (15 Hz, the "
                                  "die-contact ringing), so the rigid-body loop does not excite it", ge=0.0, unit="Hz")
    damping_ratio: float = setting(1.0, "", "critically damped: no overshoot into the die", gt=0.0, unit="")
    time_step_s: float = setting(0.002, "s", "RK4 step = controller period (500 Hz); 2 ms x the fastest closed-loop "
                                 "pole (~35 rad/s) = 0.07, well inside RK4 stability", gt=0.0, le=0.02, **_PERIOD)
    tracking_tolerance_deg: float = setting(0.05, "deg", "largest crank-angle tracking error accepted: ~0.4 mm of slide "
                                            "at die contact", gt=0.0, unit="deg")
    loop_gap_tolerance_m: float = setting(1.0e-6, "m", "largest loop-closure gap accepted, far below bearing clearances "
                                          "(~0.1 mm): a larger gap means the integration drifted", gt=0.0, unit="m")


# the tables this module reads, path -> settings dataclass (press_model/README.md's defaults table lists them)
SECTIONS = {("planning",): PlanningSection, ("planning", "transfer"): TransferSection, ("planning", "limits"): LimitsSection, ("planning", "solver"): SolverSection,
            ("playback",): PlaybackSection, ("planning", "hold"): HoldSection, ("planning", "pause"): PauseSection}


@dataclass(frozen=True)
class PlanningSpec:
    """The [planning], [planning.limits], [planning.solver] and [playback] sections of a job file (SI units)."""

    source: str
    mode: str  # "stop-at-top", "continuous", "pendulum" or "auto" (planning.modes plans each mode the job allows)
    dwell: float  # s, transfer dwell at TDC (stop-at-top only; with a transfer the least dwell, planned up from it)
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
    transfer: Transfer | None = None  # [planning.transfer]; None: none stated (the dwell is dwell_s)
    stops: tuple[StopRequest, ...] = ()  # the stroke's stops on the way ([planning.hold], [planning.pause]; planning.hold)
    # not the job's: how the press's motors share the load (motor_sharing below, from a calibration or the press file)
    sharing: MotorSharing = MotorSharing()

    def torque_limits(self, peak_torque: float) -> TorqueLimits:
        """The plan's peak-torque limits (N m, mean motor torque) on motors of T_max = ``peak_torque`` (N m): ``.verdict``
        margin x T_max, ``.feedforward`` (margin - feedback reserve) x T_max, each over the heaviest motor's factor
        (:attr:`sharing`; 1 for an even load)."""
        return TorqueLimits(peak_torque, self.torque_margin, self.feedback_reserve, self.sharing.factor)

    def rms_limit(self, rated_torque: float) -> float:
        """Cycle RMS the feed-forward is planned to (N m per motor) on a motor of T_rated = ``rated_torque`` (N m):
        (1 - thermal feedback reserve) x T_rated."""
        return (1.0 - self.thermal_reserve) * rated_torque


def read_planning(job: Job) -> PlanningSpec:
    """Validate and read the planning sections of ``job``; a job without [planning] cannot be planned. Absent keys
    take their defaults (:data:`SECTIONS`); the dwell is required in stop-at-top mode."""
    rd = FieldReader(job.source, {k: job.raw[k] for k in ("planning", "playback") if k in job.raw})
    for old in ("kp_Nm_per_rad", "kd_Nm_s_per_rad"):  # a schema-1 file has them dropped by press_model.schema
        if rd.node(("playback", old), required=False) is not None:
            rd.fail(("playback", old), job.raw["playback"][old], "is no longer read: the playback's gains come from the press's own inertia "
                    "at the crank; set playback.bandwidth_Hz and playback.damping_ratio instead (see door_panel.toml)")
    if rd.node(("planning",), required=False) is None:
        rd.fail(("planning",), "<missing>", "a job to plan needs a [planning] section: its mode's default (stop-at-top) "
                "needs the job's own dwell_s or a [planning.transfer] table (opening_height_m, time_s); every other key has a "
                "default (see the shipped door_panel.toml)")
    if "process" not in job.raw:
        rd.fail(("process",), "<missing>", "a job to plan needs a [process] section with contact_height_m, heights_m and forces_N")
    p = ("planning",)
    plan = read_section(rd, p, PlanningSection, skip=("dwell_s",))
    transfer = None
    if rd.node((*p, "transfer"), required=False) is not None:
        tr = read_section(rd, (*p, "transfer"), TransferSection)
        transfer = Transfer(tr.opening_height_m, tr.time_s)
        given = rd.node((*p, "dwell_s"), required=False)
        if given is not None:  # the transfer wins: the dwell is planned from it, so a dwell of its own is refused
            rd.fail((*p, "dwell_s"), given, "is not read beside [planning.transfer]: the dwell is planned from its "
                    "opening_height_m and time_s; remove dwell_s (or the [planning.transfer] table to keep a fixed dwell)")
    dwell_field = PlanningSection.__dataclass_fields__["dwell_s"]
    # a missing dwell (or a pendulum's missing transfer) is refused only after every key was read: a misspelt
    # [planning.transfer] is named as such, not answered with "add dwell_s"
    dwell_missing = (transfer is None and plan.mode in ("stop-at-top", "auto")
                     and rd.node((*p, "dwell_s"), required=False) is None)
    dwell = 0.0 if transfer is not None else rd.number((*p, "dwell_s"), default=dwell_field.default, **dwell_field.metadata["check"])
    if plan.mode == "continuous" and dwell > 0:
        rd.fail((*p, "dwell_s"), dwell, "must be 0 in continuous mode (the dwell is a stop at TDC, stop-at-top only)")
    lim = read_section(rd, ("planning", "limits"), LimitsSection)
    sol = read_section(rd, ("planning", "solver"), SolverSection)
    pb = read_section(rd, ("playback",), PlaybackSection)
    spec = PlanningSpec(
        source=job.source,
        mode=plan.mode,
        dwell=dwell,
        grid_step=math.radians(plan.grid_step_deg),
        sample_time=plan.sample_time_s,
        torque_margin=lim.peak_torque_margin,
        forming_speed=lim.forming_slide_speed_m_s,
        forming_window=lim.forming_window_above_contact_m,
        window_directions=lim.forming_window_directions,
        friction_tolerance=sol.friction_tolerance_s,
        friction_tolerance_torque=sol.friction_tolerance_Nm,
        friction_max_iterations=sol.friction_max_iterations,
        thermal_tolerance=sol.thermal_tolerance,
        recheck_tightening=sol.recheck_tightening,
        recheck_max_rounds=sol.recheck_max_rounds,
        continuous_tolerance=sol.continuous_search_tolerance_rad_s,
        crank_jerk=lim.crank_jerk_rad_s3,
        optimal_tolerance=sol.optimal_tolerance,
        optimal_max_iterations=sol.optimal_max_iterations,
        controller_period=plan.controller_period_s,
        playback_bandwidth=pb.bandwidth_Hz,
        playback_damping=pb.damping_ratio,
        playback_dt=pb.time_step_s,
        tracking_tolerance_deg=pb.tracking_tolerance_deg,
        loop_gap_tolerance=pb.loop_gap_tolerance_m,
        feedback_reserve=lim.feedback_reserve,
        thermal_reserve=lim.thermal_feedback_reserve,
        transfer=transfer,
        stops=read_stops(rd),
    )
    rd.delegate((*p, "cam"))  # the master-position cam's settings: planning.cams.CamSettings reads them
    rd.delegate((*p, "power"))  # the supply limit: planning.power.read_power reads it
    rd.reject_unread(JOB_FORMAT)
    if transfer is None and plan.mode == "pendulum":
        rd.fail((*p, "transfer"), "<missing>", "pendulum mode needs [planning.transfer] with opening_height_m and time_s "
                "(the turning points lie at or above the opening; see the shipped door_panel.toml)")
    if dwell_missing:
        rd.number((*p, "dwell_s"), default=None)  # refused: required, naming the key to add
    return spec
