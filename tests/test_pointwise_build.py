"""What the batch model's per-point build reads from the per-point Pinocchio path, against that path's own calls: the grid
positions kept on disk by the press geometry are the warm-started position solves, bit for bit, and a StatePrep or an
inverse dynamics on state_at's loop closure (its constraint matrix ws.K_last, ws.data at q) is the one that closes the loop again."""
import math

import numpy as np

from press_model import dynamics as D
from press_model import kinematic_tables as KT
from press_model import kinematics as K
from press_model.cycle import crank_grid
from press_model.model import Workspace


def test_grid_positions_are_the_warm_started_solves_fresh_and_from_the_disk(ref_model, tmp_path, monkeypatch):
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    theta = crank_grid(3.0)
    ws = Workspace(ref_model)
    solved = np.array([K.state_at(ref_model, ws, float(a), 1.0, 0.0).q for a in theta])
    fresh = KT.grid_positions(ref_model, theta)
    assert len(list((tmp_path / "servo-press-twin" / "kinematics").glob("kinematics_*.npz"))) == 1
    stored = KT.grid_positions(ref_model, theta)
    assert fresh.tobytes() == solved.tobytes() and stored.tobytes() == solved.tobytes()


def test_a_state_from_a_grid_position_closes_at_its_first_check(ref_model, monkeypatch):
    theta = crank_grid(10.0)
    qs = KT.grid_positions(ref_model, theta)
    calls = []
    real = K.loop_terms
    monkeypatch.setattr(K, "loop_terms", lambda *a: calls.append(1) or real(*a))
    ws = Workspace(ref_model)
    for a, q in zip(theta, qs):
        assert K.state_at(ref_model, ws, float(a), 2.0, -5.0, q).q.tobytes() == q.tobytes()
    assert len(calls) == len(theta)


def test_stateprep_on_state_ats_loop_closure_is_the_one_that_closes_it_again(ref_model, cushion):
    job, _ = cushion
    loads = D.slide_loads(ref_model, job.process)
    ws, rng = Workspace(ref_model), np.random.default_rng(5)
    for deg in np.linspace(2.0, 358.0, 9):
        st = K.state_at(ref_model, ws, math.radians(deg), rng.uniform(-3.0, 3.0), rng.uniform(-20.0, 20.0))
        given = D.StatePrep.on_closure(ref_model, ws, st, loads)
        own = D.StatePrep(ref_model, Workspace(ref_model), st.q, st.v, st.a, st.height, st.height_dot, loads)
        for name in ("A_inv", "u_s", "P", "base_rhs", "w", "rot"):
            assert getattr(given, name).tobytes() == getattr(own, name).tobytes(), name
        A = np.column_stack([ref_model.crank_row, ws.K_last[:-1].T])
        assert given.A_inv.tobytes() == np.linalg.inv(A).tobytes()  # the compiled gesv on the identity is numpy's inv
        a = D.inverse_dynamics(ref_model, ws, st, loads, on_closure=True)
        b = D.inverse_dynamics(ref_model, Workspace(ref_model), st, loads)
        assert (a.crank_torque, a.joint_reactions.tobytes(), a.guide_normal) == (b.crank_torque, b.joint_reactions.tobytes(),
                                                                                 b.guide_normal)
