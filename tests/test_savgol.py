"""The Savitzky-Golay smoothing of calibration/identification/savgol.py against scipy.signal's (an independent
implementation: a least-squares solve per window position and ndimage's convolution) and against the property that
defines it: a polynomial of the filter's order passes unchanged."""
import numpy as np
import pytest
from scipy.signal import savgol_coeffs, savgol_filter

from calibration.identification.savgol import coefficients, smooth_periodic, smooth_piece

CASES = [(5, 2), (11, 3), (15, 2), (21, 3), (31, 4)]


@pytest.mark.parametrize("window, order", CASES)
def test_smoothing_is_scipys(window, order):
    rng = np.random.default_rng(window)
    y = 1e4 * np.sin(np.linspace(0.0, 6.0, 360)) + rng.normal(0.0, 50.0, 360)
    Y = rng.normal(size=(97, 3))
    scale = np.max(np.abs(y))
    # scipy's own coefficients carry ~4e-13 of rounding at (31, 4) (ours agree with exact rationals to 1e-15)
    assert np.allclose(smooth_periodic(y, window, order), savgol_filter(y, window, order, mode="wrap"), rtol=0, atol=1e-11 * scale)
    assert np.allclose(smooth_piece(y[:120], window, order), savgol_filter(y[:120], window, order, mode="interp"), rtol=0,
                       atol=1e-11 * scale)
    assert np.allclose(smooth_piece(Y, window, order), savgol_filter(Y, window, order, mode="interp", axis=0), rtol=0, atol=1e-11)
    assert np.allclose(smooth_periodic(Y, window, order), savgol_filter(Y, window, order, mode="wrap", axis=0), rtol=0, atol=1e-11)
    assert np.allclose(coefficients(window, order), savgol_coeffs(window, order), rtol=0, atol=1e-12)


@pytest.mark.parametrize("window, order", CASES)
def test_a_polynomial_of_the_order_passes_unchanged(window, order):
    x = np.linspace(-1.3, 2.1, 80)
    p = np.polyval(np.arange(1.0, order + 2.0), x)  # degree = order
    assert np.allclose(smooth_piece(p, window, order), p, rtol=0, atol=1e-12 * np.max(np.abs(p)))
    assert coefficients(window, order).sum() == pytest.approx(1.0, abs=1e-14)


def test_a_window_that_is_no_window_is_refused():
    with pytest.raises(ValueError, match="odd"):
        coefficients(10, 3)
    with pytest.raises(ValueError, match="shorter"):
        smooth_piece(np.zeros(5), 7, 3)
