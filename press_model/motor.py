"""Servo motor torque from the crank-side torque, Eq. 16, with the drive shared by several motors, and the two
drive losses Eq. 16 leaves out as options of the press file ([drive.losses], off by default).

The losses (:func:`eq16`), after the split of a gearbox's power loss into a load-dependent and a no-load part
(Niemann & Winter, Maschinenelemente Bd. II, 2nd ed., Springer 1989, Ch. 21; ISO/TR 14179-2:2001, Gears - Thermal
capacity - Part 2):

* load-dependent: the paper's constant efficiency eta is a mesh loss proportional to the transmitted torque, i.e. a
  constant mean coefficient of mesh friction. ISO/TR 14179-2 takes that coefficient as growing with the tooth load,
  mu_mz ~ (F_bt / b)^0.2 (Schlenk's formula); to first order about a working load F_0 that is
  mu_0 (0.8 + 0.2 F / F_0), a loss fraction with a constant part (eta's) and a part growing linearly with the load
  (k's, here a free parameter): an extra loss torque k T_B |T_B| on top of eta, with T_B = B / (n u) the
  transmitted torque per motor referred to the motor shaft (B the crank-side bracket of Eq. 16) and
  k = load_loss_at_rated / T_rated. The loss opposes the motion: it adds to the motor torque when the motors drive
  and subtracts when the crank drives them (a friction torque, the same size either way). Efficiency while
  driving: 1 / (1 / eta + k |T_B|), falling with the load.
* no-load: churning, seals, bearings' no-load friction and the motor's own drag grow with speed; their first-order
  form is a viscous torque c omega_m at the motor shaft (c in N m s/rad per motor), as in the drive-friction models
  of robot identification (Armstrong-Helouvry, Dupont, Canudas de Wit, Automatica 30(7), 1994).

How this relates to the SYNTHETIC generator (:mod:`calibration.synthetic.effects`, which does not import this): its load effect
scales the ideal motor torque T_0 = B / (n u eta^s) by 1 / (1 - a |T_0| / T_rated) when driving and by
(1 - a |T_0| / T_rated) when braking. Both are linear falls of the efficiency with load, but the generator measures
the load as T_0 (eta included), divides rather than adds, and so is asymmetric (to first order k = a / eta^2 when
driving, a eta^2 when braking) and has higher-order terms this form lacks. Its viscous effect is c omega_m, the
same first-order form.
"""
from __future__ import annotations

import numpy as np

from .press_data import Drive


def efficiency_exponent(drive: Drive, power):
    """+1 where the motors drive (power > 0), -1 where they brake, and the press file's choice at zero power."""
    at_zero = 1.0 if drive.standstill == "motoring" else -1.0
    return np.where(power > 0, 1.0, np.where(power < 0, -1.0, at_zero))


def motor_torque(drive: Drive, crank_torque, theta_dot, theta_ddot):
    """Torque per motor (N m), Eq. 16, of the press file's drive: :func:`eq16` with its constants and losses.

    ``crank_torque`` is the linkage's drive torque (-lambda_21, N m), theta in rad/s and rad/s^2.
    """
    return eq16(crank_torque, theta_dot, theta_ddot, drive.gear_inertia, drive.efficiency, drive.gear_ratio, drive.motors,
                drive.standstill == "motoring", drive.load_loss_per_Nm, drive.viscous)


def eq16(crank_torque, theta_dot, theta_ddot, gear_inertia, efficiency, gear_ratio: float, motors: int, motoring_at_zero: bool,
         load_loss=0.0, viscous=0.0):
    """Torque per motor (N m), Eq. 16: (tau_crank + J_gear u^2 theta_ddot) / (n u eta^sgn(P)), P the power at the crank,
    plus the press file's optional losses (module docstring): s k T_B |T_B| + c u theta_dot, T_B = B / (n u).

    The one implementation of Eq. 16: numbers or numpy arrays that broadcast (the batch path passes the sets'
    J_gear, eta, k and c as (B, 1) columns and the crank angles' theta as (n,) rows). ``crank_torque`` in N m, theta
    in rad/s and rad/s^2, ``gear_inertia`` in kg m^2, ``efficiency`` in (0, 1]; at P = 0 the motors count as
    driving when ``motoring_at_zero`` (the press file's ``standstill``, see :func:`efficiency_exponent`).
    ``load_loss`` k in 1/(N m) (load_loss_at_rated / rated torque), ``viscous`` c in N m s/rad at the motor shaft;
    both zero (the paper's model) leave the expression as it was.
    """
    u = gear_ratio
    bracket = np.asarray(crank_torque) + gear_inertia * (u * u) * np.asarray(theta_ddot)
    power = bracket * np.asarray(theta_dot)
    forward = power >= 0 if motoring_at_zero else power > 0  # at P = 0 the press file's choice
    nu = motors * u
    # n u eta^s as n u eta or n u (1 / eta): no pow per sample, and the products on the (B, 1) columns only
    torque = bracket / np.where(forward, nu * np.asarray(efficiency), nu * (1.0 / np.asarray(efficiency)))
    if np.any(load_loss):
        k = np.asarray(load_loss)
        tb = bracket * (1.0 / nu)
        torque = torque + np.where(forward, k, -k) * (tb * np.abs(tb))  # opposes the motion (module docstring)
    if np.any(viscous):
        torque = torque + np.asarray(viscous) * u * np.asarray(theta_dot)
    return torque


def crank_input_torque(drive: Drive, motor_torque_nm, theta_dot):
    """Torque (N m) that the motors deliver at the crank through the gear, before its inertia: the B of :func:`eq16`
    whose motor torque is ``motor_torque_nm`` (n u eta^s T_m without the losses). With the losses on, the motor side
    first loses c omega_m; the rest R drives the gear, R = T_B / eta^s + s k T_B |T_B|, solved for T_B (the root on
    the branch through zero; a braking torque beyond the gear's largest, eta^2 / (4 k), gives that largest one)."""
    tm = np.asarray(motor_torque_nm)
    td = np.asarray(theta_dot)
    if drive.viscous:
        tm = tm - drive.viscous * drive.gear_ratio * td
    s = efficiency_exponent(drive, tm * td)
    nu = drive.motors * drive.gear_ratio
    if not drive.load_loss_at_rated:
        return nu * drive.efficiency**s * tm
    k, inv = drive.load_loss_per_Nm, drive.efficiency ** (-s)
    a = np.abs(tm)
    a = np.where(s < 0, np.minimum(a, inv * inv / (4.0 * k)), a)  # braking: no more than the gear can pass back
    # s k x^2 + eta^-s x - a = 0 for x = |T_B|, in the form without cancellation
    x = 2.0 * a / (inv + np.sqrt(np.maximum(inv * inv + 4.0 * s * k * a, 0.0)))
    return nu * np.sign(tm) * x


def gear_inertia_at_crank(drive: Drive) -> float:
    """J_gear u^2 (kg m^2): the reduction system's inertia seen at the crank."""
    return drive.gear_inertia * drive.gear_ratio**2
