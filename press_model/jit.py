"""numba where it is installed: plain-Python loops over scalars, compiled on first use and cached on disk."""
from __future__ import annotations

import functools


@functools.cache
def compiled(fn):
    """``fn`` compiled by numba (numpy's error model, machine code cached on disk), or None without numba.

    Compiled on the first call for a function, so that a command that never needs it does not pay numba's
    import (~0.2 s) or the cache load; ``fn`` itself stays callable as plain Python.
    """
    try:
        import numba
    except ImportError:  # pragma: no cover
        return None
    return numba.njit(error_model="numpy", cache=True)(fn)
