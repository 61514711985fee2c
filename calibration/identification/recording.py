"""Properties of the recording, not of the press: the torque channel's delay behind the angle channel, the
encoder's zero offset and the lost motion in the gear between the motor's encoder and the crank, estimated with the
parameters and corrected in the log.

A drive's torque channel is often filtered or sent over a bus, so it lags the angle; an encoder zero set a
little off shifts every angle. Both move the measured curve along the crank angle, which the calibrated
parameters then absorb (a 0.5 deg offset moved mu_s by 30 % on a SYNTHETIC log). To first order the measured
curve gains d x (-omega dT/dtheta) from a delay d and delta x (-dT/dtheta) from an offset delta
(:func:`calibration.identification.adequacy.shift_columns`): their sizes are the coefficients of these two columns when the
calibrated model's residual is regressed on them beside the residual Jacobian (:func:`calibration.identification.adequacy.regress`).

The regression reads the log's *bin means* (:attr:`calibration.traces.drive_log.DriveLog.torque_binned`: the mean of every
sample whose angle rounds to a grid point), not the interpolated curve Eq. 28 fits: interpolation reads the two
samples beside a grid point and leaves the other 5 to 15 of a degree at 500 Hz unread, so on the tested points (off
the force steps, where a bin mean smears nothing) the bin means carry a fraction of the noise, and the delay's
standard error halves (0.85 -> 0.35 ms on the two-speed SYNTHETIC logs of scripts/bench_adequacy.py --joint).
That noise, not a bias, was what kept the delay from 1 ms: over 16 noise seeds of a SYNTHETIC log pair with no
delay the first regression on the interpolated curve came out +0.22 +- 0.18 ms (mean +- its standard error; sd 0.74
ms per log), on the bin means +0.04 +- 0.11 ms (sd 0.35 ms). Each bin mean is the torque at its samples' mean
angle, a few hundredths of a degree off the grid point, and is taken there (:func:`bin_angle_correction`): left at
the grid point, those offsets read as +0.14 ms of delay on a noise-free closed-form log with none.

:func:`estimate` iterates: fit, regress, correct the *log* (each torque sample moved to the crank angle of its own
time t - d, the angles less delta; :func:`calibration.traces.drive_log.read_drive_log`), refit locally from the last
estimate (a step
whose corrected log the model fits no better on the tested points is not taken, and the iteration stops; "fits" is
the tested points' residual less its least-squares fit by the parameters' columns, :func:`fit_rms`, not the residual
at Eq. 28's refit, whose peak term follows the corrected log's re-read peak noise), until a
step is below the job's ``stop_standard_errors`` (0.25 shipped) of a standard error (its Mahalanobis length in the estimate's covariance, so that a step
along a poorly determined direction counts for what it is) or the job's iteration limit. The first-order columns only steer the
iteration; each correction itself is exact, so the estimate does not carry their linearisation error. The
correction moves the samples along the angle, it does not read the torque between them: interpolating the torque at
t + d averages two samples' noise (half its variance at half a sample), so a corrected log could fit better for its
smoothing alone, which the "fits no better" test would reward, and the regression saw other noise than the log's.

**Lost motion.** The angle is the motor's encoder over the gear ratio u; with a lost motion b (motor radians) in
the gear the crank lags it by b / (2 u) while the gear torque drives and leads it by as much while it brakes, so the
curve gains sgn(T) x (offset column) / (2 u) per motor radian (:func:`shift_design` with the gear ratio; the score
test's column, :func:`calibration.identification.adequacy.candidate_columns`). Where some log's gear torque reverses
(each sign on at least ``REVERSAL_SHARE`` of the grid) it is estimated as a third column beside the delay and offset
and corrected like them: each torque sample moves half the gap against the sign of the gear torque at the first
fit (:func:`calibration.traces.drive_log.grid_rows`, ``lost_motion``); elsewhere it is an encoder offset. Below the
score test's power (a standard error of about 3 motor deg on the cushion test's log) it was left in the log, and the
parameters absorbed it: psi and m8 came out low, 1 of 8 SYNTHETIC runs at 8 motor deg was outside its joint region
without a warning (seeds 7100-7107). Its uncertainty now widens the intervals like the delay's and offset's
(calibration/identification/run.py, ``_recording_spread``). The residual the three columns are regressed on is the bin means
less the model's own bin means (:func:`bin_smear`): the first-order angle correction (:func:`bin_angle_correction`)
leaves the curvature over a bin, which reads as lost motion where the crank changes speed within a few degrees. A
step along the lost motion that overshoots costs more than it gains (the parameters absorb a lost motion left in the
log better than one corrected twice over), so a step whose corrected log fits no better is halved before it is
given up. A lost motion is a gap, so the correction never goes below zero (a negative estimate is noise; it is
reported, the log is not moved by it).

**The crank motion's error.** The model curve of a log whose crank speed and acceleration come from a speed fit
carries that fit's error (:mod:`calibration.identification.motion_error`), largest at a sharp speed ramp's ends, where
the curve is steep and the shift columns are large. The regression weighs each row by the inverse of its noise's plus
that model variance (:func:`calibration.identification.adequacy.regress`, ``weighted``), and the estimate's covariance
holds both. Unweighted, a two-speed log with noisy angle and speed channels (SYNTHETIC seed 9303, 15-degree ramps) read
its motion error as a +0.12 deg offset, and the joint estimate corrected its partner cushion-test log by it, which
that log's score tests then saw (NOT ADEQUATE, offset t 4.0).
The delay and offset are one per estimate, shared by every log of a joint fit: the logs are taken as recorded through
one drive (the same torque channel filter, the same encoder zero), and that sharing is what lets a second speed
separate the two; logs recorded through another drive or after re-homing the encoder belong to separate fits.

On one motion, omega varies little over the turn and the two columns are nearly proportional: the log then
fixes a combination of delay and offset, not each. The correlation of the two estimates says so (beyond the
job's correlation_limit: "cannot be told apart"); a second log at another speed separates them.
"""
from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from scipy import interpolate, stats

from calibration.identification.adequacy import REVERSAL_SHARE, regress, shift_columns

if TYPE_CHECKING:
    from calibration.identification.settings import CalibrationSettings


@dataclass(frozen=True)
class RecordingEstimate:
    """The estimated channel delay (s) and encoder offset (deg) with their standard errors, intervals and correlation;
    where the gear torque reverses, the lost motion in the gear (motor deg) estimated beside them."""

    channel_delay_s: float
    angle_offset_deg: float
    std: tuple[float, float]  # s, deg
    low: tuple[float, float]
    high: tuple[float, float]
    correlation: float
    separable: bool
    iterations: int
    level: float
    correlation_limit: float
    logs: int = 1  # logs the estimate comes from (several: jointly, the same delay and offset in each)
    corrected: bool = True  # False: the log shows no shift beyond its noise and is fitted as logged
    lost_motion_deg: float | None = None  # motor deg; None: no log's gear torque reverses, so none is estimated
    lost_motion_std_deg: float = 0.0
    lost_motion_interval: tuple[float, float] = (0.0, 0.0)  # motor deg, at ``level``
    covariance: tuple = ()  # of (delay s, offset rad[, lost motion motor rad]), as nested tuples

    def cov(self) -> np.ndarray:
        """(2, 2) or (3, 3): the covariance of (delay s, offset rad[, lost motion motor rad])."""
        if self.covariance:
            return np.array(self.covariance, float)
        sd = np.array([self.std[0], math.radians(self.std[1])])
        return np.outer(sd, sd) * np.array([[1.0, self.correlation], [self.correlation, 1.0]])

    def record(self) -> dict:
        """The ``nuisance`` entry of calibrated.json."""
        lash = {} if self.lost_motion_deg is None else {
            "lost_motion_motor_deg": self.lost_motion_deg}
        out = {
            "channel_delay_s": self.channel_delay_s, "angle_offset_deg": self.angle_offset_deg, **lash,
            "intervals": {"channel_delay_s": list(self.low[:1] + self.high[:1]), "angle_offset_deg": [self.low[1], self.high[1]],
                          **({"lost_motion_motor_deg": list(self.lost_motion_interval)} if lash else {})},
            "standard_errors": {"channel_delay_s": self.std[0], "angle_offset_deg": self.std[1],
                                **({"lost_motion_motor_deg": self.lost_motion_std_deg} if lash else {})},
            "correlation": self.correlation, "separable": self.separable, "iterations": self.iterations, "logs": self.logs,
            "corrected": self.corrected,
            "level": self.level,
            "method": "estimated with the parameters: the residual regressed on the delay and offset columns (and, where the gear "
                      "torque reverses, the lost motion's) beside the residual "
                      "Jacobian, the log corrected (torque read delay later, angles less the offset, each sample moved half the "
                      "lost motion against the gear torque's sign) and the parameters refitted "
                      "locally, until a step is below the job's stop_standard_errors of a standard error (calibration/identification/recording.py); the parameters' "
                      "intervals carry its uncertainty (the calibration refitted on the curve shifted by the shift "
                      "columns one standard deviation either way along each principal axis of their covariance, added in "
                      "quadrature to each half-width; a log not corrected also by the shift as estimated; calibration/identification/run.py)",
        }
        return out

    def statement(self) -> str:
        """One line for people. A shift whose interval holds zero is reported as none beyond the noise, not as a value:
        the log does not carry it (its sign and size are the noise's)."""
        def shown(what, v, lo, hi, fmt, unit):
            iv = f"{100 * self.level:g} % interval {lo:{fmt}} .. {hi:{fmt}} {unit}"
            return f"no {what} beyond its noise ({iv})" if lo <= 0.0 <= hi else f"a {what} of {v:{fmt}} {unit} ({iv})"

        base = (f"recording {'corrected' if self.corrected else 'not corrected (no shift beyond the noise)'}: "
                + shown("torque-channel delay", self.channel_delay_s * 1e3, self.low[0] * 1e3, self.high[0] * 1e3, ".2f", "ms")
                + " and " + shown("encoder offset", self.angle_offset_deg, self.low[1], self.high[1], "+.3f", "deg"))
        if self.lost_motion_deg is not None:
            base += ", " + shown("lost motion in the gear", self.lost_motion_deg, *self.lost_motion_interval, "+.1f", "motor deg")
        if not self.separable:
            where = "on this motion" if self.logs == 1 else f"on these {self.logs} logs' motions"
            base += (f"; {where} delay and offset cannot be told apart (correlation {self.correlation:+.2f}): "
                     + ("their joint shift of the curve is corrected, " if self.corrected else "")
                     + "the split between them is not known (a log at another speed separates them)")
        return base


def shift_design(parts, gear_ratio: float | None = None) -> np.ndarray:
    """The delay and offset columns (n, 2) of one log or several end to end: ``parts`` is a list of (theta rad,
    theta_dot rad/s, model torque N m) per log (:func:`calibration.identification.adequacy.shift_columns` on each);
    with ``gear_ratio``, (n, 3): the lost motion's column beside them, what the curve gains per motor radian of lost
    motion in the gear (sgn(T) x the offset column / (2 u); :func:`calibration.identification.adequacy.candidate_columns`)."""
    cols = []
    for th, thd, T in parts:
        delay, offset = shift_columns(th, thd, T)
        more = [np.sign(T) * offset / (2.0 * gear_ratio)] if gear_ratio is not None else []
        cols.append(np.column_stack([delay, offset, *more]))
    return np.vstack(cols)


def torque_reverses(curves) -> bool:
    """True when some curve (N m, a log's gear torque on its grid) has each sign on at least ``REVERSAL_SHARE`` of
    its points: only there does lost motion differ from an encoder offset (:func:`calibration.identification.adequacy.candidate_columns`)."""
    return any(min(np.mean(np.asarray(T) > 0), np.mean(np.asarray(T) < 0)) >= REVERSAL_SHARE for T in curves)


def measured_curve(parts) -> np.ndarray:
    """The measured curve the estimate regresses on, of one log or several end to end: ``parts`` is a list of (the
    log's bin means of all samples, :attr:`calibration.traces.drive_log.DriveLog.torque_binned`; the interpolated stroke
    mean Eq. 28 fits) per log, the bin means taken where they exist (module docstring)."""
    return np.concatenate([np.where(np.isfinite(b), b, m) if b is not None else np.asarray(m, float) for b, m in parts])


def bin_angle_correction(parts) -> np.ndarray:
    """(n,) rad, of one log or several end to end, to go with :func:`measured_curve`: ``parts`` is a list of (the
    log's bin means, :attr:`calibration.traces.drive_log.DriveLog.torque_binned`; their mean angle less the grid point,
    ``angle_binned_offset``), 0 where the interpolated curve stands in. A bin mean is the torque at its samples' mean
    angle, theta + delta, so measured - model at theta holds -(offset column) x delta of a model without any shift:
    the residual adds (offset column) x delta back (:func:`calibration.identification.adequacy.shift_columns`; the offset column
    is -dT/dtheta). Left in, those few hundredths of a degree read as a delay: +0.14 ms on a noise-free log with
    none (tests/test_recording.py)."""
    return np.concatenate([np.where(np.isfinite(b), d, 0.0) if b is not None and d is not None else np.zeros(np.shape(m))
                           for b, d, m in parts])


def bin_smear(angles: np.ndarray | None, theta: np.ndarray, torque: np.ndarray) -> np.ndarray:
    """(n,) N m: the bin mean of the curve ``torque`` (N m on the uniform periodic grid ``theta`` rad) read at the
    log's torque sample angles ``angles`` (rad, unwrapped; :attr:`calibration.traces.drive_log.DriveLog.torque_angles`)
    and binned as the log's bin means are, less its value at the grid point; 0 where a bin holds no sample, and all 0
    without the angles. A bin mean is the torque averaged over its samples' angles: :func:`bin_angle_correction` takes
    the first order of that, this all of it; the rest (the curvature over the bin, weighted by where the samples fall)
    is what a lost-motion column, a shift that flips with the torque's sign, reads as lost motion where the crank
    changes speed within a few degrees (-1.2 motor deg, 3.9 standard errors, on a noise-free SYNTHETIC two-speed log
    with 15-degree ramps). Between the grid points the curve is Akima's: it reproduces a parabola, and a force step
    moves it no more than two points away (cubic splines ring on)."""
    n = theta.size
    if angles is None:
        return np.zeros(n)
    step = 2.0 * math.pi / n
    pad = 3  # Akima reads two points on each side: the padding makes the curve periodic over the turn
    x = theta[0] + step * np.arange(-pad, n + pad + 1)
    y = np.asarray(torque, float)[np.mod(np.arange(-pad, n + pad + 1), n)]
    curve = interpolate.Akima1DInterpolator(x, y)
    k = np.rint((np.asarray(angles, float) - theta[0]) / step)
    idx = np.mod(k, n).astype(np.int64)
    at = theta[0] + np.mod(np.asarray(angles, float) - theta[0], 2.0 * math.pi)
    count = np.bincount(idx, minlength=n)
    mean = np.bincount(idx, curve(at), minlength=n) / np.maximum(count, 1)
    return np.where(count > 0, mean - torque, 0.0)


def fit_rms(resid: np.ndarray, J: np.ndarray, mask: np.ndarray) -> float:
    """N m: the RMS over ``mask`` of the residual ``resid`` (n,) less its least-squares fit by the parameters' columns
    ``J`` (n, k): how well the log can be fitted near these parameters, whichever point of that neighbourhood Eq. 28
    chose. A corrected log is judged by this, not by the residual at Eq. 28's refit: Eq. 28's peak term reads a measured
    peak that any correction re-reads with other interpolation weights (a fresh draw of its noise, 44 N m lower at 1 ms
    and 2 ms alike on a SYNTHETIC log with a 2 ms delay), and the refit that follows it trades the tested points' fit for
    it (RMS 36.7 -> 38.6 N m at the true delay, 36.0 -> 33.1 with the parameters' fit taken out)."""
    r = np.asarray(resid, float)[mask]
    X = np.asarray(J, float)[mask]
    sc = np.sqrt(np.sum(X ** 2, axis=0))
    X = X[:, sc > 0] / sc[sc > 0]
    e = r - X @ np.linalg.lstsq(X, r, rcond=None)[0] if X.size else r
    return float(np.sqrt(np.mean(e * e)))


def estimate(state: Callable[..., tuple], refit: Callable[[object, np.ndarray], np.ndarray], x0: np.ndarray,
             cs: CalibrationSettings, logs: int = 1, model_variance: np.ndarray | None = None
             ) -> tuple[RecordingEstimate, object, np.ndarray]:
    """The iteration of the module docstring, with the job's [calibration] settings ``cs``: at most
    ``recording.iterations`` corrections, the intervals at ``interval_level``, ``correlation_limit`` for the
    delay-offset correlation, the adequacy ``level`` as the first regression's ``alpha``, ``recording.stop_standard_errors``
    as ``stop`` and ``recording.step_halvings`` as the ``halvings`` 1, 1/2, ... below; ``logs``: how many logs the
    recording's estimate is shared by.

    ``state(delay_s, offset_deg)`` -> (problem, resid_fn, jac_fn, columns_fn, mask) for the log (or logs: delay
    and offset are the recording's, the same in every log) corrected by that much: ``resid_fn(x)`` measured - model
    (n,), ``jac_fn(x)`` (n, k) d(model)/dx, ``columns_fn(x)`` (n, 2) the delay and offset columns at x
    (:func:`shift_design`); ``refit(problem, x)`` the local refit from x. When ``columns_fn`` gives three columns, the
    third is the lost motion's (per motor radian) and ``state(delay_s, offset_deg, lost_motion_motor_deg)`` takes it.
    Returns (the estimate, the problem on the
    finally corrected log, its parameters). The log is corrected only when it shows a shift beyond its noise (the
    Wald statistic of the first regression beyond the chi-square quantile at ``alpha``, as many degrees of freedom
    as columns): a correction by noise
    alone could move a force step across a grid point for nothing; otherwise the estimate is reported, not applied.
    ``stop``: the iteration ends once the shift still seen is below this many standard errors; ``halvings``: the
    fractions of a step tried in turn until the corrected log fits better (the job's ``step_halvings``) (a step that overshoots along the lost
    motion costs more than it gains: the parameters absorb a lost motion left in the log better than one corrected
    twice over, so the fit there is no better although the shift is real). When no correction fits better the
    estimate is that of the first regression, reported as not applied. ``model_variance`` (n,) N m^2: the model
    curve's own variance in each row (the crank motion's error, :mod:`calibration.identification.motion_error`; every
    log's end to end, None: exact), taken in by weighted least squares (:func:`calibration.identification.adequacy.regress`):
    a log whose model curve is uncertain where the curve is steep (a sharp speed ramp's ends) otherwise reads that
    error as a shift and, jointly, corrects every log by it.
    """
    iterations, level, correlation_limit = cs.recording.iterations, cs.interval_level, cs.correlation_limit
    alpha, stop = cs.adequacy.level, cs.recording.stop_standard_errors
    halvings = tuple(0.5 ** i for i in range(cs.recording.step_halvings + 1))
    prob, resid_fn, jac_fn, columns_fn, mask = state(0.0, 0.0)
    x = np.asarray(x0, float)
    m = int(np.asarray(columns_fn(x)).reshape(len(mask), -1).shape[1])
    if m == 3:
        prob, resid_fn, jac_fn, columns_fn, mask = state(0.0, 0.0, 0.0)

    def user(c):  # (delay s, offset deg[, lost motion motor deg]) as ``state`` takes them
        return (float(c[0]), *(math.degrees(float(v)) for v in c[1:]))

    c = np.zeros(m)  # [delay s, offset rad(, lost motion motor rad)] corrected so far
    first = None
    it = 0
    B = np.eye(m)  # d(shift still seen) / d(correction): -1 x this to first order; Broyden-updated from the iterations
    last = None
    seen = None  # (residual, Jacobian) at x on the current log, when the step's check has already computed them
    while True:
        R, J = seen if seen is not None else (resid_fn(x), jac_fn(x))
        b, V, dof = regress(R, J, columns_fn(x), mask, model_variance, weighted=True)
        sd = np.sqrt(np.clip(np.diag(V), 0.0, None))
        if last is not None:  # secant (Broyden) update: the first-order columns misjudge the nearly collinear direction
            dc, db = c - last[0], b - last[1]
            if dc @ dc > 0:
                B = B + np.outer(-db - B @ dc, dc) / (dc @ dc)
        wald = float(b @ np.linalg.pinv(V) @ b)
        if it == 0 and wald < stats.chi2.ppf(1.0 - alpha, m):
            first = (b, V, dof)
            break
        small = wald <= stop ** 2
        if small or it >= iterations:
            break
        step = np.linalg.solve(B, b) if abs(np.linalg.det(B)) > 1e-3 else b
        old = fit_rms(R, J, mask)
        for frac in halvings:  # the full step, then shorter ones: the refit absorbs too short a correction better than too long a one
            c_new = c + frac * step
            if m == 3:  # a lost motion is a gap, never negative: a negative estimate is noise, and the log is not moved by it
                c_new[2] = max(c_new[2], 0.0)
            new = state(*user(c_new))
            x_new = refit(new[0], x)
            seen = (new[1](x_new), new[2](x_new))
            if fit_rms(*seen, new[4]) < old:
                break
        else:
            break  # no corrected log fits better: keep the last correction (a step along a direction the log cannot see)
        last = (c.copy(), b)
        c, x, it = c_new, x_new, it + 1
        prob, resid_fn, jac_fn, columns_fn, mask = new
    if first is None and it == 0:  # the log shows a shift, but no correction of it fits better: reported, not applied
        first = (b, V, dof)
    if first is not None:  # not applied: report what the log shows
        c = np.asarray(first[0], float)
    d_s, o_deg = float(c[0]), math.degrees(float(c[1]))
    q = float(stats.t.ppf(0.5 + level / 2.0, dof))
    sd_s, sd_deg = float(sd[0]), math.degrees(float(sd[1]))
    corr = float(V[0, 1] / (sd[0] * sd[1])) if sd[0] > 0 and sd[1] > 0 else 0.0
    lash = {}
    if m == 3:
        lm, lsd = math.degrees(float(c[2])), math.degrees(float(sd[2]))
        lash = dict(lost_motion_deg=lm, lost_motion_std_deg=lsd, lost_motion_interval=(lm - q * lsd, lm + q * lsd))
    est = RecordingEstimate(d_s, o_deg, (sd_s, sd_deg), (d_s - q * sd_s, o_deg - q * sd_deg), (d_s + q * sd_s, o_deg + q * sd_deg),
                            corr, abs(corr) <= correlation_limit, it, level, correlation_limit, logs, first is None,
                            covariance=tuple(map(tuple, np.asarray(V, float))), **lash)
    return est, prob, x
