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

import copy
from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from press_io.errors import SolverError
from .forces import BalanceForce, ProcessForce, guide_friction, revolute_friction
from .kinematics import KinState, linear_solve, loop_terms
from .model import LWA, PressModel, Workspace
from .reaction_fixed_point import NOT_CONVERGED, NOT_FINITE, fixed_point_settings, solve_fixed_point


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


def slide_loads(pm: PressModel, process: ProcessForce) -> SlideLoads:
    """Balance force of this press plus the given process force."""
    return SlideLoads(BalanceForce.from_press(pm.press, pm.assembly.stroke), process)


class StatePrep:
    """Everything at one (q, v, a) that does not depend on friction: RNEA, transmitted forces, the solve matrix.

    The geometric part (loop Jacobian, solve matrix, joint orientations) depends on q only; :meth:`at`
    gives the same state at another acceleration without recomputing it; :meth:`on_closure` builds it on the loop
    closure :func:`kinematics.state_at` has just solved.
    """

    def __init__(self, pm: PressModel, ws: Workspace, q, v, a, height, height_dot, loads: SlideLoads):
        _, K = loop_terms(pm, ws.data, q)
        self._place(pm, ws, q, K)
        self._load(v, a, height, height_dot, loads)

    @classmethod
    def on_closure(cls, pm: PressModel, ws: Workspace, st: KinState, loads: SlideLoads) -> "StatePrep":
        """The StatePrep at kinematic state ``st`` where ``ws`` was just used by :func:`kinematics.state_at` for ``st``:
        its position solve's last constraint matrix (``ws.K_last``) and ``ws.data``'s joint Jacobians and placements at
        st.q are this one's, so the loop closure's Pinocchio passes are not run again (the same numbers)."""
        prep = cls.__new__(cls)
        prep._place(pm, ws, st.q, ws.K_last)
        prep._load(st.v, st.a, st.height, st.height_dot, loads)
        return prep

    def _place(self, pm: PressModel, ws: Workspace, q, K) -> None:
        """The part at q alone, from the constraint matrix ``K`` (loop_terms') and ``ws.data`` placed at q."""
        m, data = pm.model, ws.data
        self.pm, self.rm, self._data, self._q = pm, pm.reaction_map, data, q
        # tree-joint orientations at q, kept here because rnea leaves data.oMi untouched (the placements taken out of
        # Pinocchio's vector at once: indexing it copies one placement a call, ~5 us each)
        self.rot = np.ascontiguousarray(np.array([M.homogeneous for M in data.oMi.tolist()])[self.rm.tree_jids, :2, :3])
        self.u_s = pm.axis @ pin.getFrameJacobian(m, data, pm.slide_frame, LWA)[:3]
        A = np.empty((pm.nv, pm.nv))
        A[:, 0] = pm.crank_row
        A[:, 1:] = K[:-1].T
        self.A_inv = linear_solve(A, np.eye(pm.nv))  # np.linalg.inv(A): the same gesv on the identity, a tenth of the call

    def _load(self, v, a, height, height_dot, loads: SlideLoads) -> None:
        """The part at the tree velocity ``v`` and acceleration ``a`` and the slide forces at ``height``, ``height_dot``."""
        self._v = v
        self.balance, self.process = (float(f) for f in loads(height, height_dot))
        self.f_ext = self.balance + self.process
        self.w = self.pm.joint_rows @ v
        self.height_dot = float(height_dot)
        self._accelerate(a)

    def _accelerate(self, a) -> None:
        tau0 = pin.rnea(self.pm.model, self._data, self._q, self._v, a)
        # force each tree joint transmits with no external or loop forces, world frame, in-plane
        f = np.ascontiguousarray(np.array([f.vector for f in self._data.f.tolist()])[self.rm.tree_jids, :3])
        self.P = np.einsum("tij,tj->ti", self.rot, f)
        self.base_rhs = tau0 - self.u_s * self.f_ext

    def at(self, a) -> "StatePrep":
        """The same state at tree acceleration ``a``: only the RNEA terms are recomputed."""
        other = copy.copy(self)
        other._accelerate(a)
        return other

    def moving(self, v, a) -> "StatePrep":
        """The same configuration at tree velocity ``v`` and acceleration ``a``: the geometric part (q only) is kept,
        the RNEA terms and the joint speeds are recomputed (the same values as a new :class:`StatePrep` at (q, v, a))."""
        other = copy.copy(self)
        other._v = v
        other.w = self.pm.joint_rows @ v
        other._accelerate(a)
        return other

    def friction(self, n_rev, n_s):
        """Friction torques (N m) and guide force (N) for given reaction magnitudes."""
        fr = self.pm.press.friction
        return (revolute_friction(fr.mu_r, fr.c_r, self.pm.bearing_radii, n_rev, self.w),
                float(guide_friction(fr.mu_s, fr.c_s, n_s, self.height_dot)))

    def generalized_friction(self, tau_f, f_s):
        """Friction as generalized forces on the tree coordinates (Eq. 11, 12)."""
        return self.pm.joint_rows.T @ tau_f + self.u_s * f_s

    def solve(self, tau_f, f_s):
        """Drive torque (N m), loop forces (N) and reaction magnitudes (N) for given friction."""
        x = self.A_inv @ (self.base_rhs - self.generalized_friction(tau_f, f_s))
        lam = x[1:].reshape(-1, 2)
        rm, axis2 = self.rm, self.pm.axis[:2]
        R = self.P - rm.cut_coef @ lam - np.outer(rm.slide_coef * self.f_ext, axis2)
        n_rev = np.where(rm.revolute_tree >= 0, np.linalg.norm(R[rm.revolute_tree], axis=1), np.linalg.norm(lam[rm.revolute_cut], axis=1))
        rg = R[rm.guide_tree]
        return float(x[0]), n_rev, float(np.linalg.norm(rg - (rg @ axis2) * axis2))


def reactions_settled(n_rev, n_s, new_rev, new_s, tol: float) -> tuple[bool, float]:
    """Whether the friction/reaction fixed point has converged, and the last change (N)."""
    change = max(float(np.max(np.abs(new_rev - n_rev))), abs(new_s - n_s))
    return change <= tol * max(1.0, float(np.max(new_rev)), new_s), change


def _finite_forces(pm: PressModel, st: KinState, n_rev, n_s) -> None:
    """Refuse reactions that overflowed: no friction setting helps there, an absurd number in the press data does."""
    if not (np.all(np.isfinite(n_rev)) and np.isfinite(n_s)):
        raise SolverError(f"{pm.press.source}: the joint reactions at crank angle {np.degrees(st.theta) % 360:.2f} deg are not finite "
                          "numbers (they overflowed): a value in the press data is far outside what a press can have; check "
                          "gravity, masses, bearing radii, friction and balance values for a wrong unit or exponent")


def inverse_dynamics(pm: PressModel, ws: Workspace, st: KinState, loads: SlideLoads, friction: bool = True,
                     on_closure: bool = False) -> DynState:
    """Drive torque, joint reactions and friction at kinematic state ``st`` (friction fixed point included);
    ``on_closure``: ``ws`` was just used by :func:`kinematics.state_at` for ``st`` (:meth:`StatePrep.on_closure`).

    The fixed point is :meth:`StatePrep.friction` and :meth:`StatePrep.solve` iterated until
    :func:`reactions_settled`, run as one compiled loop (:mod:`press_model.reaction_fixed_point`)."""
    with np.errstate(over="ignore", invalid="ignore"):  # an overflow is refused below, by name, not warned about
        prep = (StatePrep.on_closure(pm, ws, st, loads) if on_closure else
                StatePrep(pm, ws, st.q, st.v, st.a, st.height, st.height_dot, loads))
    out = np.empty((2, len(prep.w)))
    settings = fixed_point_settings(pm, prep.f_ext, prep.height_dot, friction)
    tau_d, n_s, f_s, it, status, change = solve_fixed_point(pm.friction_constants, prep.A_inv, prep.base_rhs, prep.u_s,
                                                            prep.P, prep.w, settings, out)
    if status == NOT_FINITE:
        _finite_forces(pm, st, out[0], n_s)
    if status == NOT_CONVERGED:
        raise SolverError(
            f"friction/reaction fixed point did not converge at crank angle {np.degrees(st.theta) % 360:.2f} deg "
            f"after {it} iterations (last change {change:.3g} N); raise numerics.friction_max_iterations or check the friction data"
        )
    return DynState(tau_d, out[0], n_s, out[1], f_s, prep.balance, prep.process, prep.w, st.height_dot, it)
