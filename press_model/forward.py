"""Forward dynamics under a motor torque: Pinocchio's constrained dynamics with Baumgarte stabilisation (Eq. 8).

The cut joints become Pinocchio ``RigidConstraintModel`` s (3D point contacts between the two bodies,
expressed LOCAL_WORLD_ALIGNED; their out-of-plane row is identically satisfied and the proximal solver's
mu > 0 keeps it harmless). The gear inertia J_gear u^2 is the drive joint's armature. Friction depends
on the reactions, which depend on the accelerations, so each evaluation solves a fixed point.

Speed: at fixed (q, v) the constrained dynamics are affine in the generalized force, and the mechanism has
one degree of freedom, so a generalized force phi changes the accelerations only along the null space of
the loop Jacobian: Delta a = N (N^T phi) / (N^T M N), N = the tree velocity per unit crank speed at q (the
first row of the inverse of [drive row; loop Jacobian]), N^T M N the inertia reduced to the crank (armature
included). The reactions are affine in Delta a and in the friction, and the friction (Eqs. 10, 12) is affine
in the reaction magnitudes. One Pinocchio ``constraintDynamics`` without friction, one RNEA at that
acceleration and one RNEA along N (no gravity, no speed) give every map; the fixed point then runs on
a 2 x (joints + guide) linear map, without Pinocchio calls. The maps and the fixed point are one compiled
loop (:func:`friction_accel`). A test checks it against the plain iteration (friction -> constrained dynamics ->
reactions) to 1e-10.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable

import numpy as np
import pinocchio as pin

from .dynamics import SlideLoads
from press_io.errors import SolverError
from .jit import compiled
from .kinematics import linear_solve, loop_rows
from .model import PressModel, Workspace
from .motor import CrankInput, gear_inertia_at_crank
from .pinocchio_views import StackedViews

# proximal solver settings: accuracy, mu, max iterations (mu > 0 because of the redundant z rows)
_PROX = (1e-13, 1e-10, 50)


class ForwardModel:
    """Constants for forward dynamics: a Pinocchio model with the gear inertia as armature, and the loop constraints."""

    def __init__(self, pm: PressModel):
        if np.count_nonzero(pm.crank_row) != 1:
            raise SolverError("forward dynamics needs the driven crank to hang directly from the frame by its drive joint")
        self.pm = pm
        # the crank row's one entry: crank angle, speed and acceleration are it times one coordinate (the same numbers
        # as the row's dot product, without a numpy call)
        self.drive = int(np.flatnonzero(pm.crank_row)[0])
        self.drive_gain = float(pm.crank_row[self.drive])
        self.model = pm.model.copy()
        self.model.armature[pm.drive_v_index] = gear_inertia_at_crank(pm.press.drive)
        num = pm.press.numerics
        # Eq. 8: gamma - 2 phi1 dPhi - phi2^2 Phi, i.e. Kd = 2 phi1 and Kp = phi2^2
        baum = pin.BaumgarteCorrectorParameters(num.baumgarte_phi2_per_s**2, 2.0 * num.baumgarte_phi1_per_s)
        self.constraints = pin.StdVec_RigidConstraintModel()
        for c in pm.cuts:
            f1, f2 = self.model.frames[c.first_frame], self.model.frames[c.second_frame]
            cm = pin.RigidConstraintModel(
                pin.ContactType.CONTACT_3D, self.model, f1.parentJoint, f1.placement, f2.parentJoint, f2.placement,
                pin.ReferenceFrame.LOCAL_WORLD_ALIGNED,
            )
            cm.setBaumgarteCorrectorParameters(baum)
            self.constraints.append(cm)
        # the same tree without gravity: RNEA along N at rest gives M N and the forces it transmits
        self.model_no_gravity = pm.model.copy()
        self.model_no_gravity.gravity.linear = np.zeros(3)
        self.armature = gear_inertia_at_crank(pm.press.drive)
        self.crank_input = CrankInput(pm.press.drive)  # n u eta^s T_m (N m at the crank; with the drive losses, the B of Eq. 16)
        rm = pm.reaction_map
        # the 'normal' vectors whose magnitudes drive friction: revolute joints (tree or cut), then the guide
        n_tree, n_cut = len(pm.tree_names), len(pm.cuts)
        # rows of [tree forces; cut forces; guide transverse force] whose magnitudes are the normals
        self.normal_rows = np.append(np.where(rm.revolute_tree >= 0, rm.revolute_tree, n_tree + rm.revolute_cut), n_tree + n_cut)
        fr = pm.press.friction
        # (viscous N m s/rad or N s/m, Coulomb m) per friction input: revolute joints (mu_r times the bearing radius), the guide
        self.coefficients = np.array([np.append(np.full(len(pm.bearing_radii), fr.c_r), fr.c_s),
                                      np.append(fr.mu_r * pm.bearing_radii, fr.mu_s)])
        axis2 = pm.axis[:2]
        self.guide_proj = np.eye(2) - np.outer(axis2, axis2)
        self.normal_map = NormalMap(self)
        # the ids the compiled steps read: the cut points' frames, the tree joints', and the slide point's geometry
        # (state_rows': its frame, the tree coordinates its frame Jacobian has columns for, the guide axis, the drive
        # and joints' rows)
        self.cut_frames = np.array(pm.cut_frames, dtype=np.int64)
        self.tree_jids = np.array(rm.tree_jids, dtype=np.int64)
        slide_support = np.zeros(pm.nv, dtype=bool)
        for jid in self.model.supports[self.model.frames[pm.slide_frame].parentJoint][1:]:  # the universe has no coordinate
            slide_support[self.model.joints[jid].idx_v] = True
        self.slide_geometry = (pm.slide_frame, slide_support, np.ascontiguousarray(pm.axis, dtype=float),
                               np.ascontiguousarray(pm.crank_row, dtype=float), np.ascontiguousarray(pm.joint_rows, dtype=float))


class NormalMap:
    """The vectors whose magnitudes are the normal forces (revolute joints, tree or cut, then the guide's transverse
    force) as one constant linear map of the tree joints' forces P (world x, y), the cut forces lambda and the slide's
    force f: V = G (P, lambda, f), with the x components of every vector first, then the y components. Built once per
    model by applying the reaction rules to unit inputs."""

    def __init__(self, fm: ForwardModel):
        pm, rm = fm.pm, fm.pm.reaction_map
        n_tree, n_cut = len(pm.tree_names), len(pm.cuts)
        n_in = 2 * n_tree + 2 * n_cut + 1
        basis = np.eye(n_in)
        P = basis[: 2 * n_tree].T.reshape(n_in, n_tree, 2)
        lam = basis[2 * n_tree : 2 * n_tree + 2 * n_cut].T.reshape(n_in, n_cut, 2)
        f = basis[-1]
        # R = P - cut_coef lambda - slide_coef f axis (per tree joint, N)
        R = P - np.einsum("tc,kcd->ktd", rm.cut_coef, lam) - f[:, None, None] * rm.slide_coef[None, :, None] * pm.axis[None, None, :2]
        guide = np.einsum("de,ke->kd", fm.guide_proj, R[:, rm.guide_tree])
        V = np.concatenate([R, lam, guide[:, None]], axis=1)[:, fm.normal_rows]  # (inputs, normals, 2)
        G = np.concatenate([V[:, :, 0], V[:, :, 1]], axis=1).T  # (x rows then y rows, inputs)
        self.G = np.ascontiguousarray(G)  # (2 x normals, 2 x tree joints + 2 x cuts + 1)


class ForwardWorkspace:
    def __init__(self, fm: ForwardModel):
        self.data = fm.model.createData()
        self.cdata = pin.StdVec_RigidConstraintData()
        for cm in fm.constraints:
            self.cdata.append(cm.createData())
        pin.initConstraintDynamics(fm.model, self.data, fm.constraints, self.cdata)
        self.prox = pin.ProximalSettings(*_PROX)
        self.id_ws = Workspace(fm.pm)
        self.data_no_gravity = fm.model_no_gravity.createData()
        self.normals = None  # last converged reactions: a warm start for the friction iteration
        # buffers reused by every evaluation: the loop residual and K (loop_terms'), [drive row, loop Jacobian^T], the
        # slide's row u_s, the friction speeds, the tree joints' forces (world x, y)
        pm = fm.pm
        self.K = np.empty((pm.nv, pm.nv))
        self.A = np.empty((pm.nv, pm.nv))
        self.identity = np.eye(pm.nv)
        self.u_s = np.empty(pm.nv)
        self.speeds = np.empty(pm.joint_rows.shape[0] + 1)
        self.P = np.empty((2, 2 * len(pm.reaction_map.tree_jids)))
        # friction_accel's rows: tau0, M N, the slide's row u_s, the drive row, the joints' rows (set once)
        self.gen = np.empty((4 + pm.joint_rows.shape[0], pm.nv))
        self.gen[3] = pm.crank_row
        self.gen[4:] = pm.joint_rows
        # friction_accel's scalars: slide force (N), armature (kg m^2), tolerance, iterations, 1 = start from ``normals``
        self.settings = np.array([0.0, fm.armature, pm.press.numerics.friction_tolerance,
                                  pm.press.numerics.friction_max_iterations, 0.0])
        self.zero_v = np.zeros(pm.nv)
        # live views of the Data's frame positions, joint orientations and joint forces, every frame or joint at once
        # (pinocchio_views.py), so each evaluation reads them without a Python-level lookup per frame or joint
        data, ng, m = self.id_ws.data, self.data_no_gravity, pm.model
        self.frame_positions = StackedViews(data, [data.oMf[i].translation for i in range(m.nframes)])
        self.rotations = StackedViews(data, [data.oMi[j].rotation for j in range(m.njoints)])
        self.forces = StackedViews(data, [data.f[j].linear for j in range(m.njoints)])
        self.forces_no_gravity = StackedViews(ng, [ng.f[j].linear for j in range(m.njoints)])
        self.residual = np.empty(pm.n_loop_rows)  # loop residual (m) of the last evaluation's configuration


@dataclass
class ForwardResult:
    a: np.ndarray  # tree accelerations
    crank_accel: float  # rad/s^2
    crank_torque_in: float  # N m delivered by the gear at the crank (n u eta^s T_m)
    iterations: int


def crank_angle(pm: PressModel, q: np.ndarray) -> float:
    """theta_c (rad) of configuration q."""
    return float(pm.crank_row @ q - pm.press.drive.angle_offset)


def forward_dynamics(fm: ForwardModel, fws: ForwardWorkspace, q, v, motor_torque: float, loads: SlideLoads,
                     friction: bool = True) -> ForwardResult:
    """Accelerations of the press at (q, v) under ``motor_torque`` N m per motor, loads and friction.

    ``iterations`` counts the friction fixed point's steps on the linear maps (see the module docstring). Leaves the
    loop residual at q (m) in ``fws.residual``.
    """
    pm = fm.pm
    m, data = pm.model, fws.id_ws.data
    # the joint Jacobians and frame placements at q, then the loop rows, the slide's row and the speeds from them
    pin.computeJointJacobians(m, data, q)
    pin.updateFramePlacements(m, data)
    frames = fws.frame_positions.array()
    (compiled(loop_rows) or loop_rows)(data.J, frames[fm.cut_frames], pm.cut_support, pm.crank_row, fws.residual, fws.K)
    position, s_dot, theta_dot = (compiled(state_rows) or state_rows)(data.J, frames, fws.K, v, fm.slide_geometry,
                                                                      (fws.A, fws.u_s, fws.speeds))
    tau_in = fm.crank_input(motor_torque, theta_dot)
    balance, process = (float(f) for f in loads(position - pm.assembly.s_bdc, s_dot))
    f_ext = balance + process
    u_s = fws.u_s
    gen = pm.crank_row * tau_in + u_s * f_ext
    a0 = np.array(pin.constraintDynamics(fm.model, fws.data, q, v, gen, fm.constraints, fws.cdata, fws.prox))
    if not friction:
        return ForwardResult(a0, fm.drive_gain * float(a0[fm.drive]), tau_in, 0)
    A_inv = linear_solve(fws.A, fws.identity)  # np.linalg.inv(A) as StatePrep takes it: the same gesv, fewer checks
    N = A_inv[0]  # tree velocity per unit crank speed at q (null space of the loop Jacobian)
    gen = fws.gen  # its last rows hold the drive row and the joints' rows (set once in the workspace)
    gen[0] = pin.rnea(m, data, q, v, a0)
    gen[1] = pin.rnea(fm.model_no_gravity, fws.data_no_gravity, q, fws.zero_v, N)
    gen[2] = u_s
    # the tree joints' forces at a0 and along N (no gravity, no speed), turned to world x, y
    (compiled(joint_forces_xy) or joint_forces_xy)(fws.rotations.array(), fws.forces.array(), fws.forces_no_gravity.array(),
                                                   fm.tree_jids, fws.P)
    settings = fws.settings
    settings[0] = f_ext
    if fws.normals is None:
        settings[4] = 0.0
        fws.normals = np.empty(len(fm.normal_rows))
    dtdd, it = (compiled(friction_accel) or friction_accel)(A_inv, fws.P, gen, fws.speeds, fm.normal_map.G, fm.coefficients,
                                                             fws.normals, settings)
    settings[4] = 1.0
    if it < 0:
        fws.normals = None
        raise SolverError(f"forward dynamics: friction fixed point did not converge at crank angle {math.degrees(crank_angle(pm, q)) % 360:.2f} deg")
    a = a0 + N * dtdd
    return ForwardResult(a, fm.drive_gain * float(a[fm.drive]), tau_in, it)


def state_rows(J, frames, K, v, slide_geometry, out):
    """(the slide point's position along the guide m, its speed m/s, the crank speed rad/s) at the state whose joint
    Jacobians ``J`` (Pinocchio's data.J, 6 x nv) and frame positions ``frames`` (every frame, m) Pinocchio has just
    computed, with ``K`` loop_terms' constraint matrix there and the tree velocity ``v``; fills ``out`` = (A = [drive
    row, loop Jacobian^T], the slide's row u_s (m per rad or m), the friction inputs' rates: the joints' relative
    speeds rad/s, then the slide's m/s). ``slide_geometry``: :class:`ForwardModel`'s.

    u_s is getFrameJacobian's LOCAL_WORLD_ALIGNED linear rows at the slide point along the guide axis: the tree is planar
    (omega = (0, 0, J[5]), p_z = 0), so its x, y, z rows are J[0] - p_y J[5], J[1] + p_x J[5] and J[2] on the columns
    of the joints supporting the point, as in :func:`press_model.kinematics.loop_rows`. Plain loops, for
    :func:`press_model.jit.compiled`."""
    slide_frame, support, axis, crank_row, joint_rows = slide_geometry
    A, u_s, speeds = out
    nv = K.shape[0]
    p = frames[slide_frame]
    position = axis[0] * p[0] + axis[1] * p[1] + axis[2] * p[2]
    s_dot = 0.0
    theta_dot = 0.0
    for k in range(nv):
        A[k, 0] = crank_row[k]
        for r in range(nv - 1):
            A[k, 1 + r] = K[r, k]
        if support[k]:
            u_s[k] = axis[0] * (J[0, k] - p[1] * J[5, k]) + axis[1] * (J[1, k] + p[0] * J[5, k]) + axis[2] * J[2, k]
        else:
            u_s[k] = 0.0
        s_dot += u_s[k] * v[k]
        theta_dot += crank_row[k] * v[k]
    for j in range(joint_rows.shape[0]):
        w = 0.0
        for k in range(nv):
            w += joint_rows[j, k] * v[k]
        speeds[j] = w
    speeds[joint_rows.shape[0]] = s_dot
    return position, s_dot, theta_dot


def joint_forces_xy(rotations, forces, forces_no_gravity, jids, P):
    """Fill ``P`` (2, 2 x tree joints) with the tree joints' forces turned to world x, y (N): row 0 the forces of the
    RNEA at the frictionless accelerations, row 1 those along N (no gravity, no speed), x then y per joint, from the
    Data's joint orientations ``rotations`` and local joint forces (every joint) and the tree joints' ids ``jids``.
    Plain loops, for :func:`press_model.jit.compiled`."""
    for t in range(jids.shape[0]):
        j = jids[t]
        for i in range(2):
            P[0, 2 * t + i] = rotations[j, i, 0] * forces[j, 0] + rotations[j, i, 1] * forces[j, 1] + rotations[j, i, 2] * forces[j, 2]
            P[1, 2 * t + i] = (rotations[j, i, 0] * forces_no_gravity[j, 0] + rotations[j, i, 1] * forces_no_gravity[j, 1]
                               + rotations[j, i, 2] * forces_no_gravity[j, 2])


def friction_accel(A_inv, P, gen, speeds, G, coefficients, normals, settings):
    """The crank acceleration friction adds (rad/s^2) and the fixed point's iteration count (-1: not converged), with
    the converged normal forces left in ``normals`` (N, or N m per m of radius), from the state's linear maps (module
    docstring): ``A_inv`` the inverse of [drive row; loop Jacobian]^T, ``P`` (2, 2 x tree joints) the tree joints'
    forces (world x, y) at the frictionless accelerations and per unit crank acceleration along N, ``gen`` the rows
    (inverse dynamics tau0, M N, the slide's row u_s, the drive row, then the joints' rows), ``speeds`` the friction
    inputs' rates, ``G`` :class:`NormalMap`'s, ``coefficients`` :class:`ForwardModel`'s,
    ``settings`` (slide force N, armature, tolerance, most iterations, 1 if ``normals`` holds a warm start).

    Plain loops over a few numbers, for :func:`press_model.jit.compiled`: numpy's dozens of calls on 7- to 20-element
    arrays cost ten times the arithmetic. The friction inputs phi = (joint torques, guide force) enter the generalized
    force as Phi phi (Phi's columns the joints' rows and u_s); a generalized force g moves the crank acceleration by
    N.g / j_eff and the cut forces by A_inv[1:] (M N N.g / j_eff - g); so the normal vectors are V0 + (u c^T - H Phi) phi
    with c = N.Phi / j_eff, H = G_lambda A_inv[1:], u = G_P PN + H M N (G's columns of the cut forces and of P), and friction is affine in the normals
    (phi = phi_v + D n, Eqs. 10, 12)."""
    f_ext, armature, tol = settings[0], settings[1], settings[2]
    n_rows, nv = G.shape[0], A_inv.shape[0]
    n_P = P.shape[1]
    n_lam = G.shape[1] - n_P - 1
    k = speeds.shape[0]
    n_v = n_rows // 2
    j_eff = 0.0
    drive = 0.0
    for i in range(nv):
        j_eff += A_inv[0, i] * gen[1, i]
        drive += gen[3, i] * A_inv[0, i]
    j_eff += armature * drive * drive
    Phi = np.empty((nv, k))
    for i in range(nv):
        for j in range(k - 1):
            Phi[i, j] = gen[4 + j, i]
        Phi[i, k - 1] = gen[2, i]
    c = np.empty(k)  # np.empty and zeroing loops rather than np.zeros: one allocation routine for numba to compile
    phi_v = np.empty(k)
    D = np.empty(k)
    for j in range(k):
        c[j] = 0.0
        for i in range(nv):
            c[j] += A_inv[0, i] * Phi[i, j]
        c[j] /= j_eff
        sgn = 1.0 if speeds[j] > 0.0 else (-1.0 if speeds[j] < 0.0 else 0.0)
        phi_v[j] = -coefficients[0, j] * abs(speeds[j]) * sgn
        D[j] = -coefficients[1, j] * sgn
    c_phi_v = 0.0
    for j in range(k):
        c_phi_v += c[j] * phi_v[j]
    g0 = np.empty(nv)  # tau0 - u_s f, and Phi phi_v
    g_phi = np.empty(nv)
    for i in range(nv):
        g0[i] = gen[0, i] - gen[2, i] * f_ext
        g_phi[i] = 0.0
        for j in range(k):
            g_phi[i] += Phi[i, j] * phi_v[j]
    V0 = np.empty(n_rows)
    W0 = np.empty(n_rows)
    W = np.empty((n_rows, k))
    HPhi = np.empty(k)
    h = np.empty(nv)
    for r in range(n_rows):
        for i in range(nv):  # row r of H
            h[i] = 0.0
        for l in range(n_lam):
            for i in range(nv):
                h[i] += G[r, n_P + l] * A_inv[1 + l, i]
        u = 0.0
        v0 = 0.0
        for t in range(n_P):
            u += G[r, t] * P[1, t]
            v0 += G[r, t] * P[0, t]
        v0 += G[r, n_P + n_lam] * f_ext
        h_phi = 0.0
        for j in range(k):
            HPhi[j] = 0.0
        for i in range(nv):
            u += h[i] * gen[1, i]
            v0 += h[i] * g0[i]
            h_phi += h[i] * g_phi[i]
            for j in range(k):
                HPhi[j] += h[i] * Phi[i, j]
        V0[r] = v0
        W0[r] = v0 + u * c_phi_v - h_phi
        for j in range(k):
            W[r, j] = (u * c[j] - HPhi[j]) * D[j]
    if settings[4] == 0.0:  # no warm start: the frictionless normals
        for r in range(n_v):
            normals[r] = math.hypot(V0[r], V0[n_v + r])
    new = np.empty(n_v)
    for it in range(1, int(settings[3]) + 1):
        big = 0.0
        for r in range(n_v):
            x = W0[r]
            y = W0[n_v + r]
            for j in range(k):
                x += W[r, j] * normals[j]
                y += W[n_v + r, j] * normals[j]
            new[r] = math.hypot(x, y)
            big = max(big, new[r])
        change = 0.0
        for r in range(n_v):
            change = max(change, abs(new[r] - normals[r]))
            normals[r] = new[r]
        # the rule of dynamics.reactions_settled: every change below tol x the largest normal force (at least 1 N)
        if change <= tol * max(1.0, big):
            dtdd = 0.0
            for j in range(k):
                dtdd += c[j] * (phi_v[j] + D[j] * normals[j])  # friction at the converged normals
            return dtdd, it
    return 0.0, -1


@dataclass
class Trajectory:
    """Integrated motion. Arrays over the time samples (s, rad, rad/s, rad/s^2, m)."""

    time: np.ndarray
    theta: np.ndarray
    theta_dot: np.ndarray
    theta_ddot: np.ndarray
    motor_torque: np.ndarray
    loop_residual: np.ndarray  # largest cut-joint gap at each sample, m


def integrate(fm: ForwardModel, q0, v0, motor: Callable[[float, float, float], float], loads: SlideLoads,
              t_end: float, dt: float, friction: bool = True, progress: Callable[[float], None] | None = None) -> Trajectory:
    """Integrate from (q0, v0) for ``t_end`` s with classical RK4 steps of ``dt`` s.

    ``motor(t, theta_c, theta_dot)`` returns the torque per motor (N m): a feed-forward table, a
    controller, or both.
    """
    pm = fm.pm
    fws = ForwardWorkspace(fm)
    drive, gain, offset = fm.drive, fm.drive_gain, pm.press.drive.angle_offset  # crank_angle(q), crank_row @ v

    def f(t, q, v):
        th, thd = gain * float(q[drive]) - offset, gain * float(v[drive])
        tm = motor(t, th, thd)
        res = forward_dynamics(fm, fws, q, v, tm, loads, friction)
        return res.a, res, th, thd, tm

    n = int(math.ceil(t_end / dt - 1e-9))
    q, v, t = np.array(q0, float), np.array(v0, float), 0.0
    out = {k: [] for k in ("time", "theta", "theta_dot", "theta_ddot", "motor_torque", "loop_residual")}

    def record(t, res, th, thd, tm):
        out["time"].append(t)
        out["theta"].append(th)
        out["theta_dot"].append(thd)
        out["theta_ddot"].append(res.crank_accel)
        out["motor_torque"].append(tm)
        res_loop = fws.residual  # forward_dynamics has just evaluated the loops at this q
        out["loop_residual"].append(float(np.max(np.abs(res_loop))) if len(res_loop) else 0.0)

    for _ in range(n):
        h = min(dt, t_end - t)
        k1a, *first = f(t, q, v)
        record(t, *first)
        # each stage's velocity is the slope of q the next stage steps along
        v2 = v + h / 2 * k1a
        k2a = f(t + h / 2, q + h / 2 * v, v2)[0]
        v3 = v + h / 2 * k2a
        k3a = f(t + h / 2, q + h / 2 * v2, v3)[0]
        v4 = v + h * k3a
        k4a = f(t + h, q + h * v3, v4)[0]
        q = q + h / 6 * (v + 2 * v2 + 2 * v3 + v4)
        v = v + h / 6 * (k1a + 2 * k2a + 2 * k3a + k4a)
        t += h
        if progress is not None:
            progress(t / t_end)
    record(t, *f(t, q, v)[1:])
    return Trajectory(**{k: np.array(val) for k, val in out.items()})

