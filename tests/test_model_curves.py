"""The calibration's model curves (calibration/identification/curves.py): each distinct crank torque computed once, the
numbers of press_model.batch.motor_torques to the bit."""
from __future__ import annotations

import numpy as np
import pytest

import calibration.identification.curves as curves
from press_model.batch import build_batch_model, evaluate_chunk, motor_torques
from press_model.press_data import load_press

STEP_DEG = 5.0  # a coarse grid: what is tested holds at every angle


@pytest.fixture(scope="module")
def bm(cushion):
    job, motion = cushion
    return build_batch_model(load_press(), motion, job.process, step_deg=STEP_DEG)


def _sets(bm, rows: int) -> np.ndarray:
    """``rows`` parameter sets: a few points of the box, each repeated with only the drive's gear inertia and efficiency
    moved, and the whole repeated (the bootstrap's refits all start at one point)."""
    rng = np.random.default_rng(5)
    col = {n: i for i, n in enumerate(bm.names)}
    X = []
    for _ in range(rows // 6):
        x = bm.low + rng.random(bm.n_params) * (bm.high - bm.low)
        for j_gear, eta in ((0.0, 0.0), (0.1, 0.0), (0.0, -0.1), (0.2, 0.1)):
            y = x.copy()
            y[col["J_gear"]] += j_gear * (bm.high - bm.low)[col["J_gear"]]
            y[col["eta_gear"]] += eta * (bm.high - bm.low)[col["eta_gear"]]
            X.append(y)
    X += X[: rows - len(X)]
    return np.array(X)


def test_the_crank_torque_reads_every_column_it_is_keyed_on_and_no_other(bm):
    keyed = set(curves.crank_columns(bm).tolist())
    assert {bm.names.index("J_gear"), bm.names.index("eta_gear")}.isdisjoint(keyed)
    x = bm.nominal + 0.3 * (bm.high - bm.nominal)
    X = np.tile(x, (bm.n_params + 1, 1))
    for j in range(bm.n_params):
        X[j + 1, j] = bm.low[j] + 0.8 * (bm.high[j] - bm.low[j])
    crank = evaluate_chunk(bm, X).crank_torque
    moved = {j for j in range(bm.n_params) if crank[j + 1].tobytes() != crank[0].tobytes()}
    assert moved <= keyed  # a column left out of the key moves no crank torque (or the memo would mix sets up)
    assert {bm.names.index(n) for n in ("m8", "mu_r", "mu_s", "psi")} <= moved


@pytest.mark.parametrize("rows", [40, 300], ids=["Eq. 16 in numpy (under 64 sets)", "Eq. 16 compiled, two chunks"])
def test_the_curves_are_those_of_the_batch_model_to_the_bit(bm, rows):
    X = _sets(bm, rows)
    assert np.array_equal(curves.motor_curves(bm, X), motor_torques(bm, X))
    assert curves.motor_curves(bm, X).tobytes() == motor_torques(bm, X).tobytes()


def test_each_distinct_crank_torque_is_computed_once(cushion, monkeypatch):
    job, motion = cushion
    bm = build_batch_model(load_press(), motion, job.process, step_deg=STEP_DEG)  # a model no call has seen yet
    X = _sets(bm, 48)
    evaluated = []
    real = curves.iter_chunks

    def counted(bm_, sets, *args, **kwargs):
        evaluated.append(len(sets))
        return real(bm_, sets, *args, **kwargs)

    monkeypatch.setattr(curves, "iter_chunks", counted)
    first = curves.motor_curves(bm, X)
    distinct = len({r.tobytes() for r in X[:, curves.crank_columns(bm)]})
    assert distinct == 8 and evaluated == [distinct]
    assert np.array_equal(curves.motor_curves(bm, X[::-1]), first[::-1]) and evaluated == [distinct]  # remembered
