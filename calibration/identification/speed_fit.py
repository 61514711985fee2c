"""The crank motion of a drive log: its speed and acceleration by local polynomial fits of the logged speed samples,
each window as wide as the log's own speed noise allows (or, with ``speed_harmonics`` = N, a Fourier series).

The model needs the crank speed and acceleration at every grid point; the acceleration is the speed's derivative
(theta_ddot = theta_dot d(theta_dot)/d(theta)), so the speed is fitted smoothly rather than differentiated point to
point. A Fourier series in crank angle (:class:`press_model.motion.FourierSpeed`) cannot do it where a motion
changes its acceleration abruptly (the ends of a speed ramp): on a 1-degree grid even 178 harmonics left a two-speed
motion with 15-degree ramps an acceleration error of 3.7 % of its peak there, which called clean SYNTHETIC logs NOT
ADEQUATE (F up to 1.37; with the generator's own speed and acceleration F = 1.01-1.15). The grid's speed does not
say where between two points a kink lies; the log's samples (500 Hz, 0.07-0.23 degree apart) do.

The local fit (:func:`local_speed`, :class:`LocalSpeed`): at every grid point a polynomial in crank angle is fitted by
least squares to the speed samples of all strokes within a window of half-width h; its value is the speed, its slope
d(theta_dot)/d(theta). h comes from the log: the narrowest window holds samples at ``window_min_samples`` distinct
angles (closer than ``duplicate_step_fraction`` of a sampling step they count once), each wider one ``window_ratio``
times wider, and the window stops growing where its slope leaves what the narrower ones allow (Katkovnik's
intersection of confidence intervals, ICI: the largest window whose slope interval, +- Gamma standard errors, still
meets every narrower one's). The standard errors come from the speed samples' own white noise, estimated from their
third differences in time (:func:`speed_noise`); Gamma is the normal quantile at the adequacy level shared
(Bonferroni) among the grid points and windows tested, so that noise alone stops a window early at some grid point
in at most that fraction of logs. Where the speed is smooth the window widens and averages the noise; where it bends
it stays as narrow as the noise lets it; an exact speed keeps the narrowest window everywhere.
The rule chooses the window, not the estimate in it: the speed and slope are those of a local polynomial of
``estimate_degree`` (3) over the chosen window. The rule stops a window only where its quadratic's slope has left
the narrower windows' intervals of +- Gamma standard errors, so the quadratic's bias there is many of its own
standard errors (with Gamma 4.9 and the sqrt(2) ladder about 26 where the speed is smooth: bias h^2, error h^-1.5).
That bias is one-signed, it rounds off every acceleration peak, and the model reads it as too much inertia: on
SYNTHETIC two-speed logs with 15-degree ramps, 1 motor rpm of speed noise and a 12-bit resolver, the quadratic's
acceleration was 2.4-2.8 % short along the true one and J_gear came out 3-4 % high (with an exact speed column the
windows stay narrow and the bias vanishes; the angle channel's noise was no part of it: the same fit at the true
angles gave the same). In a symmetric window the leading term of that bias is the speed's third derivative, which
the cubic holds: its slope is the quadratic's less that term's estimate, at 2.5 times the standard error. What is
left is where the speed's curvature jumps (a ramp's ends), a bias proportional to h that no polynomial holds: 0.1-0.3
% of the acceleration along the true one on those logs. Which samples: the
motor speed column's, at the angle both channels give (:func:`joint_angle`: a resolver's count and noise on the angle
channel would otherwise move each speed sample along a ramp), or the angle channel's differences when they are the
less noisy (:func:`speed_source`); where the speed column's rotation disagrees with the angle channel's beyond their
noise (:func:`channel_disagreement`: a spike where the motor crosses a gear's lost motion, a filtered speed) its samples
there are set aside, or, where the disagreement is not local, the angle channel gives the crank motion.
Between the grid points the speed is the cubic Hermite interpolant of the fitted values and slopes. Each point's fit
states its own error (:func:`fit_error`: the noise's covariance and the chosen window's estimated bias), which the
lack-of-fit test and the intervals take in (:mod:`calibration.identification.motion_error`).

A log without its samples (a DriveLog made otherwise) falls back to a Fourier series of as many harmonics as its
speed spectrum carries above its stroke-to-stroke noise (:func:`chosen_harmonics`).
What the local fit assumes: white speed noise (a drive's low-pass filtered speed has correlated samples, whose
third differences understate the noise; the windows then stay narrower than they could).
"""
from __future__ import annotations

import hashlib
import math
from dataclasses import dataclass

import numpy as np
from scipy import stats
from scipy.interpolate import CubicHermiteSpline

from press_model.motion import FourierSpeed

_TWO_PI = 2.0 * math.pi
_FIRST_LEVELS = 6  # windows tried before the samples farther out are fetched (a cost, not a result: the same choice)


def chosen_harmonics(speed: np.ndarray, spread: np.ndarray | None, count: np.ndarray | None, level: float) -> int:
    """The number of harmonics (1 to n / 2 - 1) of a Fourier fit of the stroke-mean crank speed ``speed`` (n,) rad/s on
    a uniform grid over one turn, with its stroke-to-stroke standard deviation ``spread`` (n,) rad/s (NaN where a point
    is covered once) and ``count`` (n,) the strokes at each point; ``level`` the chance that noise alone adds harmonics.

    The rule: the discrete Fourier coefficients a_k, b_k of ``speed``; white noise of variance s^2 in the mean at each
    point gives each the variance 2 s^2 / n, so q_k = (a_k^2 + b_k^2) n / (2 s^2) is chi-square on 2 degrees of freedom
    for a harmonic the motion does not have. s^2 is the mean of spread^2 / count over the grid (a log that covers no
    angle twice: the upper half of its spectrum, its median q taken as noise). Every harmonic up to the highest with
    q_k beyond the chi-square quantile at ``level`` shared among the n / 2 - 1 tested (Bonferroni) is kept; a
    noise-free speed keeps every harmonic the grid holds."""
    w = np.asarray(speed, float)
    n = w.size
    top = n // 2 - 1
    c = np.fft.rfft(w)[1:top + 1] * (2.0 / n)  # a_k - i b_k of w = a0 + sum a_k cos k theta + b_k sin k theta
    power = np.abs(c) ** 2
    var = math.nan
    if spread is not None and count is not None:
        s, cnt = np.asarray(spread, float), np.asarray(count, float)
        ok = np.isfinite(s) & (cnt >= 2)
        if ok.any():
            var = float(np.mean(s[ok] ** 2 / cnt[ok]))
    if not math.isfinite(var):  # no replicates: the upper half of the spectrum taken as noise
        var = float(np.median(power[top // 2:])) * n / 2.0 / stats.chi2.median(2)
    if var <= 0.0:
        return top  # an exact speed: nothing to filter
    q = power * n / (2.0 * var)
    above = np.flatnonzero(q > stats.chi2.isf(level / top, 2))
    return int(above[-1]) + 1 if above.size else 1


def speed_harmonics(log, cs) -> int:
    """The harmonics of a Fourier fit of the crank speed of ``log`` (a calibration.traces.drive_log.DriveLog) under the
    calibration settings ``cs``: the job's ``speed_harmonics``, or with 0 there, as many as the log's own speed
    spectrum carries above its noise (:func:`chosen_harmonics`, at the job's adequacy level: a harmonic too many is a
    false alarm of its own). Used when the job fixes the harmonics or the log has no samples (:func:`crank_motion`)."""
    if cs.speed_harmonics:
        return cs.speed_harmonics
    return chosen_harmonics(log.crank_speed, log.crank_speed_spread, np.sum(np.isfinite(log.stroke_torque), axis=0),
                            cs.adequacy.level)


def speed_noise(time_s: np.ndarray, speed: np.ndarray, trim: float) -> float:
    """rad/s: the standard deviation of the white noise in the speed samples ``speed`` (rad/s) logged at ``time_s`` (s,
    time order), from their third differences d = -w[i-1] + 3 w[i] - 3 w[i+1] + w[i+2] (variance 20 s^2 for white noise)
    over the runs of regular sampling (a gap or a sorted-out row breaks a run). The motion's own share is its snap times
    dt^3, far below the noise, except for a few samples where its jerk jumps (the ends of a sharp ramp): the largest
    fraction ``trim`` of the d^2 is left out and the mean of the rest taken for 20 s^2 times the mean of a chi-square(1)
    cut at the same quantile (the mean of squares, not their median: a quantized speed's many zero differences keep
    their share). 0 for an exact speed."""
    t, w = np.asarray(time_s, float), np.asarray(speed, float)
    if w.size < 4:
        return 0.0
    dt = np.diff(t)
    step = float(np.median(dt))
    regular = np.abs(dt - step) <= 0.5 * step
    ok = regular[2:] & regular[1:-1] & regular[:-2]
    if not ok.any():
        return 0.0
    d2 = np.sort((-w[:-3] + 3.0 * w[1:-2] - 3.0 * w[2:-1] + w[3:])[ok] ** 2)
    keep = max(1, int(math.ceil((1.0 - trim) * d2.size)))
    q = float(stats.chi2.ppf(keep / d2.size, 1))
    cut_mean = float(stats.chi2.cdf(q, 3)) / (keep / d2.size) if keep < d2.size else 1.0  # E[x | x <= q] of chi-square(1)
    return math.sqrt(float(np.mean(d2[:keep])) / (20.0 * cut_mean))


@dataclass(frozen=True, eq=False)
class LocalSpeed:
    """The crank motion of a drive log from local fits of its speed: ``speed`` (n,) rad/s and ``slope`` (n,)
    d(theta_dot)/d(theta) in rad/s per rad at the uniform grid ``theta`` (n,) rad from 0 over one turn, ``window`` (n,)
    rad the half-width each fit used, ``noise`` rad/s the speed samples' noise, ``source`` which channel gave them; between the grid points the periodic
    cubic Hermite interpolant of speed and slope. Gives theta_dot (rad/s), theta_ddot (rad/s^2), time (s since
    theta = 0) and period (s), as press_model.motion's motions do."""

    theta: np.ndarray
    speed: np.ndarray
    slope: np.ndarray
    window: np.ndarray
    noise: float
    source: str  # "speed": the motor speed column's samples; "angle": the angle channel's differences (speed_source)
    _spline: CubicHermiteSpline
    _time_table: np.ndarray
    # (n, 2, 2) the covariance of (speed rad/s, slope rad/s per rad) of each grid point's fit from the speed samples'
    # white noise (None: not known); the crank motion's own uncertainty (calibration/identification/motion_error.py)
    covariance: np.ndarray | None = None
    why: str = ""  # why that channel (speed_source)
    disagree: bool = False  # the speed column disagreed with the angle channel beyond their noise (channel_disagreement)

    _TABLE_POINTS = 7200  # time table step 0.05 deg, as FourierSpeed's

    @classmethod
    def from_grid(cls, theta, speed, slope, window, noise: float, covariance=None,
                  channel: tuple[str, str, bool] = ("speed", "", False)) -> "LocalSpeed":
        """The motion of fitted ``speed`` and ``slope`` at the grid ``theta`` (``covariance`` (n, 2, 2) of each point's
        speed and slope, or None); ``channel``: the samples' source ("speed" or "angle"), why that one, and whether the
        two channels disagreed (:func:`speed_source`). Refuses a speed not positive everywhere."""
        source, why, disagree = channel
        th, w, s = (np.asarray(a, float) for a in (theta, speed, slope))
        spline = CubicHermiteSpline(np.append(th, _TWO_PI), np.append(w, w[0]), np.append(s, s[0]))
        fine = np.linspace(0.0, _TWO_PI, cls._TABLE_POINTS + 1)
        v = spline(fine)
        if not np.all(v > 0):
            raise ValueError(f"the fitted crank speed is not positive over the whole turn (min {v.min():.4g} rad/s)")
        inv = 1.0 / v
        table = np.concatenate(([0.0], np.cumsum(0.5 * (inv[1:] + inv[:-1]) * np.diff(fine))))
        return cls(th, w, s, np.asarray(window, float), float(noise), source, spline, table,
                   None if covariance is None else np.asarray(covariance, float), why, bool(disagree))

    def theta_dot(self, theta):
        return self._spline(np.mod(np.asarray(theta, float), _TWO_PI))

    def theta_ddot(self, theta):
        th = np.mod(np.asarray(theta, float), _TWO_PI)
        return self._spline(th) * self._spline(th, 1)

    def time(self, theta):
        th = np.asarray(theta, dtype=float)
        turns = np.floor(th / _TWO_PI)
        fine = np.linspace(0.0, _TWO_PI, len(self._time_table))
        return turns * self.period + np.interp(th - turns * _TWO_PI, fine, self._time_table)

    @property
    def period(self) -> float:
        return float(self._time_table[-1])


def _runs(t: np.ndarray) -> np.ndarray:
    """(k + 1,) the indices where the runs of regular sampling of the times ``t`` (s) start, and len(t) (a step more
    than half a median step off breaks a run: a gap or a sorted-out row)."""
    dt = np.diff(t)
    step = float(np.median(dt)) if dt.size else 0.0
    breaks = np.flatnonzero(np.abs(dt - step) > 0.5 * step) + 1
    return np.concatenate(([0], breaks, [t.size]))


def joint_angle(time_s: np.ndarray, angle: np.ndarray, speed: np.ndarray, angle_noise: float, speed_noise_: float) -> np.ndarray:
    """rad: the crank angle at each sample from both channels, each as its noise deserves: the integral of the speed
    column (``speed`` rad/s at ``time_s`` s; its noise ``speed_noise_`` rad/s per sample makes a random walk in the angle)
    anchored to the angle channel (``angle`` rad, unwrapped, white noise ``angle_noise`` rad) by a centred moving average
    of their difference over L samples. The average leaves sigma_u^2 / L of the angle's noise and about
    sigma_w^2 dt^2 L / 6 of the walk's; L = sqrt(6) sigma_u / (sigma_w dt) makes the sum least (a complementary filter
    whose crossover the two noises set, not a choice): an exact angle keeps its own samples (L = 1), an exact speed
    column the whole run's average (its integral, shifted onto the angle channel). Within each run of regular
    sampling; a gap starts a new run."""
    t, u, w = (np.asarray(a, float) for a in (time_s, angle, speed))
    out = u.copy()
    bounds = _runs(t)
    for a, b in zip(bounds[:-1], bounds[1:]):
        if b - a < 2:
            continue
        tt, ww = t[a:b], w[a:b]
        step = float(np.median(np.diff(tt)))
        integral = np.concatenate(([0.0], np.cumsum(0.5 * (ww[1:] + ww[:-1]) * np.diff(tt))))
        d = u[a:b] - integral
        n = b - a
        if angle_noise <= 0.0:
            continue  # an exact angle channel: nothing to take from the speed column
        half = n if speed_noise_ <= 0.0 else int(round(0.5 * (math.sqrt(6.0) * angle_noise / (speed_noise_ * step) - 1.0)))
        half = min(max(half, 0), n)
        if half == 0:
            continue
        c = np.concatenate(([0.0], np.cumsum(d)))
        i = np.arange(n)
        lo, hi = np.maximum(i - half, 0), np.minimum(i + half + 1, n)
        out[a:b] = integral + (c[hi] - c[lo]) / (hi - lo)
    return out


# sampling steps over which the two channels' rotations are compared: a 20-ms spike at 500 Hz to a filter's lag over a ramp
DISAGREEMENT_BLOCKS = (5, 20, 80, 320)
SPIKE_BLOCKS = 4  # a local disagreement runs over at most this many shortest blocks (40 ms at 500 Hz: a glitch, a gap crossed)


def channel_disagreement(time_s: np.ndarray, angle: np.ndarray, speed: np.ndarray, angle_noise: float,
                         speed_noise_: float, level: float) -> tuple[float, float, float, float, np.ndarray]:
    """Do the speed column and the angle channel tell the same rotation? (largest |z|, its threshold, the rotation
    difference there in rad, that block's length in s, and (samples,) True on the samples of every shortest block
    beyond the threshold): over disjoint blocks of each length of
    ``DISAGREEMENT_BLOCKS`` sampling steps within the runs of regular sampling, D = the angle channel's rotation
    (``angle`` rad, unwrapped, white noise ``angle_noise`` rad) less the speed column's integral (``speed`` rad/s at
    ``time_s`` s, trapezoids with their leading error h^2/12 (w'(b) - w'(a)) taken out; white noise ``speed_noise_``
    rad/s), z = D over its noise's standard deviation, sqrt(2 sigma_u^2 + sigma_w^2 h^2 (m - 1/2)) for m steps of h.
    The threshold is the normal quantile at ``level`` shared (Bonferroni) among every block tested, so two channels
    that agree pass at that chance. A spike in the speed column (a drive's speed estimate crossing a gear's lost
    motion, a glitch), a speed filtered behind the angle, or a speed of another scale shows as a rotation the angle
    channel does not make. Beside the noise a thousandth of the block's rotation is allowed: a speed column scaled to
    0.1 % (a gear ratio rounded in the press file) is no disagreement, and two exact channels sampled from a table
    differ by a few millionths of a radian over a ramp."""
    t, u, w = (np.asarray(a, float) for a in (time_s, angle, speed))
    bounds = _runs(t)
    found = []
    for m in DISAGREEMENT_BLOCKS:
        for a0, b0 in zip(bounds[:-1], bounds[1:]):
            n = b0 - a0
            if n < m + 3:
                continue  # too short a run for a block
            tt, uu, ww = t[a0:b0], u[a0:b0], w[a0:b0]
            h = float(np.median(np.diff(tt)))
            integral = np.concatenate(([0.0], np.cumsum(0.5 * (ww[1:] + ww[:-1]) * np.diff(tt))))
            slope = np.gradient(ww, tt)
            ends = np.arange(1, n - 1 - m, m)  # block starts; a sample on each side for the slope
            D = (uu[ends + m] - uu[ends]) - (integral[ends + m] - integral[ends]) - h * h / 12.0 * (slope[ends + m] - slope[ends])
            allowed = 1e-3 * np.abs(uu[ends + m] - uu[ends])
            sd = np.sqrt(2.0 * angle_noise ** 2 + speed_noise_ ** 2 * h * h * (m - 0.5) + allowed ** 2)
            found.append((np.abs(D) / sd, D, m * h, a0 + ends, m))
    flagged = np.zeros(t.size, bool)
    if not found:
        return 0.0, math.inf, 0.0, 0.0, flagged
    gamma = float(stats.norm.isf(level / (2.0 * sum(f[0].size for f in found))))
    for z, _, _, starts, m in found:
        if m == DISAGREEMENT_BLOCKS[0]:
            for i in starts[z > gamma]:
                flagged[i:i + m + 1] = True
    z, D, span, _, _ = max(found, key=lambda f: float(f[0].max()))
    k = int(np.argmax(z))
    return float(z[k]), gamma, float(D[k]), span, flagged


def local_disagreement(time_s: np.ndarray, angle: np.ndarray, speed: np.ndarray, flagged: np.ndarray,
                       noises: tuple[float, float], level: float) -> bool:
    """True when the speed column (``speed`` rad/s at ``time_s`` s) disagrees with the angle channel (``angle`` rad,
    unwrapped) only on the samples ``flagged`` by :func:`channel_disagreement` (``noises``: the angle's and the speed's
    white noise, rad and rad/s; ``level`` its level): they are a tenth of the samples or less, no run of them is longer
    than ``SPIKE_BLOCKS`` of the shortest blocks, and with the angle channel's speed in their place the column agrees
    at every block length. A spike (a glitch, a gear's lost motion crossed) is local; a filter's lag lasts as long as
    each ramp."""
    flagged = np.asarray(flagged, bool)
    edges = np.flatnonzero(np.diff(np.concatenate(([0], flagged.astype(np.int8), [0]))))
    longest = int(np.max(edges[1::2] - edges[::2])) if edges.size else 0
    if not 0 < longest <= SPIKE_BLOCKS * DISAGREEMENT_BLOCKS[0] + 1 or np.count_nonzero(flagged) > 0.1 * flagged.size:
        return False
    patched = np.array(speed, float)
    patched[flagged] = np.gradient(np.asarray(angle, float), np.asarray(time_s, float))[flagged]
    z, gamma, _, _, _ = channel_disagreement(time_s, angle, patched, *noises, level)
    return z <= gamma


def speed_source(samples: np.ndarray, trim: float, level: float = 0.01):
    """The crank speed samples the local fit takes, from ``samples`` (rows, 3: time s, unwrapped crank angle rad, crank
    speed rad/s, time order): the motor speed column, or the angle channel's differences (u[i+1] - u[i]) / dt at the
    mid-angles of regular sampling steps, whichever is the less noisy by :func:`speed_noise` (``trim`` its share of the
    largest differences left out). A drive's speed is the encoder's filtered derivative and the angle the encoder
    itself, so the angle's differences may carry far less noise; a jittered time stamp or a coarsely logged angle
    makes them the noisier. (Differences of white angle noise are correlated, which the estimate overstates by a
    factor sqrt(70 / 40) = 1.3: the choice leans to the speed column.) Where the speed column's rotation and the
    angle channel's disagree beyond their noise (:func:`channel_disagreement` at ``level``: a spike, a gear's lost
    motion crossed in the motor's speed, a filtered speed) the angle channel's differences are taken however noisy:
    the angle is the crank's own record, the speed a drive's estimate of it; where the disagreement is local
    (:func:`local_disagreement`) only the speed samples of the blocks beyond the threshold are set aside, and the
    rest keeps the speed column's lower noise. The speed column's samples sit at the
    :func:`joint_angle` of both channels, not at the angle channel's own reading: where the speed changes fast, an
    angle read with noise (a resolver's count and converter noise) moves each sample along the curve by the speed's
    slope times that noise, which the speed's own noise estimate does not see (an exact speed column with a 12-bit
    motor resolver put the acceleration off by 5-17 % of its peak where a 15-degree ramp ends). Returns (time s,
    angle rad, speed rad/s, noise rad/s, "speed" or "angle", why: one phrase, whether the channels disagree)."""
    t, u, w = (np.asarray(c, float) for c in np.asarray(samples, float).T)
    speed_sigma = speed_noise(t, w, trim)
    angle_sigma = speed_noise(t, u, trim)  # the same third differences read the angle channel's white noise (rad)
    z, gamma, rotation, span, flagged = channel_disagreement(t, u, w, angle_sigma, speed_sigma, level)
    if z > gamma:
        why = (f"the motor speed column disagrees with the angle channel: over {1e3 * span:.0f} ms their rotations differ by "
               f"{math.degrees(rotation):+.3g} crank deg, {z:.0f} times their noise (beyond {gamma:.1f}: a spike, a gear's lost "
               "motion crossed or a filtered speed)")
        if local_disagreement(t, u, w, flagged, (angle_sigma, speed_sigma), level):  # set those samples aside
            keep = ~flagged
            return (t[keep], joint_angle(t[keep], u[keep], w[keep], angle_sigma, speed_sigma), w[keep], speed_sigma, "speed",
                    why + f"; its {np.count_nonzero(flagged)} samples where it does were set aside, the rest agree", True)
        why += ", so the angle channel gives the crank motion"
    else:
        why = f"the two channels agree within their noise (largest difference {z:.1f} times it, below {gamma:.1f})"
    best = (t, joint_angle(t, u, w, angle_sigma, speed_sigma), w, speed_sigma, "speed",
            why + "; the speed column is the less noisy", z > gamma)
    if t.size >= 4:
        dt = np.diff(t)
        step = float(np.median(dt))
        ok = np.abs(dt - step) <= 0.5 * step
        if np.count_nonzero(ok) >= 3:
            tm, um, wm = 0.5 * (t[1:] + t[:-1])[ok], 0.5 * (u[1:] + u[:-1])[ok], (np.diff(u) / np.where(ok, dt, 1.0))[ok]
            noise = speed_noise(tm, wm, trim)
            if z > gamma:
                best = (tm, um, wm, noise, "angle", why, True)
            elif noise < best[3]:
                best = (tm, um, wm, noise, "angle", why + "; the angle channel's differences are the less noisy", False)
    return best


def local_speed(theta: np.ndarray, samples: np.ndarray, level: float, cfg) -> LocalSpeed:
    """The :class:`LocalSpeed` of the module docstring's rule at the uniform grid ``theta`` (n,) rad over one turn from
    the speed samples ``samples`` (rows, 3: time s, unwrapped crank angle rad, crank speed rad/s, time order), the
    windows chosen at ``level`` (the chance that noise alone narrows a window somewhere) under ``cfg``
    (calibration.identification.settings.SpeedSection: the narrowest window's samples, the next one's ratio, the noise
    estimate's trim), the widest half a turn."""
    ratio = cfg.window_ratio
    th = np.asarray(theta, float)
    t, u, w, sigma, source, why, disagree = speed_source(samples, cfg.noise_trim, level)
    a = np.mod(u, _TWO_PI)
    order = np.argsort(a, kind="stable")
    a, w = a[order], w[order]
    a3, w3 = np.concatenate((a - _TWO_PI, a, a + _TWO_PI)), np.tile(w, 3)  # the turn on either side: windows wrap
    half = math.pi
    k = max(int(cfg.window_min_samples), int(cfg.estimate_degree) + 1, 3)
    # the narrowest window holds k distinct angles; strokes of a whole number of sampling periods repeat their angles to
    # the last digits, so angles closer than a fraction of the sampling step count once
    n = th.size
    step_at = np.full(n, np.nan)
    np.fmax.at(step_at, np.mod(np.rint(np.mod(0.5 * (u[1:] + u[:-1]), _TWO_PI) / (_TWO_PI / n)).astype(np.int64), n),
               np.where(np.diff(t) <= 1.5 * np.median(np.diff(t)), np.diff(u), np.nan))  # a gap is no sampling step
    step_at = np.where(np.isfinite(step_at), step_at, np.nanmax(step_at))
    near_step = step_at[np.mod(np.rint(a / (_TWO_PI / n)).astype(np.int64), n)]
    au = a[np.concatenate(([True], np.diff(a) >= cfg.duplicate_step_fraction * near_step[1:]))]
    au3 = np.concatenate((au - _TWO_PI, au, au + _TWO_PI))
    at = np.searchsorted(au3, th)
    near = np.sort(np.abs(au3[at[:, None] + np.arange(-k, k)[None, :]] - th[:, None]), axis=1)
    h0 = np.maximum(near[:, k - 1], 1e-12)
    levels = int(math.floor(math.log(half / float(h0.min())) / math.log(ratio))) + 1
    gamma = float(stats.norm.isf(level / (2.0 * th.size * max(levels, 1))))
    speed, slope, window = np.empty(th.size), np.empty(th.size), np.empty(th.size)
    cov = np.empty((th.size, 2, 2))
    reach = np.minimum(h0 * ratio ** _FIRST_LEVELS, half)
    pending = np.arange(th.size)
    while pending.size:  # the samples of the first few windows; more only where the window keeps growing
        sums = []
        for j in pending:
            lo, hi = np.searchsorted(a3, th[j] - reach[j]), np.searchsorted(a3, th[j] + reach[j], side="right")
            x, y = a3[lo:hi] - th[j], w3[lo:hi]
            o = np.argsort(np.abs(x), kind="stable")
            sums.append(_window_sums(x[o], y[o], float(h0[j]), float(reach[j]), ratio, cfg.estimate_degree))
        # every point's quadratics inverted in one call: the same inverse per matrix as one call each, at a
        # fraction of the calls' overhead (numpy's linalg loops over a stack matrix by matrix)
        inv2 = _split(_pinv_stack([m[:, :3, :3] for _, m, _ in sums]), [len(hs) for hs, _, _ in sums])
        chosen = [_ici_window(hs, rz, i2, sigma, gamma) for (hs, _, rz), i2 in zip(sums, inv2)]
        done = np.array([stopped or reach[j] >= half for j, (_, stopped) in zip(pending, chosen)], dtype=bool)
        used = [slice(max(k - 1, 0), k + 1) for k, _ in chosen]
        finished = np.flatnonzero(done)
        if max(int(cfg.estimate_degree), 2) == 2:  # the estimate is the rule's quadratic
            inv = [inv2[i][used[i]] for i in finished]
        else:
            inv = _split(_pinv_stack([sums[i][1][used[i]] for i in finished]), [used[i].stop - used[i].start for i in finished])
        parts = []
        for i, iv in zip(finished, inv):
            hs, _, rz = sums[i]
            speed[pending[i]], slope[pending[i]], window[pending[i]], *part = _ici_estimate(
                hs, rz, iv, chosen[i][0], used[i], sigma, ratio)
            parts.append(part)
        biased = [b for _, b in parts if b is not None]
        eigen = iter(zip(*np.linalg.eigh(np.stack(biased)))) if biased else iter(())
        for i, (noise, bias) in zip(finished, parts):
            cov[pending[i]] = with_positive_part(noise, None if bias is None else next(eigen))
        pending = pending[~done]
        reach[pending] = np.minimum(reach[pending] * ratio ** _FIRST_LEVELS, half)
    return LocalSpeed.from_grid(th, speed, slope, window, sigma, cov, (source, why, disagree))


def _window_sums(x: np.ndarray, y: np.ndarray, h0: float, h_max: float, ratio: float, degree: int = 2):
    """The normal equations of the local polynomial fits of ``degree`` at x = 0 over |x| <= h (``x`` rad sorted by
    |x|, ``y`` rad/s) for h = h0, h0 ratio, ... <= ``h_max`` (those holding enough samples): (hs (levels,) rad,
    m (levels, p, p) their normal matrices and rz (levels, p) their right-hand sides, both in z = x / h)."""
    p = max(int(degree), 2) + 1  # the estimate's coefficients; the rule's quadratic uses the first three
    hs = h0 * ratio ** np.arange(int(math.floor(math.log(max(h_max / h0, 1.0)) / math.log(ratio))) + 1)
    counts = np.searchsorted(np.abs(x), hs * (1.0 + 1e-12), side="right")
    keep = counts >= p
    hs, counts = hs[keep], counts[keep]
    # only the samples of the widest window kept, and numpy's power only where it rounds (x^0 and x^1 are exact): the
    # same table, a cost (the windows' powers were most of the crank motion's CPU), not a result
    end = int(counts[-1]) if counts.size else 0
    x, y = x[:end], y[:end]
    xp = np.empty((end, 2 * p - 1))
    xp[:, 0], xp[:, 1] = 1.0, x
    xp[:, 2:] = x[:, None] ** np.arange(2, 2 * p - 1)[None, :]
    s = np.cumsum(xp, axis=0)[counts - 1]  # (levels, 2p - 1): sums of x^0..x^(2p-2) in each window
    r = np.cumsum(xp[:, :p] * y[:, None], axis=0)[counts - 1]  # (levels, p): sums of x^m y
    scale = hs[:, None] ** -np.arange(2 * p - 1)[None, :]  # in z = x / h the normal equations stay well conditioned
    sz, rz = s * scale, r * scale[:, :p]
    return hs, sz[:, np.add.outer(np.arange(p), np.arange(p))], rz  # m[l, i, j] = sz[l, i + j]


def _pinv_stack(ms: list[np.ndarray]) -> np.ndarray:
    """The pseudo-inverses of the symmetric matrices of every stack in ``ms`` (each (levels, q, q)), end to end.
    k distinct angles make them regular; pinv only guards the rounding."""
    return np.linalg.pinv(np.concatenate(ms), hermitian=True) if ms else None


def _split(stacked: np.ndarray | None, sizes: list[int]) -> list[np.ndarray]:
    """``stacked`` cut back into pieces of ``sizes`` along its first axis (none: no pieces)."""
    return [] if not sizes else np.split(stacked, np.cumsum(sizes)[:-1])


def _ici_window(hs: np.ndarray, rz: np.ndarray, inv2: np.ndarray, sigma: float, gamma: float) -> tuple[int, bool]:
    """(index k of the window the rule takes among ``hs``, whether a wider window failed: False, the widest was
    taken): the largest window whose local quadratic's slope interval c1 +- ``gamma`` standard errors (white noise
    ``sigma``) meets every narrower window's; ``rz`` and ``inv2`` the windows' right-hand sides and inverse quadratic
    normal matrices (:func:`_window_sums`)."""
    slope2 = np.einsum("kij,kj->ki", inv2, rz[:, :3])[:, 1] / hs
    se = sigma * np.sqrt(np.maximum(inv2[:, 1, 1], 0.0)) / hs
    low = np.maximum.accumulate(slope2 - gamma * se)
    high = np.minimum.accumulate(slope2 + gamma * se)
    stopped = bool(np.any(low > high))
    return (max(int(np.argmax(low > high)) - 1, 0) if stopped else hs.size - 1), stopped


def _ici_estimate(hs: np.ndarray, rz: np.ndarray, inv: np.ndarray, k: int, used: slice, sigma: float, ratio: float):
    """(value rad/s, slope rad/s per rad, half-width rad, the parts of the (2, 2) error matrix, :func:`fit_error`) at x = 0 of the
    estimate's polynomial over the window ``k`` the rule took; ``inv`` the inverse normal matrices of the windows
    ``used`` (the chosen one and the next narrower, its bias estimate). The quadratic chooses the window (the rule's
    test); the estimate of a higher degree takes out the bias the rule lets through (module docstring)."""
    beta = np.einsum("kij,kj->ki", inv, rz[used])
    value, slope = beta[:, 0], beta[:, 1] / hs[used]
    return float(value[-1]), float(slope[-1]), float(hs[k]), *fit_error(value, slope, hs[used], inv, sigma, value.size - 1, ratio)


def fit_error(value: np.ndarray, slope: np.ndarray, hs: np.ndarray, inv: np.ndarray, sigma: float, k: int,
              ratio: float) -> tuple[np.ndarray, np.ndarray | None]:
    """The parts of (2, 2) the mean squared error matrix of (value rad/s, slope rad/s per rad) of the window ``k`` the ICI rule took
    among the windows of half-widths ``hs`` (their fits ``value``, ``slope`` and inverse normal matrices ``inv`` in
    z = x / h, of the estimate's polynomial, white noise ``sigma``): the noise's covariance plus the outer product of
    the window's estimated bias. The rule stops a window where its bias becomes visible beside the narrower windows'
    noise; the cubic estimate takes out the smooth part of it, not the part where the speed's curvature jumps (the
    ends of a ramp: a bias proportional to h times the jump, which no polynomial holds). Its estimate: the step from
    the next narrower window, extrapolated as a bias proportional to h: b = (est_k - est_k-1) ratio / (ratio - 1),
    less the step's own noise (b b' minus its covariance, the positive part): where the cubic has taken the bias out
    the step is noise, which counted as bias stated the acceleration's error 2-2.5 times too large (RMS of error /
    stated standard deviation 0.4-0.6 on SYNTHETIC noisy ramp logs; with the noise taken out 0.7-1.0).
    The narrowest window (or a single one) gets no bias term. Returns (the noise's covariance, the bias term before its
    positive part is taken, None where there is none): :func:`with_positive_part` of the two is the matrix, the bias
    terms of every grid point decomposed in one call (numpy's eigh works a stack matrix by matrix: the same numbers)."""
    def noise(i):  # the noise's covariance of window i's (value, slope); z = x / h back to x
        unit = np.array([1.0, 1.0 / hs[i]])
        return sigma ** 2 * inv[i, :2, :2] * np.outer(unit, unit)

    if k == 0:
        return noise(k), None
    c = ratio / (ratio - 1.0)
    b = np.array([value[k] - value[k - 1], slope[k] - slope[k - 1]]) * c
    # the step's own noise: nested least-squares fits have cov(est_k, est_k-1) = var(est_k), so var(step) is
    # var(est_k-1) - var(est_k); its square less that is the bias's square (its positive part: a matrix >= 0)
    return noise(k), np.outer(b, b) - c * c * (noise(k - 1) - noise(k))


def with_positive_part(noise: np.ndarray, eigen) -> np.ndarray:
    """(2, 2) :func:`fit_error`'s matrix: its ``noise`` plus the positive part of its bias term, given by the bias
    term's eigen decomposition ``eigen`` ((w, q) of np.linalg.eigh; None: no bias term)."""
    if eigen is None:
        return noise
    w, q = eigen
    return noise + (q * np.maximum(w, 0.0)) @ q.T


def crank_motion(log, cs):
    """The crank motion the model is built on for ``log`` (a calibration.traces.drive_log.DriveLog) under the
    calibration settings ``cs``: a Fourier series of the job's ``speed_harmonics`` when it fixes them; else the local
    fit of the log's speed samples (:func:`local_speed`, ``[calibration.speed]``), or for a log without samples a
    Fourier series of :func:`chosen_harmonics`. Raises ValueError when the fitted speed is not positive everywhere."""
    samples = getattr(log, "speed_samples", None)
    if cs.speed_harmonics or samples is None:
        return FourierSpeed.fit(log.theta, log.crank_speed, speed_harmonics(log, cs))
    return _remembered_local_speed(log.theta, samples, cs.adequacy.level, cs.speed)


MEMO_MOTIONS = 16  # local fits remembered per process (~0.2 MB each): then it starts again
_MOTIONS: dict = {}  # content key of local_speed's arguments -> its LocalSpeed, arrays read-only


def _remembered_local_speed(theta: np.ndarray, samples: np.ndarray, level: float, cfg) -> LocalSpeed:
    """:func:`local_speed` of these arguments, the one made before in this process for the same bytes: a process that
    calibrates one log several times (the test suite's shared log, ``reproduce``'s methods, a recording estimate's
    states seen before) fitted the same crank motion each time, 0.2-1.4 s of CPU each. Its arrays are made read-only:
    the object is shared."""
    th, sm = np.ascontiguousarray(theta, dtype=float), np.ascontiguousarray(samples, dtype=float)
    digest = hashlib.sha256(th.tobytes())
    digest.update(np.array(th.shape + sm.shape, dtype=np.int64).tobytes())
    digest.update(sm.tobytes())
    key = (digest.hexdigest(), float(level), repr(cfg))
    motion = _MOTIONS.get(key)
    if motion is None:
        motion = local_speed(th.copy(), sm, level, cfg)  # its own grid: the log's stays writable
        for a in (motion.theta, motion.speed, motion.slope, motion.window, motion._time_table, motion.covariance):
            if isinstance(a, np.ndarray):
                a.setflags(write=False)
        if len(_MOTIONS) >= MEMO_MOTIONS:
            _MOTIONS.clear()
        _MOTIONS[key] = motion
    return motion


def describe(motion) -> str:
    """One phrase on a crank motion of :func:`crank_motion`: its harmonics or its windows (deg)."""
    if isinstance(motion, LocalSpeed):
        wd = np.degrees(motion.window)
        return (f"local fit of the {motion.source} channel, windows +-{wd.min():.2g} to {wd.max():.2g} deg (median "
                f"{np.median(wd):.2g}), speed noise {motion.noise:.2g} rad/s" + (f": {motion.why}" if motion.why else ""))
    return f"{motion.harmonics} harmonics"
