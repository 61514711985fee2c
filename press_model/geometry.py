"""Plane geometry shared by the press reader and the batch evaluator: least-squares trilateration.

Link 4's centre of mass is the point whose distances to its three fixed vertices best fit the sampled
Ls41, Ls42, Ls43. One implementation serves the single press file and the vectorised batch alike, so
the two paths give the same COM to rounding.
"""
from __future__ import annotations

import numpy as np

_TRI_MAX_ITER = 100
_TRI_POLISH = 3
# a fitted point is accepted when the gradient of the squared distance residuals is at most this (m);
# the fit reaches ~1e-16, so only inconsistent or non-finite input trips it
GRADIENT_TOL = 1e-9


def _tri_terms(c, points, distances):
    """Unit vectors from the points to c (b, k, 2), distances (b, k) and residuals (b, k)."""
    diff = c[:, None, :] - points[None]
    rr = np.sqrt(diff[..., 0] * diff[..., 0] + diff[..., 1] * diff[..., 1])  # np.linalg.norm(diff, axis=2), 3x faster
    rr = np.where(rr < 1e-12, 1e-12, rr)
    return diff / rr[..., None], rr, rr - distances


def _tri_derivatives(c, points, distances):
    """Gradient (b, 2), Gauss-Newton matrix and exact Hessian (b, 2, 2) of f = sum(res^2) / 2, and res."""
    u, rr, res = _tri_terms(c, points, distances)
    g = np.einsum("bki,bk->bi", u, res)
    uu = u[..., :, None] * u[..., None, :]
    H_gn = uu.sum(axis=1)
    q = res / rr
    H = H_gn + q.sum(axis=1)[:, None, None] * np.eye(2) - np.einsum("bk,bkij->bij", q, uu)
    return g, H_gn, H, res


def _solve2(H, g):
    """-H^-1 g for (b, 2, 2) and (b, 2), and whether H is positive definite."""
    det = H[:, 0, 0] * H[:, 1, 1] - H[:, 0, 1] * H[:, 1, 0]
    pd = (H[:, 0, 0] > 0) & (det > 0)
    step = np.column_stack([H[:, 1, 1] * g[:, 0] - H[:, 0, 1] * g[:, 1],
                            H[:, 0, 0] * g[:, 1] - H[:, 1, 0] * g[:, 0]]) / -np.where(det != 0, det, 1.0)[:, None]
    return step, pd


def _descend(points: np.ndarray, distances: np.ndarray, c: np.ndarray) -> np.ndarray:
    """Local minimiser of f = sum (|c - p_i| - d_i)^2 / 2 from the starts c (B, 2).

    Newton steps on a Hessian shifted to be positive definite where it is not (so every step descends,
    also in the curved valleys that inconsistent distances make), each step halved until f decreases;
    near the minimum the shift vanishes and the steps are plain Newton, exact to rounding.
    """
    c = np.array(c, dtype=float)
    idx = np.arange(len(c))  # sets still moving
    scale = 1.0 + np.abs(points).max()
    for _ in range(_TRI_MAX_ITER):
        cc, d = c[idx], distances[idx]
        g, H_gn, H, res = _tri_derivatives(cc, points, d)
        tr, det = H[:, 0, 0] + H[:, 1, 1], H[:, 0, 0] * H[:, 1, 1] - H[:, 0, 1] * H[:, 1, 0]
        lam_min = tr / 2 - np.sqrt(np.maximum(tr * tr / 4 - det, 0.0))
        floor = 1e-3 * (H_gn[:, 0, 0] + H_gn[:, 1, 1])
        shift = np.where(lam_min > floor, 0.0, floor - lam_min)
        step, _ = _solve2(H + shift[:, None, None] * np.eye(2), g)
        f0 = np.sum(res**2, axis=1)
        a = np.ones(len(idx))
        trial = cc + step
        check = np.arange(len(idx))
        for _ in range(60):  # halve the step until f does not increase
            worse = np.sum(_tri_terms(trial[check], points, d[check])[2] ** 2, axis=1) > f0[check]
            check = check[worse]
            if not len(check):
                break
            a[check] *= 0.5
            trial[check] = cc[check] + a[check, None] * step[check]
        c[idx] = trial
        # near a minimum the closing plain-Newton steps finish the job quadratically
        done = (np.linalg.norm(g, axis=1) <= 1e-8 * scale) | (np.abs(a[:, None] * step).max(axis=1) <= 1e-12 * scale)
        idx = idx[~done]
        if not len(idx):
            break
    for _ in range(_TRI_POLISH):  # plain Newton where the Hessian is positive definite: exact to rounding
        g, _, H, _ = _tri_derivatives(c, points, distances)
        step, pd = _solve2(H, g)
        c = c + np.where(pd[:, None], step, 0.0)
    return c


def _starts(points: np.ndarray, distances: np.ndarray) -> list[np.ndarray]:
    """Starting points: the centroid and, for each pair of points, where their two circles meet (or come closest)."""
    B = distances.shape[0]
    out = [np.tile(points.mean(axis=0), (B, 1))]
    k = len(points)
    for i in range(k):
        for j in range(i + 1, k):
            dv = points[j] - points[i]
            dist = np.hypot(*dv)
            a = (distances[:, i] ** 2 - distances[:, j] ** 2 + dist**2) / (2 * dist)
            h = np.sqrt(np.maximum(distances[:, i] ** 2 - a**2, 0.0))
            mid = points[i] + a[:, None] * dv / dist
            perp = np.array([-dv[1], dv[0]]) / dist
            out += [mid + h[:, None] * perp, mid - h[:, None] * perp]
    return out


def trilaterate(points: np.ndarray, distances: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Least-squares points (B, 2) whose distances to ``points`` (k, 2) best fit ``distances`` (B, k), m.

    Inconsistent distances (as the sensitivity ranges of a COM produce) give f several local minima, so
    the descent runs from the centroid and from each pair's circle intersections, and the lowest wins.
    Returns the points and the norm of the gradient of f at them (m; ~1e-16 at a minimum).
    """
    best_c, best_f = None, None
    for start in _starts(points, distances):
        c = _descend(points, distances, start)
        f = np.sum(_tri_terms(c, points, distances)[2] ** 2, axis=1)
        f = np.where(np.all(np.isfinite(c), axis=1), f, np.inf)
        if best_c is None:
            best_c, best_f = c, f
        else:
            better = f < best_f - 1e-15 * (1.0 + best_f)
            best_c, best_f = np.where(better[:, None], c, best_c), np.where(better, f, best_f)
    g, _, _, _ = _tri_derivatives(best_c, points, distances)
    gnorm = np.linalg.norm(g, axis=1)
    return best_c, np.where(np.all(np.isfinite(best_c), axis=1), gnorm, np.inf)
