"""Forward dynamics under a motor torque: Pinocchio's constrained dynamics with Baumgarte stabilisation (Eq. 8).

The cut joints become Pinocchio ``RigidConstraintModel`` s (3D point contacts between the two bodies,
expressed LOCAL_WORLD_ALIGNED; their out-of-plane row is identically satisfied and the proximal solver's
mu > 0 keeps it harmless). The gear inertia J_gear u^2 is the drive joint's armature. Friction depends
on the reactions, which depend on the accelerations: each evaluation iterates friction -> constrained
dynamics -> reactions to a fixed point.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable

import numpy as np
import pinocchio as pin

from .dynamics import SlideLoads, StatePrep, reactions_settled
from .errors import SolverError
from .kinematics import _loop_terms, slide_motion
from .model import PressModel, Workspace
from .motor import crank_input_torque, gear_inertia_at_crank

# proximal solver settings: accuracy, mu, max iterations (mu > 0 because of the redundant z rows)
_PROX = (1e-13, 1e-10, 50)


class ForwardModel:
    """Constants for forward dynamics: a Pinocchio model with the gear inertia as armature, and the loop constraints."""

    def __init__(self, pm: PressModel):
        if np.count_nonzero(pm.crank_row) != 1:
            raise SolverError("forward dynamics needs the driven crank to hang directly from the frame by its drive joint")
        self.pm = pm
        self.model = pm.model.copy()
        self.model.armature[pm.drive_v_index] = gear_inertia_at_crank(pm.press.drive)
        num = pm.press.numerics
        # Eq. 8: gamma - 2 phi1 dPhi - phi2^2 Phi, i.e. Kd = 2 phi1 and Kp = phi2^2
        baum = pin.BaumgarteCorrectorParameters(num.baumgarte_phi2**2, 2.0 * num.baumgarte_phi1)
        self.constraints = pin.StdVec_RigidConstraintModel()
        for c in pm.cuts:
            f1, f2 = self.model.frames[c.first_frame], self.model.frames[c.second_frame]
            cm = pin.RigidConstraintModel(
                pin.ContactType.CONTACT_3D, self.model, f1.parentJoint, f1.placement, f2.parentJoint, f2.placement,
                pin.ReferenceFrame.LOCAL_WORLD_ALIGNED,
            )
            cm.setBaumgarteCorrectorParameters(baum)
            self.constraints.append(cm)


class ForwardWorkspace:
    def __init__(self, fm: ForwardModel):
        self.data = fm.model.createData()
        self.cdata = pin.StdVec_RigidConstraintData()
        for cm in fm.constraints:
            self.cdata.append(cm.createData())
        pin.initConstraintDynamics(fm.model, self.data, fm.constraints, self.cdata)
        self.prox = pin.ProximalSettings(*_PROX)
        self.id_ws = Workspace(fm.pm)
        self.normals = None  # last converged reactions: a warm start for the friction iteration


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
    """Accelerations of the press at (q, v) under ``motor_torque`` N m per motor, loads and friction."""
    pm = fm.pm
    theta_dot = float(pm.crank_row @ v)
    tau_in = float(crank_input_torque(pm.press.drive, motor_torque, theta_dot))
    s, s_dot, _ = slide_motion(pm, fws.id_ws.data, q, v, np.zeros_like(v))
    height = s - pm.assembly.s_bdc
    n_rev, n_s = fws.normals if (friction and fws.normals is not None) else (np.zeros(len(pm.joint_names)), 0.0)
    tol = pm.press.numerics.friction_tolerance
    # friction needs only the joint speeds and the slide speed, which do not depend on a
    prep = StatePrep(pm, fws.id_ws, q, v, np.zeros_like(v), height, s_dot, loads)
    drive_and_loads = pm.crank_row * tau_in + prep.u_s * prep.f_ext
    for it in range(1, pm.press.numerics.friction_max_iterations + 1):
        tau_f, f_s = prep.friction(n_rev, n_s) if friction else (np.zeros(len(pm.joint_names)), 0.0)
        tau = drive_and_loads + prep.generalized_friction(tau_f, f_s)
        a = pin.constraintDynamics(fm.model, fws.data, q, v, tau, fm.constraints, fws.cdata, fws.prox)
        if not friction:
            break
        _, new_rev, new_s = prep.at(a).solve(tau_f, f_s)
        done, _ = reactions_settled(n_rev, n_s, new_rev, new_s, tol)
        n_rev, n_s = new_rev, new_s
        if done:
            break
    else:
        raise SolverError(f"forward dynamics: friction fixed point did not converge at crank angle {math.degrees(crank_angle(pm, q)) % 360:.2f} deg")
    fws.normals = (n_rev, n_s) if friction else None
    return ForwardResult(np.array(a), float(pm.crank_row @ a), tau_in, it)


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

    def f(t, q, v):
        th, thd = crank_angle(pm, q), float(pm.crank_row @ v)
        tm = motor(t, th, thd)
        res = forward_dynamics(fm, fws, q, v, tm, loads, friction)
        return v, res.a, res, tm

    n = int(math.ceil(t_end / dt - 1e-9))
    q, v, t = np.array(q0, float), np.array(v0, float), 0.0
    out = {k: [] for k in ("time", "theta", "theta_dot", "theta_ddot", "motor_torque", "loop_residual")}

    def record(t, q, v, res, tm):
        out["time"].append(t)
        out["theta"].append(crank_angle(pm, q))
        out["theta_dot"].append(float(pm.crank_row @ v))
        out["theta_ddot"].append(res.crank_accel)
        out["motor_torque"].append(tm)
        res_loop, _ = _loop_terms(pm, fws.id_ws.data, q)
        out["loop_residual"].append(float(np.max(np.abs(res_loop))) if len(res_loop) else 0.0)

    for _ in range(n):
        h = min(dt, t_end - t)
        k1v, k1a, r1, tm1 = f(t, q, v)
        record(t, q, v, r1, tm1)
        k2v, k2a, *_ = f(t + h / 2, q + h / 2 * k1v, v + h / 2 * k1a)
        k3v, k3a, *_ = f(t + h / 2, q + h / 2 * k2v, v + h / 2 * k2a)
        k4v, k4a, *_ = f(t + h, q + h * k3v, v + h * k3a)
        q = q + h / 6 * (k1v + 2 * k2v + 2 * k3v + k4v)
        v = v + h / 6 * (k1a + 2 * k2a + 2 * k3a + k4a)
        t += h
        if progress is not None:
            progress(t / t_end)
    _, _, r, tm = f(t, q, v)
    record(t, q, v, r, tm)
    return Trajectory(**{k: np.array(val) for k, val in out.items()})
