"""The logged force's stated accuracy in the design (calibration/design/information.py, runs.py): the covariance it adds
to a prediction is that of the refit `calibrate` makes with the force a step off, and the search's criterion carries it."""
from __future__ import annotations

import numpy as np
import pytest

from calibration.design.information import ForceAccuracy, ForceNoise, PeakPin, accuracy_covariance, accuracy_factor
from calibration.design.runs import criterion
from calibration.identification.process_force import FORCE_STEP, ProcessForceSection


def _pinned_fit(A, y, a, target):
    """argmin |y - A x|^2 subject to a x = target, from the KKT system (not the design's rank-one formula)."""
    k = A.shape[1]
    K = np.block([[2.0 * A.T @ A, a[:, None]], [a[None, :], np.zeros((1, 1))]])
    return np.linalg.solve(K, np.concatenate([2.0 * A.T @ y, [target]]))[:k]


def test_the_accuracy_covariance_is_that_of_the_refit_with_the_force_a_step_off():
    """A linear model y = A x whose process force adds G f to the torque, its model peak (row p) pinned to the measured
    peak: fitted with the logged force a step higher in scale (and, apart, offset by a step of its peak where on), the
    estimate moves; each move times the stated accuracy over the step, over the normal 97.5 % quantile, the two in
    quadrature, is the standard deviation `calibrate` adds. The prediction's diagonal is that, parameter by parameter."""
    rng = np.random.default_rng(11)
    n, k, p = 80, 4, 23
    A = rng.normal(size=(n, k))
    curve = np.where(np.arange(n) < 30, rng.uniform(0.5, 1.0, n), 0.0)  # N: a force on over part of the turn
    g = rng.normal(size=n) * 0.8  # N m per N of force
    st = ProcessForceSection(logged_scale_accuracy=0.015, logged_offset_accuracy=0.005)
    a = A[p]
    moves = []
    for step in accuracy_factor(curve).T:  # the force one step higher in scale, then offset by a step of its peak
        extra = g * step  # what the model torque gains with it
        moves.append(_pinned_fit(A, -extra, a, -extra[p]))  # truth x = 0: the log is the model with the true force
    q = 1.959963984540054
    expected = np.hypot(np.abs(moves[0]) * 0.015, np.abs(moves[1]) * 0.005) / FORCE_STEP / q
    E = A.T @ (g[:, None] * accuracy_factor(curve))  # unit noise variance
    acc = ForceAccuracy(ForceNoise(E, g[p] * accuracy_factor(curve)[p]), st)
    cov = accuracy_covariance(np.linalg.inv(A.T @ A), acc, PeakPin(a, 0.3), np.ones(k))
    assert np.sqrt(np.diag(cov)) == pytest.approx(expected, rel=1e-9)
    assert np.all(expected > 0.0)


def test_the_criterion_carries_the_accuracy_as_the_covariance_it_adds():
    """The criterion with the accuracy's terms E is the log det of the inverse of F^-1 + F^-1 E E^T F^-1 (formed and
    inverted directly), and a design whose force moves the estimates scores lower than without it."""
    rng = np.random.default_rng(5)
    m, k = 6, 4
    B = rng.normal(size=(40, m))
    F = B.T @ B
    E = rng.normal(size=(m, 2)) * 3.0
    C = np.linalg.inv(F) + np.linalg.inv(F) @ E @ E.T @ np.linalg.inv(F)
    direct = -np.linalg.slogdet(C)[1]
    with_acc = criterion(F[None, None], k, 1.0, E[None, None])[0]
    assert with_acc == pytest.approx(direct, rel=1e-10)
    assert with_acc < criterion(F[None, None], k, 1.0)[0] - 0.1
