"""The measured peak's Savitzky-Golay filter made once as a linear map (calibration/identification/peak.py) filters a
piece as scipy's own ``savgol_filter(mode="interp")`` does: the same centred fit inside, the polynomial fitted to each
end's window at the ends; and the whole periodic curve as ``mode="wrap"``."""
import numpy as np
import pytest
from scipy.signal import savgol_filter

from calibration.identification.peak import _savgol_piece, filter_curve


@pytest.mark.parametrize("length, win, order", [(300, 21, 3), (45, 45, 3), (500, 31, 2), (100, 11, 4), (40, 5, 0)])
def test_a_piece_is_filtered_as_scipy_filters_it(length, win, order):
    rng = np.random.default_rng(length)
    x = 1000.0 * rng.normal(size=length) + 5e4 * np.sin(np.linspace(0.0, 3.0, length))
    ours, scipys = _savgol_piece(x, win, order), savgol_filter(x, win, order, mode="interp")
    half = win // 2
    assert np.array_equal(ours[half:-half], scipys[half:-half])  # the same convolution, the same coefficients
    assert np.max(np.abs(ours - scipys)) <= 1e-12 * np.max(np.abs(scipys))  # the ends: the same fit, to rounding


def test_a_curve_without_steps_is_filtered_round_the_turn():
    th = np.linspace(0.0, 2.0 * np.pi, 720, endpoint=False)
    curve = 3e4 * np.sin(th) ** 3 + 500.0 * np.random.default_rng(1).normal(size=th.size)
    assert np.array_equal(filter_curve(th, curve, [], 21.0, 3), savgol_filter(curve, 43, 3, mode="wrap"))
