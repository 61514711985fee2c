"""SYNTHETIC production for the drift chart: each stroke's efficiency ratio (:func:`monitoring.strokes.efficiency_ratio`)
on torque curves of the batch model plus white noise, a million strokes in seconds. NOT measured data: every result
made from it records ``SYNTHETIC``, the seed and the truth (the drive efficiency of each stroke).

The curves are the batch model's motor torque of the true parameters with eta_gear as the stroke's own (a step or a
ramp of wear), on the log's crank motion and the job's process force; the noise per grid point is the log's channel
noise (:func:`monitoring.tonnage.channel_noise`). The ratio is linear in the curve, so each chunk of strokes is one
matrix product.
"""
from __future__ import annotations

import numpy as np

from press_model.batch import BatchModel, motor_torques

CHUNK = 50_000  # strokes per draw: 50,000 x ~100 motoring points of doubles, 40 MB


def eta_curves(bm: BatchModel, parameters: dict, etas: np.ndarray) -> np.ndarray:
    """(E, n) N m per motor: the batch model's motor torque at ``parameters`` (SI) with eta_gear at each of ``etas``."""
    return motor_torques(bm, [{**parameters, "eta_gear": float(e)} for e in etas])


def production_ratios(curves: np.ndarray, etas: np.ndarray, eta_of_stroke: np.ndarray, model: np.ndarray, motoring: np.ndarray,
                      noise_Nm: float, seed: int) -> np.ndarray:
    """(S,): the efficiency ratio of each SYNTHETIC stroke whose true eta_gear is ``eta_of_stroke`` (S,): its clean ratio
    interpolated between the ``curves`` at ``etas`` (increasing), plus the ratio of white noise of ``noise_Nm`` per point
    (drawn in chunks from ``seed``)."""
    m = model[motoring]
    clean = curves[:, motoring] @ m / float(m @ m)
    out = np.interp(eta_of_stroke, etas, clean)
    rng = np.random.default_rng(seed)
    for start in range(0, len(out), CHUNK):
        stop = min(start + CHUNK, len(out))
        out[start:stop] += rng.normal(0.0, noise_Nm, size=(stop - start, m.size)) @ m / float(m @ m)
    return out
