"""Least-squares trilateration of link 4's COM: the global minimum over the whole sensitivity range."""
import numpy as np
import pytest
from scipy.optimize import minimize

from press_model import geometry
from press_model.geometry import trilaterate
from press_model.press_data import load_press


@pytest.fixture(scope="module")
def link4():
    press = load_press()
    b = press.bodies["link4"]
    nominal = np.array([press.parameter_values()[n] for n in ("Ls41", "Ls42", "Ls43")])
    return np.array([b.points["E"], b.points["C"], b.points["D"]]), nominal


def cost(c, pts, d):
    return 0.5 * np.sum((np.linalg.norm(c - pts, axis=1) - d) ** 2)


def cost_gradient(c, pts, d):
    """d cost / d c, by hand: BFGS's own finite differences took most of the module's time, for no other minima."""
    r = np.linalg.norm(c - pts, axis=1)
    return ((r - d) / r) @ (c - pts)


GRID = np.linspace(-1.5, 1.5, 301)  # m, 1 cm apart: the box the fits' minima lie in


def lowest_minimum(pts, d):
    """The lowest local minimum of ``cost`` found by BFGS from every point of a 1-cm grid of the box that is no higher
    than its eight neighbours (outside the box counts as higher): a start in each basin wider than the grid, the lowest
    point of it the grid sees. It replaced 12-24 random starts in the box (most of the module's time), which find a
    basin only as often as they fall into it."""
    X, Y = np.meshgrid(GRID, GRID, indexing="ij")
    F = np.pad(0.5 * sum((np.hypot(X - p[0], Y - p[1]) - di) ** 2 for p, di in zip(pts, d)), 1, constant_values=np.inf)
    n = len(GRID)
    low = np.ones((n, n), bool)
    for i in (0, 1, 2):
        for j in (0, 1, 2):
            if (i, j) != (1, 1):
                low &= F[1:-1, 1:-1] <= F[i:i + n, j:j + n]
    starts = np.column_stack([X[low], Y[low]])
    return min((minimize(cost, x0, args=(pts, np.asarray(d)), method="BFGS", jac=cost_gradient, options={"gtol": 1e-12})
                for x0 in starts), key=lambda r: r.fun)


def test_nominal_distances_give_the_body_frame_origin(link4):
    pts, nominal = link4
    c, g = trilaterate(pts, nominal[None])
    assert np.allclose(c, 0.0, atol=1e-12) and g[0] < 1e-12


@pytest.mark.parametrize("d", [
    [1.4194120109155774, 0.9595018621392548, 0.3796734228223562],  # stalled a Gauss-Newton/Newton fit
    [1.4192834027458365, 0.9199521013620918, 0.28057148204217064],  # stopped Levenberg-Marquardt short
    [0.7 * 1.2425, 0.7 * 0.9496, 0.7 * 0.314],
])
def test_hard_cases_reach_the_global_minimum(link4, d):
    pts, _ = link4
    c, g = trilaterate(pts, np.array([d]))
    best = lowest_minimum(pts, d)
    assert g[0] < 1e-12
    assert cost(c[0], pts, np.array(d)) <= best.fun + 1e-14


def test_random_in_range_samples(link4):
    pts, nominal = link4
    rng = np.random.default_rng(7)
    D = nominal * rng.uniform(0.7, 1.3, (5000, 3))
    c, g = trilaterate(pts, D)
    assert np.max(g) < 1e-12
    for i in rng.choice(len(D), 40, replace=False):
        assert cost(c[i], pts, D[i]) <= lowest_minimum(pts, D[i]).fun + 1e-14


def test_compiled_and_plain_python_fits_agree(link4):
    """The press reader fits one row in plain Python, a design thousands compiled: one algorithm, same points."""
    pts, nominal = link4
    rng = np.random.default_rng(11)
    D = nominal * rng.uniform(0.7, 1.3, (geometry.COMPILE_ROWS + 20, 3))
    D[3] = np.nan  # no point fits: an infinite gradient on both paths
    c, g = trilaterate(pts, D)
    c_py, g_py = np.empty_like(c), np.empty_like(g)
    geometry._fit_rows(pts, D, c_py, g_py)
    assert np.isinf(g[3]) and np.isinf(g_py[3])
    keep = np.arange(len(D)) != 3
    assert np.max(np.abs(c[keep] - c_py[keep])) <= 1e-14 and np.max(g[keep]) < 1e-12
