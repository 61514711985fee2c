"""The logged process force's noise: estimated from the log's turns, carried through the force curve's smoothing, and
into the design's predicted covariance (calibration/identification/force_noise.py, calibration/design/information.py)."""
from __future__ import annotations

import numpy as np
import pytest

from calibration.design.information import ForceNoise, PeakPin, force_covariance, pinned_covariance
from calibration.identification.process_force import logged_force
from calibration.identification.settings import CalibrationSettings
from press_model.kinematics import grid_heights
from press_model.model import PressModel

JOB = "cushion-test"


@pytest.fixture(scope="module")
def grid(press, job):
    pm = PressModel(press)
    theta = np.radians(np.arange(360.0))
    h, hd = grid_heights(pm, theta)
    return theta, (h, hd), np.asarray(job.process(h, hd), float), CalibrationSettings.from_job(job).process_force


def _turns(F, sigma, counts, rng):
    """Each turn's bin means of a force channel with white noise ``sigma`` per sample, and the stroke mean interpolated."""
    means = F[None, :] + rng.normal(0.0, 1.0, counts.shape) * sigma / np.sqrt(counts)
    binned = np.sum(means * counts, axis=0) / np.sum(counts, axis=0)
    return means, binned


def test_the_force_channel_noise_is_estimated_from_the_turns_and_carried_through_the_smoothing(job, grid):
    """Against brute force: the curve made again from many redraws of the channel's noise scatters, point by point, as
    the noise factor says; the noise per sample is the one the turns were drawn with (nothing of the generator is read)."""
    theta, heights, F, st = grid
    sigma = 0.02 * F.max()
    rng = np.random.default_rng(3)
    counts = rng.integers(5, 9, size=(3, F.size))  # samples a turn puts in each 1-deg bin (500 Hz, 10-17 spm)
    means, binned = _turns(F, sigma, counts, rng)
    lf = logged_force("log", theta, means, heights, job.process, st, binned, (means, counts))
    assert abs(lf.sample_noise_N / sigma - 1.0) < 0.1
    predicted = np.sqrt(np.sum(lf.noise_factor ** 2, axis=1))
    curves = []
    for _ in range(150):
        m, b = _turns(F, sigma, counts, rng)
        curves.append(logged_force("log", theta, m, heights, job.process, st, b).curve)
    seen = np.std(np.array(curves), axis=0, ddof=1)
    loaded = predicted > 0.0
    assert np.all(seen[~loaded] == 0.0)  # the unloaded slide's pieces are set to zero: no noise there
    ratio = np.sqrt(np.mean(seen[loaded] ** 2) / np.mean(predicted[loaded] ** 2))
    assert 0.9 < ratio < 1.1
    assert np.corrcoef(seen[loaded], predicted[loaded])[0, 1] > 0.8  # the shape along the turn too (the pieces' ends)


def test_the_designs_force_covariance_is_that_of_the_pinned_least_squares_estimate():
    """A linear model y = A x + noise fitted with the model's force F + e in place of F (torque G e more), its peak
    row pinned to the measured peak: the estimates' covariance over many draws against pinned_covariance +
    force_covariance."""
    rng = np.random.default_rng(7)
    n, k, W = 60, 3, 20
    A = rng.normal(size=(n, k))
    Lg = rng.normal(size=(n, W)) * 0.3  # diag(G) L_F: the model torque's noise per unit of the force noise's coordinates
    p = 17  # the pinned peak's grid point
    a, sig, sp = A[p], 1.0, 0.4
    M = np.linalg.inv(A.T @ A)
    cov = sig ** 2 * M
    E = A.T @ Lg / sig ** 2  # information's share: A^T diag(g) L_F / (s^2 c)
    predicted = pinned_covariance(cov, PeakPin(a, sp)) + force_covariance(cov, ForceNoise(E, Lg[p]), PeakPin(a, sp))
    X = []
    for _ in range(20000):
        w = rng.normal(size=W)
        y = rng.normal(size=n) * sig - Lg @ w  # the truth is x = 0; the model's force noise adds Lg w to its torque
        xl = M @ (A.T @ y)
        g = M @ a
        target = rng.normal() * sp - Lg[p] @ w  # the model's peak a x + (Lg w)_p pinned to the measured peak (noise sp)
        X.append(xl - g * (a @ xl - target) / (a @ g))
    seen = np.cov(np.array(X).T)
    assert np.allclose(np.sqrt(np.diag(seen)), np.sqrt(np.diag(predicted)), rtol=0.03)
    assert not np.allclose(np.diag(predicted), np.diag(pinned_covariance(cov, PeakPin(a, sp))), rtol=0.1)  # the force matters here
