"""One live numpy array over a Pinocchio Data's vector of small per-joint or per-frame arrays.

Pinocchio hands out ``data.oMi[j].rotation``, ``data.oMf[i].translation`` or ``data.f[j].linear`` as numpy views of
its own memory, one Python round trip (~1 us) each; stacking a dozen of them on every evaluation of the forward
dynamics cost more than the Pinocchio algorithms themselves. Those vectors are ``std::vector`` s of fixed-size
structs, so their members lie at one constant step in memory: a single strided view (numpy's ``as_strided``) sees all
of them at once, live, as the algorithms overwrite them. The step is measured from the views' own addresses, never
assumed, and every element is checked to lie where the step puts it; where that fails (another layout), the stack is
copied per call instead, the same numbers.
"""
from __future__ import annotations

import numpy as np
from numpy.lib.stride_tricks import as_strided


def _address(a: np.ndarray) -> int:
    return a.__array_interface__["data"][0]


class StackedViews:
    """The per-element views ``views`` (equal shapes and strides, kept alive by their owner ``owner``, a Pinocchio
    Data) as one array of shape (len(views), *shape): :meth:`array`."""

    def __init__(self, owner, views: list[np.ndarray]):
        self.owner = owner  # the Data whose memory the views read
        self.views = views
        self.live = _strided(views)

    def array(self) -> np.ndarray:
        """The elements now, stacked (same unit as the views): the live strided view (read only), or a fresh copy where
        the layout is not one step apart."""
        return self.live if self.live is not None else np.array(self.views)


def _strided(views: list[np.ndarray]) -> np.ndarray | None:
    """One read-only view over ``views`` when they lie one constant step apart in memory with equal shapes and strides,
    else None."""
    first = views[0]
    if any(v.shape != first.shape or v.strides != first.strides or v.dtype != first.dtype for v in views):
        return None
    start = _address(first)
    step = _address(views[1]) - start if len(views) > 1 else 0
    if any(_address(v) != start + i * step for i, v in enumerate(views)):
        return None
    return as_strided(first, shape=(len(views),) + first.shape, strides=(step,) + first.strides, writeable=False)
