"""LAPACK's gesv (LU with partial pivoting) on a small square system, callable from plain and numba-compiled code.

In plain Python :func:`solve_columns` is numpy's np.linalg.solve. In compiled code (:func:`register_compiled`) it is
the call numba's own np.linalg.solve makes, numba's ``numba_xgesv`` (scipy's cython_lapack dgesv) on a column-major
copy of the matrix and of the right-hand sides, so the same bits; without numba's checks, shape dispatch and error
messages, whose typing and lowering were most of the compile of every function that solved (~5 s of CPU each).
"""
from __future__ import annotations

import functools

import numpy as np

SINGULAR = "Matrix is singular to machine precision."  # numpy's and numba's message


def solve_columns(K, B):
    """X (n, m; B's unit over K's) with K X = B for a square K (n, n) and right-hand sides B (n, m); raises numpy's
    LinAlgError where K is singular. Compiled (:func:`register_compiled`), X is column-major (as numba's solve gives)
    and K, B must be finite (LAPACK's compiled call does not check them)."""
    return np.linalg.solve(K, B)


@functools.cache
def register_compiled() -> None:
    """Make :func:`solve_columns` callable from numba-compiled code (an overload by numba's external LAPACK entry);
    once per process (later calls do nothing), before the first compile of a function that calls it."""
    from numba.core import types
    from numba.extending import overload
    from numba.np.linalg import F_INT_nbtype, F_INT_nptype  # LAPACK's integer: int32, or int64 where numpy's is ILP64

    xgesv = types.ExternalFunction("numba_xgesv", types.intc(
        types.char, types.intp, types.intp, types.CPointer(types.float64), types.intp, types.CPointer(F_INT_nbtype),
        types.CPointer(types.float64), types.intp))
    double = ord("d")  # the kind numba_xgesv dispatches on

    @overload(solve_columns)
    def _solve_columns(K, B):
        def impl(K, B):
            n, m = K.shape[0], B.shape[1]
            lu = np.empty((n, n)).T  # column-major copies: gesv overwrites both
            for j in range(n):
                for i in range(n):
                    lu[i, j] = K[i, j]
            x = np.empty((m, n)).T
            for j in range(m):
                for i in range(n):
                    x[i, j] = B[i, j]
            pivots = np.empty(n, F_INT_nptype)
            if xgesv(double, n, m, lu.ctypes, n, pivots.ctypes, x.ctypes, n) > 0:
                raise np.linalg.LinAlgError(SINGULAR)
            return x

        return impl
