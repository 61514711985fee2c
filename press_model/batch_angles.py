"""A batch model at some of its crank angles, and the angles at which two batch models compute alike.

Two load cases of one press on one motion (the no-load cycle and the cushion test) differ only where the process force
acts: at every other grid angle their batch models hold the same constants to the bit, so the friction fixed point of a
parameter set gives the same crank torque there in both. :func:`alike_angles` finds those angles; :func:`at_angles` is
the model restricted to the others, whose kernel runs only there. The kernel treats each angle and each set apart
(:mod:`batch_kernel`), so a restricted model's torques are the full model's at its angles, to the bit (tests).
"""
from __future__ import annotations

from dataclasses import fields, is_dataclass, replace

import numpy as np

from .batch import BatchModel

# the fields that hold one entry per grid angle, and the axis of it
PER_ANGLE = {"theta": 0, "theta_dot": 0, "theta_ddot": 0, "height": 0, "height_dot": 0, "base": 1, "visc": 1, "coul": 0,
             "base_pt": 0, "visc_pt": 0, "coul_tau": 0, "coul_lam": 0, "slide": 0}
# per-angle fields the friction fixed point and Eq. 16 read: where all of them agree, so do the crank and motor torques
KERNEL_INPUTS = ("theta_dot", "theta_ddot", "base_pt", "visc_pt", "coul_tau", "coul_lam")
# fields that say nothing about a set's torques (the source file, the motion's period: names and records only)
NOT_COMPUTED = ("press", "period")


def at_angles(bm: BatchModel, angles: np.ndarray) -> BatchModel:
    """``bm`` on the grid angles ``angles`` (indices into ``bm.theta``, increasing) only: a model of len(angles) points
    whose kernel, Eq. 16 and error messages (``theta``) are ``bm``'s at those angles."""
    angles = np.asarray(angles, dtype=np.int64)
    arrays = {}
    for name, axis in PER_ANGLE.items():
        a = np.ascontiguousarray(np.take(getattr(bm, name), angles, axis=axis))
        a.setflags(write=False)
        arrays[name] = a
    return replace(bm, **arrays)


def alike_angles(a: BatchModel, b: BatchModel) -> np.ndarray:
    """Boolean mask (n,) of the grid angles at which ``b`` gives every parameter set the crank and motor torques that
    ``a`` gives it, bit for bit: the models agree in every constant that is not per angle, and at those angles in every
    per-angle constant the kernel and Eq. 16 read. All False where the models are of other presses, grids or
    parameters."""
    n = a.n_points
    if b.n_points != n or not np.array_equal(a.theta, b.theta):
        return np.zeros(n, dtype=bool)
    for f in fields(BatchModel):
        if f.name not in PER_ANGLE and f.name not in NOT_COMPUTED and not _same(getattr(a, f.name), getattr(b, f.name)):
            return np.zeros(n, dtype=bool)
    alike = np.ones(n, dtype=bool)
    for name in KERNEL_INPUTS:
        x, y = getattr(a, name), getattr(b, name)
        if x.shape != y.shape:
            return np.zeros(n, dtype=bool)
        # compared as bits: -0.0 and 0.0 (or two NaNs) are not taken for each other
        bits_x = np.ascontiguousarray(x).view(np.uint64).reshape(n, -1)
        bits_y = np.ascontiguousarray(y).view(np.uint64).reshape(n, -1)
        alike &= (bits_x == bits_y).all(axis=1)
    return alike


def _same(x, y) -> bool:
    """Whether two constants of a batch model are the same: arrays bit for bit, dataclasses and tuples field by field."""
    if isinstance(x, np.ndarray) or isinstance(y, np.ndarray):
        x, y = np.asarray(x), np.asarray(y)
        return x.shape == y.shape and x.dtype == y.dtype and x.tobytes() == y.tobytes()
    if is_dataclass(x) and not isinstance(x, type):
        return type(x) is type(y) and all(_same(getattr(x, f.name), getattr(y, f.name)) for f in fields(x))
    if isinstance(x, (tuple, list)):
        return isinstance(y, (tuple, list)) and len(x) == len(y) and all(_same(p, q) for p, q in zip(x, y))
    if isinstance(x, float) and isinstance(y, float):
        return np.float64(x).tobytes() == np.float64(y).tobytes()  # 0.0 and -0.0 are other constants
    return type(x) is type(y) and x == y
