"""The measured peak's noise in the intervals: how far it moves the Eq. 28 estimate, and the note that says so.

Eq. 28's peak term is normalised by |Y_PR,0|. When the theoretical model's peak error |Y_PR,0| x peak is only a few
times the noise left in the filtered measured peak (:mod:`calibration.identification.peak`, ``sigma_Nm``), the
peak term is heavy, the fit holds the model's peak at the measured one, and that peak's noise moves the estimate.
The intervals carry this move:

- The bootstrap (:mod:`calibration.identification.bootstrap`) rebuilds Eq. 28 on every resampled curve, its filtered
  peak included, and the peak points are resampled (only the die-contact window and the force steps' neighbours
  stay in place), so each refit draws the measured peak anew. :func:`carried` compares the refits' peaks' scatter
  with ``sigma_Nm`` and calibrated.json records both. Where the filter's window around the peak reaches points kept
  in place (a peak just after the die-contact window, as on the crank-slider job), that share of the noise
  (:func:`held_share`) is not redrawn, and the calibration adds that share of :func:`linearised_move` to the
  bootstrap intervals.
- The Jacobian intervals belong to least squares, which has no peak term. :func:`linearised_move` gives what the
  Eq. 28 estimator moves by when the measured peak moves by one ``sigma_Nm`` either way, on the linearised Eq. 28
  the bootstrap's local solver minimises (:func:`calibration.identification.bootstrap.refit_batch`); the calibration
  adds it in quadrature to the Jacobian intervals' standard errors. Where the peak term holds the model's peak on
  the measured one the move is the whole constrained response; where it does not, the move is about zero.

So a small |Y_PR,0| is no longer a reason to distrust the intervals, and :func:`peak_noise_note` is a note, not a
warning: it says the peak term follows the peak's noise and that the intervals carry it.
"""
from __future__ import annotations

import numpy as np

from calibration.identification.bootstrap import _local_step
from calibration.identification.peak import peak_row
from calibration.identification.problem import Objective
from calibration.identification.uncertainty import curve_jacobian


def linearised_move(obj: Objective, x: np.ndarray, sigma_Nm: float) -> np.ndarray:
    """(k,) SI: the standard deviation the measured peak's noise (``sigma_Nm``, N m, one standard deviation of the
    filtered measured peak) gives the Eq. 28 estimate at x: the linearised Eq. 28 at x (the model's peak at its peak
    point, as :func:`calibration.identification.bootstrap.refit_batch` linearises it) minimised over the calibration
    range with the measured peak as measured, one ``sigma_Nm`` higher and one lower; the root mean square of the two
    moves from the first (two-point Gauss-Hermite rule for a normal error). Zero without noise."""
    x = np.asarray(x, float)
    if not sigma_Nm > 0.0:
        return np.zeros(len(x))
    p = obj.problem
    span = p.high - p.low
    m = obj.peak_points
    sq = np.sqrt(m.sum())
    T = obj.torques(x[None])[0]
    J = curve_jacobian(obj.torques, span, x) * span  # N m per unit of range
    jm = int(np.flatnonzero(m)[np.argmax(np.abs(T[m]))])  # the model's peak point
    sgn = np.sign(T[jm]) or 1.0
    u = (x - p.low) / span
    moves = []
    for peak in (obj.measured_peak, obj.measured_peak + sigma_Nm, obj.measured_peak - sigma_Nm):
        moves.append(_local_step(((T - obj.measured)[m] / sq, J[m] / sq, (abs(T[jm]) - peak) / peak, sgn * J[jm] / peak),
                                 (p.weight, obj.rmse0, abs(obj.pr0)), -u, 1.0 - u))
    s0, up, down = moves
    return np.sqrt(0.5 * ((up - s0) ** 2 + (down - s0) ** 2)) * span


def held_share(theta: np.ndarray, measured: np.ndarray, peak_points: np.ndarray, fixed: np.ndarray, steps,
               window_deg: float, order: int, ringing=None) -> float:
    """The share (0..1) of the filtered measured peak's noise variance that sits on ``fixed`` grid points (bool, n):
    the points the bootstrap keeps in place with their own residual (the die-contact window, the force steps'
    neighbours), so that its refits do not redraw that share. The filter is linear: its weights at the peak's grid
    point (the largest |filtered ``measured``| over ``peak_points``) are its response to a unit at each point
    (:func:`calibration.identification.peak.peak_row`); the share
    is the sum of the squared weights on fixed points over the sum of all, for noise of equal variance at each point.
    ``ringing``: the die-contact ringing removed before the filter (:func:`calibration.identification.peak.peak_filter`),
    whose fit spreads the weights over the window's points."""
    row = peak_row(theta, measured, peak_points, steps, window_deg, order, ringing)
    reached = np.flatnonzero(row)
    w = row[reached]
    fixed = np.asarray(fixed, bool)[reached]
    total = float(w @ w)
    return float(w[fixed] @ w[fixed]) / total if total > 0.0 else 0.0


def carried(peaks: np.ndarray | None) -> float | None:
    """N m: the scatter (standard deviation) of the bootstrap refits' filtered measured peaks, the peak noise the
    bootstrap intervals carry; None without refits."""
    if peaks is None or len(peaks) < 2:
        return None
    return float(np.std(np.asarray(peaks, float), ddof=1))


def peak_noise_note(gap_Nm: float, sigma_Nm: float, limit: float, refit_scatter_Nm: float | None) -> str | None:
    """A note when the theoretical model's peak error ``gap_Nm`` (|Y_PR,0| x the measured peak, N m) is within
    ``limit`` times the noise left in the filtered measured peak (``sigma_Nm``); None otherwise. ``refit_scatter_Nm``:
    :func:`carried` (None: the intervals are the Jacobian ones)."""
    if not (sigma_Nm > 0.0 and gap_Nm < limit * sigma_Nm):
        return None
    how = (f"the bootstrap's refits redraw the peak, their filtered peaks scattering by {refit_scatter_Nm:.0f} N m, and the "
           "Jacobian intervals add its linearised move" if refit_scatter_Nm is not None else
           "the Jacobian intervals add its linearised move")
    return (f"the theoretical model's peak error |Y_PR,0| x peak = {gap_Nm:.0f} N m is {gap_Nm / sigma_Nm:.1f} times the noise left "
            f"in the filtered measured peak ({sigma_Nm:.0f} N m; note below {limit:g} times): Eq. 28's peak term, normalised by "
            f"it, follows that noise, and the intervals carry it ({how}; calibration/identification/peak_noise.py); a log "
            "with more strokes narrows them")
