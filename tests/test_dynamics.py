"""Dynamics of the reference press checked against independent formulations and invariants."""
import math

import numpy as np
import pytest
from closed_form import EightBar, derivatives

from press_model import dynamics as D
from press_model import kinematics as K
from press_model.cycle import gear_loss_power, simulate_cycle
from press_model.forces import BalanceForce
from press_model.forward import ForwardModel, ForwardWorkspace, forward_dynamics, integrate
from press_model.model import Workspace
from press_model.motor import motor_torque


def virtual_work_torque(press, cf, theta, w, al, s_bdc, stroke, process):
    """Frictionless drive torque by virtual work: generalised inertia M(theta) from closed-form kinematics.

    tau = I(theta) al + (1/2) I'(theta) w^2 + dV/dtheta - F_slide dy_s/dtheta, with
    I = sum m |r'|^2 + J phi'^2 and I'/2 = sum m r'.r'' + J phi' phi''.
    """
    g = press.gravity
    names = list(press.bodies)

    def stacked(th):
        pose = cf.pose(th)
        return np.concatenate([np.append(pose[n][0], pose[n][1]) for n in names])

    d1, d2 = derivatives(stacked, theta)
    inertia = half_dI = dV = 0.0
    for k, n in enumerate(names):
        b = press.bodies[n]
        r1, r2 = d1[3 * k : 3 * k + 2], d2[3 * k : 3 * k + 2]
        p1, p2 = d1[3 * k + 2], d2[3 * k + 2]
        inertia += b.mass * r1 @ r1 + b.inertia * p1 * p1
        half_dI += b.mass * r1 @ r2 + b.inertia * p1 * p2
        dV += b.mass * g * r1[1]
    y = cf.slide_y(theta)
    ys1 = d1[3 * names.index(press.slide_body) + 1]
    h = y - s_bdc
    f_slide = BalanceForce.from_press(press, stroke)(h) + process(h, ys1 * w)
    return inertia * al + half_dI * w * w + dV - f_slide * ys1


def test_frictionless_torque_equals_virtual_work(ref_model, cushion):
    """RNEA + loop Jacobians (Pinocchio) vs virtual work on closed-form kinematics: 1e-6 relative."""
    job, motion = cushion
    pm, ws = ref_model, Workspace(ref_model)
    loads = D.slide_loads(pm, job.process)
    cf = EightBar(pm.press)
    ours, ref = [], []
    for deg in np.arange(0.5, 360, 7.0):  # off-grid angles, non-uniform speed
        th = math.radians(deg)
        w, al = float(motion.theta_dot(th)), float(motion.theta_ddot(th))
        st = K.state_at(pm, ws, th, w, al)
        ours.append(D.inverse_dynamics(pm, ws, st, loads, friction=False).crank_torque)
        ref.append(virtual_work_torque(pm.press, cf, th, w, al, pm.assembly.s_bdc, pm.assembly.stroke, job.process))
    ours, ref = np.array(ours), np.array(ref)
    assert np.max(np.abs(ours - ref)) / np.max(np.abs(ref)) < 1e-6
    assert np.any(np.abs(np.array([motion.theta_ddot(math.radians(d)) for d in (30, 200)])) > 0.1)


def test_energy_balance_over_a_cycle(ref_model, cushion):
    """Motor-side work = process work + joint/guide friction + gear losses; conservative forces cancel."""
    job, motion = cushion
    pm = ref_model
    c = simulate_cycle(pm, motion, job.process)
    drive = pm.press.drive
    motor_work = drive.motors * c.motor_work_per_motor(drive.gear_ratio)
    gear_loss = float(np.sum(gear_loss_power(pm, c) * c.dt_weights))
    assert c.friction_work() > 0 and gear_loss > 0 and c.process_work() > 0
    # cushion force x cushion stroke; the force step at 71.06 deg falls between 1-degree samples (~0.6 %)
    assert c.process_work() == pytest.approx(5.0e6 * 0.30, rel=1e-2)
    balance = motor_work - (c.process_work() + c.friction_work() + gear_loss)
    assert abs(balance) / motor_work < 1e-6


def test_friction_raises_torque_and_reactions_are_consistent(ref_model, cushion):
    job, motion = cushion
    pm, ws = ref_model, Workspace(ref_model)
    loads = D.slide_loads(pm, job.process)
    st = K.state_at(pm, ws, math.radians(100), float(motion.theta_dot(math.radians(100))), 0.0)
    r0 = D.inverse_dynamics(pm, ws, st, loads, friction=False)
    r1 = D.inverse_dynamics(pm, ws, st, loads)
    assert r1.crank_torque > r0.crank_torque  # friction opposes motion in the working stroke
    assert r1.friction_power > 0
    # at joint G the slide and link 7 exchange at least the cushion force minus slide weight and guide terms
    g = r1.joint_reactions[list(pm.joint_names).index("G")]
    assert g > 5.0e6 - 2.0e6
    # the fixed point really is one: friction recomputed from the returned reactions reproduces itself
    from press_model.forces import revolute_friction

    fr = pm.press.friction
    again = revolute_friction(fr.mu_r, fr.c_r, pm.bearing_radii, r1.joint_reactions, r1.joint_speeds)
    assert np.allclose(again, r1.joint_friction, rtol=1e-9, atol=1e-6)


def test_motor_efficiency_sign_logic(ref_model):
    drive = ref_model.press.drive
    u, n, eta = drive.gear_ratio, drive.motors, drive.efficiency
    assert motor_torque(drive, 1000.0, 1.0, 0.0) == pytest.approx(1000.0 / (n * u * eta))  # motoring
    assert motor_torque(drive, -1000.0, 1.0, 0.0) == pytest.approx(-1000.0 * eta / (n * u))  # braking
    assert motor_torque(drive, 0.0, 1.0, 2.0) == pytest.approx(drive.gear_inertia * u * 2.0 / (n * eta))


def test_forward_dynamics_reproduces_prescribed_acceleration(ref_model, cushion):
    job, motion = cushion
    pm, ws = ref_model, Workspace(ref_model)
    loads = D.slide_loads(pm, job.process)
    fm = ForwardModel(pm)
    fws = ForwardWorkspace(fm)
    for deg in range(0, 360, 20):
        th = math.radians(deg)
        st = K.state_at(pm, ws, th, float(motion.theta_dot(th)), float(motion.theta_ddot(th)))
        r = D.inverse_dynamics(pm, ws, st, loads)
        tm = float(motor_torque(pm.press.drive, r.crank_torque, st.theta_dot, st.theta_ddot))
        fd = forward_dynamics(fm, fws, st.q, st.v, tm, loads)
        scale = max(abs(st.theta_ddot), 1e-3)
        assert abs(fd.crank_accel - st.theta_ddot) / scale < 1e-8
        assert np.max(np.abs(fd.a - st.a)) < 1e-8 * max(1.0, np.max(np.abs(st.a)))


@pytest.mark.parametrize("load", ["none", "cushion"])
def test_forward_integration_keeps_loops_closed(ref_model, cushion, load):
    """RK4 + Baumgarte over one turn driven by the inverse-dynamics torque: loop gaps stay below 1e-6 m."""
    from press_model.forces import NO_PROCESS

    job, motion = cushion
    process = job.process if load == "cushion" else NO_PROCESS
    pm, ws = ref_model, Workspace(ref_model)
    c = simulate_cycle(pm, motion, process, step_deg=0.5)
    th_grid, tm_grid = np.append(c.theta, 2 * math.pi), np.append(c.motor_torque, c.motor_torque[0])
    st = K.state_at(pm, ws, 0.0, float(motion.theta_dot(0.0)), float(motion.theta_ddot(0.0)))
    tr = integrate(ForwardModel(pm), st.q, st.v, lambda t, th, thd: float(np.interp(th % (2 * math.pi), th_grid, tm_grid)),
                   D.slide_loads(pm, process), motion.period, motion.period / 360)
    assert np.max(tr.loop_residual) < 1e-6
    if load == "none":  # no force step between grid points: the open-loop playback follows the plan
        assert math.degrees(tr.theta[-1]) == pytest.approx(360.0, abs=0.1)
        assert np.max(np.abs(tr.theta_dot - motion.theta_dot(tr.theta)) / motion.theta_dot(tr.theta)) < 1e-3


def test_reactions_do_not_depend_on_what_the_workspace_computed_before(ref_model, cushion):
    """StatePrep on a fresh workspace (no forward kinematics run at q) gives the same reactions."""
    job, motion = cushion
    pm = ref_model
    loads = D.slide_loads(pm, job.process)
    st = K.state_at(pm, Workspace(pm), math.radians(100), 1.0, 0.3)
    other = Workspace(pm)
    K.state_at(pm, other, math.radians(250), 1.0, 0.0)  # leaves its data at another configuration
    a = D.StatePrep(pm, other, st.q, st.v, st.a, st.height, st.height_dot, loads).solve(np.zeros(9), 0.0)
    b = D.StatePrep(pm, Workspace(pm), st.q, st.v, st.a, st.height, st.height_dot, loads).solve(np.zeros(9), 0.0)
    ref = D.inverse_dynamics(pm, Workspace(pm), st, loads, friction=False)
    for r in (a, b):
        assert r[0] == pytest.approx(ref.crank_torque, rel=1e-12)
        assert np.allclose(r[1], ref.joint_reactions, rtol=1e-12)


def test_forward_dynamics_linear_friction_maps_equal_the_plain_iteration(ref_model, cushion):
    """The one-call friction maps of forward_dynamics against the plain fixed point (friction -> Pinocchio
    constrained dynamics -> reactions, repeated), at perturbed off-manifold states with the cushion force."""
    import pinocchio as pin

    from press_model.motor import crank_input_torque as motor_crank_input

    job, motion = cushion
    pm, ws = ref_model, Workspace(ref_model)
    loads = D.slide_loads(pm, job.process)
    fm = ForwardModel(pm)
    fws = ForwardWorkspace(fm)
    rng = np.random.default_rng(11)
    for deg in range(5, 360, 40):
        st = K.state_at(pm, ws, math.radians(deg), rng.uniform(0.3, 3.0), rng.uniform(-20, 20))
        q = st.q + rng.normal(0, 1e-6, len(st.q))  # slightly off the loop closure, as in an integration
        tm = rng.uniform(-20000, 20000)
        fws.normals = None
        new = forward_dynamics(fm, fws, q, st.v, tm, loads)
        # plain iteration
        thd = float(pm.crank_row @ st.v)
        tau_in = float(motor_crank_input(pm.press.drive, tm, thd))
        s_pos, s_dot, _ = K.slide_motion(pm, ws.data, q, st.v, np.zeros_like(st.v))
        prep = D.StatePrep(pm, ws, q, st.v, np.zeros_like(st.v), s_pos - pm.assembly.s_bdc, s_dot, loads)
        base = pm.crank_row * tau_in + prep.u_s * prep.f_ext
        n_rev, n_s = np.zeros(len(pm.joint_names)), 0.0
        data, cdata = fm.model.createData(), pin.StdVec_RigidConstraintData()
        for cm in fm.constraints:
            cdata.append(cm.createData())
        pin.initConstraintDynamics(fm.model, data, fm.constraints, cdata)
        prox = pin.ProximalSettings(1e-13, 1e-10, 50)
        for _ in range(60):
            tau_f, f_s = prep.friction(n_rev, n_s)
            a = pin.constraintDynamics(fm.model, data, q, st.v, base + prep.generalized_friction(tau_f, f_s), fm.constraints, cdata, prox)
            _, new_rev, new_s = prep.at(a).solve(tau_f, f_s)
            done = max(np.max(np.abs(new_rev - n_rev)), abs(new_s - n_s)) <= 1e-13 * max(1.0, np.max(new_rev), new_s)
            n_rev, n_s = new_rev, new_s
            if done:
                break
        tau_f, f_s = prep.friction(n_rev, n_s)
        a = pin.constraintDynamics(fm.model, data, q, st.v, base + prep.generalized_friction(tau_f, f_s), fm.constraints, cdata, prox)
        assert np.max(np.abs(new.a - a)) < 1e-9 * max(1.0, np.max(np.abs(a))), deg



def test_forward_dynamics_compiled_friction_loop_equals_plain_python(ref_model, cushion, monkeypatch):
    """forward_dynamics' friction maps and fixed point compiled by numba (press_model.jit) against the same function run
    as plain Python: the same accelerations to round-off and the same iteration counts at perturbed states; with too
    few iterations allowed, the same one-line error from both."""
    import dataclasses

    import press_model.forward as forward
    from press_io.errors import SolverError
    from press_model.jit import compiled

    if compiled(forward.friction_accel) is None:  # pragma: no cover - numba is a dependency
        pytest.skip("numba is not installed")
    job, motion = cushion
    pm, ws = ref_model, Workspace(ref_model)
    loads = D.slide_loads(pm, job.process)
    rng = np.random.default_rng(5)
    states = []
    for deg in range(3, 360, 45):
        st = K.state_at(pm, ws, math.radians(deg), rng.uniform(0.3, 3.0), rng.uniform(-20, 20))
        states.append((st.q + rng.normal(0, 1e-6, len(st.q)), st.v, rng.uniform(-20000, 20000)))

    def run():
        fm = ForwardModel(pm)
        fws = ForwardWorkspace(fm)
        return [forward_dynamics(fm, fws, q, v, tm, loads) for q, v, tm in states]

    fast = run()
    with monkeypatch.context() as mp:
        mp.setattr(forward, "compiled", lambda fn: None)
        plain = run()
    for f, p in zip(fast, plain):
        assert f.iterations == p.iterations > 1
        np.testing.assert_allclose(f.a, p.a, rtol=1e-13, atol=1e-13 * np.max(np.abs(p.a)))
    few = dataclasses.replace(pm.press.numerics, friction_max_iterations=1)
    monkeypatch.setattr(pm, "press", dataclasses.replace(pm.press, numerics=few))
    errors = []
    for compiled_or_not in (compiled, lambda fn: None):
        monkeypatch.setattr(forward, "compiled", compiled_or_not)
        with pytest.raises(SolverError, match="friction fixed point did not converge at crank angle") as err:
            run()
        errors.append(str(err.value))
    assert errors[0] == errors[1]
