"""The forward dynamics' reads of Pinocchio's Data and its compiled steps checked against Pinocchio's own per-frame calls
and numpy's expressions (press_model/forward.py, press_model/pinocchio_views.py)."""
import math

import numpy as np
import pinocchio as pin

from press_model import dynamics as D
from press_model import kinematics as K
from press_model.forward import ForwardModel, ForwardWorkspace, forward_dynamics, friction_accel
from press_model.kinematics import LWA
from press_model.model import Workspace
from press_model.motor import crank_input_torque
from press_model.pinocchio_views import StackedViews


def accelerations_by_pinocchio_calls(fm, q, v, motor_torque, loads):
    """The accelerations of forward_dynamics' formulation (module docstring of press_model/forward.py) with every input
    read by Pinocchio's per-frame and per-joint calls and numpy's linear algebra, on a fresh Data: the slide's row by
    getFrameJacobian, positions from data.oMf, orientations from data.oMi, joint forces from data.f."""
    pm = fm.pm
    m, data = pm.model, pm.model.createData()
    res, Kc = K.loop_terms(pm, data, q)
    u_s = pm.axis @ pin.getFrameJacobian(m, data, pm.slide_frame, LWA)[:3]
    height = float(pm.axis @ data.oMf[pm.slide_frame].translation) - pm.assembly.s_bdc
    s_dot = float(u_s @ v)
    f_ext = sum(float(f) for f in loads(height, s_dot))
    tau_in = float(crank_input_torque(pm.press.drive, motor_torque, float(pm.crank_row @ v)))
    cdata = pin.StdVec_RigidConstraintData()
    for cm in fm.constraints:
        cdata.append(cm.createData())
    cd = fm.model.createData()
    pin.initConstraintDynamics(fm.model, cd, fm.constraints, cdata)
    a0 = np.array(pin.constraintDynamics(fm.model, cd, q, v, pm.crank_row * tau_in + u_s * f_ext, fm.constraints, cdata,
                                         pin.ProximalSettings(1e-13, 1e-10, 50)))
    A_inv = np.linalg.inv(np.column_stack([pm.crank_row, Kc[:-1].T]))
    N = A_inv[0]
    tau0 = pin.rnea(m, data, q, v, a0).copy()
    jids = pm.reaction_map.tree_jids
    rot = np.array([data.oMi[j].rotation[:2] for j in jids])
    forces = np.array([data.f[j].linear for j in jids])
    ng = fm.model_no_gravity.createData()
    MN = pin.rnea(fm.model_no_gravity, ng, q, np.zeros(pm.nv), N).copy()
    forces_ng = np.array([ng.f[j].linear for j in jids])
    P = np.stack([np.einsum("tij,tj->ti", rot, forces).ravel(), np.einsum("tij,tj->ti", rot, forces_ng).ravel()])
    gen = np.vstack([tau0, MN, u_s, pm.crank_row, pm.joint_rows])
    num = pm.press.numerics
    settings = np.array([f_ext, fm.armature, num.friction_tolerance, num.friction_max_iterations, 0.0])
    dtdd, it = friction_accel(A_inv, P, gen, np.append(pm.joint_rows @ v, s_dot), fm.normal_map.G, fm.coefficients,
                              np.empty(len(fm.normal_rows)), settings)
    assert it > 0
    return a0 + N * dtdd, res


def test_forward_dynamics_equals_its_formulation_on_pinocchio_calls(ref_model, cushion):
    """At perturbed off-manifold states (the cushion force on and off, motoring and braking) forward_dynamics' live views
    and compiled steps give the accelerations and loop residual of the same formulation read by Pinocchio's per-frame
    calls and numpy's inverse, to round-off."""
    job, motion = cushion
    pm, ws = ref_model, Workspace(ref_model)
    loads = D.slide_loads(pm, job.process)
    fm = ForwardModel(pm)
    fws = ForwardWorkspace(fm)
    rng = np.random.default_rng(17)
    for deg in (10, 100, 170, 200, 290):
        st = K.state_at(pm, ws, math.radians(deg), rng.uniform(0.3, 3.0), rng.uniform(-20, 20))
        q = st.q + rng.normal(0, 1e-6, len(st.q))
        tm = rng.uniform(-20000, 20000)
        fws.normals = None  # no warm start: the reference starts from the frictionless normals too
        a = forward_dynamics(fm, fws, q, st.v, tm, loads).a
        ref, res = accelerations_by_pinocchio_calls(fm, q, st.v, tm, loads)
        np.testing.assert_allclose(a, ref, rtol=1e-12, atol=1e-12 * np.max(np.abs(ref)))
        np.testing.assert_allclose(fws.residual, res, rtol=0, atol=1e-15)


def test_stacked_views_follow_pinocchio_and_copy_where_not_one_step_apart(ref_model):
    """The strided view over a Data's frame positions shows Pinocchio's values after each new configuration (live), and
    views that are not one step apart in memory are stacked by copy with the same values."""
    pm = ref_model
    data = pm.model.createData()
    stack = StackedViews(data, [data.oMf[i].translation for i in range(pm.model.nframes)])
    assert stack.live is not None
    for theta in (0.3, 2.0):
        pin.framesForwardKinematics(pm.model, data, K.solve_position(pm, Workspace(pm), theta))
        np.testing.assert_array_equal(stack.array(), np.array([data.oMf[i].translation for i in range(pm.model.nframes)]))
    scattered = [np.arange(3.0), np.arange(3.0, 6.0) * 2]  # two separate allocations: no common step to rely on
    other = StackedViews(None, [scattered[0], scattered[1], scattered[0]])
    assert other.live is None
    np.testing.assert_array_equal(other.array(), np.array([scattered[0], scattered[1], scattered[0]]))

