"""The joint (simultaneous) 95 % region beside the per-parameter intervals: it holds every per-parameter interval,
it is the per-parameter interval for one parameter, and it holds all the truths at once at its level on a cheap
linear-Gaussian problem with known truth (many replicates, SYNTHETIC, seeds in the tests), where the per-parameter
intervals, taken together, do not. The CLI-level check that calibrated.json carries it is
test_calibration_peak_bootstrap_validation.py::test_calibrated_json_carries_the_joint_region (it reuses that file's run).
"""
from types import SimpleNamespace

import numpy as np
import pytest

from calibration.identification.bootstrap import order_statistic_quantiles, simultaneous_extra
from calibration.identification.uncertainty import analyse, sidak_level

LEVEL = 0.95
REFITS = 40  # the shipped job's [calibration.bootstrap] refits


def _basic_and_joint(X, x_hat, level=LEVEL):
    """The basic interval of refits X about x_hat and the joint region, as parametric_bootstrap builds them."""
    q_lo, q_hi = order_statistic_quantiles(X, level)
    low_b, high_b = 2.0 * x_hat - q_hi, 2.0 * x_hat - q_lo
    extra = simultaneous_extra(X, level)
    return (low_b, high_b), (low_b - extra, high_b + extra), extra


def test_joint_region_holds_each_interval_and_is_the_interval_for_one_parameter():
    rng = np.random.default_rng(11)
    C = np.array([[1.0, 0.95, 0.2], [0.95, 1.0, 0.1], [0.2, 0.1, 1.0]]) * np.outer([1e-2, 3.0, 1e3], [1e-2, 3.0, 1e3])
    x_hat = np.array([0.9, 50.0, 3e4])
    for _ in range(20):
        X = x_hat + rng.standard_normal((REFITS, 3)) @ np.linalg.cholesky(C).T + rng.standard_normal(3) * [1e-2, 3.0, 1e3]
        (lo, hi), (jlo, jhi), extra = _basic_and_joint(X, x_hat)
        assert np.all(extra > 0.0) and np.all(jlo < lo) and np.all(jhi > hi)  # three at once need more than one at a time
        for j in range(3):  # one parameter alone: the joint region is its interval
            (lo1, hi1), (jlo1, jhi1), e1 = _basic_and_joint(X[:, [j]], x_hat[[j]])
            assert e1[0] == 0.0 and (jlo1[0], jhi1[0]) == (lo1[0], hi1[0]) == (lo[j], hi[j])
    assert sidak_level(LEVEL, 1) == LEVEL and sidak_level(LEVEL, 6) ** 6 == pytest.approx(LEVEL, rel=1e-12)


def _linear_objective(A, y, span):
    """A stand-in for calibration.identification.problem.Objective on the linear model y = A x + noise (what analyse reads)."""
    k = A.shape[1]
    problem = SimpleNamespace(names=tuple(f"p{j}" for j in range(k)), low=-span * np.ones(k), high=span * np.ones(k))
    # every point enters Y_RMSE (no die-contact window on a linear model)
    return SimpleNamespace(problem=problem, torques=lambda P: np.atleast_2d(P) @ A.T, residuals=lambda x: A @ x - y,
                           peak_points=np.ones(len(y), bool))


def test_jacobian_joint_region_covers_all_truths_at_its_level():
    """SYNTHETIC: y = A truth + N(0, 1), n = 80, k = 4, 600 replicates (seed 5): the Sidak box of analyse holds all
    four truths in about 95 % of replicates; the per-parameter intervals, all four at once, near 0.95^4 = 81 %."""
    rng = np.random.default_rng(5)
    n, k, reps = 80, 4, 600
    A = rng.standard_normal((n, k))
    truth = np.array([1.0, -2.0, 0.5, 3.0])
    joint = each = 0
    for _ in range(reps):
        y = A @ truth + rng.standard_normal(n)
        x_hat = np.linalg.lstsq(A, y, rcond=None)[0]
        u = analyse(_linear_objective(A, y, 100.0), x_hat, LEVEL)
        assert np.all(u.joint_low <= u.low) and np.all(u.joint_high >= u.high)
        joint += np.all((u.joint_low <= truth) & (truth <= u.joint_high))
        each += np.all((u.low <= truth) & (truth <= u.high))
    se = np.sqrt(LEVEL * (1 - LEVEL) / reps)
    assert LEVEL - 3 * se <= joint / reps <= 0.99  # covers at its level (the AR(1) inflation of analyse errs a little wide)
    assert each / reps < LEVEL - 5 * se  # the per-parameter intervals taken together do not


def test_bootstrap_joint_region_covers_all_truths_at_its_level():
    """SYNTHETIC: y = A truth + N(0, 1), n = 400 (about a drive log's grid), k = 6 with two correlated columns, 4000
    replicates (seed 9), each with 40 residual-bootstrap refits (least squares is linear, so a refit is one product):
    the joint region from the refits (the functions parametric_bootstrap uses) holds all six truths in about 95 % of
    replicates, each basic interval its own truth in about 95 %, and all six basic intervals at once far less."""
    rng = np.random.default_rng(9)
    n, k, reps = 400, 6, 4000
    A = rng.standard_normal((n, k))
    A[:, 1] = 0.9 * A[:, 0] + np.sqrt(1 - 0.81) * A[:, 1]  # correlated estimates, as on a drive log
    pinv = np.linalg.pinv(A)
    truth = np.linspace(-1.0, 2.0, k)
    joint = each_all = 0
    each = np.zeros(k)
    for _ in range(reps):
        y = A @ truth + rng.standard_normal(n)
        x_hat = pinv @ y
        e = y - A @ x_hat
        X = x_hat + (e[rng.integers(0, n, size=(REFITS, n))] @ pinv.T)  # refits on x_hat's curve plus resampled residuals
        (lo, hi), (jlo, jhi), _ = _basic_and_joint(X, x_hat)
        hit = (lo <= truth) & (truth <= hi)
        each += hit
        each_all += hit.all()
        joint += np.all((jlo <= truth) & (truth <= jhi))
    se = np.sqrt(LEVEL * (1 - LEVEL) / reps)
    assert abs(joint / reps - LEVEL) <= 3 * se
    assert np.all(np.abs(each / reps - LEVEL) <= 3 * np.sqrt(LEVEL * (1 - LEVEL) / reps))
    assert each_all / reps < LEVEL - 10 * se
