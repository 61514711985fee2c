"""press_model.gesv: the compiled LAPACK gesv behind kinematics.linear_solve and the Newton steps gives the bits of
scipy's dgesv (the routine numba's np.linalg.solve calls), refuses a singular matrix as numpy does, and leaves
non-finite systems to numpy."""
import numpy as np
import pytest
from scipy.linalg import lapack

from press_model.jit import compiled
from press_model.kinematics import _finite_solve, linear_solve


def test_compiled_solve_gives_lapack_dgesvs_bits_for_vectors_and_matrices():
    if compiled(_finite_solve) is None:  # pragma: no cover - numba is a dependency
        pytest.skip("numba is not installed")
    rng = np.random.default_rng(11)
    for n in (2, 7, 9):
        for _ in range(20):
            K = rng.normal(size=(n, n)) * rng.uniform(1e-3, 1e3, n)  # columns of several scales: pivoting matters
            for rhs in (rng.normal(size=n), rng.normal(size=(n, 3)), np.eye(n)):
                want = lapack.dgesv(K, rhs.reshape(n, -1))[2]
                got = linear_solve(K, rhs)
                assert got.shape == rhs.shape
                assert got.tobytes() == (want.ravel() if rhs.ndim == 1 else want).tobytes()
                if rhs.ndim == 2:
                    assert got.flags.f_contiguous  # column-major, as numba's np.linalg.solve returned it


def test_singular_matrix_raises_numpys_error_and_non_finite_goes_to_numpy():
    with pytest.raises(np.linalg.LinAlgError, match="singular"):
        linear_solve(np.ones((3, 3)), np.ones(3))
    K = np.eye(3)
    K[1, 2] = np.nan
    assert np.array_equal(linear_solve(K, np.ones(3)), np.linalg.solve(K, np.ones(3)), equal_nan=True)
