"""Savitzky-Golay smoothing (Savitzky and Golay, Anal. Chem. 36, 1964): each sample replaced by the value there of the
least-squares polynomial of a given order through the window of samples around it; round the turn (the window wraps,
:func:`smooth_periodic`) or along a piece whose first and last half-windows take the polynomial of its first and last
whole window (:func:`smooth_piece`). Along axis 0; the values keep their unit.

numpy only: scipy.signal's import brings scipy.stats with it, ~0.6 s of CPU, a tenth of `calibrate` on one log.
"""
from __future__ import annotations

from functools import lru_cache

import numpy as np


@lru_cache(maxsize=None)
def fit_matrix(window: int, order: int) -> np.ndarray:
    """(window, window), read-only: row i gives the value at the window's i-th sample of the least-squares polynomial of
    degree ``order`` through the window's samples (the projection V pinv(V), V the Vandermonde matrix of the sample
    positions, centred and scaled to [-1, 1] so that it is well conditioned; the projection does not depend on that)."""
    if window % 2 != 1 or not 0 <= order < window:
        raise ValueError(f"a Savitzky-Golay window must be odd and longer than its order, not {window} for order {order}")
    half = window // 2
    x = (np.arange(window, dtype=float) - half) / max(half, 1)
    V = x[:, None] ** np.arange(order + 1)
    H = V @ np.linalg.pinv(V)
    H.setflags(write=False)
    return H


def coefficients(window: int, order: int) -> np.ndarray:
    """(window,) the weights that give the smoothed value at a window's middle sample from its samples (dimensionless;
    symmetric, summing to 1)."""
    return fit_matrix(window, order)[window // 2]


def smooth_periodic(y: np.ndarray, window: int, order: int) -> np.ndarray:
    """``y`` (n, ...) smoothed along axis 0 as one period: the window wraps round from the last sample to the first."""
    y = np.asarray(y, dtype=float)
    c, half = coefficients(window, order), window // 2
    out = np.zeros_like(y)
    for j, w in enumerate(c):
        out += w * np.roll(y, half - j, axis=0)  # y[(i + j - half) mod n] at i
    return out


def smooth_piece(y: np.ndarray, window: int, order: int) -> np.ndarray:
    """``y`` (n, ...) with n >= ``window`` smoothed along axis 0 as a piece: the middle samples as the window's middle
    sample, the first and last half-windows by the polynomial of the first and last whole window."""
    y = np.asarray(y, dtype=float)
    n, half = y.shape[0], window // 2
    if n < window:
        raise ValueError(f"a piece of {n} samples is shorter than the Savitzky-Golay window of {window}")
    H = fit_matrix(window, order)
    c = H[half]
    out = np.empty_like(y)
    inner = np.zeros_like(y[half:n - half])
    for j, w in enumerate(c):
        inner += w * y[j:n - window + 1 + j]
    out[half:n - half] = inner
    out[:half] = np.tensordot(H[:half], y[:window], axes=1)
    out[n - half:] = np.tensordot(H[window - half:], y[n - window:], axes=1)
    return out
