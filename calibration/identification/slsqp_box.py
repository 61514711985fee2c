"""SLSQP on a small box-bounded problem with inequality constraints, without ``scipy.optimize.minimize``'s set-up.

The refits' local step (:func:`calibration.identification.bootstrap._local_step`) solves a 7-unknown problem with
SLSQP about 15 function evaluations at a time, 555 times in one calibration: scipy's compiled routine takes a fifth of
that CPU, ``minimize``'s Python the rest (bounds and constraints standardised on every call, each evaluation through
a memoising wrapper that copies and compares the point). :func:`minimize_box` hands the same routine the same numbers
in the same order, so the steps are the ones ``minimize(method="SLSQP")`` takes, bit for bit (tests/
test_slsqp_box.py), at a third of the CPU.

The routine is scipy's private ``scipy.optimize._slsqplib.slsqp`` (scipy >= 1.16, whose SLSQP is C), used only on the
releases it was checked on (:data:`CHECKED_SCIPY`): elsewhere :func:`minimize_box` calls ``minimize`` itself.
"""
from __future__ import annotations

from collections.abc import Callable

import numpy as np

# The private routine's call (its state keys, workspace size and modes) was checked against minimize() bit for bit on
# these scipy releases (tests/test_slsqp_box.py); on any other, private code may have changed under the same name, so
# minimize() itself runs: slower, never wrong.
CHECKED_SCIPY = ((1, 16), (1, 17))


def _private_routine():
    """scipy's C SLSQP routine where this scipy is one :data:`CHECKED_SCIPY` names, else None."""
    import scipy

    try:
        release = tuple(int(part) for part in scipy.__version__.split(".")[:2])
    except ValueError:  # pragma: no cover - an unusual version string: take the public path
        return None
    if release not in CHECKED_SCIPY:  # pragma: no cover
        return None
    try:  # the C routine behind minimize(method="SLSQP"), driven here through its reverse-communication loop
        from scipy.optimize._slsqplib import slsqp
    except ImportError:  # pragma: no cover
        return None
    return slsqp


_slsqp = _private_routine()


def minimize_box(fun: Callable, grad: Callable, x0: np.ndarray, bounds: tuple[np.ndarray, np.ndarray], ineq: Callable,
                 ineq_jac: np.ndarray, maxiter: int, ftol: float) -> np.ndarray:
    """The point (n,) where ``minimize(fun, x0, jac=grad, bounds=zip(lo, hi), constraints=[{"type": "ineq", "fun":
    ineq, "jac": lambda x: ineq_jac}], method="SLSQP", options={"maxiter": maxiter, "ftol": ftol})`` stops, the same
    bits; in the units of ``x0``. ``bounds``: (lo, hi), each (n,), -inf and +inf where there is no bound;
    ``ineq(x)`` (m,) >= 0 the constraints, ``ineq_jac`` (m, n) their constant Jacobian."""
    lo, hi = (np.asarray(b, dtype=float) for b in bounds)
    if _slsqp is None:  # pragma: no cover
        from scipy.optimize import minimize

        bounds = [(a if np.isfinite(a) else None, b if np.isfinite(b) else None) for a, b in zip(lo, hi)]
        return minimize(fun, x0, jac=grad, bounds=bounds, constraints=[{"type": "ineq", "fun": ineq, "jac": lambda x: ineq_jac}],
                        method="SLSQP", options={"maxiter": maxiter, "ftol": ftol}).x
    x = np.clip(np.asarray(x0, dtype=float).ravel(), lo, hi)  # minimize starts inside the bounds too
    n = len(x)
    C = np.asfortranarray(np.atleast_2d(np.asarray(ineq_jac, dtype=float)))
    m = len(C)
    d = np.array(ineq(x), dtype=float)
    xl, xu = np.where(np.isfinite(lo), lo, np.nan), np.where(np.isfinite(hi), hi, np.nan)  # the routine's "no bound"
    # the routine's state, and its workspace as its own header sizes it (no equality constraints)
    state = {"acc": ftol, "alpha": 0.0, "f0": 0.0, "gs": 0.0, "h1": 0.0, "h2": 0.0, "h3": 0.0, "h4": 0.0, "t": 0.0,
             "t0": 0.0, "tol": 10.0 * ftol, "exact": 0, "inconsistent": 0, "reset": 0, "iter": 0, "itermax": int(maxiter),
             "line": 0, "m": m, "meq": 0, "mode": 0, "n": n}
    work = n * (n + 1) // 2 + 3 * m * n + 9 * m + 8 * n * n + 35 * n + 28 + (0 if m else 2 * n * (n + 1))
    buffer = np.zeros(max(work, 1))
    indices = np.zeros(max(m + 2 * n + 2, 1), dtype=np.int32)
    mult = np.zeros(max(1, m + 2 * n + 2))
    fx, g = fun(x.copy()), np.atleast_1d(grad(x.copy()))
    while True:
        _slsqp(state, fx, g, C, d, x, mult, xl, xu, buffer, indices)
        if state["mode"] == 1:  # the routine asks for the objective and the constraints at its new x
            fx = fun(x.copy())
            d[:] = ineq(x)
        elif state["mode"] == -1:  # ... for the gradients (the constraints' is constant: written again, as minimize does)
            g = np.atleast_1d(grad(x.copy()))
            C[:] = ineq_jac
        else:
            return x
