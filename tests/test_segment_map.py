"""planning.segment_map: a segment function mapped over segments with its own Jacobian blocks gives the same values and
the same Jacobian, bit for bit, as CasADi's derivative of the plain map (the jerk-limited stage's rows and the plans
written from them then stay the same bytes), also where the unknowns enter through another segment function."""
import casadi as ca
import numpy as np
import pytest

from planning.segment_map import segment_map

N = 40


def _segment_functions():
    """A segment's rows in the shape of the stage's: unknowns z = (w0, w1, a0, a1, h), an angle, parameters; products,
    quotients, a square root and a cubic in time, and a function of another's output (the thermal row of the torque)."""
    z, dth, p = ca.SX.sym("z", 5), ca.SX.sym("dth"), ca.SX.sym("p", 4)
    w0, w1, a0, a1, h = (z[i] for i in range(5))
    checks = [w0 + a0 * q * h + (a1 - a0) * q * q * h / 2.0 for q in (0.25, 0.5, 0.75)]
    torque = ca.Function("torque", [z, dth, p], [ca.cse(ca.vertcat(
        (p[0] * a0 + p[1] * w0 * w0 + p[2]) / p[3], (p[0] * a1 + p[1] * w1 * w1 + p[2]) / p[3],
        *[(p[0] * (a0 + q * (a1 - a0)) + p[1] * wq * wq) / p[3] for q, wq in zip((0.25, 0.5, 0.75), checks)]))])
    y, th = ca.SX.sym("y", 5), ca.SX.sym("th", 2)
    square = ca.Function("square", [y, z, th], [z[4] * sum(ca.sqrt(y[q] * y[q] + th[0]) * th[1] * y[q] for q in range(5))])
    rows = ca.Function("rows", [z, dth], [ca.vertcat((w0 * h + h * h * (2.0 * a0 + a1) / 6.0 - dth) / dth,
                                                     w1 - w0 - h * (a0 + a1) / 2.0, *[(c + h) / 3.0 for c in checks])])
    torque_square = ca.Function("torque_square", [z, dth, p, th], [square(torque(z, dth, p), z, th)])
    return rows, torque, torque_square


def _forward_jacobian(sym, expr):
    """(value, Jacobian in the first symbol) of ``expr``, the Jacobian taken in forward mode as the stage's NLP's is (its
    rows far outnumber the colours of its columns); in reverse mode the sums run in another order (round-off apart)."""
    f = ca.Function("f", sym, [ca.vec(expr)], {"ad_weight": 0})
    jac = f.jacobian()
    return ca.Function("value_and_jacobian", sym, [f(*sym), jac(*sym, f(*sym))[0]])


def _data(seed=3):
    rng = np.random.default_rng(seed)
    return (rng.normal(size=(5, N)), rng.uniform(0.01, 0.02, (1, N)), rng.uniform(0.5, 2.0, (4, N)),
            rng.uniform(0.5, 2.0, (2, 1)))


@pytest.mark.parametrize("which", ["rows", "torque", "torque_square"])
def test_own_jacobian_is_casadis_bit_for_bit(which):
    rows, torque, torque_square = _segment_functions()
    fn = {"rows": rows, "torque": torque, "torque_square": torque_square}[which]
    Zd, Dd, Pd, THd = _data()
    x = ca.MX.sym("x", 5 * N)
    Z, D, P, TH = ca.reshape(x, 5, N), ca.MX.sym("D", 1, N), ca.MX.sym("P", 4, N), ca.MX.sym("TH", 2)
    args = {"rows": (Z, D), "torque": (Z, D, P), "torque_square": (Z, D, P, ca.repmat(TH, 1, N))}[which]
    # beside the continuity rows, as in the stage's NLP
    plain = ca.vertcat(ca.vec(rows.map(N, "serial")(Z, D)), ca.vec(fn.map(N, "serial")(*args)))
    own = ca.vertcat(ca.vec(segment_map(rows, N)(Z, D)), ca.vec(segment_map(fn, N)(*args)))
    sym = [x, D, P, TH]

    def value_and_jacobian(expr):
        v, j = _forward_jacobian(sym, expr)(Zd.ravel("F"), Dd, Pd, THd)
        return np.asarray(v).ravel(), j

    v0, j0 = value_and_jacobian(plain)
    v1, j1 = value_and_jacobian(own)
    assert np.array_equal(v0, v1)
    assert j1.sparsity() == j0.sparsity()
    assert np.array_equal(np.asarray(j1.nonzeros()), np.asarray(j0.nonzeros()))
    assert np.all(np.isfinite(j0.nonzeros())) and j0.nnz() > 0


def test_chained_through_the_lossy_rows_form():
    """The torque's output taken on by elementwise MX products and sums (the drive losses' rows, press_model.motor.
    lossy_torque_rows, with the speed of another mapped function): the chain rule through the own Jacobians gives
    CasADi's bits too."""
    rows, torque, _ = _segment_functions()
    Zd, Dd, Pd, _ = _data(5)
    x = ca.MX.sym("x", 5 * N)
    Z, D, P, q = ca.reshape(x, 5, N), ca.MX.sym("D", 1, N), ca.MX.sym("P", 4, N), ca.MX.sym("q", 3)
    z = ca.SX.sym("z", 5)
    speed = ca.Function("speed", [z], [ca.vertcat(z[0], z[1], (z[0] + z[1]) / 2.0 + z[4] * (z[2] - z[3]) / 8.0)])
    out = []
    for mapped in (lambda fn: fn.map(N, "serial"), lambda fn: segment_map(fn, N)):
        y, w = mapped(torque)(Z, D, P)[:3, :], mapped(speed)(Z)
        common = q[0] * y * y + q[1] * w + q[2]
        e = ca.vertcat(ca.vec(mapped(rows)(Z, D)), ca.vec(y + common), ca.vec(0.8 * y + common))
        out.append(_forward_jacobian([x, D, P, q], e)(Zd.ravel("F"), Dd, Pd, [0.01, 0.3, 2.0])[1])
    assert out[0].sparsity() == out[1].sparsity()
    assert np.array_equal(np.asarray(out[0].nonzeros()), np.asarray(out[1].nonzeros()))


def test_refuses_a_function_it_cannot_map():
    x = ca.SX.sym("x", 2, 2)
    with pytest.raises(ValueError, match="column-vector inputs"):
        segment_map(ca.Function("f", [x], [ca.trace(x)]), 3)
