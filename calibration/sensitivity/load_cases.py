"""The responses of one Sobol design under several load cases of one press, with the work the cases share done once.

``reproduce`` analyses the same design (one seed, one N) under the no-load cycle and under the cushion test: one motion,
two process forces. Away from the cushion's stroke (252 of the 360 grid angles) the two batch models hold the same
constants to the bit, so every set's friction fixed point there gives the same crank torque in both
(:func:`press_model.batch_angles.alike_angles`). :func:`cases_evaluator` runs the kernel for the first case at every
angle and for each other case only at the angles where it differs, and computes the sets' features (COM fits) once;
Eq. 16 and the responses then run per case as :func:`calibration.sensitivity.report.response_evaluator` runs them, so
each case's responses are that evaluator's, bit for bit (tests).
"""
from __future__ import annotations

from typing import TYPE_CHECKING, Callable, Sequence

import numpy as np

from calibration.responses import RESPONSES, all_responses

if TYPE_CHECKING:  # numba and Pinocchio come with the batch model: imported where used
    from press_model.batch import BatchModel


def cases_evaluator(bms: Sequence[BatchModel], chunk_size: int) -> Callable[[np.ndarray], np.ndarray]:
    """A callable mapping parameter rows X (B, D) to the responses of every model of ``bms`` side by side, (B, 4 len(bms)):
    columns 4 k .. 4 k + 3 are model k's Eqs. 22-25 (N m, 1, N m, J) against its nominal parameters' curve, as
    ``response_evaluator(bms[k], chunk_size=chunk_size)`` gives them. ``chunk_size``: sets per kernel call."""
    from press_model.batch import evaluate_chunk, feature_chunks, motor_torques
    from press_model.batch_angles import alike_angles, at_angles

    first = bms[0]
    refs = [motor_torques(bm, bm.nominal[None])[0] for bm in bms]
    # per later model: the angles its kernel runs at, and the model there (None: all of them, with its own features)
    own = []
    for bm in bms[1:]:
        alike = alike_angles(first, bm)
        angles = np.flatnonzero(~alike)
        own.append((angles, None if not alike.any() else at_angles(bm, angles) if len(angles) else False))

    def evaluate(X: np.ndarray) -> np.ndarray:
        out = np.empty((len(X), len(RESPONSES) * len(bms)))
        for rows, x, f in feature_chunks(first, X, chunk_size):
            res = evaluate_chunk(first, x, feats=f, offset=rows.start)
            out[rows, : len(RESPONSES)] = all_responses(res.motor_torque, refs[0], first.theta_dot, first.gear_ratio)
            for k, (bm, (angles, part)) in enumerate(zip(bms[1:], own), start=1):
                out[rows, len(RESPONSES) * k : len(RESPONSES) * (k + 1)] = _responses(bm, x, f, rows.start, res.crank_torque,
                                                                                      angles, part, refs[k])
        return out

    return evaluate


def _responses(bm: BatchModel, x: np.ndarray, feats, offset: int, crank: np.ndarray, angles: np.ndarray, part,
               ref: np.ndarray) -> np.ndarray:
    """Responses (B, 4) of ``bm`` for the sets ``x`` (features ``feats``; ``offset``: the row of x[0] in the design), whose
    crank torques are ``crank`` (the first model's) but at ``angles``, computed by ``part`` (``bm`` at those angles;
    False: at none; None: ``bm`` differs from the first model at every angle, so everything is computed anew)."""
    from press_model.batch import evaluate_chunk, motor_torque_eq16

    if part is None:
        res = evaluate_chunk(bm, x, offset=offset)
        return all_responses(res.motor_torque, ref, bm.theta_dot, bm.gear_ratio)
    if part is not False:
        crank = crank.copy()
        crank[:, angles] = evaluate_chunk(part, x, feats=feats, offset=offset, motor=False).crank_torque
    return all_responses(motor_torque_eq16(bm, x, crank), ref, bm.theta_dot, bm.gear_ratio)
