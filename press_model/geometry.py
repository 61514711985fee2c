"""Plane geometry shared by the press reader and the batch evaluator: least-squares trilateration.

Link 4's centre of mass is the point whose distances to its three fixed vertices best fit the sampled
Ls41, Ls42, Ls43. One implementation serves the single press file and the batch alike: a loop over
rows of distances, run as plain Python for a few rows (the press reader; numba's import and cache
load would cost more than the fit) and compiled by numba for many (a Sobol design fits ~10,000 rows),
so the two paths give the same COM to rounding.
"""
from __future__ import annotations

import math

import numpy as np

from .jit import compiled

_TRI_MAX_ITER = 100
_TRI_HALVINGS = 60
_TRI_POLISH = 3
# a fitted point is accepted when the gradient of the squared distance residuals is at most this (m);
# the fit reaches ~1e-16, so only inconsistent or non-finite input trips it
GRADIENT_TOL = 1e-9
COMPILE_ROWS = 64  # from this many rows the fit runs compiled (when numba is installed)


def _fit_rows(points, distances, com, gnorm):
    """Fill com (B, 2) and gnorm (B,) with the least-squares point of each row of distances (B, k), m.

    Inconsistent distances (as the sensitivity ranges of a COM produce) give f = sum (|c - p_i| - d_i)^2 / 2
    several local minima, so the descent runs from the centroid and from the two points where each pair's
    circles meet (or come closest), and the lowest f wins. Each descent takes Newton steps on a Hessian
    shifted to be positive definite where it is not (so every step descends, also in the curved valleys
    that inconsistent distances make), each step halved until f does not increase; near the minimum the
    shift vanishes and the steps are plain Newton, and three plain Newton steps polish the point to
    rounding. gnorm is |grad f| at the winner (m; ~1e-16 at a minimum, inf if no start gave a finite point).

    Plain Python on scalars, so that numba can compile it unchanged (:func:`trilaterate` chooses).
    """
    k = points.shape[0]
    n_starts = 1 + k * (k - 1)
    starts = np.empty((n_starts, 2))
    scale = 1.0
    cx0, cy0 = 0.0, 0.0
    for i in range(k):
        scale = max(scale, 1.0 + abs(points[i, 0]), 1.0 + abs(points[i, 1]))
        cx0 += points[i, 0]
        cy0 += points[i, 1]
    starts[0, 0], starts[0, 1] = cx0 / k, cy0 / k
    for b in range(distances.shape[0]):
        s = 1
        for i in range(k):
            for j in range(i + 1, k):
                dvx, dvy = points[j, 0] - points[i, 0], points[j, 1] - points[i, 1]
                dist = math.hypot(dvx, dvy)
                a = (distances[b, i] ** 2 - distances[b, j] ** 2 + dist**2) / (2 * dist)
                h = math.sqrt(max(distances[b, i] ** 2 - a**2, 0.0))
                mx, my = points[i, 0] + a * dvx / dist, points[i, 1] + a * dvy / dist
                px, py = -dvy / dist, dvx / dist
                starts[s, 0], starts[s, 1] = mx + h * px, my + h * py
                starts[s + 1, 0], starts[s + 1, 1] = mx - h * px, my - h * py
                s += 2
        best_x, best_y, best_f = math.nan, math.nan, math.inf
        for s in range(n_starts):
            cx, cy = starts[s, 0], starts[s, 1]
            it, polished = 0, 0
            while polished < _TRI_POLISH:
                # gradient g, Gauss-Newton matrix A and exact Hessian H of f at (cx, cy), and 2 f
                g0 = g1 = a00 = a01 = a11 = qs = q00 = q01 = q11 = f0 = 0.0
                for i in range(k):
                    dx, dy = cx - points[i, 0], cy - points[i, 1]
                    rr = max(math.sqrt(dx * dx + dy * dy), 1e-12)
                    ux, uy = dx / rr, dy / rr
                    res = rr - distances[b, i]
                    q = res / rr
                    g0 += ux * res
                    g1 += uy * res
                    a00 += ux * ux
                    a01 += ux * uy
                    a11 += uy * uy
                    qs += q
                    q00 += q * ux * ux
                    q01 += q * ux * uy
                    q11 += q * uy * uy
                    f0 += res * res
                h00, h01, h11 = a00 + qs - q00, a01 - q01, a11 + qs - q11
                if it == _TRI_MAX_ITER:  # polish: plain Newton where H is positive definite, exact to rounding
                    det = h00 * h11 - h01 * h01
                    if h00 > 0 and det > 0:
                        cx, cy = cx - (h11 * g0 - h01 * g1) / det, cy - (h00 * g1 - h01 * g0) / det
                    polished += 1
                    continue
                tr, det = h00 + h11, h00 * h11 - h01 * h01
                lam_min = tr / 2 - math.sqrt(max(tr * tr / 4 - det, 0.0))
                floor = 1e-3 * (a00 + a11)
                shift = 0.0 if lam_min > floor else floor - lam_min
                s00, s11 = h00 + shift, h11 + shift
                det = s00 * s11 - h01 * h01
                det = det if det != 0 else 1.0
                sx, sy = -(s11 * g0 - h01 * g1) / det, -(s00 * g1 - h01 * g0) / det
                step = 1.0
                tx, ty = cx + sx, cy + sy
                for _ in range(_TRI_HALVINGS):  # halve the step until f does not increase
                    f = 0.0
                    for i in range(k):
                        dx, dy = tx - points[i, 0], ty - points[i, 1]
                        res = max(math.sqrt(dx * dx + dy * dy), 1e-12) - distances[b, i]
                        f += res * res
                    if not f > f0:
                        break
                    step *= 0.5
                    tx, ty = cx + step * sx, cy + step * sy
                cx, cy = tx, ty
                # near a minimum the closing plain-Newton steps finish the job quadratically
                near = math.sqrt(g0 * g0 + g1 * g1) <= 1e-8 * scale or max(abs(step * sx), abs(step * sy)) <= 1e-12 * scale
                it = _TRI_MAX_ITER if near else it + 1
            f = 0.0
            for i in range(k):
                dx, dy = cx - points[i, 0], cy - points[i, 1]
                res = max(math.sqrt(dx * dx + dy * dy), 1e-12) - distances[b, i]
                f += res * res
            if not (math.isfinite(cx) and math.isfinite(cy)):
                f = math.inf
            # a later start wins only where it is lower by more than rounding (the earlier one if neither is finite)
            if s == 0 or (f < best_f - 1e-15 * (1.0 + best_f) if math.isfinite(best_f) else f < best_f):
                best_x, best_y, best_f = cx, cy, f
        com[b, 0], com[b, 1] = best_x, best_y
        g0 = g1 = 0.0
        for i in range(k):
            dx, dy = best_x - points[i, 0], best_y - points[i, 1]
            rr = max(math.sqrt(dx * dx + dy * dy), 1e-12)
            res = rr - distances[b, i]
            g0 += dx / rr * res
            g1 += dy / rr * res
        gnorm[b] = math.sqrt(g0 * g0 + g1 * g1) if math.isfinite(best_x) and math.isfinite(best_y) else math.inf


def trilaterate(points: np.ndarray, distances: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Least-squares points (B, 2) whose distances to ``points`` (k, 2) best fit ``distances`` (B, k), m.

    The global minimum over several starts (see :func:`_fit_rows`). Returns the points and the norm of the
    gradient of f = sum (|c - p_i| - d_i)^2 / 2 at them (m; ~1e-16 at a minimum, inf where no point fits).
    """
    points = np.ascontiguousarray(points, dtype=float)
    distances = np.ascontiguousarray(np.atleast_2d(distances), dtype=float)
    com, gnorm = np.empty((len(distances), 2)), np.empty(len(distances))
    fit = compiled(_fit_rows) if len(distances) >= COMPILE_ROWS else None
    (fit or _fit_rows)(points, distances, com, gnorm)
    return com, gnorm
