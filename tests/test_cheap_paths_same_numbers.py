"""Paths that spare a calibration work give the numbers of the full computation to the bit: the crank motion's window
sums from the widest window's samples and numpy's power on x^2 and up only, the batch model's features of sets sharing
their centre-of-mass distances without np.unique, a model chunk without Eq. 16."""
from __future__ import annotations

import numpy as np
import pytest

from calibration.identification.speed_fit import _window_sums
from press_model.batch import build_batch_model, evaluate_chunk, features
from press_model.press_data import load_press

STEP_DEG = 5.0  # tests/test_model_curves.py's grid: its batch model from the disk cache; what is tested holds at every angle


def _whole_table(x, y, h0, h_max, ratio, degree):
    """The window sums as first written: every sample of the reach raised to every power 0 .. 2p - 2 by numpy."""
    p = max(int(degree), 2) + 1
    hs = h0 * ratio ** np.arange(int(np.floor(np.log(max(h_max / h0, 1.0)) / np.log(ratio))) + 1)
    counts = np.searchsorted(np.abs(x), hs * (1.0 + 1e-12), side="right")
    hs, counts = hs[counts >= p], counts[counts >= p]
    xp = x[:, None] ** np.arange(2 * p - 1)[None, :]
    s = np.cumsum(xp, axis=0)[counts - 1]
    r = np.cumsum(xp[:, :p] * y[:, None], axis=0)[counts - 1]
    scale = hs[:, None] ** -np.arange(2 * p - 1)[None, :]
    return hs, (s * scale)[:, np.add.outer(np.arange(p), np.arange(p))], r * scale[:, :p]


@pytest.mark.parametrize("degree", [2, 3])
def test_window_sums_are_those_of_the_whole_power_table(degree):
    rng = np.random.default_rng(11)
    for reach in (0.05, 0.4, np.pi):
        x = rng.uniform(-reach, reach, 3000)
        x = x[np.argsort(np.abs(x), kind="stable")]
        y = 2.0 + 0.3 * np.sin(7.0 * x) + 0.01 * rng.standard_normal(x.size)
        for got, want in zip(_window_sums(x, y, 0.004, reach, np.sqrt(2.0), degree),
                             _whole_table(x, y, 0.004, reach, np.sqrt(2.0), degree)):
            assert got.shape == want.shape and got.tobytes() == want.tobytes()


@pytest.fixture(scope="module")
def bm(cushion):
    job, motion = cushion
    return build_batch_model(load_press(), motion, job.process, step_deg=STEP_DEG)


def test_features_of_sets_sharing_their_com_distances_are_those_of_the_sorted_path(bm):
    rng = np.random.default_rng(3)
    X = np.tile(bm.nominal, (7, 1))
    X[:, :] += rng.random(X.shape) * 0.1 * (bm.high - bm.low)  # every column moved, the distances too
    X[1:6, :] = X[0]  # six rows share everything, so their distances
    X[1:6, bm.names.index("m8")] += np.arange(1, 6)  # but a mass
    shared = features(bm, X[:6])[0]  # one distance row: the short path
    mixed = features(bm, X)[0]  # the seventh row's own distances: np.unique's path
    assert shared.tobytes() == mixed[:6].tobytes()


def test_a_chunk_without_eq16_has_the_crank_torque_of_one_with_it(bm):
    X = np.tile(bm.nominal, (3, 1)) + np.linspace(0.0, 0.2, 3)[:, None] * (bm.high - bm.nominal)
    full, crank_only = evaluate_chunk(bm, X), evaluate_chunk(bm, X, motor=False)
    assert crank_only.motor_torque is None and full.motor_torque.shape == X.shape[:1] + (bm.n_points,)
    assert crank_only.crank_torque.tobytes() == full.crank_torque.tobytes()
    assert crank_only.iterations.tobytes() == full.iterations.tobytes()


def test_a_crank_motion_fitted_again_is_the_one_remembered_with_the_same_numbers():
    from types import SimpleNamespace

    from calibration.identification.settings import CalibrationSettings
    from calibration.identification.speed_fit import crank_motion, local_speed

    rng = np.random.default_rng(4)
    t = np.arange(1500) / 500.0  # three strokes at 2 rad/s, 500 Hz: a SYNTHETIC speed column with a ripple and noise
    u = 2.0 * t + 0.05 * np.sin(2.0 * t)
    w = 2.0 + 0.1 * np.cos(2.0 * t) + 0.002 * rng.standard_normal(t.size)
    theta = np.linspace(0.0, 2.0 * np.pi, 72, endpoint=False)
    cs = CalibrationSettings()
    log = SimpleNamespace(theta=theta, speed_samples=np.column_stack([t, u, w]))
    first = crank_motion(log, cs)
    again = crank_motion(SimpleNamespace(theta=theta.copy(), speed_samples=log.speed_samples.copy()), cs)
    fresh = local_speed(theta, log.speed_samples, cs.adequacy.level, cs.speed)
    assert again is first and not first.speed.flags.writeable and theta.flags.writeable  # the log's own grid untouched
    for name in ("theta", "speed", "slope", "window", "covariance"):
        assert getattr(first, name).tobytes() == getattr(fresh, name).tobytes(), name
    other = crank_motion(SimpleNamespace(theta=theta, speed_samples=np.column_stack([t, 1.01 * u, 1.01 * w])), cs)
    assert other is not first and not np.array_equal(other.speed, first.speed)
