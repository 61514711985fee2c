"""Plane geometry shared by the press reader and the batch evaluator: least-squares trilateration.

Link 4's centre of mass is the point whose distances to its three fixed vertices best fit the sampled
Ls41, Ls42, Ls43. One implementation serves the single press file and the vectorised batch alike, so
the two paths give the same COM to rounding.
"""
from __future__ import annotations

import numpy as np

_TRI_MAX_ITER = 100
_TRI_GN_FIRST = 5  # Gauss-Newton steps before Newton steps are allowed
_TRI_POLISH = 2
# a fitted point is accepted when the gradient of the squared distance residuals is at most this (m);
# the fit reaches ~1e-16, so only inconsistent or non-finite input trips it
GRADIENT_TOL = 1e-9


def _tri_terms(c, points, distances):
    """Unit vectors from the points to c (b, k, 2), distances (b, k) and residuals (b, k)."""
    diff = c[:, None, :] - points[None]
    rr = np.linalg.norm(diff, axis=2)
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


def trilaterate(points: np.ndarray, distances: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Least-squares points (B, 2) whose distances to ``points`` (k, 2) best fit ``distances`` (B, k), m.

    The minimiser of f = sum (|c - p_i| - d_i)^2 / 2 reached from the centroid, a few Gauss-Newton steps, then Newton steps with the exact Hessian wherever it is
    positive definite (Gauss-Newton elsewhere), every step halved until f does not increase, and two
    final plain Newton steps. The result is exact to rounding (gradient ~1e-16 m); plain Gauss-Newton
    oscillates on inconsistent distances and Levenberg-Marquardt stops short in flat valleys. Returns the points and the norm of the gradient
    of f (m).
    """
    B = distances.shape[0]
    c = np.tile(points.mean(axis=0), (B, 1))
    idx = np.arange(B)  # sets still moving
    for it in range(_TRI_MAX_ITER):
        cc, d = c[idx], distances[idx]
        g, H_gn, H, res = _tri_derivatives(cc, points, d)
        step, _ = _solve2(H_gn, g)
        if it >= _TRI_GN_FIRST:
            newton, pd = _solve2(H, g)
            step = np.where(pd[:, None], newton, step)
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
        small = np.abs(a[:, None] * step).max(axis=1) <= 1e-12 * (1.0 + np.abs(cc).max(axis=1))
        idx = idx[~small | (it < _TRI_GN_FIRST)]
        if not len(idx):
            break
    for _ in range(_TRI_POLISH):  # plain Newton where the Hessian is positive definite: exact to rounding
        g, _, H, _ = _tri_derivatives(c, points, distances)
        step, pd = _solve2(H, g)
        c = c + np.where(pd[:, None], step, 0.0)
    g, _, _, _ = _tri_derivatives(c, points, distances)
    gnorm = np.linalg.norm(g, axis=1)
    return c, np.where(np.all(np.isfinite(c), axis=1), gnorm, np.inf)
