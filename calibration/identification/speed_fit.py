"""The crank motion of a drive log: its speed as a Fourier series whose harmonics the log's own spectrum chooses.

The model needs the crank speed and acceleration at every grid point; the acceleration is the speed's derivative
(theta_ddot = theta_dot d(theta_dot)/d(theta)), so the speed is fitted smoothly rather than differentiated as
logged (:class:`press_model.motion.FourierSpeed`). How many harmonics: as many as the log's speed carries above its
own noise. A fixed number either cuts off a motion's sharper features (24 harmonics left a two-speed motion's
changes of speed an acceleration error that called clean logs NOT ADEQUATE, F = 2.9-3.9; 67 on a SYNTHETIC log
with 15-degree speed ramps) or differentiates noise it need not.

The rule (:func:`chosen_harmonics`): the stroke-mean speed on the n-point grid has the discrete Fourier
coefficients a_k, b_k; white noise of variance s^2 in the mean at each point gives each of them the variance
2 s^2 / n, so q_k = (a_k^2 + b_k^2) n / (2 s^2) is chi-square on 2 degrees of freedom for a harmonic the motion
does not have. s^2 comes from the stroke-to-stroke spread of the speed (the mean of spread^2 / count over the
grid), as the adequacy test takes the torque's noise; a log that covers no angle twice takes it from the upper half
of its spectrum (the median q there taken as noise). The fit keeps every harmonic up to the highest one with q_k
beyond the chi-square quantile at ``level`` shared among the n / 2 - 1 harmonics tested (Bonferroni): a motion's
own harmonic is kept unless it is lost in the noise, and noise alone reaches beyond the motion's harmonics in at
most a fraction ``level`` of logs. A noise-free speed keeps every harmonic the grid can hold.

What no speed representation on a 1-degree grid recovers: where the acceleration has a kink (the ends of a speed
ramp), the grid's speed does not say where between two points it lies, and the acceleration there is off by
up to some 3 % of its peak whatever the fit (a periodic cubic spline through the grid speed gives the same).
"""
from __future__ import annotations

import math

import numpy as np
from scipy import stats


def chosen_harmonics(speed: np.ndarray, spread: np.ndarray | None, count: np.ndarray | None, level: float) -> int:
    """The number of harmonics (1 to n / 2 - 1) of the module docstring's rule for the stroke-mean crank speed
    ``speed`` (n,) rad/s on a uniform grid over one turn, with its stroke-to-stroke standard deviation ``spread`` (n,)
    rad/s (NaN where a point is covered once) and ``count`` (n,) the strokes at each point; ``level`` the chance
    that noise alone adds harmonics."""
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
    """The harmonics of the crank-speed fit of ``log`` (a calibration.traces.drive_log.DriveLog) under the calibration
    settings ``cs``: the job's ``speed_harmonics``, or with 0 there (the default), as many as the log's own speed
    spectrum carries above its noise (:func:`chosen_harmonics`, at the job's adequacy level: a harmonic too many is a
    false alarm of its own). The log problem and every refit on the same log take this one number."""
    if cs.speed_harmonics:
        return cs.speed_harmonics
    return chosen_harmonics(log.crank_speed, log.crank_speed_spread, np.sum(np.isfinite(log.stroke_torque), axis=0),
                            cs.adequacy_level)
