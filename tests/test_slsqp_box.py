"""calibration/identification/slsqp_box.py: SLSQP driven without minimize's set-up stops where
``scipy.optimize.minimize(method="SLSQP")`` stops, bit for bit, on problems of the refits' local step (the
linearised Eq. 28 in epigraph form within a trust-region box) and on one whose bounds and constraints bind."""
import numpy as np
import pytest
from scipy.optimize import minimize

from calibration.identification.slsqp_box import minimize_box


def epigraph_problem(rng, d=6, n=40):
    """A linearised Eq. 28 (w |r + J s| / a0 + (1 - w) t, t >= |g + h s| / b0) as the bootstrap's _local_step builds
    it: (fun, grad, ineq, rows, x0, lo, hi)."""
    r, J = rng.normal(size=n), rng.normal(size=(n, d))
    g, h = rng.normal(), rng.normal(size=d)
    w, a0, b0 = 0.5, 1.0 + rng.random(), 0.5 + rng.random()
    rad = 10.0 ** rng.uniform(-3, 0)

    def fun(v):
        e = r + J @ v[:d]
        return w * np.sqrt(e @ e) / a0 + (1.0 - w) * v[d]

    def grad(v):
        e = r + J @ v[:d]
        return np.concatenate([w * (J.T @ e) / (max(np.sqrt(e @ e), 1e-300) * a0), [1.0 - w]])

    def ineq(v):
        q = (g + h @ v[:d]) / b0
        return np.array([v[d] - q, v[d] + q])

    rows = np.vstack([np.concatenate([-h / b0, [1.0]]), np.concatenate([h / b0, [1.0]])])
    u = rng.random(d)
    lo, hi = np.maximum(-rad, -u), np.minimum(rad, 1.0 - u)
    return fun, grad, ineq, rows, np.concatenate([np.zeros(d), [abs(g) / b0]]), lo, hi


@pytest.mark.parametrize("seed", range(12))
def test_the_steps_are_minimizes_bit_for_bit(seed):
    fun, grad, ineq, rows, x0, lo, hi = epigraph_problem(np.random.default_rng(seed))
    ref = minimize(fun, x0, jac=grad, bounds=list(zip(lo, hi)) + [(0.0, None)], method="SLSQP",
                   constraints=[{"type": "ineq", "fun": ineq, "jac": lambda v: rows}], options={"maxiter": 100, "ftol": 1e-14})
    got = minimize_box(fun, grad, x0, (np.append(lo, 0.0), np.append(hi, np.inf)), ineq, rows, maxiter=100, ftol=1e-14)
    assert got.tobytes() == ref.x.tobytes(), (got, ref.x)


def test_binding_bounds_and_constraint_and_the_iteration_limit_as_minimize():
    """A quadratic pulled outside its box, under a linear constraint that binds, and stopped by maxiter."""
    c = np.array([3.0, -2.0, 0.5])

    def fun(x):
        return float((x - c) @ (x - c))

    def grad(x):
        return 2.0 * (x - c)

    A = np.array([[-1.0, -1.0, -1.0]])

    def ineq(x):  # x0 + x1 + x2 <= 0, which the unconstrained minimum in the box (1, -1, 0.25) breaks
        return np.array([-x.sum()])

    lo, hi = np.array([-1.0, -1.0, -np.inf]), np.array([1.0, np.inf, 0.25])
    for maxiter in (1, 2, 100):
        ref = minimize(fun, np.zeros(3), jac=grad, bounds=[(-1.0, 1.0), (-1.0, None), (None, 0.25)], method="SLSQP",
                       constraints=[{"type": "ineq", "fun": ineq, "jac": lambda x: A}], options={"maxiter": maxiter, "ftol": 1e-12})
        got = minimize_box(fun, grad, np.zeros(3), (lo, hi), ineq, A, maxiter=maxiter, ftol=1e-12)
        assert got.tobytes() == ref.x.tobytes(), (maxiter, got, ref.x)
    assert got[1] == pytest.approx(-1.0) and got.sum() == pytest.approx(0.0, abs=1e-9)  # a bound and the constraint bind


def test_the_private_routine_is_driven_on_the_scipy_releases_it_was_checked_on():
    """Where this scipy is one the routine's call was checked on, the comparisons above drive the private routine (not
    minimize against itself); elsewhere minimize runs."""
    import scipy

    from calibration.identification import slsqp_box

    checked = tuple(int(p) for p in scipy.__version__.split(".")[:2]) in slsqp_box.CHECKED_SCIPY
    assert (slsqp_box._slsqp is not None) == checked
