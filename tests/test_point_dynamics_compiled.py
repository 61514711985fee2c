"""The per-point Pinocchio path's compiled and whole-array parts against the plain per-call formulation they replace."""
import dataclasses
import math

import numpy as np
import pinocchio as pin
import pytest

from press_io.errors import SolverError
from press_model import dynamics as D
from press_model import kinematics as K
from press_model import reaction_fixed_point as RFP
from press_model.jit import compiled
from press_model.model import Workspace


def _states(pm, n=12, seed=3):
    """Kinematic states around the turn at random crank speeds and accelerations (both signs: friction reverses)."""
    ws, rng = Workspace(pm), np.random.default_rng(seed)
    return [K.state_at(pm, ws, math.radians(deg), rng.uniform(-3.0, 3.0), rng.uniform(-20, 20))
            for deg in np.linspace(1.0, 359.0, n)]


def _plain_iteration(pm, ws, st, loads):
    """The fixed point as StatePrep's friction and solve iterated until reactions_settled (the numpy formulation):
    (drive torque, reactions, guide normal, joint friction, guide friction, iterations)."""
    prep = D.StatePrep(pm, ws, st.q, st.v, st.a, st.height, st.height_dot, loads)
    tau_d, n_rev, n_s = prep.solve(np.zeros_like(prep.w), 0.0)
    num = pm.press.numerics
    for it in range(2, num.friction_max_iterations + 1):
        tau_f, f_s = prep.friction(n_rev, n_s)
        tau_d, new_rev, new_s = prep.solve(tau_f, f_s)
        done, _ = D.reactions_settled(n_rev, n_s, new_rev, new_s, num.friction_tolerance)
        n_rev, n_s = new_rev, new_s
        if done:
            break
    else:
        raise AssertionError("the plain iteration did not converge")
    tau_f, f_s = prep.friction(n_rev, n_s)
    tau_d, _, _ = prep.solve(tau_f, f_s)
    return tau_d, n_rev, n_s, tau_f, f_s, it


def _close(a, b):
    np.testing.assert_allclose(a, b, rtol=1e-13, atol=1e-13 * max(1.0, float(np.max(np.abs(b)))))


def test_inverse_dynamics_fixed_point_equals_statepreps_iteration(ref_model, cushion):
    """inverse_dynamics' compiled fixed point gives StatePrep's plain iteration's torque, reactions and friction to
    round-off, in the same number of iterations; without friction, StatePrep's frictionless solve."""
    job, _ = cushion
    pm, ws = ref_model, Workspace(ref_model)
    loads = D.slide_loads(pm, job.process)
    for st in _states(pm):
        got = D.inverse_dynamics(pm, ws, st, loads)
        tau_d, n_rev, n_s, tau_f, f_s, it = _plain_iteration(pm, ws, st, loads)
        assert got.iterations == it > 2
        _close(got.crank_torque, tau_d)
        _close(got.joint_reactions, n_rev)
        _close(got.guide_normal, n_s)
        _close(got.joint_friction, tau_f)
        _close(got.guide_friction, f_s)
        bare = D.inverse_dynamics(pm, ws, st, loads, friction=False)
        prep = D.StatePrep(pm, ws, st.q, st.v, st.a, st.height, st.height_dot, loads)
        tau0, rev0, s0 = prep.solve(np.zeros_like(prep.w), 0.0)
        assert bare.iterations == 1 and not np.any(bare.joint_friction) and bare.guide_friction == 0.0
        _close(bare.crank_torque, tau0)
        _close(bare.joint_reactions, rev0)
        _close(bare.guide_normal, s0)


def test_fixed_point_compiled_equals_plain_python(ref_model, cushion, monkeypatch):
    """The fixed point compiled by numba (press_model.jit) against the same function run as plain Python: the same values
    to round-off and iteration counts; with too few iterations allowed, the same one-line error from both."""
    if compiled(RFP.reaction_fixed_point) is None:  # pragma: no cover - numba is a dependency
        pytest.skip("numba is not installed")
    job, _ = cushion
    pm = ref_model
    loads = D.slide_loads(pm, job.process)
    states = _states(pm, n=6, seed=8)

    def run():
        ws = Workspace(pm)
        return [D.inverse_dynamics(pm, ws, st, loads) for st in states]

    fast = run()
    with monkeypatch.context() as mp:
        mp.setattr(RFP, "compiled", lambda fn: None)
        plain = run()
    for f, p in zip(fast, plain):
        assert f.iterations == p.iterations > 2
        for name in ("crank_torque", "joint_reactions", "guide_normal", "joint_friction", "guide_friction"):
            _close(getattr(f, name), getattr(p, name))
    few = dataclasses.replace(pm.press.numerics, friction_max_iterations=2)
    monkeypatch.setattr(pm, "press", dataclasses.replace(pm.press, numerics=few))
    errors = []
    for compiled_or_not in (compiled, lambda fn: None):
        monkeypatch.setattr(RFP, "compiled", compiled_or_not)
        with pytest.raises(SolverError, match="friction/reaction fixed point did not converge at crank angle .* after 2 iterations") as err:
            run()
        errors.append(str(err.value))
    assert errors[0] == errors[1]


def test_loop_terms_equal_pinocchio_frame_jacobians(ref_model):
    """loop_terms' loop Jacobian formed from data.J on whole arrays is, bit for bit, the difference of Pinocchio's
    LOCAL_WORLD_ALIGNED frame Jacobians of each cut's two points, and its residual the difference of their placements,
    at the assembly sweep's configurations and at configurations off the loop closure."""
    pm = ref_model
    m, data, rng = pm.model, pm.model.createData(), np.random.default_rng(4)
    lwa = pin.ReferenceFrame.LOCAL_WORLD_ALIGNED
    for q in list(pm.assembly.qs[::7]) + [pm.assembly.qs[3] + rng.normal(0.0, 0.3, pm.nv) for _ in range(20)]:
        res, Kmat = K.loop_terms(pm, data, q)
        pin.computeJointJacobians(m, data, q)
        pin.updateFramePlacements(m, data)
        for i, c in enumerate(pm.cuts):
            rows = slice(2 * i, 2 * i + 2)
            want = pin.getFrameJacobian(m, data, c.first_frame, lwa)[:2] - pin.getFrameJacobian(m, data, c.second_frame, lwa)[:2]
            assert np.array_equal(Kmat[rows], want)
            assert np.array_equal(res[rows], data.oMf[c.first_frame].translation[:2] - data.oMf[c.second_frame].translation[:2])
        assert np.array_equal(Kmat[-1], pm.crank_row)


def test_state_at_compiled_equals_plain_python(ref_model, monkeypatch):
    """state_at with its compiled loop rows, Newton steps and solves (press_model.jit) against the same functions run as
    plain Python, warm-started point to point along a turn: the same positions, velocities and accelerations to
    round-off; and velocity/acceleration given the position solve's constraint matrix equal them recomputing it."""
    if compiled(K.newton_update) is None:  # pragma: no cover - numba is a dependency
        pytest.skip("numba is not installed")
    pm, rng = ref_model, np.random.default_rng(6)
    grid = [(math.radians(deg), rng.uniform(-3.0, 3.0), rng.uniform(-20, 20)) for deg in np.arange(0.0, 360.0, 7.5)]

    def run():
        ws = Workspace(pm)
        return [K.state_at(pm, ws, *point) for point in grid]

    fast = run()
    with monkeypatch.context() as mp:
        mp.setattr(K, "compiled", lambda fn: None)
        plain = run()
    ws = Workspace(pm)
    for f, p, point in zip(fast, plain, grid):
        for name in ("q", "v", "a"):
            _close(getattr(f, name), getattr(p, name))
        v = K.velocity(pm, ws, f.q, point[1])
        assert np.array_equal(v, f.v)
        assert np.array_equal(K.acceleration(pm, ws, f.q, v, point[2]), f.a)
