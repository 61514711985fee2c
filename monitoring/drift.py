"""Drift over strokes: a two-sided CUSUM on a standardised per-stroke statistic, its decision limit set for a stated
in-control average run length (ARL: strokes between false alarms).

The limit comes from Siegmund's approximation of the one-sided CUSUM's ARL for a normal statistic with unit variance
(Siegmund 1985; Montgomery, *Introduction to Statistical Quality Control*, Sec. 9.1):

    ARL(delta) = (exp(-2 D b) + 2 D b - 1) / (2 D^2),  D = delta - k,  b = h + 1.166  (b^2 at D = 0),

and the two sides' alarms add (1/ARL = 1/ARL+ + 1/ARL-), so each side is set to twice the stated ARL. The in-control
mean and standard deviation come from a baseline of the press's first strokes (Phase I). The rate the chart reaches on
long clean production is measured, not assumed (scripts/bench_tonnage.py, tests/test_tonnage.py).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.optimize import brentq

from press_model.jit import compiled

SIEGMUND_SHIFT = 1.166  # the approximation's correction of the boundary for the overshoot of a normal walk


def siegmund_arl(h: float, k: float, delta: float) -> float:
    """Average run length (strokes) of a one-sided CUSUM with decision limit ``h`` and reference ``k`` (both in
    standard deviations) when the statistic's mean is ``delta`` sd from the in-control mean."""
    d, b = delta - k, h + SIEGMUND_SHIFT
    if abs(d) < 1e-9:
        return b * b
    return (math.exp(-2.0 * d * b) + 2.0 * d * b - 1.0) / (2.0 * d * d)


def decision_limit(in_control_strokes: float, k: float) -> float:
    """h (sd) of each side of a two-sided CUSUM whose false alarms come once in ``in_control_strokes`` strokes."""
    target = 2.0 * in_control_strokes
    return float(brentq(lambda h: siegmund_arl(h, k, 0.0) - target, 1e-6, 100.0))


@dataclass(frozen=True)
class Cusum:
    """A two-sided CUSUM on a statistic of in-control ``mean`` and ``sd``, reference ``k`` and limit ``h`` (sd)."""

    mean: float
    sd: float
    k: float
    h: float

    @classmethod
    def from_baseline(cls, baseline: np.ndarray, in_control_strokes: float, k: float) -> "Cusum":
        """The chart of a baseline (the in-control strokes' statistic) for the stated in-control ARL."""
        b = np.asarray(baseline, dtype=float)
        b = b[np.isfinite(b)]
        if b.size < 30:
            raise ValueError(f"a CUSUM baseline needs at least 30 finite strokes, got {b.size}")
        return cls(float(np.mean(b)), float(np.std(b, ddof=1)), float(k), decision_limit(in_control_strokes, k))

    def detection_delay(self, shift_sd: float) -> float:
        """Strokes (average) to an alarm after a step of ``shift_sd`` standard deviations (Siegmund, the side it moves)."""
        return siegmund_arl(self.h, self.k, abs(shift_sd))

    def run(self, values: np.ndarray) -> np.ndarray:
        """Indices of the strokes at which the chart alarms; after each alarm both sums restart at zero (the press is
        looked at, the chart begins again). NaN strokes (no statistic) leave the sums as they are."""
        z = (np.asarray(values, dtype=float) - self.mean) / self.sd
        return _alarms(z, self.k, self.h)


COMPILE_STROKES = 50_000  # from this many strokes the recursion runs compiled (when numba is installed)


def _alarms(z: np.ndarray, k: float, h: float) -> np.ndarray:
    """Indices of the strokes where the CUSUM recursion over ``z`` alarms. Compiled where numba is installed and the
    strokes are many (a million in milliseconds); fewer run as plain Python (~1.5 us a stroke: 50,000 take less CPU
    than numba's compile of it on an empty cache, ~0.3 s), the same operations and so the same alarms."""
    z = np.ascontiguousarray(z, dtype=float)
    recursion = compiled(_recursion) if len(z) >= COMPILE_STROKES else None
    return np.flatnonzero((recursion or _recursion)(z, float(k), float(h)))


def _recursion(z, k, h):
    out = np.zeros(z.shape[0], dtype=np.bool_)
    hi = 0.0
    lo = 0.0
    for i in range(z.shape[0]):
        if z[i] != z[i]:  # NaN
            continue
        hi = max(0.0, hi + z[i] - k)
        lo = max(0.0, lo - z[i] - k)
        if hi > h or lo > h:
            out[i] = True
            hi = 0.0
            lo = 0.0
    return out
