"""The synthetic calibration experiment: a servo-drive log made from the model with a chosen truth.

The paper's measured torque is not published, so ``servo-press experiment`` writes the drive log that
the servo-cushion experiment of Section 4.1 would give on a press whose parameters are the *truth*
(the job's [experiment.truth], Table 4 of the paper by default): the model's motor torque plus the
effects the model does not contain (a damped oscillation at die contact and white noise), sampled in
time over several strokes. The log says in its header that it is synthetic; the truth and the seed go
in a sidecar ``<log>.truth.json`` that nothing in calibration reads. Optional further effects of a real log
(channel delay, encoder offset, load-dependent efficiency, viscous loss, AR(1) noise, ripple) are applied to
the log's channels by :mod:`calibration.synthetic.effects`, never through the model. Where the job has a process force the
log also carries it (``process_force_N``: the true force on the slide, the truth's cushion force, plus white noise), as a
servo die cushion or a tonnage monitor logs it, unless [experiment] ``process_force_logged = false``.
"""
from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from press_model.disk_cache import array_digest, cached_arrays, press_key
from press_io.errors import PressDataError
from press_model.forces import ProcessForce
from press_io.interrupts import deferred
from press_model.jobs import JOB_FORMAT, Job, load_job, make_motion
from press_model.kinematic_tables import force_steps, geometry_key, grid_states, heights_table, step_grid
from press_model.cycle import motor_torque_of_states
from press_model.model import PressModel
from press_io.outputs import versions, write_json
from press_model.params import apply_overrides, read_overrides
from press_model.press_data import PressData, is_reference_press
from press_model.readers import FieldReader
from press_model.settings_fields import read_section, setting

from calibration.traces.drive_log import write_drive_log
from calibration.synthetic.effects import (LogEffects, ar1_noise, backlash_lag, gap_lead, logged_angle_speed, motor_channels,
                                               motor_side_losses)

_ONE_SIDED = 1e-9  # rad: evaluate the model just before / after a force step


_TORQUE = dict(unit="N m", limit="max_motor_torque_Nm", what="any servo motor's torque")
_RECORDER = dict(limit="max_sample_rate_Hz", what="any drive's recorder")


def _logged_strokes(rd: FieldReader, path: tuple, default: int) -> int:
    """The strokes of a synthetic log: a whole number from 2 (what `calibrate` needs) to max_logged_strokes."""
    n = rd.integer(path, default=default, limit="max_logged_strokes", what="what a calibration needs")
    if n < 2:
        rd.fail(path, n, "must be at least 2: `calibrate` judges the model against the stroke-to-stroke noise and "
                "refuses a log of one stroke; log 2 strokes or more (3 by default)")
    return n


@dataclass(frozen=True)
class ExperimentSection:
    """The plain keys of a job's [experiment] (all per motor); its [experiment.truth] is the job's own, [experiment.effects]
    :class:`calibration.effects.LogEffects`."""

    sample_rate_Hz: float = setting(500.0, "Hz", "a typical servo-drive trace rate", gt=0.0, unit="Hz", **_RECORDER)
    # at least 2: `calibrate` judges the model against the stroke-to-stroke noise, which needs two whole strokes (it
    # refuses a one-stroke log); at most max_logged_strokes (run_limits.toml: the log's size in memory and time)
    strokes: int = setting(3, "", "three consecutive strokes", read=lambda rd, path, default: _logged_strokes(rd, path, default))
    noise_sigma_Nm: float = setting(150.0, "N m", "white measurement noise (the reference press's drive)", ge=0.0, **_TORQUE)
    contact_oscillation_Nm: float = setting(3000.0, "N m", "amplitude of the damped ringing at die contact (the reference "
                                            "press's)", ge=0.0, **_TORQUE)
    contact_oscillation_decay_s: float = setting(0.03, "s", "the ringing's decay time", gt=0.0, unit="s")
    contact_oscillation_frequency_Hz: float = setting(15.0, "Hz", "the ringing's frequency: the linkage's lowest mode",
                                                      gt=0.0, unit="Hz", **_RECORDER)
    model_step_deg: float = setting(0.25, "deg", "crank step of the model curve the samples are interpolated from "
                                    "(error < 0.1 N m, far below the noise)", gt=0.0, le=5.0, unit="deg",
                                    limit="min_step_deg", what="the crank step any run needs")
    process_force_logged: bool = setting(True, "", "a servo die cushion (its force control) or a tonnage monitor logs the "
                                         "force on the slide beside the drive's channels: the log gets process_force_N "
                                         "wherever the job has a process force")
    process_force_noise_of_peak: float = setting(0.005, "1", "RMS noise of that force channel per sample over its peak: "
                                                 "a pressure- or strain-derived force channel reads to about 0.5 % of its "
                                                 "full scale (transducer noise and the oil's pressure ripple)",
                                                 ge=0.0, lt=0.5, unit="1")


@dataclass(frozen=True)
class ExperimentSettings:
    """The [experiment] table of a job file (SI units)."""

    sample_rate: float  # Hz
    strokes: int
    noise_sigma: float  # N m per motor
    oscillation: float  # N m per motor
    decay: float  # s
    frequency: float  # Hz
    model_step: float  # rad
    truth: dict  # parameter name -> value
    effects: LogEffects = LogEffects()  # the optional [experiment.effects] (all off by default)
    force_logged: bool = True  # the log gets process_force_N where the job has a process force
    force_noise_of_peak: float = 0.005  # 1: that column's white noise, RMS over the force's peak

    @classmethod
    def from_job(cls, job: Job) -> "ExperimentSettings":
        """The job's [experiment] settings: absent keys take :class:`ExperimentSection`'s defaults; [experiment.truth] is required."""
        rd = FieldReader(job.source, {"experiment": job.raw.get("experiment")})
        e = ("experiment",)
        if job.raw.get("experiment") is None:
            rd.fail(e, None, "is missing: a job needs an [experiment] table to make a synthetic drive log (see cushion_test.toml)")
        truth_table = rd.table((*e, "truth"))
        effects_table = rd.table((*e, "effects"), required=False)
        x = read_section(rd, e, ExperimentSection)
        s = cls(
            sample_rate=x.sample_rate_Hz,
            strokes=x.strokes,
            noise_sigma=x.noise_sigma_Nm,
            oscillation=x.contact_oscillation_Nm,
            decay=x.contact_oscillation_decay_s,
            frequency=x.contact_oscillation_frequency_Hz,
            model_step=math.radians(x.model_step_deg),
            truth={k: rd.number((*e, "truth", k)) for k in truth_table},
            effects=LogEffects.from_mapping(effects_table, job.source),
            force_logged=x.process_force_logged,
            force_noise_of_peak=x.process_force_noise_of_peak,
        )
        rd.seen.update((*e, "effects", k) for k in effects_table)  # read and checked by LogEffects.from_mapping
        rd.reject_unread(JOB_FORMAT)
        return s


FORCE_CHANNEL = {"process_force_logged": "force_logged", "process_force_noise_of_peak": "force_noise_of_peak"}  # [experiment] key -> field


def with_log_effects(settings: ExperimentSettings, items: Mapping) -> ExperimentSettings:
    """``settings`` with the effects of ``items`` (name -> size, :mod:`calibration.synthetic.effects`) in place of its
    own, and the force channel's [experiment] keys (``process_force_logged``, ``process_force_noise_of_peak``) where
    ``items`` names them (the checks' tables of effects: a log without the column says so)."""
    items = dict(items)
    force = {field: items.pop(key) for key, field in FORCE_CHANNEL.items() if key in items}
    if "force_logged" in force:
        force["force_logged"] = bool(force["force_logged"])
    return dataclasses.replace(settings, effects=LogEffects(**items), **force)


def experiment_truth(press: PressData, job: Job, truth: str | None) -> dict:
    """The true parameter values (SI units) of a synthetic log: ``truth`` (--truth, JSON text or file), else the
    job's [experiment.truth], checked against ``press`` (a job's truth written for another press is refused, saying so)."""
    if truth is not None:
        return read_overrides(truth, press, "--truth")
    values = ExperimentSettings.from_job(job).truth
    try:
        apply_overrides(press, values, "truth")
    except PressDataError as exc:  # the job's truth was written for another press: say where it comes from
        raise PressDataError(f"{job.source} [experiment.truth]", exc.field, exc.value,
                             f"{exc.expected} of the press {press.name}; give --truth with values for this press "
                             "(JSON, SI units) or a job whose [experiment.truth] fits it") from None
    return values


def reference_truth_note(press: PressData, job: Job, truth: str | None, values: dict) -> str | None:
    """A note when a press other than the reference takes, from its job's [experiment.truth] (no --truth), values that
    are the shipped cushion test's, the reference press's calibrated ones (the paper's Table 4): copied with the job,
    they are the SYNTHETIC log's truth although they describe the paper's press, not this one. Names each with this
    press's own value and the difference in %. None: --truth given, the reference press, or no such value."""
    if truth is not None or is_reference_press(press.fingerprint):
        return None
    shipped = ExperimentSettings.from_job(load_job("cushion-test")).truth
    own = press.parameter_values()
    same = [n for n, v in values.items() if n in shipped and shipped[n] == v and n in own]
    if not same:
        return None
    unit = {n: f" {press.parameters[n].unit}" if press.parameters[n].unit not in ("", "-", "1") else "" for n in same}
    what = ", ".join(f"{n} = {values[n]:,.6g}{unit[n]} (this press: {own[n]:,.6g}{unit[n]}"
                     + (f", {100.0 * (values[n] / own[n] - 1.0):+.1f} %)" if own[n] else ")") for n in same)
    return (f"NOTE: {job.source} [experiment.truth] holds the reference press's calibrated values (the paper's Table 4, as shipped "
            f"in cushion_test.toml) for {what}: the SYNTHETIC log is made with them as written, not with {press.name}'s own; "
            "set [experiment.truth] (or --truth) to the values you want the log's press to have")


def theta_of_time(motion, t: np.ndarray) -> np.ndarray:
    """Unwrapped crank angle (rad) at times t (s) since theta = 0, by Newton on the motion's t(theta)."""
    t = np.asarray(t, dtype=float)
    period = motion.period
    turns = np.floor(t / period)
    tr = t - turns * period
    th = 2.0 * math.pi * tr / period
    for _ in range(50):
        step = (motion.time(th) - tr) * motion.theta_dot(th)
        th = np.clip(th - step, 0.0, 2.0 * math.pi)
        if np.max(np.abs(step)) < 1e-13:
            break
    return th + 2.0 * math.pi * turns


def torque_table(pm: PressModel, motion, process: ProcessForce, step: float,
                 geometry: dict | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Model motor torque (N m per motor) on a crank grid of ``step`` rad over [0, 2 pi], with one-sided
    values at each force step, so that linear interpolation never smears a step across a grid cell. ``geometry``:
    :func:`press_model.kinematic_tables.geometry_key` of ``pm`` where the caller has it."""
    geometry = geometry or geometry_key(pm)
    theta = step_grid(int(math.ceil(2.0 * math.pi / step)), force_steps(pm, geometry, process), _ONE_SIDED)
    td, tdd = np.asarray(motion.theta_dot(theta), dtype=float), np.asarray(motion.theta_ddot(theta), dtype=float)

    def table() -> dict:
        # the per-point model on kinematics kept by the press geometry: a new truth reruns only the inverse dynamics
        return {"torque": motor_torque_of_states(pm, process, grid_states(pm, geometry, theta, td, tdd))}

    if type(process) is not ProcessForce:  # its repr is its data only for the plain class
        return theta, table()["torque"]
    # the same arrays every run (the per-point path, ~1.2 s of CPU for a 0.25 deg grid): kept on disk by the press data
    # (truth included), the code, the grid with its speeds and the process force
    key = {**press_key(pm.press), "grid": [array_digest(theta), array_digest(td), array_digest(tdd)], "process": repr(process)}
    return theta, np.array(cached_arrays("torque", key, ("torque",), table)["torque"])


def _logged_force(pm: PressModel, geometry: dict, process: ProcessForce, theta: np.ndarray, noise_of_peak: float,
                  seed: int) -> tuple[np.ndarray, float]:
    """(N, N): the true process force at the crank angles ``theta`` (rad, wrapped) with white noise of ``noise_of_peak`` times
    its peak (an own random stream: the torque's noise stays that of the plain log). Heights on a 0.5-deg grid with
    one-sided points at the force steps, linear between them (error far below a micrometre), the force of Eq. 14 at them;
    and the noise's standard deviation. ``geometry``: :func:`press_model.kinematic_tables.geometry_key` of ``pm``."""
    th = step_grid(720, force_steps(pm, geometry, process), _ONE_SIDED)
    h, hd = heights_table(pm, geometry, th)
    f = np.asarray(process(np.interp(theta, th, h), np.interp(theta, th, hd)), dtype=float)
    peak = float(np.max(np.abs(f))) if f.size else 0.0
    return f + np.random.default_rng([seed, 2]).normal(0.0, noise_of_peak * peak, size=f.shape), noise_of_peak * peak


def synthetic_log(press: PressData, job: Job, truth: dict, seed: int, settings: ExperimentSettings | None = None) -> dict:
    """Columns of the synthetic drive log (time_s, crank_angle_deg, motor_speed_rpm, motor_torque_Nm, and process_force_N
    where the job has a process force and [experiment] process_force_logged) and its provenance. ``truth`` overrides the press's parameters (names of the press file, SI units)."""
    settings = settings or ExperimentSettings.from_job(job)
    if job.motion is None:
        raise PressDataError(job.source, "[motion]", None, "is missing: the experiment needs the job's crank motion")
    true_press = apply_overrides(press, truth, "truth")
    pm = PressModel(true_press)
    motion = make_motion(job.motion, job.source)
    fx = settings.effects
    process = job.process  # the true force: the job's times the cushion's scale (effects.py)
    if fx.cushion_force_scale != 1.0:
        process = dataclasses.replace(process, forces=tuple(fx.cushion_force_scale * f for f in process.forces))
    geometry = geometry_key(pm)  # the key of the kinematics kept on disk, made once per log
    grid, table = torque_table(pm, motion, process, settings.model_step, geometry)

    t = np.arange(int(math.floor(settings.strokes * motion.period * settings.sample_rate)) + 1) / settings.sample_rate
    u = press.drive.gear_ratio
    rng = np.random.default_rng(seed)
    white = rng.normal(0.0, settings.noise_sigma, size=t.shape)
    phase = float(np.random.default_rng([seed, 1]).uniform(0.0, 2.0 * math.pi))  # own stream: the noise stays that of the plain log
    steps = force_steps(pm, geometry, job.process)
    rms = None

    def physical(tt):
        """The torque per motor (N m) the drive delivers at times tt: model, motor-side losses, die-contact ringing."""
        nonlocal rms
        th = theta_of_time(motion, tt)
        wrapped_t = np.mod(th, 2.0 * math.pi)
        torque = np.interp(wrapped_t, grid, table)
        if fx.backlash_deg and not fx.crank_follows_motion:  # the angle is the motor's (its encoder / u); the crank lags it by half the gap the gear torque's way
            wrapped_t = np.mod(th - backlash_lag(torque, th, math.radians(fx.backlash_deg) / u), 2.0 * math.pi)
            torque = np.interp(wrapped_t, grid, table)
        if rms is None:
            rms = math.sqrt(float(np.mean(torque ** 2)))  # sized on the undelayed samples, the same for every call
        torque = motor_side_losses(torque, motion.theta_dot(wrapped_t) * u, th * u, fx, press.motor.rated_torque, rms, phase)
        if steps:  # unmodelled: ringing after each die contact
            contact = steps[0]
            t_contact = np.sort(motion.time(contact + 2.0 * math.pi * np.arange(-1, settings.strokes + 2)))
            # time since the latest contact at or before each sample, by a sorted search: memory grows with the log,
            # not with samples x strokes (a full difference table took 23.5 GB at 760 strokes)
            last = np.searchsorted(t_contact, tt, side="right") - 1
            since = np.where(last >= 0, tt - t_contact[np.maximum(last, 0)], np.inf)
            ring = np.where(np.isfinite(since), settings.oscillation * np.exp(-since / settings.decay)
                            * np.sin(2.0 * math.pi * settings.frequency * np.where(np.isfinite(since), since, 0.0)), 0.0)
            torque = torque + ring
        return torque

    physical(t)  # fixes the RMS the losses are sized against on the log's own samples
    torque = physical(t - fx.channel_delay_s) if fx.channel_delay_s else physical(t)
    torque = torque + ar1_noise(white, fx.noise_ar1_rho)
    theta = theta_of_time(motion, t)
    wrapped = np.mod(theta, 2.0 * math.pi)
    crank_rate, read = motion.theta_dot(wrapped), wrapped  # read: the angle the angle channel reads, rad
    if fx.crank_follows_motion:  # the motor leads the crank by half the gap and crosses it at each reversal (effects.py)
        lead, rate = gap_lead(t, lambda tt: np.sign(np.interp(np.mod(theta_of_time(motion, tt), 2.0 * math.pi), grid, table)),
                              math.radians(fx.backlash_deg) / u, fx.backlash_crossing_s)
        crank_rate = crank_rate + rate  # the motor speed column is the motor's
        if not fx.angle_from_crank:
            read = wrapped + lead  # the motor's encoder through the gear
    speed_rpm = crank_rate * u * 60.0 / (2.0 * math.pi)
    angle_deg = np.degrees(read) + fx.angle_offset_deg  # the encoder's reading (write_drive_log wraps it)
    angle_deg, speed_rpm = logged_angle_speed(angle_deg, speed_rpm, u, fx, seed)
    if fx.motor1_share:  # one column per motor, their mean the torque per motor (effects.py)
        torque = motor_channels(torque, press.drive.motors, fx.motor1_share, settings.noise_sigma, seed)
    columns = {"time_s": t, "crank_angle_deg": angle_deg, "motor_speed_rpm": speed_rpm, "motor_torque_Nm": torque}
    force_sigma = None
    if settings.force_logged and any(f != 0.0 for f in process.forces):  # the cushion's (or tonnage monitor's) channel
        at = np.mod(theta_of_time(motion, t - fx.force_channel_delay_s), 2.0 * math.pi) if fx.force_channel_delay_s else wrapped
        columns["process_force_N"], force_sigma = _logged_force(pm, geometry, process, at, settings.force_noise_of_peak, seed)
        columns["process_force_N"] = fx.force_reading_scale * columns["process_force_N"]  # a channel reading high or low
    provenance = {
        "synthetic": True,
        "what": "synthetic servo-drive log of the servo-cushion calibration experiment (NOT measured data)",
        "seed": seed,
        "truth": dict(truth),
        "all_parameters_true": true_press.parameter_values(),
        **press.identity(),
        "job": job.name,
        "job_source": job.source,
        "effects": {
            "contact_oscillation": f"{settings.oscillation:g} * exp(-t'/{settings.decay:g} s) * sin(2 pi {settings.frequency:g} Hz t') N m per motor, t' = time since die contact",
            "noise_sigma_Nm": settings.noise_sigma,
            **({"log_effects": fx.describe()} if fx.any else {}),
            "process_force_logged": force_sigma is not None,  # the column process_force_N: the true force plus white noise
            **({"process_force_noise_sigma_N": force_sigma,
                "process_force_true_scale_to_job": fx.cushion_force_scale} if force_sigma is not None else {}),
            "sample_rate_Hz": settings.sample_rate,
            "strokes": settings.strokes,
        },
        "versions": versions(),
    }
    return {"columns": columns, "provenance": provenance}


SYNTHETIC_HEADER = "SYNTHETIC servo-drive log made by `servo-press experiment` (not measured data)"  # first line of every log


def truth_path(log_path: Path) -> Path:
    """The sidecar that holds a synthetic log's truth and seed: ``<log>.truth.json``."""
    log_path = Path(log_path)
    return log_path.with_name(log_path.name + ".truth.json") if log_path.suffix != ".csv" else log_path.with_suffix(".truth.json")


def write_experiment(press: PressData, job: Job, truth: dict, seed: int, out: Path,
                     extra_comments: tuple[str, ...] = (), extra_provenance: dict | None = None,
                     settings: ExperimentSettings | None = None, effects: Sequence[str] | None = None) -> dict:
    """Write the synthetic log to ``out`` and its truth to the sidecar; returns the provenance.

    ``extra_comments`` go in the log's header after the standard ones (e.g. ``recorded: <date>``),
    ``extra_provenance`` into the sidecar (e.g. the fleet's drift schedule); ``effects``: ``NAME=VALUE`` items
    (``experiment --effect``) replacing the job's [experiment.effects] (:mod:`calibration.synthetic.effects`)."""
    out = Path(out)
    if effects:
        settings = settings or ExperimentSettings.from_job(job)
        settings = dataclasses.replace(settings, effects=settings.effects.with_args(effects))
    res = synthetic_log(press, job, truth, seed, settings)
    c, prov = res["columns"], res["provenance"]
    prov.update(extra_provenance or {})
    comments = [
        SYNTHETIC_HEADER,
        f"seed {seed}; truth and seed in {truth_path(out).name}; press: {press.name}; job: {job.name}",
        "effects not in the model: " + prov["effects"]["contact_oscillation"] + f"; white noise sigma {prov['effects']['noise_sigma_Nm']:g} N m",
        *([("SYNTHETIC log effects (applied to the log, not in the model): "
            + "; ".join(f"{k} = {v['value']:g} {v['unit']}" for k, v in prov["effects"]["log_effects"].items()))]
          if "log_effects" in prov["effects"] else []),
        *([f"process_force_N: the true force on the slide (SYNTHETIC) with white noise sigma "
            f"{prov['effects']['process_force_noise_sigma_N']:g} N"] if prov["effects"]["process_force_logged"] else []),
        *extra_comments,
    ]
    out.parent.mkdir(parents=True, exist_ok=True)
    with deferred():  # the log and its truth as a pair: a Ctrl-C or SIGTERM between them is raised after both
        write_drive_log(out, c["time_s"], c["crank_angle_deg"], c["motor_speed_rpm"], c["motor_torque_Nm"], comments,
                        process_force_N=c.get("process_force_N"))
        write_json(truth_path(out), prov)
    return prov


def refuse_foreign_log(out: Path) -> None:
    """Refuse to replace an existing file that is not a synthetic log of `servo-press experiment` (a measured log!)."""
    from press_io.errors import ServoPressError, one_line

    try:
        with open(out, encoding="utf-8", errors="replace") as f:
            first = f.readline()
    except (FileNotFoundError, IsADirectoryError, NotADirectoryError):
        return
    except OSError:
        return  # the write reports the system's reason
    if not first.startswith(f"# {SYNTHETIC_HEADER}"):
        raise ServoPressError(f"--out {one_line(out)}: exists and is not a synthetic log of `servo-press experiment` (it may be a "
                              "measured log): choose another output path; only an earlier synthetic log is replaced")
