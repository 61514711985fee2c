"""Uncertainty of calibrated parameters from the residual Jacobian at the optimum.

Linearised least squares: with r(P) the predicted-minus-measured torque on the n grid points and J its
Jacobian at P*, cov(P) = s^2 (J^T J)^-1, s^2 = |r|^2 / (n - k). The residuals of a drive log are not
white (the unmodelled die-contact ringing and the averaging make neighbours alike), which would make
plain intervals too narrow; the covariance is therefore inflated by (1 + rho1) / (1 - rho1), the
AR(1) effective-sample-size factor of the residuals' lag-1 autocorrelation rho1 (when positive).

Two questions, two answers. Each per-parameter interval (``low``, ``high``: t-quantile at ``level``) holds its own
parameter's truth with probability ``level``, one parameter at a time; with k parameters some interval misses far
more often (six independent exact 95 % intervals all hold only 0.95^6 = 74 % of the time). The *joint region*
(``joint_low``, ``joint_high``) is a box that holds every truth at once with probability at least ``level``: the
same intervals at the Sidak level ``level ** (1 / k)`` per parameter (:func:`sidak_level`). Sidak rather than
Scheffe (the ellipsoid's shadow, sqrt(k F) wide: 3.55 against Sidak's 2.63 standard errors for six normal
estimates, and a box is what is reported) and rather than Bonferroni (1 - (1 - level) / k, always a little wider: 2.64): for a
normal (or t) estimate the box at the Sidak level holds all k at once with probability >= ``level`` whatever
the correlation (Sidak 1967, JASA 62, 626), equality for independent estimates, and it is the per-parameter
interval itself for k = 1. With the strong correlations of a drive log it is conservative (the exact max-|t|
quantile of the correlated estimates is smaller), which is the safe side for a region that promises "all at once".
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import stats

from calibration.identification.problem import Objective

_REL_STEP = 1e-4  # central-difference step as a fraction of each parameter's range: far above round-off, far below curvature


@dataclass(frozen=True)
class Uncertainty:
    names: tuple[str, ...]
    x: np.ndarray
    std: np.ndarray  # standard errors, SI units
    low: np.ndarray  # 95 % interval, clipped to the parameter bounds
    high: np.ndarray
    correlation: np.ndarray  # (k, k)
    level: float  # confidence level of the intervals
    inflation: float  # the AR(1) factor applied to the covariance
    lag1: float
    dof: int
    statements: tuple[str, ...]  # which parameters this experiment can and cannot tell apart
    joint_low: np.ndarray | None = None  # the joint (simultaneous) region at ``level``: a box holding every truth at once
    joint_high: np.ndarray | None = None
    joint_level: float | None = None  # the per-parameter level of the box's sides (Sidak)


def sidak_level(level: float, k: int) -> float:
    """The per-parameter confidence level whose k intervals hold all k truths at once with probability >= ``level``
    for normal or t estimates of any correlation (Sidak): ``level ** (1 / k)``; ``level`` itself for k = 1."""
    return float(level) ** (1.0 / max(int(k), 1))


def jacobian(obj: Objective, x: np.ndarray) -> np.ndarray:
    """d(residual)/d(parameter) (n, k) at x by central differences, all 2 k sets in one batch (N m per SI unit); zero
    outside the objective's peak points, as the residual (:meth:`calibration.identification.problem.Objective.residuals`)."""
    return curve_jacobian(obj.torques, obj.problem.high - obj.problem.low, x) * obj.peak_points[:, None]


def curve_jacobian(torques, span: np.ndarray, x: np.ndarray) -> np.ndarray:
    """d(curve)/d(parameter) (n, k) at x by central differences of ``torques(P (B, k)) -> (B, n)``, steps a fixed
    fraction of each parameter's range ``span``, all 2 k sets in one call (N m per SI unit)."""
    P, h = central_sets(span, x)
    return central_difference(torques(P), h)


def central_sets(span: np.ndarray, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The 2 k parameter sets (2 k, k) of :func:`curve_jacobian` at x (x + h_j e_j, x - h_j e_j for each j) and the steps h (k,)."""
    x = np.asarray(x, float)
    h = _REL_STEP * np.asarray(span, float)
    k = len(x)
    P = np.tile(x, (2 * k, 1))
    for j in range(k):
        P[2 * j, j] += h[j]
        P[2 * j + 1, j] -= h[j]
    return P, h


def central_difference(T: np.ndarray, h: np.ndarray) -> np.ndarray:
    """d(curve)/d(parameter) (n, k) from the curves T (2 k, n) of :func:`central_sets`' sets and their steps h."""
    return ((T[0::2] - T[1::2]) / (2.0 * h[:, None])).T


def analyse(obj: Objective, x: np.ndarray, level: float = 0.95, corr_limit: float = 0.9, rel_limit: float = 0.5) -> Uncertainty:
    """Intervals (``level``), correlation and identifiability at x.

    A parameter is called *not identified* when its interval is wider than ``rel_limit`` of its
    calibration range; a pair is called *not separable* when |correlation| > ``corr_limit``.
    """
    p = obj.problem
    used = obj.peak_points
    r = obj.residuals(x)
    J = jacobian(obj, x)
    n, k = int(used.sum()), J.shape[1]
    dof = max(n - k, 1)
    s2 = float(r @ r) / dof
    rc = r[used] - r[used].mean()
    lag1 = float(np.dot(rc[1:], rc[:-1]) / np.dot(rc, rc)) if np.dot(rc, rc) > 0 else 0.0
    inflation = (1.0 + lag1) / (1.0 - lag1) if 0.0 < lag1 < 1.0 else 1.0
    # scale columns so the normal matrix is well conditioned whatever the units (kg vs efficiency)
    scale = p.high - p.low
    Js = J * scale
    cov_s = np.linalg.pinv(Js.T @ Js) * s2 * inflation
    cov = cov_s * np.outer(scale, scale)
    std = np.sqrt(np.clip(np.diag(cov), 0.0, None))
    q = stats.t.ppf(0.5 + level / 2.0, dof)
    lo, hi = np.maximum(x - q * std, p.low), np.minimum(x + q * std, p.high)
    joint_level = sidak_level(level, k)
    qj = stats.t.ppf(0.5 + joint_level / 2.0, dof)
    jlo, jhi = np.maximum(x - qj * std, p.low), np.minimum(x + qj * std, p.high)
    with np.errstate(invalid="ignore", divide="ignore"):
        corr = cov / np.outer(std, std)
    corr = np.where(np.isfinite(corr), corr, 0.0)
    np.fill_diagonal(corr, 1.0)
    return Uncertainty(p.names, np.asarray(x, float), std, lo, hi, corr, level, inflation, lag1, dof,
                       tuple(_statements(p.names, std, scale, corr, corr_limit, rel_limit, q)), jlo, jhi, joint_level)


def _statements(names, std, scale, corr, corr_limit, rel_limit, q) -> list[str]:
    out = []
    width = 2.0 * q * std / scale
    good = [n for n, w in zip(names, width) if w <= rel_limit]
    poor = [f"{n} (interval {100 * w:.0f} % of its range)" for n, w in zip(names, width) if w > rel_limit]
    if good:
        out.append("identified by this experiment: " + ", ".join(good) + ".")
    if poor:
        out.append("not identified by this experiment: " + ", ".join(poor) + ".")
    k = len(names)
    pairs = [(names[i], names[j], corr[i, j]) for i in range(k) for j in range(i + 1, k) if abs(corr[i, j]) > corr_limit]
    for a, b, c in pairs:
        out.append(f"{a} and {b} cannot be told apart (correlation {c:+.2f}): the experiment sees mainly a combination of them.")
    if not pairs:
        out.append(f"no pair of parameters is correlated beyond |{corr_limit}|: the experiment tells them apart.")
    return out
