"""Effects a real drive log carries and the model does not, for SYNTHETIC logs (``servo-press experiment``).

Every synthetic log of this project is the model's torque plus what the model lacks. Besides the die-contact
ringing and white noise of :mod:`calibration.synthetic.experiment`, these are the effects an identification engineer meets
on a real servo press; each is applied *to the log* (its time, angle and torque channels) by the code below and
never through the model that calibration fits, so a test of the calibration on them is a test on effects the
calibration was not built around:

* ``channel_delay_s``: the torque channel lags the angle channel (filtering, bus latency): the torque logged at
  time t is the physical torque at t - delay.
* ``angle_offset_deg``: the encoder zero is off: the logged crank angle is the true one plus the offset.
* ``efficiency_drop_at_rated``: the gear efficiency falls linearly with load, eta(T) = eta (1 - a |T_m| / T_rated)
  (a per unit of the motor's rated torque): the motors supply T_m eta / eta(T) when they drive and
  T_m eta(T) / eta when they brake.
* ``viscous_loss_of_rms``: a drive loss proportional to motor speed, c omega_m, with c set so that its RMS over
  the log is this fraction of the model torque's RMS.
* ``noise_ar1_rho``: the measurement noise is AR(1) with this lag-one correlation per sample (same marginal
  sigma as the white noise it replaces).
* ``ripple_of_rms`` at ``ripple_order`` per motor turn: a torque ripple sin(order x motor angle + phase) with an
  amplitude of this fraction of the model torque's RMS (phase from the seed).

* ``force_channel_delay_s``: the force column (where [experiment] logs it) lags the angle channel: the force logged
  at time t is the force on the slide at t - delay (a cushion's pressure transducer filtered, a monitor on another bus).
* ``cushion_force_scale``: the true process force is this times the job's (the cushion's force control or the part
  off its nominal; 1 = as the job says): the torque is made with it, the job the calibration reads keeps its own,
  and the log's force column (when [experiment] logs it) holds it.
* ``coulomb_drag_of_rms``: a drag torque of constant magnitude opposing the motor's rotation (bearing and seal
  friction of the motor and gearbox), T_d sgn(omega_m), of this fraction of the model torque's RMS.
* ``backlash_deg``: lost motion in the gear (motor degrees): where the gear torque reverses, the motor turns this far
  with the load disconnected, so the log's torque reads the torque of the crank angle the gear catches up with,
  backlash / u later (the crank lags the motor by half the backlash after each reversal).
* ``backlash_crossing_s``: with ``backlash_deg``, the time the motor takes to cross the gap at each reversal of the
  gear torque (0: at once). The crank then follows the job's motion and the motor leads it by half the gap while the
  gear torque drives (lags while it brakes), crossing from one side to the other at a constant rate over this time:
  the motor speed column carries the crossing (8 motor deg in 20 ms: 67 rpm on top of the motor's speed for 20 ms).
  The torque is the crank's throughout (the motor's own inertia torque while it crosses the gap is not modelled).
* ``angle_from_crank``: 1: the angle channel reads the crank itself (a crank-side encoder, the press controller's crank
  angle), not the motor's encoder through the gear; 0 (default): the motor's, which carries the lost motion. With
  lost motion and this 1 the log's torque sits at the crank's own angle and only the speed column sees the gap.
* ``angle_counts_per_motor_rev``: the angle channel is a motor encoder (or resolver) of this many counts per motor
  revolution, read through the gear: the logged crank angle is the motor's angle rounded to a count, divided by u.
* ``angle_noise_deg``: white noise (RMS, crank deg) on the logged crank angle (a resolver's converter noise).
* ``speed_noise_rpm``: white noise (RMS, motor rpm) on the logged motor speed (the drive's speed estimate, a filtered
  derivative of its encoder).
  The channel noises have their own random streams: the torque's noise stays that of the plain log.
* ``force_reading_scale``: the logged force channel (process_force_N, where [experiment] logs it) reads this times the
  true force (a cushion's pressure transducer or a tonnage monitor calibrated off); the torque is made with the true
  force. 1 = exact.
* ``motor1_share``: the motors do not share the load evenly: motor 1 carries this share of the total torque, the
  others the rest in equal parts, and the log holds one torque column per motor (motor_torque_Nm_1 ... _M) instead of
  their mean. Each channel is its share of the total plus its own white noise of the plain log's sigma, drawn from
  its own stream and made to add to zero over the motors (so the channels' mean is the plain log's torque, noise
  and all): 0 (off) writes the one column of the mean.

All sizes are zero (off; the force scale 1) unless the job's ``[experiment.effects]`` or ``experiment --effect NAME=VALUE`` sets them;
the sidecar of the log records them.
"""
from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import asdict, dataclass

import numpy as np
from scipy.signal import lfilter

from press_io.errors import PressDataError
from press_model.readers import FieldReader

# name -> (lower bound, upper bound, unit, what it is); bounds exclusive above, inclusive below (angle offset: symmetric)
LIMITS = {
    "channel_delay_s": (0.0, 0.1, "s", "delay of the torque channel behind the angle channel"),
    "angle_offset_deg": (-10.0, 10.0, "deg", "encoder zero offset: logged angle minus true angle"),
    "efficiency_drop_at_rated": (0.0, 0.5, "1", "fall of the gear efficiency at the motor's rated torque, linear in |torque|"),
    "viscous_loss_of_rms": (0.0, 0.5, "1", "RMS of a speed-proportional drive loss, as a fraction of the model torque's RMS"),
    "noise_ar1_rho": (0.0, 1.0, "1", "lag-one correlation per sample of AR(1) measurement noise"),
    "ripple_of_rms": (0.0, 0.5, "1", "torque ripple amplitude, as a fraction of the model torque's RMS"),
    "ripple_order": (1.0, 1000.0, "per motor turn", "ripple periods per motor revolution"),
    "force_channel_delay_s": (0.0, 0.1, "s", "delay of the logged process force behind the angle channel"),
    "cushion_force_scale": (0.5, 2.0, "1", "true process force over the job's"),
    "coulomb_drag_of_rms": (0.0, 0.5, "1", "constant-magnitude drag opposing the motor's rotation, as a fraction of the model torque's RMS"),
    "backlash_deg": (0.0, 90.0, "motor deg", "lost motion in the gear where its torque reverses"),
    "backlash_crossing_s": (0.0, 0.5, "s", "time the motor takes to cross the gear's lost motion at each torque reversal"),
    "angle_from_crank": (0.0, 1.5, "1", "1: the angle channel reads the crank, not the motor's encoder through the gear"),
    "angle_counts_per_motor_rev": (0.0, 1.0e9, "counts per motor rev", "resolution of the angle channel's motor encoder (0: exact)"),
    "angle_noise_deg": (0.0, 1.0, "crank deg", "white noise of the logged crank angle, RMS"),
    "speed_noise_rpm": (0.0, 100.0, "motor rpm", "white noise of the logged motor speed, RMS"),
    "force_reading_scale": (0.5, 2.0, "1", "logged process force over the true force (the force channel's scale error; 1: exact)"),
    "motor1_share": (0.0, 1.0, "1", "share of the total torque motor 1 carries, the others the rest evenly, one torque column per motor (0: off)"),
}
_DEFAULT_ON = {"ripple_order", "cushion_force_scale", "force_reading_scale"}  # effects whose default is no zero: on when they differ from it


@dataclass(frozen=True)
class LogEffects:
    """Sizes of the effects of the module docstring (SI except where the name says; 0 = off)."""

    channel_delay_s: float = 0.0
    angle_offset_deg: float = 0.0
    efficiency_drop_at_rated: float = 0.0
    viscous_loss_of_rms: float = 0.0
    noise_ar1_rho: float = 0.0
    ripple_of_rms: float = 0.0
    ripple_order: float = 6.0
    cushion_force_scale: float = 1.0
    force_channel_delay_s: float = 0.0
    coulomb_drag_of_rms: float = 0.0
    backlash_deg: float = 0.0
    backlash_crossing_s: float = 0.0
    angle_from_crank: float = 0.0
    angle_counts_per_motor_rev: float = 0.0
    angle_noise_deg: float = 0.0
    speed_noise_rpm: float = 0.0
    force_reading_scale: float = 1.0
    motor1_share: float = 0.0

    @classmethod
    def from_mapping(cls, raw: Mapping | None, source: str) -> "LogEffects":
        """Read the ``[experiment.effects]`` table (missing keys: off); unknown keys are refused."""
        raw = {} if raw is None else raw
        if not isinstance(raw, Mapping):
            raise PressDataError(source, "experiment.effects", raw, "must be a table of effect sizes")
        rd = FieldReader(source, {"experiment": {"effects": dict(raw)}})
        vals = {}
        for name, (lo, hi, unit, _) in LIMITS.items():
            low = {"ge": lo} if name not in ("angle_offset_deg", "cushion_force_scale", "force_reading_scale") else {"gt": lo}
            vals[name] = rd.number(("experiment", "effects", name), **low, lt=hi, default=getattr(cls(), name), unit=unit)
        rd.reject_unread(f"known effects: {', '.join(LIMITS)}")
        if vals["angle_from_crank"] not in (0.0, 1.0):
            rd.fail(("experiment", "effects", "angle_from_crank"), vals["angle_from_crank"],
                    "must be 0 (the motor's encoder through the gear) or 1 (an encoder on the crank)")
        return cls(**vals)

    @property
    def crank_follows_motion(self) -> bool:
        """True when the crank, not the motor, follows the job's motion through a lost motion (module docstring:
        the gap crossed in a time, or the angle read on the crank)."""
        return bool(self.backlash_deg and (self.backlash_crossing_s or self.angle_from_crank))

    def with_args(self, items: Sequence[str] | None, source: str = "--effect") -> "LogEffects":
        """These effects with ``NAME=VALUE`` items (the CLI's ``--effect``) replacing the named sizes."""
        if not items:
            return self
        raw = {k: v for k, v in asdict(self).items()}
        for item in items:
            name, sep, value = str(item).partition("=")
            name = name.strip()
            if not sep or name not in LIMITS:
                raise PressDataError(source, "--effect", item, f"must be NAME=VALUE with NAME one of {', '.join(LIMITS)}")
            try:
                raw[name] = float(value)
            except ValueError:
                raise PressDataError(source, f"--effect {name}", value, f"must be a number in {LIMITS[name][2]}") from None
        return LogEffects.from_mapping(raw, source)

    @property
    def any(self) -> bool:
        return any(getattr(self, n) != getattr(LogEffects(), n) for n in LIMITS if n != "ripple_order")

    def describe(self) -> dict:
        """The sidecar's record: each effect that is on, with its size, unit and meaning."""
        out = {}
        for name, (_, _, unit, what) in LIMITS.items():
            v = getattr(self, name)
            if name == "ripple_order":
                if self.ripple_of_rms:
                    out[name] = {"value": v, "unit": unit, "what": what}
            elif v != getattr(LogEffects(), name):
                out[name] = {"value": v, "unit": unit, "what": what}
        return out


def load_dependent(torque: np.ndarray, drop_at_rated: float, rated_Nm: float) -> np.ndarray:
    """Motor torque (N m) through a gear whose efficiency falls by ``drop_at_rated`` x |T| / rated (module docstring).

    ``torque``: the model's motor torque with the constant efficiency; positive torque drives (the crank turns forward)."""
    if not drop_at_rated:
        return torque
    f = 1.0 - drop_at_rated * np.abs(torque) / rated_Nm
    if np.any(f <= 0.0):
        raise PressDataError("experiment.effects", "efficiency_drop_at_rated", drop_at_rated,
                             "leaves no efficiency at the log's largest torque; choose a smaller fall")
    return np.where(torque > 0.0, torque / f, torque * f)


def ar1_noise(white: np.ndarray, rho: float) -> np.ndarray:
    """AR(1) noise of the same marginal variance as ``white`` (a stationary start), lag-one correlation ``rho``."""
    if not rho:
        return white
    e = np.empty_like(white)
    e[0] = white[0]  # stationary start: the first value has the marginal variance
    e[1:] = lfilter([math.sqrt(1.0 - rho * rho)], [1.0, -rho], white[1:], zi=[rho * white[0]])[0]
    return e


def motor_side_losses(model_torque: np.ndarray, motor_speed: np.ndarray, motor_angle: np.ndarray, fx: LogEffects,
                      rated_Nm: float, rms_Nm: float, phase: float) -> np.ndarray:
    """The model torque (N m per motor) with the load-dependent efficiency, the viscous loss and the ripple.

    ``motor_speed`` rad/s and ``motor_angle`` rad at the motor shaft; ``rms_Nm`` the model torque's RMS that
    the viscous loss and the ripple are sized against; ``phase`` (rad) of the ripple."""
    T = load_dependent(model_torque, fx.efficiency_drop_at_rated, rated_Nm)
    if fx.viscous_loss_of_rms:
        c = fx.viscous_loss_of_rms * rms_Nm / math.sqrt(float(np.mean(motor_speed ** 2)))
        T = T + c * motor_speed
    if fx.ripple_of_rms:
        T = T + fx.ripple_of_rms * rms_Nm * np.sin(fx.ripple_order * motor_angle + phase)
    if fx.coulomb_drag_of_rms:
        T = T + fx.coulomb_drag_of_rms * rms_Nm * np.sign(motor_speed)
    return T


def logged_angle_speed(angle_deg: np.ndarray, speed_rpm: np.ndarray, gear_ratio: float, fx: LogEffects,
                       seed: int) -> tuple[np.ndarray, np.ndarray]:
    """(crank deg, motor rpm): the angle channel ``angle_deg`` (crank deg, unwrapped) and the speed column ``speed_rpm``
    as the drive logs them under ``fx``'s channel noises (module docstring): the angle rounded to a count of the motor
    encoder of ``gear_ratio`` u, then white angle noise; white speed noise. Streams [seed, 3] and [seed, 4]."""
    a, w = np.asarray(angle_deg, float), np.asarray(speed_rpm, float)
    if fx.angle_counts_per_motor_rev:
        count_deg = 360.0 / (fx.angle_counts_per_motor_rev * gear_ratio)  # one count in crank deg
        a = np.round(a / count_deg) * count_deg
    if fx.angle_noise_deg:
        a = a + np.random.default_rng([seed, 3]).normal(0.0, fx.angle_noise_deg, a.shape)
    if fx.speed_noise_rpm:
        w = w + np.random.default_rng([seed, 4]).normal(0.0, fx.speed_noise_rpm, w.shape)
    return a, w


def backlash_lag(torque: np.ndarray, theta: np.ndarray, backlash_rad_crank: float) -> np.ndarray:
    """rad: how far the crank lags its rigid position at each sample (crank angles ``theta`` unwrapped, rising), for a
    gear of ``backlash_rad_crank`` lost motion (crank side) whose torque ``torque`` (the model's, N m) changes sign:
    after each reversal the motor crosses the gap while the crank is left behind, half the backlash either way of
    the centre (a lag that steps by the backlash at each reversal, +half while driving, -half while braking)."""
    if not backlash_rad_crank:
        return np.zeros_like(theta)
    return 0.5 * backlash_rad_crank * np.sign(torque)


def gap_lead(t: np.ndarray, sign_at, gap_rad_crank: float, crossing_s: float) -> tuple[np.ndarray, np.ndarray]:
    """(rad, rad/s): how far the motor leads the crank (crank side) at the times ``t`` (s), and the lead's rate, for a
    gear of ``gap_rad_crank`` lost motion (crank side) whose torque's sign at given times is ``sign_at(times)``: half
    the gap the gear torque's way, crossed at a constant rate over ``crossing_s`` after each reversal (the mean of the
    sign over the last ``crossing_s``; 0: at once, no rate)."""
    t = np.asarray(t, float)
    half = 0.5 * gap_rad_crank
    if crossing_s <= 0.0:
        return half * sign_at(t), np.zeros_like(t)
    step = crossing_s / 50.0  # the sign's integral to a fiftieth of the crossing: the lead to 2 % of the gap at worst
    fine = np.arange(t.min() - crossing_s - step, t.max() + 2.0 * step, step)
    s = sign_at(fine)
    integral = np.concatenate(([0.0], np.cumsum(0.5 * (s[1:] + s[:-1]) * step)))
    lead = half * (np.interp(t, fine, integral) - np.interp(t - crossing_s, fine, integral)) / crossing_s
    return lead, half * (sign_at(t) - sign_at(t - crossing_s)) / crossing_s


def motor_channels(torque: np.ndarray, motors: int, motor1_share: float, sigma: float, seed: int) -> np.ndarray:
    """(motors, n) each motor's torque channel (N m) of the log whose torque per motor (their mean) is ``torque`` (n,):
    motor 1 carries ``motor1_share`` of the total, the others the rest evenly, each with white noise of ``sigma`` N m
    (stream [seed, 4]) less the motors' mean noise, so that the channels' mean is ``torque`` (module docstring)."""
    if motors < 2:
        raise PressDataError("experiment.effects", "motor1_share", motor1_share, f"needs a press of two motors or more "
                             f"(this one has {motors}): leave it 0")
    shares = np.array([motor1_share] + [(1.0 - motor1_share) / (motors - 1)] * (motors - 1))
    noise = np.random.default_rng([seed, 4]).normal(0.0, sigma, size=(motors, torque.size))
    return motors * shares[:, None] * torque[None, :] + noise - noise.mean(axis=0)
