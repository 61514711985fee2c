"""Closed-loop inverse dynamics with every joint reaction, built on Pinocchio's RNEA and frame Jacobians.

At a kinematic state the tree's generalized forces satisfy

    rnea(q, v, a) = r_crank * tau_d + J_c^T lambda + u_s (F_slide + f_guide) + sum_j U_j^T tau_j      (Eq. 6, 11, 15)

with the drive torque tau_d (the paper's -lambda_21), the cut-joint forces lambda (2 planar rows per
cut; the out-of-plane row is never formed), the slide's external force along the guide, the guide
friction and the revolute friction torques (Eq. 10-12). The reaction at a tree joint is the force
Pinocchio's RNEA transmits through it, corrected by the external and loop forces carried by its subtree.
Friction depends on the reactions, so the two are iterated to a fixed point.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from .errors import SolverError
from .forces import BalanceForce, ProcessForce, guide_friction, revolute_friction
from .kinematics import KinState, _loop_terms
from .model import LWA, PressModel, Workspace


@dataclass(frozen=True)
class SlideLoads:
    """External forces on the slide along the guide (N, up): balance (Eq. 13) and process (Eq. 14)."""

    balance: BalanceForce
    process: ProcessForce

    def __call__(self, height, height_dot):
        return self.balance(height), self.process(height, height_dot)


@dataclass
class DynState:
    """Inverse-dynamics result at one state. Forces in N, torques in N m."""

    crank_torque: float  # tau_d = -lambda_21, the torque the drive applies to the crank
    joint_reactions: np.ndarray  # |N_j| at each revolute joint, press-file order
    guide_normal: float  # |N_s|
    joint_friction: np.ndarray  # tau_j, Eq. 10
    guide_friction: float  # Eq. 12, along the guide axis
    balance_force: float
    process_force: float
    joint_speeds: np.ndarray  # relative angular velocity at each revolute joint, rad/s
    slide_speed: float  # m/s along the guide axis
    iterations: int

    @property
    def friction_power(self) -> float:
        """Power dissipated by joint and guide friction (W, >= 0)."""
        return float(-(self.joint_friction @ self.joint_speeds) - self.guide_friction * self.slide_speed)


class ReactionMap:
    """Constant maps from loop and slide forces to the force each tree joint carries (built per model)."""

    def __init__(self, pm: PressModel):
        press = pm.press
        n_tree, n_cut = len(pm.tree_names), len(pm.cuts)
        self.cut_coef = np.zeros((n_tree, n_cut))
        self.slide_coef = np.zeros(n_tree)
        for i, name in enumerate(pm.tree_names):
            carried = pm.carries[name]
            for c, cut in enumerate(pm.cuts):
                j = press.joints[cut.name]
                self.cut_coef[i, c] = (j.first[0] in carried) - (j.second[0] in carried)
            self.slide_coef[i] = press.slide_body in carried
        tree_index = {n: i for i, n in enumerate(pm.tree_names)}
        cut_index = {c.name: i for i, c in enumerate(pm.cuts)}
        self.revolute_tree = np.array([tree_index.get(j.name, -1) for j in press.revolute_joints])
        self.revolute_cut = np.array([cut_index.get(j.name, -1) for j in press.revolute_joints])
        self.guide_tree = tree_index[press.guide.name]
        self.tree_jids = [pm.tree_joint_id[n] for n in pm.tree_names]


def _reaction_map(pm: PressModel) -> ReactionMap:
    rm = pm.__dict__.get("_reaction_map")
    if rm is None:
        rm = pm.__dict__["_reaction_map"] = ReactionMap(pm)
    return rm


def slide_loads(pm: PressModel, process: ProcessForce) -> SlideLoads:
    """Balance force of this press plus the given process force."""
    return SlideLoads(BalanceForce.from_press(pm.press, pm.assembly.stroke), process)


def inverse_dynamics(pm: PressModel, ws: Workspace, st: KinState, loads: SlideLoads, friction: bool = True) -> DynState:
    """Drive torque, joint reactions and friction at kinematic state ``st`` (friction fixed point included)."""
    m, data = pm.model, ws.data
    press = pm.press
    rm = _reaction_map(pm)
    tau0 = pin.rnea(m, data, st.q, st.v, st.a).copy()
    # force each tree joint transmits with no external or loop forces, world frame, in-plane
    P = np.array([(data.oMi[j].rotation @ data.f[j].linear)[:2] for j in rm.tree_jids])
    _, K = _loop_terms(pm, data, st.q)
    u_s = pm.axis @ pin.getFrameJacobian(m, data, pm.slide_frame, LWA)[:3]
    A = np.empty((pm.nv, pm.nv))
    A[:, 0] = pm.crank_row
    A[:, 1:] = K[:-1].T
    A_inv = np.linalg.inv(A)

    balance, process = loads(st.height, st.height_dot)
    f_ext = float(balance + process)
    w = pm.joint_rows @ st.v
    base_rhs = tau0 - u_s * f_ext
    axis2 = pm.axis[:2]
    fr = press.friction
    n_rev = np.zeros(len(w))
    n_s = 0.0
    tol = press.numerics.friction_tolerance
    for it in range(1, press.numerics.friction_max_iterations + 1):
        if friction:
            tau_f = revolute_friction(fr.mu_r, fr.c_r, pm.bearing_radii, n_rev, w)
            f_s = float(guide_friction(fr.mu_s, fr.c_s, n_s, st.height_dot))
            rhs = base_rhs - pm.joint_rows.T @ tau_f - u_s * f_s
        else:
            tau_f, f_s, rhs = np.zeros_like(w), 0.0, base_rhs
        x = A_inv @ rhs
        lam = x[1:].reshape(-1, 2)
        R = P - rm.cut_coef @ lam - np.outer(rm.slide_coef * f_ext, axis2)
        new_rev = np.where(rm.revolute_tree >= 0, np.linalg.norm(R[rm.revolute_tree], axis=1), np.linalg.norm(lam[rm.revolute_cut], axis=1))
        rg = R[rm.guide_tree]
        new_s = float(np.linalg.norm(rg - (rg @ axis2) * axis2))
        change = max(np.max(np.abs(new_rev - n_rev)), abs(new_s - n_s))
        scale = max(1.0, np.max(new_rev), new_s)
        n_rev, n_s = new_rev, new_s
        if not friction or change <= tol * scale:
            break
    else:
        raise SolverError(
            f"friction/reaction fixed point did not converge at crank angle {np.degrees(st.theta) % 360:.2f} deg "
            f"after {it} iterations (last change {change:.3g} N); raise numerics.friction_max_iterations or check the friction data"
        )
    if friction:  # friction evaluated at the converged reactions, consistent with the returned x
        tau_f = revolute_friction(fr.mu_r, fr.c_r, pm.bearing_radii, n_rev, w)
        f_s = float(guide_friction(fr.mu_s, fr.c_s, n_s, st.height_dot))
        x = A_inv @ (base_rhs - pm.joint_rows.T @ tau_f - u_s * f_s)
    return DynState(float(x[0]), n_rev, n_s, tau_f, f_s, float(balance), float(process), w, st.height_dot, it)
