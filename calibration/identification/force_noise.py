"""The logged process force's noise and its share of the intervals.

A log's ``process_force_N`` replaces the job's nominal force in the model (:mod:`calibration.identification.process_force`),
noise and all: the model's torque carries the force channel's noise, smoothed but not gone, and a smooth force error
over the cushion stroke moves eta_gear as a force scale would. That noise is independent of the torque channel's, so
its share of each parameter's spread adds in quadrature to the intervals, as the recording correction's does
(calibration/identification/run.py); calibrated.json records it as ``interval_widening.logged_force_sd``.

**The noise, from the log itself** (:func:`binned_standard_errors`): the force is the same in every turn at a crank angle,
so each turn's bin mean of the force channel scatters from turn to turn by the channel's noise only (as the torque's
stroke-to-stroke scatter is its noise, :mod:`calibration.identification.adequacy`). The scatter is pooled over each
piece between the force's steps (its end points, whose bins may straddle a step, left out), which allows a loaded
cushion a noise other than an unloaded slide's; each grid point's bin mean then has that variance over its sample
count. Nothing is taken from the job's [experiment] settings.

**Its curve** (:class:`calibration.identification.process_force.LoggedForce` ``noise_factor``): the curve is a linear map of
the bin means (the piecewise Savitzky-Golay filter, the snapped transition points, the unloaded pieces set to zero),
so its noise is that map times the bin means' standard errors: L_F w with w standard normal.

**Its share of each parameter** (:func:`logged_force_spread`): the model with the force F + e fits the log y as the model
with F fits y - G e, G the model torque per N of force at each grid point (:func:`torque_per_newton`, the model
on the force plus a small constant). The torque noise G L_F w reaches Eq. 28's estimate only through what the
estimator reads of a curve: the Jacobian's columns (Y_RMSE's gradient), the residual and the theoretical model's
residual (Y_RMSE and its normalisation Y_RMSE,0), and the filtered measured peak (:func:`calibration.identification.peak.peak_row`; the peak's grid
point alone left a tenth of eta_gear's spread out on a SYNTHETIC cushion-test log with 2 % force noise). Those
functionals, pulled back into w, span at most k + 3 + logs directions; the rest of w moves no estimate to first
order. The estimator itself is refitted locally (:func:`calibration.identification.bootstrap.refit_batch`) on the curve
shifted one standard deviation either way along each of those orthonormal directions, and the variance is the sum
over them of the mean square move (two-point Gauss-Hermite, as the recording's share): the linear propagation
cov = R G Sigma_F G R^T, R the estimator's response, at 2 (k + 3 + logs) refits instead of one per grid point.
"""
from __future__ import annotations

import dataclasses
import math

import numpy as np

from press_model.batch import with_process

from calibration.identification.bootstrap import refit_batch
from calibration.identification.peak import peak_row
from calibration.identification.uncertainty import jacobian

FORCE_PROBE = 1e-3  # the constant force added to find the torque per N, as a share of the force's peak (a numerical step)


def spread_of_mean(F: np.ndarray) -> np.ndarray:
    """(n,) N: the standard error of the stroke mean of per-turn values ``F`` (S, n) at each grid point: their
    stroke-to-stroke standard deviation over the square root of their count (NaN where fewer than two)."""
    count = np.sum(np.isfinite(F), axis=0)
    out = np.full(F.shape[1], np.nan)
    ok = count >= 2
    if ok.any():
        out[ok] = np.nanstd(F[:, ok], axis=0, ddof=1) / np.sqrt(count[ok])
    return out


def binned_standard_errors(means: np.ndarray, counts: np.ndarray, cuts: np.ndarray) -> tuple[np.ndarray, float]:
    """The standard error (n,) N of each grid point's bin mean over every turn, and the channel's noise per sample (N,
    pooled over the turn), from each turn's bin means ``means`` (T, n) and sample counts ``counts`` (T, n): the one-way
    analysis of variance's between-turn estimate sum_t c (m_t - m)^2 / (turns - 1) of the per-sample variance, pooled
    over each piece between the steps ``cuts`` (grid indices; none: one piece) without the piece's end points, over
    the sample count of each point. A piece with no turn-to-turn scatter to pool takes the whole turn's; with a
    single turn nothing is known: zeros and NaN."""
    c = np.where(np.isfinite(means), counts, 0).astype(float)
    m = np.where(c > 0, means, 0.0)
    total = c.sum(axis=0)
    mbar = np.divide((c * m).sum(axis=0), total, out=np.zeros_like(total), where=total > 0)
    ss = (c * (m - mbar) ** 2).sum(axis=0)
    dof = np.maximum((c > 0).sum(axis=0) - 1, 0).astype(float)
    n = means.shape[1]
    starts = np.sort(np.asarray(cuts, int)) if len(cuts) else np.array([0])
    interior = np.zeros(n, bool)
    piece = np.zeros(n, int)
    for i, s in enumerate(starts):
        length = ((starts[(i + 1) % starts.size] - s) % n) or n
        idx = (s + np.arange(length)) % n
        piece[idx] = i
        interior[idx[1:-1] if length >= 3 else idx] = True
    use = interior & (dof > 0)
    if not use.any():
        return np.zeros(n), math.nan
    whole = float(ss[use].sum() / dof[use].sum())
    var = np.full(starts.size, whole)
    for i in range(starts.size):
        sel = use & (piece == i)
        if dof[sel].sum() > 0:
            var[i] = float(ss[sel].sum() / dof[sel].sum())
    se = np.sqrt(np.divide(var[piece], total, out=np.zeros(n), where=total > 0))
    return se, math.sqrt(whole)


def torque_per_newton(pm, lp, x: np.ndarray) -> np.ndarray:
    """(n,) N m per N: what the model's motor torque of the log problem ``lp`` (its logged force, its crank motion) at
    the parameters ``x`` gains per N of process force at each grid point: the log's model moved to the logged force plus
    :data:`FORCE_PROBE` of its peak (:func:`press_model.batch.with_process`: the same numbers as a model built on it,
    without its RNEA runs)."""
    proc = lp.force.process
    delta = FORCE_PROBE * float(np.max(np.abs(lp.force.curve)))
    bumped = dataclasses.replace(proc, down_f=proc.down_f + delta, up_f=proc.up_f + delta)
    bm = with_process(lp.objective.bm, proc, bumped, pm)
    x = np.asarray(x, float)[None]
    return (dataclasses.replace(lp.objective, bm=bm).torques(x)[0] - lp.objective.torques(x)[0]) / delta


def noise_directions(L: np.ndarray, D: np.ndarray, rtol: float = 1e-9) -> np.ndarray:
    """(m, N): the torque curves L q_j, q_j an orthonormal basis (in the noise's own coordinates w, standard normal) of
    the span of L^T D, i.e. of what the functionals ``D`` (N, d) read of the noise L w (``L`` (N, W)); directions whose
    singular value is below ``rtol`` of the largest are dropped (nothing reads them)."""
    A = L.T @ D
    if not np.any(A):
        return np.zeros((0, L.shape[0]))
    U, s, _ = np.linalg.svd(A, full_matrices=False)
    keep = s > rtol * s[0]
    return (L @ U[:, keep]).T


def logged_force_spread(pm, lps, obj, make, x: np.ndarray, iterations: int,
                        peak_filter: tuple[float, int]) -> tuple[np.ndarray, dict | None]:
    """(k,) SI: the standard deviation the logged force's noise adds to each parameter's estimate (module docstring),
    and calibrated.json's account of it (None when no log has its force logged with a noise estimate). ``lps`` the log
    problems (calibration/identification/run.py ``LogProblem``) whose joint objective is ``obj``; ``make(curve)`` Eq. 28
    rebuilt on another curve over the logs end to end, as the calibration built it; ``x`` the estimate; ``peak_filter`` the
    measured peak's filter (window deg, order: [calibration] peak_filter_window_deg, peak_filter_order)."""
    x = np.asarray(x, float)
    noisy = [lp.force is not None and lp.force.noise_factor is not None and np.any(lp.force.noise_factor) for lp in lps]
    if not any(noisy):
        return np.zeros(len(x)), None
    sizes = [lp.objective.bm.n_points for lp in lps]
    N = sum(sizes)
    offsets = np.concatenate([[0], np.cumsum(sizes)])
    blocks = []
    for i, (lp, has) in enumerate(zip(lps, noisy)):
        if not has:
            continue
        g = torque_per_newton(pm, lp, x)
        block = np.zeros((N, sizes[i]))
        block[offsets[i]:offsets[i + 1]] = g[:, None] * lp.force.noise_factor
        blocks.append(block)
    L = np.hstack(blocks)
    measured = np.concatenate([lp.objective.measured for lp in lps])
    fit = np.concatenate([lp.objective.peak_points for lp in lps])
    T = obj.torques(np.vstack([x, obj.problem.theoretical]))
    peaks = np.zeros((N, len(lps)))
    for i, lp in enumerate(lps):  # each log's filtered measured peak: what Eq. 28's peak term reads of the curve
        o = lp.objective
        peaks[offsets[i]:offsets[i + 1], i] = peak_row(o.bm.theta, o.measured, o.peak_points, lp.steps, *peak_filter, lp.ringing)
    D = np.column_stack([jacobian(obj, x), np.where(fit, measured - T[0], 0.0), np.where(fit, measured - T[1], 0.0), peaks])
    dirs = noise_directions(L, D)
    curves = [measured] + [measured + sg * d for d in dirs for sg in (1.0, -1.0)]
    X, _, _ = refit_batch([make(c) for c in curves], x, iterations)
    sd = np.sqrt(0.5 * np.sum((X[1:] - X[0]) ** 2, axis=0))
    names = obj.problem.names
    record = {"sd": dict(zip(names, map(float, sd))), "directions": int(len(dirs)),
              "logs": [{"log_index": i, "noise_of_sample_N": lp.force.sample_noise_N,  # index: a path may name a temporary folder
                        "noise_of_binned_point_N": lp.force.binned_noise_N} for i, (lp, has) in enumerate(zip(lps, noisy)) if has],
              "what": "the logged process force's noise carried into the estimate: the force channel's noise estimated from the "
                      "log (each turn's bin means' scatter from turn to turn), through the force curve's smoothing into the "
                      "model torque (per N of force at each grid point), then Eq. 28 refitted on the curve shifted one standard "
                      "deviation either way along each direction of that noise the estimator reads "
                      "(calibration/identification/force_noise.py)"}
    return sd, record
