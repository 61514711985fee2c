"""The measured peak of Eq. 23 from a noisy drive log, and how noisy it still is.

Eq. 23 compares the model's peak torque with the measured one. The maximum of a noisy curve is biased up
and as noisy as one sample (on the synthetic reference log: +67 N m bias, 46 N m spread over 20 noise
draws), and when the theoretical model's peak error |Y_PR,0| M is small, Eq. 28's peak term then pins the
parameters to that noise. The measured peak is therefore taken from the stroke-averaged curve after a
Savitzky-Golay filter (a local polynomial fit, which keeps a smooth peak's height where a moving mean
would flatten it), applied piecewise between the process-force steps so that the step at die contact is
not smeared into its neighbours. The window and order are job settings ([calibration]
``peak_filter_window_deg``, ``peak_filter_order``), their reason given there.

Where the peak lies just after the die-contact window, the filter's window reaches into it and reads the ringing a
rigid-body model has no term for. :func:`fit_ringing` reads that ringing from the log (a damped oscillation whose
frequency, decay, amplitude and phase are all fitted) and :func:`peak_filter` removes it before the filter
([calibration] ``peak_ringing_fit``).

The noise left in the filtered peak: sigma_peak = sigma_mean * sqrt(sum c_i^2), with c the filter's
centre coefficients and sigma_mean the noise of the stroke average at one grid point, from the
stroke-to-stroke spread (median of the per-point sample deviation, made unbiased for a normal sample of
S strokes, divided by sqrt(S)); with one stroke only, from the median absolute residual of the filter.
"""
from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np
from scipy import stats
from scipy.ndimage import convolve1d
from scipy.signal import savgol_coeffs


@dataclass(frozen=True)
class MeasuredPeak:
    """The filtered measured peak (N m) over the peak points, the noise left in it, and the raw maximum."""

    value_Nm: float
    sigma_Nm: float  # standard deviation of the noise left in value_Nm
    raw_Nm: float  # max |T| of the unfiltered stroke average over the same points
    point_sigma_Nm: float  # noise of the stroke average at one grid point
    window_deg: float
    order: int
    ringing: str = ""  # what was removed before the filter (Ringing.describe), "" if nothing

    def describe(self) -> str:
        return (f"Savitzky-Golay filter, {self.window_deg:g} deg window, order {self.order}, piecewise between force steps; "
                f"filtered peak {self.value_Nm:.1f} N m (raw maximum {self.raw_Nm:.1f} N m), noise left in it {self.sigma_Nm:.1f} N m"
                + (f"; {self.ringing}" if self.ringing else ""))


def _window_points(window_deg: float, step_deg: float, order: int) -> int:
    n = int(round(window_deg / step_deg))
    n += 1 - n % 2  # odd
    return max(n, order + 2 + (order % 2 == 0))


@functools.lru_cache(maxsize=None)
def _savgol(win: int, order: int) -> tuple[np.ndarray, np.ndarray]:
    """The Savitzky-Golay filter of ``win`` points and ``order`` as a linear map, made once (the bootstrap and the noise
    weights filter thousands of curves on one grid): (its convolution coefficients (win,), what the polynomial fitted
    to a piece's first ``win`` points gives its first ``win // 2`` points (win // 2, win), 1 per 1). A piece's last
    points are the first's mirrored: the fit is the same read backwards."""
    half = win // 2
    t = (np.arange(win, dtype=float) - half) / half  # the window on [-1, 1]: a well-conditioned Vandermonde matrix
    fit = np.linalg.pinv(np.vander(t, order + 1))  # samples -> polynomial coefficients
    return savgol_coeffs(win, order), np.vander(t[:half], order + 1) @ fit


def _savgol_piece(x: np.ndarray, win: int, order: int) -> np.ndarray:
    """``x`` (m,) filtered as scipy's ``savgol_filter(x, win, order, mode="interp")`` filters it: the centred fit
    inside, the polynomial fitted to the first and the last ``win`` points on the first and last ``win // 2``
    (:func:`_savgol`; the same map to rounding)."""
    coeffs, head = _savgol(win, order)
    y = convolve1d(x, coeffs, mode="constant")
    half = win // 2
    y[:half] = head @ x[:win]
    y[-half:] = (head @ x[::-1][:win])[::-1]
    return y


def filter_curve(theta: np.ndarray, torque: np.ndarray, step_angles, window_deg: float, order: int) -> np.ndarray:
    """The periodic curve ``torque`` (n,) on the uniform grid ``theta`` (rad) filtered piecewise between the
    force-step angles (rad); a piece shorter than the window is left as it is. Returns (n,) in ``torque``'s unit."""
    T = np.asarray(torque, dtype=float)
    n = T.size
    step_deg = math.degrees(theta[1] - theta[0])
    win = _window_points(window_deg, step_deg, order)
    # first grid index at or after each step: a piece runs from one step to the next, wrapping round the turn
    cuts = sorted({int(np.searchsorted(theta, a % (2.0 * math.pi))) % n for a in step_angles})
    if not cuts:
        return convolve1d(T, _savgol(win, order)[0], mode="wrap")
    out = T.copy()
    for i, c in enumerate(cuts):
        nxt = cuts[(i + 1) % len(cuts)]
        length = (nxt - c) % n or n
        idx = (c + np.arange(length)) % n
        if length >= win:
            out[idx] = _savgol_piece(T[idx], win, order)
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


@dataclass(frozen=True)
class Ringing:
    """The die-contact ringing read from the log itself: a damped oscillation a exp(-s/decay) sin(2 pi f s + phase),
    s the time since die contact, fitted beside a local polynomial to the measured curve less a reference model curve
    over ``region`` (the die-contact window and the peak filter's reach beyond it). ``fit`` (len(region) x
    len(region)) maps that difference on the region to the fitted oscillation, with the frequency and decay held:
    amplitude and phase are linear in the curve, so the clearing is an affine map and the bootstrap's curves and the
    peak's noise weights go through the same map (:meth:`clear`)."""

    region: np.ndarray  # grid indices the oscillation is fitted on and removed from
    reference: np.ndarray  # (len(region),) N m: the reference model curve there (smooth: no oscillation)
    fit: np.ndarray  # (len(region), len(region)): difference from the reference -> fitted oscillation, N m per N m
    frequency_Hz: float
    decay_s: float
    amplitude_Nm: float  # the fitted oscillation's amplitude at die contact
    step_s: float = 0.0  # the region's mean time between grid points: what the grid resolves (0: not stated)
    span_s: float = math.inf  # the region's length in time

    def unresolved(self) -> str:
        """Why this fit is no ringing the log carries, or "" when it is one. The grid resolves an oscillation below its
        Nyquist rate 0.5 / step and above one cycle over the region, decaying in more than one step and less than the
        region's length: the fit searches exactly that box, and one that ends on its edge has found none inside it (a
        decay of one step is over before the next grid point, so its amplitude at contact is an extrapolation the log
        never shows; at the Nyquist rate it is the grid's alternating sign, which noise and a misfit at the force step
        give as well; one cycle over the region that never decays is a smooth misfit)."""
        if not self.step_s:
            return ""
        tol = 1e-3  # relative: the optimiser's bounds are met exactly by a fit pinned to them
        edges = [("at the grid's Nyquist rate", self.frequency_Hz >= (1.0 - tol) * 0.5 / self.step_s),
                 ("decaying within one grid step", self.decay_s <= (1.0 + tol) * self.step_s),
                 ("one cycle over its region", self.frequency_Hz <= (1.0 + tol) / self.span_s),
                 ("never decaying over its region", self.decay_s >= (1.0 - tol) * self.span_s)]
        hit = [w for w, on in edges if on]
        if not hit:
            return ""
        return (f"die-contact ringing not removed: its fit ended on what the crank grid resolves ({' and '.join(hit)}; "
                f"{1000.0 * self.step_s:.1f} ms between grid points there), so it found no oscillation the log carries")

    def clear(self, curve: np.ndarray, linear: bool = False) -> np.ndarray:
        """``curve`` (n,) N m less the oscillation fitted to it with this frequency and decay; ``linear``: the map's
        linear part only (for a perturbation of a curve, e.g. a unit noise at one point)."""
        out = np.array(curve, dtype=float)
        d = out[self.region] if linear else out[self.region] - self.reference
        out[self.region] -= self.fit @ d
        return out

    def describe(self) -> str:
        return (f"die-contact ringing fitted and removed before the filter: {self.frequency_Hz:.1f} Hz, decay "
                f"{1000.0 * self.decay_s:.0f} ms, {self.amplitude_Nm:.0f} N m at contact")


def fit_ringing(time_s: np.ndarray, period_s: float, measured: np.ndarray, reference: np.ndarray, contact_time_s: float,
                excluded: np.ndarray, peak_filter: tuple[float, int], step_deg: float) -> Ringing | None:
    """The damped oscillation after die contact (:class:`Ringing`) in ``measured`` (n,) N m, or None when the
    die-contact window ``excluded`` (bool, n: the grid points Eq. 28 leaves out after contact) is empty or the region
    holds too few points for the polynomial and the oscillation.

    Nothing of the oscillation is given: its frequency and decay are fitted (variable projection: a grid over the
    frequencies the grid resolves, from one cycle over the region to the Nyquist rate of its time steps, and decays
    from one time step to the region's length, then refined) to measured - ``reference`` (a model curve, N m, whose
    misfit is smooth) over the window and the peak filter's reach beyond it (``peak_filter``: its window in deg and its
    order; the same local polynomial of the peak filter takes the misfit's smooth part). ``time_s``: each grid point's time within the turn;
    ``contact_time_s``: die contact's; ``period_s``: the turn's; ``step_deg``: the grid's step."""
    from scipy.optimize import minimize

    window_deg, order = peak_filter
    excluded = np.asarray(excluded, dtype=bool)
    starts = np.flatnonzero(excluded & ~np.roll(excluded, 1))  # the window's first point after contact (it may wrap past 0 deg)
    if starts.size == 0:
        return None
    n = len(measured)
    start = int(starts[0])
    length = int(excluded.sum()) + _window_points(window_deg, step_deg, order) // 2
    region = (start + np.arange(min(length, n))) % n
    s = np.mod(np.asarray(time_s, dtype=float)[region] - contact_time_s, period_s)
    e = np.asarray(measured, dtype=float)[region] - np.asarray(reference, dtype=float)[region]
    span = float(s[-1] - s[0])
    dt = span / max(len(s) - 1, 1)
    if len(s) < order + 4 or span <= 0.0:
        return None
    poly = np.vander((s - s.mean()) / span, order + 1)

    def basis(f, tau):
        d = np.exp(-s / tau)
        return np.column_stack([poly, d * np.sin(2.0 * np.pi * f * s), d * np.cos(2.0 * np.pi * f * s)])

    q = np.linalg.qr(poly)[0]
    e_perp = e - q @ (q.T @ e)

    def rss(f, tau):
        """The residual sum of squares (N m^2) at each (f, tau) (arrays of one shape), the polynomial projected out."""
        f, tau = np.asarray(f, dtype=float)[..., None], np.asarray(tau, dtype=float)[..., None]
        d = np.exp(-s / tau)
        B = np.stack([d * np.sin(2.0 * np.pi * f * s), d * np.cos(2.0 * np.pi * f * s)], axis=-1)  # (..., m, 2)
        B = B - q @ np.einsum("mk,...mj->...kj", q, B)
        G = np.einsum("...mi,...mj->...ij", B, B) + 1e-12 * np.eye(2)
        b = np.einsum("...mi,m->...i", B, e_perp)
        return float(e_perp @ e_perp) - np.einsum("...i,...i->...", b, np.linalg.solve(G, b[..., None])[..., 0])

    bounds = [(1.0 / span, 0.5 / dt), (dt, span)]
    F, TAU = np.meshgrid(np.linspace(*bounds[0], 4 * len(s)), np.geomspace(*bounds[1], 16), indexing="ij")
    k = int(np.argmin(rss(F, TAU)))
    start_p = (F.flat[k], TAU.flat[k])
    f, tau = minimize(lambda p: float(rss(p[0], p[1])), start_p, method="Nelder-Mead", bounds=bounds,
                      options={"xatol": 1e-9, "fatol": 1e-12 * max(float(e @ e), 1e-300)}).x
    X = basis(f, tau)
    pinv = np.linalg.pinv(X)
    fit = X[:, -2:] @ pinv[-2:, :]
    a = pinv[-2:, :] @ e
    return Ringing(region, np.asarray(reference, dtype=float)[region], fit, float(f), float(tau), float(np.hypot(*a)),
                   float(dt), float(span))


def peak_filter(theta: np.ndarray, curve: np.ndarray, step_angles, window_deg: float, order: int,
                ringing: Ringing | None = None, linear: bool = False) -> np.ndarray:
    """The curve the measured peak is read from (N m, (n,)): ``curve`` less the die-contact ringing fitted to it
    (``ringing``'s frequency and decay held; ``linear``: :meth:`Ringing.clear`'s linear part, for a perturbation), then
    :func:`filter_curve`."""
    cleared = curve if ringing is None else ringing.clear(curve, linear)
    return filter_curve(theta, cleared, step_angles, window_deg, order)


def peak_row(theta: np.ndarray, curve: np.ndarray, peak_points: np.ndarray, steps, window_deg: float, order: int,
             ringing: Ringing | None = None) -> np.ndarray:
    """(n,): what the filtered peak of ``curve`` (N m, (n,)) gains per N m added to each grid point: the row of the
    linear map :func:`peak_filter` (``ringing`` removed, its frequency and decay held) at the peak's grid point, the
    largest |filtered ``curve``| over ``peak_points`` (bool, n). Zero beyond the filter's reach and the ringing's region."""
    filtered = peak_filter(theta, curve, steps, window_deg, order, ringing)
    j = int(np.flatnonzero(peak_points)[np.argmax(np.abs(filtered[peak_points]))])
    n = len(theta)
    reach = int(math.ceil(window_deg / math.degrees(theta[1] - theta[0]))) + 1  # a piece's end fits a window beyond the point
    idx = np.unique((j + np.arange(-reach, reach + 1)) % n)
    if ringing is not None:  # the ringing's fit spreads a point's weight over its region
        idx = np.union1d(idx, ringing.region)
    row = np.zeros(n)
    for i in idx:
        row[i] = peak_filter(theta, np.eye(1, n, i)[0], steps, window_deg, order, ringing, linear=True)[j]
    return row
