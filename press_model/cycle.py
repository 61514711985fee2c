"""One crank turn under a prescribed motion and load: kinematics, inverse dynamics and motor torque.

The turn is sampled on a uniform crank-angle grid from theta_c = 0 (the end point 360 deg is the
start again), so cycle integrals in time are periodic rectangle sums with weights dt = dtheta / theta_dot.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .dynamics import inverse_dynamics, slide_loads
from press_io.errors import PressDataError
from .forces import ProcessForce
from .kinematics import state_at
from .model import PressModel, Workspace
from .motor import gear_inertia_at_crank, motor_torque


@dataclass
class Cycle:
    """Arrays over one turn (length n). SI units: rad, s, m, N, N m, W."""

    theta: np.ndarray
    time: np.ndarray
    theta_dot: np.ndarray
    theta_ddot: np.ndarray
    height: np.ndarray
    height_dot: np.ndarray
    crank_torque: np.ndarray  # tau_d of the linkage (N m at the crank)
    motor_torque: np.ndarray  # per motor, Eq. 16
    joint_reactions: np.ndarray  # (n, n_revolute)
    guide_normal: np.ndarray
    balance_force: np.ndarray
    process_force: np.ndarray
    friction_power: np.ndarray  # dissipated in joints and guide, W
    joint_names: tuple
    period: float
    iterations: np.ndarray

    @property
    def dt_weights(self) -> np.ndarray:
        """Time each sample stands for (s): dtheta / theta_dot."""
        return (2.0 * math.pi / len(self.theta)) / self.theta_dot

    def rms_motor_torque(self) -> float:
        """Time-weighted RMS of the motor torque over the cycle (N m), Eq. 24."""
        w = self.dt_weights
        return float(np.sqrt(np.sum(w * self.motor_torque**2) / np.sum(w)))

    def peak_motor_torque(self) -> float:
        """max |T_m| over the cycle (N m)."""
        return float(np.max(np.abs(self.motor_torque)))

    def motor_work_per_motor(self, gear_ratio: float) -> float:
        """Eq. 25: integral of u T_m theta_dot dt over the cycle (J), one motor."""
        return float(np.sum(gear_ratio * self.motor_torque * self.theta_dot * self.dt_weights))

    def process_work(self) -> float:
        """Work done by the slide on the process over the cycle (J, >= 0)."""
        return float(np.sum(-self.process_force * self.height_dot * self.dt_weights))

    def friction_work(self) -> float:
        """Energy dissipated by joint and guide friction over the cycle (J)."""
        return float(np.sum(self.friction_power * self.dt_weights))


def crank_grid(step_deg: float) -> np.ndarray:
    """Crank angles (rad) of one turn from theta_c = 0 in steps of ``step_deg`` degrees (360 excluded)."""
    if not (isinstance(step_deg, (int, float)) and math.isfinite(step_deg) and 0 < step_deg <= 90):
        raise PressDataError("--step-deg", "step", step_deg, "must be a positive number of degrees that divides 360 (e.g. 1, 0.5, 2)")
    n = int(round(360.0 / step_deg))
    if abs(n * step_deg - 360.0) > 1e-9:
        raise PressDataError("--step-deg", "step", step_deg, "must divide 360 deg into at least 4 steps (e.g. 1, 0.5, 2)")
    return np.arange(n) * (2.0 * math.pi / n)


def simulate_cycle(pm: PressModel, motion, process: ProcessForce, step_deg: float = 1.0, friction: bool = True,
                   ws: Workspace | None = None) -> Cycle:
    """Run one crank turn from theta_c = 0 in steps of ``step_deg`` degrees."""
    theta = crank_grid(step_deg)
    td, tdd = motion.theta_dot(theta), motion.theta_ddot(theta)
    rows = _solve_points(pm, ws or Workspace(pm), process, theta, td, tdd, friction)
    crank = np.array([d.crank_torque for _, d in rows])
    drive = pm.press.drive
    return Cycle(
        theta=theta,
        time=motion.time(theta),
        theta_dot=td,
        theta_ddot=tdd,
        height=np.array([s.height for s, _ in rows]),
        height_dot=np.array([s.height_dot for s, _ in rows]),
        crank_torque=crank,
        motor_torque=motor_torque(drive, crank, td, tdd),
        joint_reactions=np.array([d.joint_reactions for _, d in rows]),
        guide_normal=np.array([d.guide_normal for _, d in rows]),
        balance_force=np.array([d.balance_force for _, d in rows]),
        process_force=np.array([d.process_force for _, d in rows]),
        friction_power=np.array([d.friction_power for _, d in rows]),
        joint_names=pm.joint_names,
        period=float(motion.period),
        iterations=np.array([d.iterations for _, d in rows]),
    )


def _solve_points(pm: PressModel, ws: Workspace, process: ProcessForce, theta, theta_dot, theta_ddot, friction: bool):
    """(KinState, DynState) at each crank angle, warm-starting each point from the previous one (the inverse dynamics
    on the loop closure state_at leaves in ``ws``)."""
    loads = slide_loads(pm, process)
    ws.q_last = None
    rows = []
    for th, w, al in zip(theta, theta_dot, theta_ddot):
        st = state_at(pm, ws, float(th), float(w), float(al))
        rows.append((st, inverse_dynamics(pm, ws, st, loads, friction=friction, on_closure=True)))
    return rows


def motor_torque_at(pm: PressModel, process: ProcessForce, theta, theta_dot, theta_ddot, friction: bool = True,
                    ws: Workspace | None = None) -> np.ndarray:
    """Motor torque per motor (N m, Eq. 16) at arbitrary crank angles (rad), speeds (rad/s) and accelerations (rad/s^2)."""
    theta, td, tdd = (np.asarray(a, dtype=float) for a in (theta, theta_dot, theta_ddot))
    rows = _solve_points(pm, ws or Workspace(pm), process, theta, td, tdd, friction)
    return motor_torque(pm.press.drive, np.array([d.crank_torque for _, d in rows]), td, tdd)


def motor_torque_of_states(pm: PressModel, process: ProcessForce, states, friction: bool = True) -> np.ndarray:
    """Motor torque per motor (N m, Eq. 16) at kinematic states already solved (:func:`press_model.kinematics.state_at`,
    e.g. kept on disk by the press geometry): :func:`motor_torque_at`'s inverse dynamics and drive without its position
    solves, the same numbers."""
    ws, loads = Workspace(pm), slide_loads(pm, process)
    crank = np.array([inverse_dynamics(pm, ws, st, loads, friction=friction).crank_torque for st in states])
    return motor_torque(pm.press.drive, crank, np.array([st.theta_dot for st in states]),
                        np.array([st.theta_ddot for st in states]))


def gear_loss_power(pm: PressModel, cycle: Cycle) -> np.ndarray:
    """Power lost in the reduction system (W, >= 0): motor-side power minus what reaches the crank."""
    drive = pm.press.drive
    motor_side = drive.motors * drive.gear_ratio * cycle.motor_torque * cycle.theta_dot
    crank_side = (cycle.crank_torque + gear_inertia_at_crank(drive) * cycle.theta_ddot) * cycle.theta_dot
    return motor_side - crank_side
