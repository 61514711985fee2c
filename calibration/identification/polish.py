"""A local polish of a two-part objective f = w A(x) / a0 + (1 - w) |B(x)| / b0, within a budget of evaluations.

Eq. 28 has this form (A = Y_RMSE, B = Y_PR, a0 = Y_RMSE,0, b0 = |Y_PR,0|). Its floor is a kink: where the
model peak equals the measured peak, |B| has a corner, and when b0 is small the minimum sits on that corner
("min Y_RMSE subject to model peak = measured peak"). A gradient method on f itself stalls at the corner;
the epigraph form is smooth on each side and has the same minimum:

    min over (u, t):  w A(u) / a0 + (1 - w) t     subject to  t - B(u) / b0 >= 0,  t + B(u) / b0 >= 0,
                                                               0 <= u <= 1 (the unit box of the bounds)

solved by scipy's SLSQP. When the minimum is on the corner both constraints are active (B = 0, the
"model peak = measured peak" constraint); when it is not, one is, and the solution is an ordinary smooth
minimum. Gradients are central differences in the unit box, all 2 d shifted points in one batch call.

Budget: every parameter set evaluated counts (value calls, gradient batches). Before a batch would exceed
``budget`` the polish stops; the answer is the best point by f among *every* row evaluated (the start
included), so the polish can never return a worse point than it was given.
"""
from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from scipy.optimize import minimize

_STEP = 1e-5  # central-difference step in the unit box: far above the 1e-11 friction fixed-point tolerance, far below curvature


class _Budget(Exception):
    pass


@dataclass(frozen=True)
class PolishResult:
    x: np.ndarray  # best point, physical units
    fun: float  # f at x
    nfev: int  # parameter sets evaluated
    iterations: int  # SLSQP iterations (0 if stopped before the first)
    message: str


def polish_two_part(parts: Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]], x0, bounds: tuple, eq28: tuple,
                    budget: int, f0: float | None = None) -> PolishResult:
    """Polish x0 on f = w A / a0 + (1 - w) |B| / b0 over the box ``bounds`` = (low, high) with at most ``budget``
    evaluations; ``eq28`` = (w, a0, b0), Eq. 28's weight and normalisations.

    ``parts(X)`` maps (m, d) physical points to the arrays (A, B), each (m,). ``f0`` is f(x0) if known (saves
    one evaluation). Returns a :class:`PolishResult`; ``x`` is x0 itself when nothing better was found.
    """
    low, high = bounds
    weight, a0, b0 = eq28
    lo, hi = np.asarray(low, float), np.asarray(high, float)
    span = hi - lo
    d = lo.size
    w = float(weight)
    x0 = np.asarray(x0, float)
    count = [0]
    best = {"f": np.inf, "x": x0.copy()}

    def evaluate(U):
        if count[0] + len(U) > budget:
            raise _Budget
        X = np.clip(lo + U * span, lo, hi)
        A, B = parts(X)
        A, B = np.asarray(A, float), np.asarray(B, float)
        count[0] += len(U)
        F = w * A / a0 + (1.0 - w) * np.abs(B) / b0
        F = np.where(np.isfinite(F), F, np.inf)
        i = int(np.argmin(F))
        if F[i] < best["f"]:
            best["f"], best["x"] = float(F[i]), X[i].copy()
        return A / a0, B / b0

    u0 = np.clip((x0 - lo) / span, 0.0, 1.0)
    if f0 is None:
        try:
            a, b = evaluate(u0[None])
        except _Budget:
            return PolishResult(x0, np.inf, 0, 0, "budget too small for one evaluation")
        a, b = float(a[0]), float(b[0])
    else:
        best["f"], best["x"] = float(f0), x0.copy()
        a, b = None, None

    cache: dict = {}

    def point(v):
        key = v[:d].tobytes()
        if key not in cache:
            A, B = evaluate(v[None, :d])
            cache.clear()
            cache[key] = {"a": float(A[0]), "b": float(B[0])}
        return cache[key]

    def grad(v):
        c = point(v)
        if "ga" not in c:
            u = v[:d]
            h = np.minimum(_STEP, 0.5)
            U = np.repeat(u[None], 2 * d, axis=0)
            for j in range(d):
                # one-sided at a wall keeps every point inside the box
                up, dn = min(u[j] + h, 1.0), max(u[j] - h, 0.0)
                U[2 * j, j], U[2 * j + 1, j] = up, dn
            A, B = evaluate(U)
            dx = U[0::2, np.arange(d)].diagonal() - U[1::2, np.arange(d)].diagonal()
            c["ga"] = (A[0::2] - A[1::2]) / dx
            c["gb"] = (B[0::2] - B[1::2]) / dx
        return c

    def fun(v):
        return w * point(v)["a"] + (1.0 - w) * v[d]

    def jac(v):
        g = grad(v)
        return np.concatenate([w * g["ga"], [1.0 - w]])

    def c_upper(v):
        return v[d] - point(v)["b"]

    def c_lower(v):
        return v[d] + point(v)["b"]

    def j_upper(v):
        return np.concatenate([-grad(v)["gb"], [1.0]])

    def j_lower(v):
        return np.concatenate([grad(v)["gb"], [1.0]])

    try:
        if b is None:
            c = point(np.concatenate([u0, [0.0]]))
            b = c["b"]
        v0 = np.concatenate([u0, [abs(b)]])
        bounds = [(0.0, 1.0)] * d + [(0.0, None)]
        cons = [{"type": "ineq", "fun": c_upper, "jac": j_upper}, {"type": "ineq", "fun": c_lower, "jac": j_lower}]
        r = minimize(fun, v0, jac=jac, bounds=bounds, constraints=cons, method="SLSQP",
                     options={"maxiter": budget, "ftol": 1e-12})
        it, msg = int(r.nit), f"SLSQP: {r.message}"
        # the SLSQP answer itself is among the evaluated rows, so best already holds it or something better
    except _Budget:
        it, msg = -1, f"stopped at the budget of {budget} evaluations"
    return PolishResult(best["x"], best["f"], count[0], max(it, 0), msg)
