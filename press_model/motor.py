"""Servo motor torque from the crank-side torque, Eq. 16, with the drive shared by several motors, and the two
drive losses Eq. 16 leaves out as options of the press file ([drive.losses], off by default).

The one home of Eq. 16's efficiency switch (eta while the motors drive, 1 / eta while the crank drives them,
the press file's ``efficiency_at_standstill`` at zero power); every other module calls one of these
(``tests/test_motor.py`` greps the packages for a spelling of the switch outside this file):

* :func:`eq16` numbers and numpy arrays (the losses included), :func:`motor_torque` for a press file's drive;
* :func:`eq16_loops` the same as plain loops over (B, n) rows for numba (the batch evaluator), the same bytes;
* :func:`torque_row_factors` |T_m| <= L as two rows linear in the crank torque (toppra, the jerk-limited stage);
* :func:`torque_bracket_interval` |T_m| <= L with the losses as an exact interval of the crank-side bracket (toppra);
* :func:`loss_coefficients`, :func:`lossy_torque_rows` and :func:`smooth_lossy_motor_torque` Eq. 16 with the losses as
  smooth rows in (y, theta_dot) and its differentiable form (the jerk-limited stage);
* :func:`smooth_motor_torque` and :func:`braking_ratio` the differentiable form of a CasADi problem (the thermal row);
* :func:`crank_gain`, :func:`crank_input_torque` and :class:`CrankInput` the inverse: the crank torque of a motor torque.

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
  of robot identification (Armstrong-Helouvry, Dupont, Canudas de Wit, Automatica 30(7), 1994);
* constant drag: the same models' Coulomb part, a torque d sgn(omega_m) of constant magnitude opposing the rotation
  (the rolling bearings' and seals' load-free friction of motor and gearbox; d in N m per motor at the motor shaft),
  none at rest (sgn 0 = 0: the static case is the press file's standstill choice, not a drag).

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


def motoring_at_zero(standstill: str) -> bool:
    """True when the press file's ``efficiency_at_standstill`` (``standstill``) counts zero power as driving."""
    return standstill == "motoring"


def efficiency_exponent(drive: Drive, power):
    """+1 where the motors drive (power > 0), -1 where they brake, and the press file's choice at zero power."""
    at_zero = 1.0 if motoring_at_zero(drive.standstill) else -1.0
    return np.where(power > 0, 1.0, np.where(power < 0, -1.0, at_zero))


def motor_torque(drive: Drive, crank_torque, theta_dot, theta_ddot):
    """Torque per motor (N m), Eq. 16, of the press file's drive: :func:`eq16` with its constants and losses.

    ``crank_torque`` is the linkage's drive torque (-lambda_21, N m), theta in rad/s and rad/s^2.
    """
    return eq16(crank_torque, theta_dot, theta_ddot, drive.gear_inertia, drive.efficiency, drive.gear_ratio, drive.motors,
                motoring_at_zero(drive.standstill), (drive.load_loss_per_Nm, drive.viscous, drive.coulomb_drag))


def eq16(crank_torque, theta_dot, theta_ddot, gear_inertia, efficiency, gear_ratio: float, motors: int, motoring_at_zero: bool,
         losses=(0.0, 0.0, 0.0)):
    """Torque per motor (N m), Eq. 16: (tau_crank + J_gear u^2 theta_ddot) / (n u eta^sgn(P)), P the power at the crank,
    plus the press file's optional losses (module docstring): s k T_B |T_B| + c u theta_dot + d sgn(theta_dot),
    T_B = B / (n u).

    The one implementation of Eq. 16: numbers or numpy arrays that broadcast (the batch path passes the sets'
    J_gear, eta, k and c as (B, 1) columns and the crank angles' theta as (n,) rows). ``crank_torque`` in N m, theta
    in rad/s and rad/s^2, ``gear_inertia`` in kg m^2, ``efficiency`` in (0, 1]; at P = 0 the motors count as
    driving when ``motoring_at_zero`` (the press file's ``standstill``, see :func:`efficiency_exponent`).
    ``losses``: (k in 1/(N m), load_loss_at_rated / rated torque; the viscous c in N m s/rad; the drag d in N m) at
    the motor shaft, the press file's three losses that travel together; all zero (the paper's model) leave the
    expression as it was.
    """
    load_loss, viscous, drag = losses
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
    if np.any(drag):
        torque = torque + np.asarray(drag) * np.sign(np.asarray(theta_dot))
    return torque


def eq16_loops(crank, theta_dot, theta_ddot, J, eta, u, nu, motoring_at_zero, out):
    """:func:`eq16` without the losses for crank torques (B, n), the sets' J_gear and eta (B,) and the grid's
    theta_dot, theta_ddot (n,), written into ``out`` (B, n; N m per motor): plain loops for numba
    (:func:`press_model.jit.compiled`), the batch evaluator's Eq. 16 for many sets without eq16's (B, n) temporaries.

    ``u`` the gear ratio, ``nu`` = motors * u as eq16 forms it. Each operation is eq16's, in its order: the bracket
    tau + (J u^2) theta_ddot, its power's sign, then the division by n u eta or n u (1 / eta); no fused
    multiply-add (numba compiles this without fastmath), so every value is numpy's to the bit (tests/test_motor.py).
    """
    uu = u * u
    for b in range(crank.shape[0]):
        j_uu = J[b] * uu
        den_forward = nu * eta[b]
        den_back = nu * (1.0 / eta[b])
        for p in range(crank.shape[1]):
            bracket = crank[b, p] + j_uu * theta_ddot[p]
            power = bracket * theta_dot[p]
            forward = power >= 0 if motoring_at_zero else power > 0
            out[b, p] = bracket / (den_forward if forward else den_back)


def torque_row_factors(drive: Drive, standstill) -> tuple[np.ndarray, np.ndarray]:
    """Eq. 16's |T_m| <= L as two rows linear in the crank-side bracket B = tau + J_gear u^2 theta_ddot.

    With theta_dot >= 0, T_m = max(B / (n u eta), B eta / (n u)), so |T_m| <= L is exactly B k_mot <= L (binds
    while the motors drive) and -B k_brk <= L (binds while they brake). Returns (k_mot, k_brk) per knot (N m of
    motor torque per N m at the crank): 1 / (n u eta) and eta / (n u), and at a knot where ``standstill[i]`` (the
    crank rests there) both 1 / (n u eta^s0) with s0 the press file's standstill exponent. The paper's Eq. 16
    only: with the losses, |T_m| <= L is the interval of :func:`torque_bracket_interval` instead.
    """
    n, u, eta = drive.motors, drive.gear_ratio, drive.efficiency
    still = np.asarray(standstill, bool)
    k_mot = np.full(len(still), 1.0 / (n * u * eta))
    k_brk = np.full(len(still), eta / (n * u))
    s0 = float(efficiency_exponent(drive, np.array(0.0)))
    k_mot[still] = k_brk[still] = 1.0 / (n * u * eta**s0)
    return k_mot, k_brk


def torque_bracket_interval(drive: Drive, limit: float, theta_dot, standstill) -> tuple[np.ndarray, np.ndarray]:
    """|T_m| <= ``limit`` (N m per motor) through :func:`eq16` with the press file's losses, as an interval of the
    crank-side bracket B = tau + J_gear u^2 theta_ddot: returns (B_lo, B_hi) per knot (N m at the crank).

    With the crank turning (theta_dot > 0) and x = B / (n u) the transmitted torque per motor, eq16 is
    T_0(x) + c u theta_dot with T_0 = x / eta + k x^2 while the motors drive (x >= 0) and eta x + k x^2 while they
    brake: continuous, increasing on the physical branch x >= -eta / (2 k) (below it, more braking torque at the crank
    would give less at the motors; :func:`crank_input_torque` caps the gear there), so |T_m| <= L is exactly
    T_0(x) in [-L - c u theta_dot, L - c u theta_dot] on that branch, an interval of x. Where ``standstill[i]``
    (theta_dot = 0) eq16 takes the press file's standstill exponent s0 for both signs: x / eta^s0 + s0 k x |x|,
    odd, so the interval is symmetric. Without losses this is (-L n u / eta, L n u eta) while turning, the bounds of
    :func:`torque_row_factors`. ``theta_dot`` (rad/s, >= 0) per knot: the speed the viscous loss is taken at.
    An empty interval (the viscous loss alone above the limit) comes back with B_hi < B_lo.
    """
    nu, eta, k, c = drive.motors * drive.gear_ratio, drive.efficiency, drive.load_loss_per_Nm, drive.viscous
    still = np.asarray(standstill, bool)
    w = np.asarray(theta_dot, float)
    viscous = c * drive.gear_ratio * w + drive.coulomb_drag * np.sign(w)  # the speed's losses: viscous and constant drag
    up, down = limit - viscous, limit + viscous  # what T_0 may reach above and below zero
    branch = -eta / (2.0 * k) if k else -np.inf  # x where eta x + k x^2 turns (the braking branch's end)
    # the roots of a x + s k x^2 = b for x >= 0 on the branch through zero, in the form without cancellation
    hi = np.where(up >= 0.0, _branch_root(1.0 / eta, k, up), -_branch_root(eta, -k, -up, empty=True))
    lo = -_branch_root(eta, -k, down)
    s0 = float(efficiency_exponent(drive, np.array(0.0)))
    at_rest = _branch_root(eta ** (-s0), s0 * k, np.full(len(still), float(limit)))
    hi, lo = np.where(still, at_rest, hi), np.where(still, -at_rest, np.maximum(lo, branch))
    return nu * lo, nu * hi


def _branch_root(a, sk, b, empty: bool = False):
    """The x >= 0 with a x + sk x^2 = b (a > 0, b >= 0) on the branch through zero: 2 b / (a + sqrt(a^2 + 4 sk b));
    where no root exists (sk < 0 and b above the top a^2 / (4 |sk|)) the top's x = a / (2 |sk|), or with ``empty``
    a value beyond it (no x reaches b: the caller's interval is to be empty)."""
    a = np.broadcast_to(np.asarray(a, float), np.shape(b))
    disc = a * a + 4.0 * sk * np.asarray(b, float)
    root = 2.0 * b / (a + np.sqrt(np.maximum(disc, 0.0)))
    if sk >= 0.0:
        return root
    top = a / (-2.0 * sk)
    return np.where(disc >= 0.0, root, 2.0 * top if empty else top)


LOSS_TERMS = 5  # the coefficients of :func:`loss_coefficients`


def loss_coefficients(drive: Drive) -> np.ndarray:
    """Eq. 16 with the losses in y = B / (n u eta), the motor torque if the motors drove without the losses (N m per
    motor): (r, q, v, b, d) = (eta^2, k eta^2 in 1/(N m), c u in N m s/rad, 2 k in 1/(N m), the constant drag d in N m),
    for :func:`lossy_torque_rows` and :func:`smooth_lossy_motor_torque`."""
    eta, k = drive.efficiency, drive.load_loss_per_Nm
    return np.array([braking_ratio(drive), k * eta * eta, drive.viscous * drive.gear_ratio, 2.0 * k, drive.coulomb_drag])


def lossy_torque_rows(y, theta_dot, coefficients):
    """Eq. 16 with the losses while the crank turns (theta_dot > 0, rad/s) as three smooth rows in (y, theta_dot), y =
    B / (n u eta) (N m per motor), ``coefficients`` (r, q, v, b) of :func:`loss_coefficients` (numbers, arrays or CasADi
    symbols). Returns (motoring form y + q y^2 + v theta_dot + d, braking form r y + q y^2 + v theta_dot + d, branch 1 + b y)
    (d the constant drag, the fifth coefficient: while the crank turns it opposes the rotation at its full size).

    The motor torque is the motoring form where y >= 0 and the braking form where y < 0 (:func:`eq16`); the motoring
    form is the larger where y >= 0, the braking form where y < 0, so |T_m| <= L on the physical branch is exactly:
    motoring form <= L, -L <= braking form <= L, branch >= 0 (:func:`torque_bracket_interval`'s interval).
    """
    r, q, v, b, d = (coefficients[i] for i in range(LOSS_TERMS))
    common = q * y * y + v * theta_dot + d
    return y + common, r * y + common, 1.0 + b * y


def smooth_lossy_motor_torque(y, theta_dot, coefficients, smoothing: float):
    """:func:`smooth_motor_torque` with the losses (N m per motor, CasADi symbols): the smooth max(y, r y) plus
    q y^2 + v theta_dot + d (``coefficients`` (r, q, v, b, d) of :func:`loss_coefficients`, b unused, d the constant drag
    while the crank turns); above eq16's T_m by at most (1 - r) ``smoothing`` / 2."""
    r, q, v, d = coefficients[0], coefficients[1], coefficients[2], coefficients[4]
    return smooth_motor_torque(y, r, smoothing) + q * y * y + v * theta_dot + d


def braking_ratio(drive: Drive) -> float:
    """eta^2: Eq. 16's torque while braking per unit of its motoring form, (B eta / (n u)) / (B / (n u eta))."""
    return drive.efficiency ** 2


def smooth_motor_torque(motoring, ratio, smoothing: float):
    """Eq. 16's motor torque (N m per motor) in a form an optimiser can differentiate, for CasADi symbols.

    ``motoring`` is B / (n u eta), the torque if the motors were driving; ``ratio`` :func:`braking_ratio` (a number or
    a symbol). The exact max(y, ratio y) is ((1 + ratio) y + (1 - ratio) |y|) / 2; here |y| is
    sqrt(y^2 + smoothing^2) (``smoothing`` in N m): the result is above the exact torque by at most
    (1 - ratio) smoothing / 2, and its square differs from the exact square by less than smoothing^2.
    """
    import casadi as ca  # only a CasADi problem's build calls this: the model's commands do not pay the import

    return 0.5 * ((1.0 + ratio) * motoring + (1.0 - ratio) * ca.sqrt(motoring * motoring + smoothing * smoothing))


def crank_gain(drive: Drive, s):
    """n u eta^s: crank torque (N m) per N m of motor torque through the gear, ``s`` = +1 while the motors drive
    and -1 while they brake (:func:`efficiency_exponent`; a number or an array)."""
    return drive.motors * drive.gear_ratio * drive.efficiency**s


class CrankInput:
    """:func:`crank_input_torque` for one scalar state at a time (the forward dynamics' integrator), with the two
    gains of the paper's Eq. 16 computed once."""

    def __init__(self, drive: Drive):
        self.drive = drive
        self._gain = {s: crank_gain(drive, s) for s in (-1.0, 1.0)}

    def __call__(self, motor_torque: float, theta_dot: float) -> float:
        """Crank torque (N m) the motors deliver through the gear for ``motor_torque`` (N m per motor) at crank speed
        ``theta_dot`` (rad/s)."""
        p = motor_torque * theta_dot
        if self.drive.has_losses or p == 0:
            return float(crank_input_torque(self.drive, motor_torque, theta_dot))
        return self._gain[1.0 if p > 0 else -1.0] * motor_torque


def crank_input_torque(drive: Drive, motor_torque_nm, theta_dot):
    """Torque (N m) that the motors deliver at the crank through the gear, before its inertia: the B of :func:`eq16`
    whose motor torque is ``motor_torque_nm`` (n u eta^s T_m without the losses). With the losses on, the motor side
    first loses c omega_m + d sgn(omega_m); the rest R drives the gear, R = T_B / eta^s + s k T_B |T_B|, solved for T_B (the root on
    the branch through zero; a braking torque beyond the gear's largest, eta^2 / (4 k), gives that largest one)."""
    tm = np.asarray(motor_torque_nm)
    td = np.asarray(theta_dot)
    if drive.viscous:
        tm = tm - drive.viscous * drive.gear_ratio * td
    if drive.coulomb_drag:
        tm = tm - drive.coulomb_drag * np.sign(td)
    s = efficiency_exponent(drive, tm * td)
    nu = drive.motors * drive.gear_ratio
    if not drive.load_loss_at_rated:
        return crank_gain(drive, s) * tm
    k, inv = drive.load_loss_per_Nm, drive.efficiency ** (-s)
    a = np.abs(tm)
    a = np.where(s < 0, np.minimum(a, inv * inv / (4.0 * k)), a)  # braking: no more than the gear can pass back
    # s k x^2 + eta^-s x - a = 0 for x = |T_B|, in the form without cancellation
    x = 2.0 * a / (inv + np.sqrt(np.maximum(inv * inv + 4.0 * s * k * a, 0.0)))
    return nu * np.sign(tm) * x


def gear_inertia_at_crank(drive: Drive) -> float:
    """J_gear u^2 (kg m^2): the reduction system's inertia seen at the crank."""
    return drive.gear_inertia * drive.gear_ratio**2
