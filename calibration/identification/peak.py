"""The measured peak of Eq. 23 from a noisy drive log, and how noisy it still is.

Eq. 23 compares the model's peak torque with the measured one. The maximum of a noisy curve is biased up
and as noisy as one sample (on the synthetic reference log: +67 N m bias, 46 N m spread over 20 noise
draws), and when the theoretical model's peak error |Y_PR,0| M is small, Eq. 28's peak term then pins the
parameters to that noise. The measured peak is therefore taken from the stroke-averaged curve after a
Savitzky-Golay filter (a local polynomial fit, which keeps a smooth peak's height where a moving mean
would flatten it), applied piecewise between the process-force steps so that the step at die contact is
not smeared into its neighbours. The window and order are job settings ([calibration]
``peak_filter_window_deg``, ``peak_filter_order``), their reason given there.

The noise left in the filtered peak: sigma_peak = sigma_mean * sqrt(sum c_i^2), with c the filter's
centre coefficients and sigma_mean the noise of the stroke average at one grid point, from the
stroke-to-stroke spread (median of the per-point sample deviation, made unbiased for a normal sample of
S strokes, divided by sqrt(S)); with one stroke only, from the median absolute residual of the filter.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import stats
from scipy.signal import savgol_coeffs, savgol_filter


@dataclass(frozen=True)
class MeasuredPeak:
    """The filtered measured peak (N m) over the peak points, the noise left in it, and the raw maximum."""

    value_Nm: float
    sigma_Nm: float  # standard deviation of the noise left in value_Nm
    raw_Nm: float  # max |T| of the unfiltered stroke average over the same points
    point_sigma_Nm: float  # noise of the stroke average at one grid point
    window_deg: float
    order: int

    def describe(self) -> str:
        return (f"Savitzky-Golay filter, {self.window_deg:g} deg window, order {self.order}, piecewise between force steps; "
                f"filtered peak {self.value_Nm:.1f} N m (raw maximum {self.raw_Nm:.1f} N m), noise left in it {self.sigma_Nm:.1f} N m")


def _window_points(window_deg: float, step_deg: float, order: int) -> int:
    n = int(round(window_deg / step_deg))
    n += 1 - n % 2  # odd
    return max(n, order + 2 + (order % 2 == 0))


def filter_curve(theta: np.ndarray, torque: np.ndarray, step_angles, window_deg: float, order: int) -> np.ndarray:
    """The periodic curve ``torque`` (n,) on the uniform grid ``theta`` (rad) filtered piecewise between the
    force-step angles (rad); a piece shorter than the window is left as it is."""
    T = np.asarray(torque, dtype=float)
    n = T.size
    step_deg = math.degrees(theta[1] - theta[0])
    win = _window_points(window_deg, step_deg, order)
    # first grid index at or after each step: a piece runs from one step to the next, wrapping round the turn
    cuts = sorted({int(np.searchsorted(theta, a % (2.0 * math.pi))) % n for a in step_angles})
    if not cuts:
        return savgol_filter(T, win, order, mode="wrap")
    out = T.copy()
    for i, c in enumerate(cuts):
        nxt = cuts[(i + 1) % len(cuts)]
        length = (nxt - c) % n or n
        idx = (c + np.arange(length)) % n
        if length >= win:
            out[idx] = savgol_filter(T[idx], win, order, mode="interp")
    return out


def measured_peak(theta: np.ndarray, torque: np.ndarray, spread: np.ndarray, strokes: int, peak_points: np.ndarray,
                  step_angles, window_deg: float, order: int) -> MeasuredPeak:
    """The robust measured peak of Eq. 23 (module docstring) over ``peak_points`` (bool, n)."""
    T = np.asarray(torque, dtype=float)
    m = np.asarray(peak_points, dtype=bool)
    filtered = filter_curve(theta, T, step_angles, window_deg, order)
    win = _window_points(window_deg, math.degrees(theta[1] - theta[0]), order)
    gain = float(np.sqrt(np.sum(savgol_coeffs(win, order) ** 2)))
    s = np.asarray(spread, dtype=float)
    s = s[m & np.isfinite(s)]
    if strokes >= 2 and s.size:
        # median of a normal sample's deviation with S - 1 degrees of freedom is sigma sqrt(chi2 median / (S - 1))
        point = float(np.median(s)) / math.sqrt(stats.chi2.median(strokes - 1) / (strokes - 1)) / math.sqrt(strokes)
    else:
        resid = (T - filtered)[m]
        point = 1.4826 * float(np.median(np.abs(resid))) / math.sqrt(max(1.0 - gain**2, 1e-12))
    return MeasuredPeak(float(np.max(np.abs(filtered[m]))), point * gain, float(np.max(np.abs(T[m]))), point, float(window_deg), int(order))
