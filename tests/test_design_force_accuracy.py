"""The logged force's stated accuracy in the design (calibration/design/information.py, runs.py): the covariance it adds
to a prediction is that of the refit `calibrate` makes with the force a step off, and the search's criterion carries it."""
from __future__ import annotations

import numpy as np
import pytest

import itertools

from calibration.design.information import (ForceNoise, PeakPin, accuracy_factor, carried_covariance, filter_gain,
                                            filter_gain_key, per_standard_deviation)
from calibration.design.runs import RunStack, criterion, exchange
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
    acc = per_standard_deviation(ForceNoise(E, g[p] * accuracy_factor(curve)[p]), st)
    F, pin = A.T @ A, PeakPin(a, 0.3)
    added = carried_covariance(F, k, pin, acc) - carried_covariance(F, k, pin)
    assert np.sqrt(np.diag(added)) == pytest.approx(expected, rel=1e-7)
    assert np.all(expected > 0.0)


def test_the_criterion_carries_the_accuracy_as_the_covariance_it_adds():
    """Unpinned, the criterion with the accuracy's terms E is the log det of the inverse of F^-1 plus, on the k
    parameters, Fk^-1 Ek Ek^T Fk^-1 (Fk the parameters' block: the refit holds the recording's delay and offset; formed
    and inverted directly), and a design whose force moves the estimates scores lower than without it."""
    rng = np.random.default_rng(5)
    m, k = 6, 4
    B = rng.normal(size=(40, m))
    F = B.T @ B
    E = rng.normal(size=(m, 2)) * 3.0
    Fk = np.linalg.inv(F[:k, :k])
    C = np.linalg.inv(F)
    C[:k, :k] += Fk @ E[:k] @ E[:k].T @ Fk
    direct = -np.linalg.slogdet(C)[1]
    with_acc = criterion(F[None, None], k, 1.0, None, ForceNoise(E[None, None], np.zeros((1, 1, 2))))[0]
    assert with_acc == pytest.approx(direct, rel=1e-9)
    assert with_acc < criterion(F[None, None], k, 1.0)[0] - 0.1


def test_the_exchange_with_pins_and_the_accuracy_finds_the_brute_force_best_pair():
    """Candidates with a model peak (the larger pins the pair's estimate) and a logged force: the exchange's pair scores
    as the best of all pairs, each pair scored by the criterion of its own sums and the pin of its larger peak."""
    rng = np.random.default_rng(3)
    C, D, m, k = 8, 2, 5, 3
    A = rng.normal(size=(C, D, 7, m)) * rng.uniform(0.2, 2.0, size=(C, D, 1, m))  # each candidate's scaled columns per draw
    info = np.swapaxes(A, -1, -2) @ A
    stack = RunStack(info, rng.normal(size=(C, D, m, 2)), rng.normal(size=(C, D, 2)), rng.uniform(1.0, 2.0, (C, D)),
                     rng.normal(size=(C, D, m)), rng.uniform(0.5, 2.0, (C, D)))

    def score(i, j):
        top = np.where(stack.peak[i] >= stack.peak[j], i, j)  # per draw the run of the larger peak
        d = np.arange(D)
        pin = PeakPin(stack.rows[top, d][None], stack.sigma[top, d][None])
        acc = ForceNoise((stack.E[i] + stack.E[j])[None], stack.acc_peak[top, d][None])
        return criterion((info[i] + info[j])[None], k, 0.9, pin, acc)[0]

    best = max(score(i, j) for i, j in itertools.combinations_with_replacement(range(C), 2))
    got = exchange(stack, 2, k, 0.9)
    assert score(*got) == pytest.approx(best)


def test_points_of_one_filter_gain_key_have_one_gain():
    """The search's memo of the peak filter's gain (calibration/design/runs.py): points whose key is equal, on random
    force steps and peak points, have the gain :func:`filter_gain` computes for each directly; the keys tell pieces'
    starts, ends and centres apart (their gains differ)."""
    rng = np.random.default_rng(2)
    theta = np.radians(np.arange(360.0))
    gains: dict = {}
    for _ in range(40):
        steps = sorted(rng.uniform(0.0, 2.0 * np.pi, rng.integers(1, 4)))
        i = int(rng.integers(0, 360)) if rng.random() < 0.5 else (int(np.degrees(steps[0])) + int(rng.integers(0, 9))) % 360
        gains.setdefault(filter_gain_key(theta, steps, i, 15.0, 2), []).append(filter_gain(theta, steps, i, 15.0, 2))
    for key, g in gains.items():
        assert np.ptp(g) < 1e-12, (key, g)
    kinds = {k[0] for k in gains}
    assert {"start", "centre"} <= kinds
    assert len({round(g[0], 9) for g in gains.values()}) > 3
