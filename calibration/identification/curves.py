"""Motor-torque curves of calibration parameter sets, each distinct crank torque computed once.

The batch model's costly part is the friction fixed point (:func:`press_model.batch.evaluate_chunk`), which gives the
crank torque; Eq. 16 turns it into the motor torque per set. The crank torque reads only the bodies' inertial
parameters, the balance and the joint and guide friction; the drive's own parameters (gear inertia, efficiency and
losses) enter Eq. 16 alone. So sets that differ only there share one crank torque: a central-difference Jacobian's
columns along eta_gear and J_gear share the point's, a fit of eta_gear alone has one crank torque for every set, and
the bootstrap's refits all start at the estimate (41 identical points and 41 identical Jacobians in their first
iteration). :func:`motor_curves` computes the crank torque of each distinct crank row once, remembering it per batch
model for later calls, and applies Eq. 16 to every set as :func:`press_model.batch.motor_torques` does.

The same bytes as :func:`press_model.batch.motor_torques`: a set's crank torque is the kernel's for that set alone,
whatever else is in its batch (press_model's tests), and Eq. 16 is applied to the same chunks of sets as there.
"""
from __future__ import annotations

import weakref

import numpy as np

from press_model.batch import DEFAULT_CHUNK, BatchModel, iter_chunks, motor_torque_eq16, parameter_array

MEMO_CURVES = 256  # crank torques remembered per batch model (0.7 MB at 360 points; a Calibration keeps its models): then it
# starts again, keeping the last call's, which the next one reads (a refit's Jacobian reads its points' crank torques)

_MEMOS: "weakref.WeakKeyDictionary[BatchModel, dict]" = weakref.WeakKeyDictionary()  # batch model -> {row bytes: curve}


def crank_columns(bm: BatchModel) -> np.ndarray:
    """The columns of ``bm``'s parameter rows that its crank torque reads (sorted indices): the bodies' masses,
    inertias and centre-of-mass distances, the balance's psi and the four friction coefficients; not the drive's
    gear inertia, efficiency or losses, which only Eq. 16 reads."""
    sources = [bm.psi, bm.mu_r, bm.c_r, bm.mu_s, bm.c_s]
    for b in bm.bodies:
        sources += [b.mass, b.inertia, *((b.distance,) if b.distance is not None else ()), *b.distances]
    return np.array(sorted({s.index for s in sources if s.index >= 0}), dtype=np.int64)


def motor_curves(bm: BatchModel, X: np.ndarray) -> np.ndarray:
    """Motor-torque curves (B, n) per motor, N m, of the parameter rows X (B, D) in ``bm.names`` order: the numbers of
    :func:`press_model.batch.motor_torques`, each distinct crank torque computed once (module docstring)."""
    X = parameter_array(bm, X)
    memo = _MEMOS.setdefault(bm, {})
    keys = np.ascontiguousarray(X[:, crank_columns(bm)])
    rows = [k.tobytes() for k in keys]
    new = list(dict.fromkeys(k for k in rows if k not in memo))  # distinct, in order of first appearance
    found = {}
    if new:
        first = {k: i for i, k in reversed(list(enumerate(rows)))}
        for sl, res in iter_chunks(bm, X[[first[k] for k in new]], motor=False):  # Eq. 16 below, on every set
            for k, curve in zip(new[sl], res.crank_torque):
                curve.setflags(write=False)
                found[k] = curve
    crank = np.array([found[k] if k in found else memo[k] for k in rows]).reshape(len(X), bm.n_points)
    if len(memo) + len(found) > MEMO_CURVES:
        memo.clear()
    memo.update(found)
    out = np.empty((len(X), bm.n_points))
    for a in range(0, len(X), DEFAULT_CHUNK):  # Eq. 16 on the chunks motor_torques gives it (compiled from 64 sets)
        sl = slice(a, min(a + DEFAULT_CHUNK, len(X)))
        out[sl] = motor_torque_eq16(bm, X[sl], crank[sl])
    return out
