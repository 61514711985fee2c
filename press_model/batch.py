"""Motor-torque curves of many sensitivity-parameter sets at once (the fast path of Section 3).

The per-point "Pinocchio path" (:func:`cycle.simulate_cycle` on ``PressModel(press.with_overrides(p))``)
solves kinematics, RNEA, loop Jacobians and the friction fixed point at every crank angle for one
parameter set. For the 28 sensitivity parameters most of that work is the same for every set:

* The kinematics (q, v, a, slide height and speed, the loop Jacobians, the solve matrix A and its
  inverse, the relative joint speeds w, the slide row u_s) do not depend on them: the Ls_i move centres
  of mass, not joints, and each link frame sits at a joint.
* The RNEA torque ``tau0`` and the tree-joint transmitted forces ``P`` (see :class:`dynamics.StatePrep`)
  are linear in each body's planar inertial parameters (m, m c_x, m c_y, I_zz about the link-frame
  origin). Their per-point coefficients come from RNEA runs of the Pinocchio model on basis inertias.
* The slide force is affine in psi * M (M the design mass, or the sum of the sampled masses; Eqs. 13, 17)
  plus the process force (Eq. 14).
* Viscous friction is linear in c_r and c_s; the Coulomb part is mu times a reaction magnitude.

So, per crank angle, the drive torque and every reaction vector are one constant matrix times a short
feature vector of the set, plus a constant matrix times the Coulomb friction terms. Only the friction
fixed point (Eqs. 10-12: reactions <-> friction, the fixed point of :func:`dynamics.inverse_dynamics` to
the press file's tolerance, reached in ~7.6 instead of ~11 passes by Anderson(1) acceleration) and the
efficiency sign of Eq. 16 are nonlinear. The fixed point runs in a compiled numba kernel when numba is
installed (:mod:`batch_kernel`, generated for the press's loop structure, two SIMD registers of sets per block, about
0.05 ms of CPU time per 360-point cycle, spread over the cores), else with numpy over a chunk of sets and all crank angles.

Model/Data split as in Pinocchio: :class:`BatchModel` holds the precomputed constants and never changes
(:func:`build_batch_model` makes one); the free functions :func:`evaluate_chunk`, :func:`iter_chunks`
and :func:`motor_torques` evaluate parameter sets, chunk by chunk so that memory stays bounded.

Agreement with the Pinocchio path is to rounding: both fit a COM given by distances to its vertices
(link 4) with the same :func:`geometry.trilaterate`.

Units: SI throughout (rad, s, m, kg, N, N m). Parameter arrays are (B, D) with the columns in the
order of ``press.parameters`` (``BatchModel.names``).
"""
from __future__ import annotations

import json
import math
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass, replace

import numpy as np
import pinocchio as pin

from .batch_kernel import GAMMA_MAX, fixed_point_numba, numba
from .cycle import crank_grid
from .disk_cache import array_digest, cached_arrays, press_key
from .dynamics import StatePrep, slide_loads
from press_io.errors import PressDataError, SolverError
from .forces import MPA, NO_PROCESS, BalanceForce, ProcessForce
from .geometry import GRADIENT_TOL, trilaterate
from .kinematic_tables import grid_positions
from .kinematics import check_contact_in_stroke, state_at
from .model import PressModel, ReactionMap, Workspace
from .jit import compiled
from .motor import eq16, eq16_loops, motoring_at_zero
from .press_data import SCALAR_TARGETS, PressData, Target

DEFAULT_CHUNK = 256  # parameter sets per chunk (numpy path: ~5 work arrays of chunk * n_points * (2 r + 1) doubles)
FEATURE_BLOCK = 16384  # parameter sets whose features (COMs, inertias) are computed in one pass


_SCALARS = {  # Target.field of a drive, friction or balance scalar -> its nominal value in the press description
    "gear_inertia": lambda p: p.drive.gear_inertia,
    "efficiency": lambda p: p.drive.efficiency,
    "load_loss": lambda p: p.drive.load_loss_at_rated,
    "viscous": lambda p: p.drive.viscous,
    "coulomb_drag": lambda p: p.drive.coulomb_drag,
    "mu_r": lambda p: p.friction.mu_r,
    "c_r": lambda p: p.friction.c_r,
    "mu_s": lambda p: p.friction.mu_s,
    "c_s": lambda p: p.friction.c_s,
    "psi": lambda p: p.balance.psi,
}


@dataclass(frozen=True)
class Source:
    """A scalar of the model: column ``index`` of the parameter array, or the constant ``value``."""

    index: int  # -1: constant
    value: float

    def take(self, X: np.ndarray) -> np.ndarray:
        """(B,) values for parameter rows X (B, D)."""
        return X[:, self.index] if self.index >= 0 else np.full(len(X), self.value)


@dataclass(frozen=True)
class BodySpec:
    """How one body's inertial data follow from the parameters (body coordinates, m, kg, kg m^2).

    ``com_kind``: "fixed" (``com``), "line" (``start + distance * direction``, unit direction) or
    "trilateration" (least squares to ``points`` at ``distances``, see :func:`trilaterate`).
    """

    name: str
    origin: np.ndarray  # the link frame's origin (its tree joint's point), body coordinates
    mass: Source
    inertia: Source  # about the COM
    com_kind: str
    com: np.ndarray | None = None
    start: np.ndarray | None = None
    direction: np.ndarray | None = None
    distance: Source | None = None
    points: np.ndarray | None = None  # (k, 2)
    distances: tuple[Source, ...] = ()


@dataclass(frozen=True, eq=False)
class BatchModel:
    """Constants of the batch evaluation of one press, motion and process. Immutable; arrays read-only.

    Per crank angle p (n of them) and output column k (0: drive torque tau_d in N m; 1..2r: the
    in-plane reaction components, x of the r = n_rev + 1 reactions then their y, N), the drive torque and
    reactions are::

        out[p] = feat @ base[:, p] + [c_r, c_s] @ visc[:, p] + (mu * N) @ coul[p]

    with feat = [pi (4 per body: m, m c_x, m c_y, I_zz at the link origin), psi * M, 1] (M the balance mass:
    the design mass, or sum(m) when the press file's balance follows the actual masses) (the
    entries that are the same for every set are folded into the constant column), mu = [mu_r] * n_rev +
    [mu_s] and N the reaction magnitudes (the fixed point). The last reaction is the guide's normal
    force (its y column is identically zero).
    """

    press: PressData
    names: tuple[str, ...]  # parameter names, column order of X
    nominal: np.ndarray
    low: np.ndarray
    high: np.ndarray
    theta: np.ndarray  # rad, uniform grid from 0
    theta_dot: np.ndarray  # rad/s
    theta_ddot: np.ndarray  # rad/s^2
    height: np.ndarray  # m above BDC
    height_dot: np.ndarray  # m/s
    period: float  # s
    bodies: tuple[BodySpec, ...]
    gear_inertia: Source
    efficiency: Source
    load_loss: Source  # the press file's load_loss_at_rated (1; 0: off), per unit of loss_reference_torque
    viscous: Source  # N m s/rad at the motor shaft (0: off)
    coulomb_drag: Source  # N m at the motor shaft (0: off)
    loss_reference_torque: float  # N m: the motors' rated torque that load_loss refers to
    mu_r: Source
    c_r: Source
    mu_s: Source
    c_s: Source
    psi: Source
    balance_mass: float | None  # kg, the design mass the balance pressure is set from; None: the sampled masses
    gear_ratio: float
    motors: int
    standstill: str
    feature_keep: np.ndarray  # columns of the full feature vector that vary between sets (the rest is folded in)
    base: np.ndarray  # (n_feat, n, 1 + 2 r)
    visc: np.ndarray  # (2, n, 1 + 2 r)
    coul: np.ndarray  # (n, r, 1 + 2 r)
    base_pt: np.ndarray  # base and visc with the crank angle first, (n, n_feat | 2, 1 + 2 r), for the kernel
    visc_pt: np.ndarray
    coul_tau: np.ndarray  # (n, r): coul[..., 0], the Coulomb terms' drive torque ...
    coul_lam: np.ndarray  # (n, nv - 1, r): ... and loop forces lambda, with
    G: np.ndarray  # (2 r - 1, nv - 1): coul[p, :, 1:2r] = (G @ coul_lam[p]).T, the same G at every angle
    slide: np.ndarray  # (n, 1 + 2 r): the output columns per N of force up on the slide (Eq. 14's process force) at each angle
    n_rev: int
    friction_tolerance: float
    friction_max_iterations: int

    @property
    def n_points(self) -> int:
        return len(self.theta)

    @property
    def n_params(self) -> int:
        return len(self.names)


@dataclass
class ChunkResult:
    """Result for a chunk of B sets over n crank angles."""

    crank_torque: np.ndarray  # (B, n) tau_d at the crank, N m
    motor_torque: np.ndarray | None  # (B, n) per motor, Eq. 16, N m (None: not asked for, see evaluate_chunk's ``motor``)
    iterations: np.ndarray  # (B, n) friction fixed-point passes, counted as inverse_dynamics counts its own (fewer: accelerated)


# ------------------------------------------------------------------------------------------------
# building the model


def _source(index: dict, target: Target, raw_value) -> Source:
    """Parameter column of the parameter that sets ``target``, else the press description's constant."""
    return Source(index.get(target, -1), float(raw_value))


def _body_specs(press: PressData, tree_origin: Mapping, index: dict) -> tuple[BodySpec, ...]:
    specs = []
    for bname, body in press.bodies.items():
        mass = _source(index, Target("bodies", "mass", bname), body.mass)
        inertia = _source(index, Target("bodies", "inertia", bname), body.inertia)
        origin = np.array(tree_origin[bname], dtype=float)
        spec = body.com_spec
        if spec.kind == "fixed":
            specs.append(BodySpec(bname, origin, mass, inertia, "fixed", com=np.array(body.com, dtype=float)))
        elif spec.kind == "trilateration":
            names = list(spec.distances)
            pts = np.array([body.points[p] for p in names], dtype=float)
            dists = tuple(_source(index, Target("bodies", "com_distances", bname, p), spec.distances[p]) for p in names)
            specs.append(BodySpec(bname, origin, mass, inertia, "trilateration", points=pts, distances=dists))
        else:
            start, toward = body.points[spec.start], body.points[spec.toward]
            direction = toward - start
            specs.append(BodySpec(bname, origin, mass, inertia, "line", start=np.array(start, dtype=float),
                                  direction=direction / np.linalg.norm(direction),
                                  distance=_source(index, Target("bodies", "com_distance", bname), spec.distance)))
    return tuple(specs)


def _check_targets(press: PressData):
    """Every parameter must be one the batch model knows how to vary."""
    for p in press.parameters.values():
        if not p.target.field:
            raise PressDataError(press.source, f"parameters.{p.name}.path", p.path,
                                 "the batch evaluator varies only body masses, inertias and COM distances, "
                                 f"and {', '.join(sorted(SCALAR_TARGETS))}; use simulate_cycle for other parameters")


def _basis_inertias():
    """Four spatial inertias and their planar parameters [m, m c_x, m c_y, I_zz at the frame origin]."""
    eye = np.eye(3)
    basis = [pin.Inertia(1.0, np.zeros(3), np.zeros((3, 3))),
             pin.Inertia(1.0, np.array([1.0, 0.0, 0.0]), np.zeros((3, 3))),
             pin.Inertia(1.0, np.array([0.0, 1.0, 0.0]), np.zeros((3, 3))),
             pin.Inertia(1.0, np.zeros(3), eye)]
    params = np.array([b.toDynamicParameters()[[0, 1, 2, 9]] for b in basis])
    return basis, params


def _planar_params(inertia: pin.Inertia) -> np.ndarray:
    return inertia.toDynamicParameters()[[0, 1, 2, 9]]


class _Linear:
    """The per-point linear solve of StatePrep.solve for many right-hand sides (columns) at once, at every crank angle of
    a grid together (a leading axis of points): the same numpy operations on the same inner shapes and strides as one
    point's, stacked (numpy's matmul makes one BLAS call a point on each), so each point's numbers are its own."""

    def __init__(self, pm: PressModel, A_inv: np.ndarray, u_s: np.ndarray, rm: ReactionMap):
        self.A_inv, self.u_s, self.P_rows = A_inv, u_s, pm.joint_rows  # A_inv (n, nv, nv), u_s (n, nv)
        self.rm = rm
        self.axis2 = pm.axis[:2]
        self.normal2 = np.array([-self.axis2[1], self.axis2[0]])

    def solve(self, tau0, f_ext, joint_tau_f, f_s):
        """Drive torque and loop forces x = [tau_d, lambda] (n, nv, k) for tau0 (n, nv, k), f_ext, f_s (k,) and the
        joint friction's generalized forces ``joint_tau_f`` = joint_rows^T tau_f ((nv, k) or (n, nv, k))."""
        u = self.u_s[:, :, None]
        return self.A_inv @ (tau0 - u * f_ext - joint_tau_f - u * f_s)

    def assemble(self, x, P, f_ext):
        """Output columns [tau_d, reaction x components, guide normal, reaction y components, 0] (n, 1 + 2 r, k) for
        x (n, nv, k), P (n, n_tree, 2, k), f_ext (k,)."""
        rm, n, k = self.rm, x.shape[0], x.shape[2]
        lam = x[:, 1:].reshape(n, -1, 2, k)
        R = P - np.einsum("tc,pcdk->ptdk", rm.cut_coef, lam) - rm.slide_coef[:, None, None] * f_ext * self.axis2[None, :, None]
        vec = np.where((rm.revolute_tree >= 0)[None, :, None, None], R[:, rm.revolute_tree], lam[:, rm.revolute_cut])
        guide = self.normal2 @ R[:, rm.guide_tree]  # component across the guide
        return np.concatenate([x[:, :1], vec[:, :, 0], guide[:, None], vec[:, :, 1], np.zeros((n, 1, k))], axis=1)


_POINTWISE = ("base", "visc", "coul", "coul_x", "height", "height_dot", "G", "slide")  # the arrays _pointwise returns


def _pointwise(pm: PressModel, bodies: tuple[BodySpec, ...], theta: np.ndarray, td: np.ndarray, tdd: np.ndarray,
               process: ProcessForce) -> dict[str, np.ndarray]:
    """The per-crank-angle constants of :class:`BatchModel` (base before folding, visc, coul, the loop-force
    form coul_x and its G, height, height_dot, the slide-force response slide) from one RNEA pass of the Pinocchio model
    a point and each body's regressor of its inertial parameters.

    A function of the press data, the crank-angle grid and speeds and the process force alone: kept on disk
    (:mod:`disk_cache`). Two passes: the Pinocchio calls a point (the state from the grid's positions, kept on disk by the
    press geometry, :func:`kinematic_tables.grid_positions`, so that the loop closes at its first check; the RNEA; each
    body's regressor and Jacobian), then the algebra of every point at once (:class:`_Linear`), the same operations as a
    point's alone.
    """
    press = pm.press
    model = pm.model
    n = len(theta)
    loads = slide_loads(pm, process)
    bal = BalanceForce.from_press(press, pm.assembly.stroke)
    rm = pm.reaction_map
    basis, basis_par = _basis_inertias()
    # the full dynamic parameters (10 a body) per unit planar parameter [m, m c_x, m c_y, I_zz]
    per_planar = np.array([b.toDynamicParameters() for b in basis]).T @ np.linalg.inv(basis_par.T)
    jids = [pm.body_joint[b.name] for b in bodies]
    supported = [np.array([j in set(model.supports[jid]) for j in rm.tree_jids]) for jid in jids]  # tree joints a body hangs on
    nominal_pi = np.concatenate([_planar_params(model.inertias[j]) for j in jids])
    n_body, nv, n_tree = len(bodies), pm.nv, len(rm.tree_jids)
    r = pm.joint_rows.shape[0] + 1
    nr = r - 1
    n_pi = 4 * n_body

    # pass 1, a point at a time: Pinocchio. Each buffer holds a point's arrays with the strides Pinocchio returns them
    # with (the rotation column-major), so that pass 2's products are the same BLAS calls as on Pinocchio's own arrays.
    reg = np.empty((n, n_body, 6, 10))
    jac = np.empty((n, n_body, 6, nv))
    rot_t = np.empty((n, n_body, 3, 3))  # each body's joint rotation, transposed: its column-major memory (3rd column unread)
    body_tree = [rm.tree_jids.index(jid) for jid in jids]  # StatePrep's rows of the bodies' joints
    A_inv, u_s, w = np.empty((n, nv, nv)), np.empty((n, nv)), np.empty((n, nr))
    tau0, P = np.empty((n, nv)), np.empty((n, n_tree, 2))
    height, height_dot, f_ext, f_proc = np.empty(n), np.empty(n), np.empty(n), np.empty(n)
    qs = grid_positions(pm, theta)
    ws = Workspace(pm)
    data = ws.data
    for p in range(n):
        st = state_at(pm, ws, float(theta[p]), float(td[p]), float(tdd[p]), qs[p])
        prep = StatePrep.on_closure(pm, ws, st, loads)
        height[p], height_dot[p] = st.height, st.height_dot
        # the torque and the tree joints' transmitted forces of each body's planar inertial parameters: the body's
        # spatial force is linear in its parameters (Pinocchio's body regressor, on the joint's velocity and
        # acceleration, gravity included, which StatePrep's RNEA left in ws.data whatever the inertias); it reaches the
        # drive through the body's joint Jacobian (at q, from the loop closure) and passes, the same force in the world
        # frame, through every tree joint that supports the body
        for i, jid in enumerate(jids):
            reg[p, i] = pin.jointBodyRegressor(model, data, jid)
            jac[p, i] = pin.getJointJacobian(model, data, jid, pin.LOCAL)
        rot_t[p, :, :, :2] = prep.rot[body_tree].swapaxes(-1, -2)
        A_inv[p], u_s[p], w[p], P[p] = prep.A_inv, prep.u_s, prep.w, prep.P
        tau0[p] = prep.base_rhs + prep.u_s * prep.f_ext  # StatePrep's RNEA torque
        f_ext[p], f_proc[p] = prep.f_ext, prep.process

    # pass 2, every point at once
    F = reg @ per_planar  # (n, n_body, 6, 4): local spatial force per planar parameter
    tau_b = (jac.swapaxes(-1, -2) @ F).transpose(0, 2, 1, 3).reshape(n, nv, n_pi)
    P_body = rot_t.swapaxes(-1, -2)[:, :, :2] @ F[:, :, :3]  # (n, n_body, 2, 4)
    P_b = np.zeros((n, n_tree, 2, n_pi))
    for i in range(n_body):
        P_b[:, supported[i], :, 4 * i : 4 * i + 4] = P_body[:, i, None]
    _check_inertial(tau_b @ nominal_pi, P_b @ nominal_pi, tau0, P, theta)

    lin = _Linear(pm, A_inv, u_s, rm)
    # feature columns: pi (inertial), then the slide force per unit psi*M and the constant part
    k_all = n_pi + 1 + nr + 1
    eye = np.eye(k_all)
    L = lin.assemble(lin.solve(np.concatenate([tau_b, np.zeros((n, nv, k_all - n_pi))], axis=2), eye[n_pi],
                               pm.joint_rows.T @ eye[n_pi + 1 : n_pi + 1 + nr], eye[-1]),
                     np.concatenate([P_b, np.zeros((n, n_tree, 2, k_all - n_pi))], axis=3), eye[n_pi])  # (n, n_out, k_all)
    L_pi, L_f, L_tf, L_fs = L[:, :, :n_pi], L[:, :, n_pi], L[:, :, n_pi + 1 : n_pi + 1 + nr], L[:, :, -1]
    # Eqs. 13, 17: Q_b = psi M g (1 + X) + z A_b p_off X with X = (1 + (H_max - H) A_b / V)^n - 1 (a point at a time, in
    # Python floats: numpy's power on an array may take another rounding than C's pow)
    per_psi_m, const_bal = np.zeros(n), np.zeros(n)
    if bal.cylinders:
        for p in range(n):
            X = (1.0 + (bal.stroke - float(height[p])) * bal.piston_area / bal.tank_volume) ** bal.exponent - 1.0
            per_psi_m[p], const_bal[p] = press.gravity * (1.0 + X), bal.cylinders * bal.piston_area * bal.pressure_offset_mpa * MPA * X
    base = np.empty((n_pi + 2, n, L.shape[1]))
    base[:n_pi] = L_pi.transpose(2, 0, 1)
    base[n_pi] = L_f * per_psi_m[:, None]
    base[n_pi + 1] = L_f * (const_bal + f_proc)[:, None]
    slide = np.ascontiguousarray(L_f)
    # Eq. 10, 12: -(mu r |N| + c |w|) sgn(w) = -c w - mu (r sgn w) |N|
    visc = np.empty((2, n, L.shape[1]))
    visc[0] = (L_tf @ (-w)[:, :, None])[:, :, 0]
    visc[1] = L_fs * (-height_dot)[:, None]
    lever = -pm.bearing_radii * np.sign(w)  # (n, nr)
    coul = np.empty((n, r, L.shape[1]))
    coul[:, :nr] = (L_tf * lever[:, None, :]).transpose(0, 2, 1)
    coul[:, nr] = L_fs * (-np.sign(height_dot))[:, None]
    # the same through the loop forces: coul[p, :, 1:] = (G @ coul_x[p, 1:]).T with a constant G
    tf_unit = np.zeros((n, nr, r))
    tf_unit[:, np.arange(nr), np.arange(nr)] = lever
    fs_unit = np.zeros((n, r))
    fs_unit[:, nr] = -np.sign(height_dot)
    coul_x = lin.A_inv @ (np.zeros((n, nv, r)) - u_s[:, :, None] * np.zeros(r) - pm.joint_rows.T @ tf_unit
                          - u_s[:, :, None] * fs_unit[:, None, :])
    n_lam = nv - 1
    x_unit = np.vstack([np.zeros((1, n_lam)), np.eye(n_lam)])
    G = lin.assemble(x_unit[None], np.zeros((1, n_tree, 2, n_lam)), np.zeros(n_lam))[0, 1:-1]
    atol = 1e-12 * np.max(np.abs(coul).reshape(n, -1), axis=1)
    linear = np.isclose(G @ coul_x[:, 1:], coul[:, :, 1:-1].swapaxes(-1, -2), rtol=1e-12, atol=atol[:, None, None])
    if not np.all(linear):
        raise SolverError("the batch model's reaction map is not linear in the loop forces in the way the kernel assumes")

    return {"base": base, "visc": visc, "coul": coul, "coul_x": coul_x, "height": height, "height_dot": height_dot, "G": G,
            "slide": slide}


def _check_inertial(tau_nom: np.ndarray, P_nom: np.ndarray, tau0: np.ndarray, P: np.ndarray, theta: np.ndarray) -> None:
    """Refuse a model whose inertial coefficients at the nominal parameters (tau_nom (n, nv), P_nom (n, n_tree, 2)) do not
    give StatePrep's RNEA torque ``tau0`` and transmitted forces ``P`` to 1e-10 of the largest at each crank angle."""
    n = len(theta)
    scale = np.maximum(1.0, np.maximum(np.max(np.abs(tau_nom), axis=1), np.max(np.abs(P_nom).reshape(n, -1), axis=1)))
    err = np.maximum(np.max(np.abs(tau_nom - tau0), axis=1), np.max(np.abs(P_nom - P).reshape(n, -1), axis=1))
    bad = np.flatnonzero(err > 1e-10 * scale)
    if bad.size:
        raise SolverError(f"the batch model's inertial coefficients do not reproduce Pinocchio's RNEA at crank angle "
                          f"{math.degrees(theta[bad[0]]):.2f} deg: the model is not planar in the way the batch path assumes")


def build_batch_model(press: PressData, motion, process: ProcessForce, step_deg: float = 1.0,
                      pm: PressModel | None = None) -> BatchModel:
    """Precompute the constants of the batch evaluation (about 0.15 s of CPU for 360 points on a loaded 2-core AMD EPYC;
    ~20 ms when the disk cache holds this press, motion and process force, see :func:`_pointwise`).

    ``pm`` is the nominal press's :class:`PressModel` if the caller already has one. The crank-angle grid
    is the one of :func:`cycle.simulate_cycle` (``step_deg``, from theta_c = 0).
    """
    _check_targets(press)
    pm = pm if pm is not None else PressModel(press)
    check_contact_in_stroke(pm, process)
    theta = crank_grid(step_deg)
    names = tuple(press.parameters)
    index = {press.parameters[nm].target: i for i, nm in enumerate(names)}
    bodies = _body_specs(press, pm.tree.origin, index)
    scal = {t.field: _source(index, t, _SCALARS[t.field](press)) for t in SCALAR_TARGETS.values()}

    td, tdd = motion.theta_dot(theta), motion.theta_ddot(theta)
    td, tdd = np.asarray(td, dtype=float), np.asarray(tdd, dtype=float)

    def pointwise() -> dict:
        return _pointwise(pm, bodies, theta, td, tdd, process)

    # the disk cache keys on the force's data: a ProcessForce's repr is its data; another force (a logged curve) may
    # name its own (cache_key); one that does neither is computed every time
    own = getattr(process, "cache_key", None)
    process_key = repr(process) if type(process) is ProcessForce else (
        {"type": type(process).__name__, **own()} if own is not None else None)
    if process_key is not None:
        key = {**press_key(pm.press), "grid": [array_digest(theta), array_digest(td), array_digest(tdd)], "process": process_key}
        pts = cached_arrays("batch", key, _POINTWISE, pointwise)
    else:
        pts = pointwise()
    base, visc, coul, coul_x, height, height_dot, G, slide = (np.array(pts[k]) for k in _POINTWISE)

    # fold the features that no parameter changes (e.g. the slide's COM lever) into the constant column
    nominal = np.array([press.parameters[k].nominal for k in names])
    low = np.array([press.parameters[k].low for k in names])
    high = np.array([press.parameters[k].high for k in names])
    probe = np.vstack([nominal, low, high, low + (high - low) * np.random.default_rng(0).random((5, len(names)))])
    balance_mass = press.balance.design_mass if press.balance.masses == "design" else None
    full, _ = _raw_features(bodies, scal["psi"], probe, "mask", balance_mass=balance_mass)
    varies = np.any(full != full[:1], axis=0)
    varies[-1] = True  # the constant column itself
    for f in np.flatnonzero(~varies):
        base[-1] += full[0, f] * base[f]
    keep = np.flatnonzero(varies)
    base = np.ascontiguousarray(base[keep])

    drive = press.drive
    arrays = {"nominal": nominal, "low": low, "high": high, "feature_keep": keep, "theta": theta,
              "theta_dot": np.asarray(td, dtype=float), "theta_ddot": np.asarray(tdd, dtype=float),
              "height": height, "height_dot": height_dot, "base": base, "visc": visc, "coul": coul,
              "base_pt": np.ascontiguousarray(base.transpose(1, 0, 2)),
              "visc_pt": np.ascontiguousarray(visc.transpose(1, 0, 2)),
              "coul_tau": np.ascontiguousarray(coul_x[:, 0]), "coul_lam": np.ascontiguousarray(coul_x[:, 1:]), "G": G,
              "slide": slide}
    for a in arrays.values():
        a.setflags(write=False)
    return BatchModel(press=press, names=names, period=float(motion.period), bodies=bodies, **scal, balance_mass=balance_mass,
                      gear_ratio=drive.gear_ratio, motors=drive.motors, standstill=drive.standstill,
                      loss_reference_torque=drive.loss_reference_torque,
                      n_rev=coul.shape[1] - 1, friction_tolerance=press.numerics.friction_tolerance,
                      friction_max_iterations=press.numerics.friction_max_iterations, **arrays)


# ------------------------------------------------------------------------------------------------
# the same model under a moved input: what the build kept, without its RNEA runs


@dataclass(frozen=True)
class ConstantMotion:
    """A constant crank speed (rad/s) and acceleration (rad/s^2) at every grid angle: not a physical motion, a basis
    for sums of models (the model's arrays are linear in 1, theta_dot^2 and theta_ddot at each angle)."""

    speed: float
    accel: float

    def theta_dot(self, theta):
        return np.full_like(np.asarray(theta, dtype=float), self.speed)

    def theta_ddot(self, theta):
        return np.full_like(np.asarray(theta, dtype=float), self.accel)

    @property
    def period(self) -> float:
        return 2.0 * math.pi / self.speed


_MOTION_TERMS: dict[str, tuple[np.ndarray, np.ndarray]] = {}  # this process's motion terms by press and grid (a few presses)


def motion_terms(press: PressData, pm: PressModel | None = None, step_deg: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    """``base_pt``'s terms per unit theta_dot^2 and per unit theta_ddot (each (n, n_feat, 1 + 2 r), SI) of ``press`` on the
    crank grid of ``step_deg``: at a fixed angle the inverse dynamics M(q) a + c(q, v) with v = J theta_dot and a = J
    theta_ddot + J' theta_dot^2 is linear in theta_dot^2 and theta_ddot, and no other ``base`` term depends on the motion
    (the process force, through the slide's direction only, is moved apart: :func:`with_motion`).
    From three models of constant motions without process force, (1, 0), (1, 1) and (2, 0) rad/s, rad/s^2 (disk-cached
    as any model, and kept for this process)."""
    pm = pm if pm is not None else PressModel(press)
    key = json.dumps({**press_key(press), "model": press_key(pm.press), "step_deg": float(step_deg)}, sort_keys=True)
    if key not in _MOTION_TERMS:
        one, acc, two = (build_batch_model(press, ConstantMotion(v, a), NO_PROCESS, step_deg=step_deg, pm=pm).base_pt
                         for v, a in ((1.0, 0.0), (1.0, 1.0), (2.0, 0.0)))
        if len(_MOTION_TERMS) >= 4:
            _MOTION_TERMS.pop(next(iter(_MOTION_TERMS)))
        _MOTION_TERMS[key] = ((two - one) / 3.0, acc - one)
    return _MOTION_TERMS[key]


def _with_arrays(bm: BatchModel, **arrays) -> BatchModel:
    for a in arrays.values():
        a.setflags(write=False)
    if "base_pt" in arrays:
        arrays["base"] = arrays["base_pt"].transpose(1, 0, 2)
    if "visc_pt" in arrays:
        arrays["visc"] = arrays["visc_pt"].transpose(1, 0, 2)
    return replace(bm, **arrays)


def _force_shift(bm: BatchModel, base_pt: np.ndarray, old: ProcessForce, new: ProcessForce, height_dot: np.ndarray) -> np.ndarray:
    """``base_pt`` with its constant feature column moved by the slide-force response times the process force's change
    from ``old`` at the model's slide motion to ``new`` at ``height_dot`` (Eq. 14's force enters nothing else)."""
    df = np.asarray(new(bm.height, height_dot), float) - np.asarray(old(bm.height, bm.height_dot), float)
    out = np.array(base_pt)
    out[:, -1, :] += bm.slide * df[:, None]
    return out


def with_process(bm: BatchModel, old: ProcessForce, new: ProcessForce, pm: PressModel | None = None) -> BatchModel:
    """The batch model ``bm`` (built with the process force ``old``) under the process force ``new``, the same press,
    grid and motion: :func:`build_batch_model` with ``new`` to rounding, from the slide-force response the build kept
    (no RNEA run repeated)."""
    check_contact_in_stroke(pm if pm is not None else PressModel(bm.press), new)
    return _with_arrays(bm, base_pt=_force_shift(bm, bm.base_pt, old, new, bm.height_dot))


def with_slide_force(bm: BatchModel, force) -> BatchModel:
    """The batch model ``bm`` with a slide force ``force`` (N, up on the slide: a scalar or one value per grid angle)
    added to the force it was built with, at every angle whatever the slide's direction (Eq. 14's direction rule left to
    the caller): the basis of the virtual tonnage, which asks what force the measured torque leaves at each angle."""
    f = np.broadcast_to(np.asarray(force, dtype=float), bm.height.shape)
    base_pt = np.array(bm.base_pt)
    base_pt[:, -1, :] += bm.slide * f[:, None]
    return _with_arrays(bm, base_pt=np.ascontiguousarray(base_pt))


def with_motion(bm: BatchModel, process: ProcessForce, theta_dot: np.ndarray, theta_ddot: np.ndarray,
                terms: tuple[np.ndarray, np.ndarray]) -> BatchModel:
    """The batch model ``bm`` (built with the process force ``process``) on another crank speed ``theta_dot`` (rad/s)
    and acceleration ``theta_ddot`` (rad/s^2) at its grid angles of the same signs: :func:`build_batch_model` on that
    motion to rounding, from ``terms`` (:func:`motion_terms` of its press and grid): the inertial terms move along
    theta_dot^2 and theta_ddot, the viscous terms and the slide's speed with theta_dot, the Coulomb terms (signs of
    the joint speeds) not at all. Raises ValueError where a speed changes sign (a model to build anew)."""
    td, tdd = np.asarray(theta_dot, float), np.asarray(theta_ddot, float)
    if td.shape != bm.theta_dot.shape or np.any(np.sign(td) != np.sign(bm.theta_dot)):
        raise ValueError("the moved crank speed changes sign (or length) on the grid: the model's Coulomb terms change; build it")
    per_vv, per_a = terms
    if per_vv.shape != bm.base_pt.shape:
        raise ValueError("the motion terms are of another grid or parameter set than the model's; build it")
    ratio = np.divide(td, bm.theta_dot, out=np.ones_like(td), where=bm.theta_dot != 0.0)
    base_pt = bm.base_pt + (td**2 - bm.theta_dot**2)[:, None, None] * per_vv + (tdd - bm.theta_ddot)[:, None, None] * per_a
    height_dot = bm.height_dot * ratio
    return _with_arrays(bm, base_pt=np.ascontiguousarray(_force_shift(bm, base_pt, process, process, height_dot)),
                        visc_pt=np.ascontiguousarray(bm.visc_pt * ratio[:, None, None]),
                        height_dot=height_dot, theta_dot=td.copy(), theta_ddot=tdd.copy())


# ------------------------------------------------------------------------------------------------
# parameter sets


def parameter_array(bm: BatchModel, sets) -> np.ndarray:
    """Parameter rows (B, D) in ``bm.names`` order from an array, a dict of columns or a list of dicts.

    Names left out take their nominal value; unknown names raise :class:`PressDataError`.
    """
    if isinstance(sets, np.ndarray) or (isinstance(sets, Sequence) and sets and not isinstance(sets[0], Mapping)):
        X = np.atleast_2d(np.asarray(sets, dtype=float))
        if X.ndim != 2 or X.shape[1] != bm.n_params:
            raise PressDataError("batch", "parameter array", X.shape, f"must have {bm.n_params} columns ({', '.join(bm.names)})")
        return _finite(X)
    col = {k: i for i, k in enumerate(bm.names)}
    if isinstance(sets, Mapping):
        lens = {np.size(v) for v in sets.values()}
        B = max(lens) if lens else 1
        X = np.tile(bm.nominal, (B, 1))
        for k, v in sets.items():
            if k not in col:
                raise PressDataError("batch", k, v, f"is not a parameter of this press; known: {', '.join(bm.names)}")
            X[:, col[k]] = v
        return _finite(X)
    X = np.tile(bm.nominal, (len(sets), 1))
    for i, s in enumerate(sets):
        for k, v in s.items():
            if k not in col:
                raise PressDataError("batch", k, v, f"is not a parameter of this press; known: {', '.join(bm.names)}")
            X[i, col[k]] = v
    return _finite(X)


def _finite(X: np.ndarray) -> np.ndarray:
    if not np.all(np.isfinite(X)):
        i, j = np.argwhere(~np.isfinite(X))[0]
        raise PressDataError("batch", f"set {i}: parameter", X[i, j], "must be a finite number")
    return X


def features(bm: BatchModel, X: np.ndarray, invalid: str = "raise", offset: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """Feature rows (B, n_feat) (see :class:`BatchModel`) and a validity mask (B,).

    A set is invalid when a trilaterated COM does not fit its distances (press_data refuses such a
    set); ``invalid="raise"`` raises :class:`PressDataError` naming the first one (row number + ``offset``),
    ``"mask"`` returns it as False in the mask.
    """
    full, ok = _raw_features(bm.bodies, bm.psi, X, invalid, offset, bm.balance_mass)
    return full[:, bm.feature_keep], ok


_ONE_ROW_FITS: dict = {}  # (points, distances) as bytes -> the one-row fit (com (1, 2) m, gnorm (1,) m), read-only


def _trilaterated(points: np.ndarray, distances: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """:func:`geometry.trilaterate` of ``distances`` (B, k), remembered where B is 1: in a batch whose sets share the
    COM's distances (a calibration fits none of them) every model call fits the same row, ~1.2 ms of Python each,
    ~0.3 s of CPU in `calibrate` on one log. The same numbers as a fit anew (the same function on the same row)."""
    if len(distances) != 1:
        return trilaterate(points, distances)
    key = (points.tobytes(), distances.tobytes())
    fit = _ONE_ROW_FITS.get(key)
    if fit is None:
        if len(_ONE_ROW_FITS) >= 256:  # a process that varies the distances one row at a time: bounded
            _ONE_ROW_FITS.clear()
        fit = trilaterate(points, distances)
        for a in fit:
            a.setflags(write=False)
        _ONE_ROW_FITS[key] = fit
    return fit


def _raw_features(bodies, psi: Source, X: np.ndarray, invalid: str, offset: int = 0, balance_mass: float | None = None):
    if invalid not in ("raise", "mask"):
        raise PressDataError("batch", "invalid", invalid, "must be 'raise' or 'mask'")
    B = len(X)
    feats = np.empty((B, 4 * len(bodies) + 2))
    ok = np.ones(B, dtype=bool)
    total_mass = np.zeros(B)
    for i, b in enumerate(bodies):
        m, J = b.mass.take(X), b.inertia.take(X)
        if b.com_kind == "fixed":
            com = np.tile(b.com, (B, 1))
        elif b.com_kind == "line":
            com = b.start + b.distance.take(X)[:, None] * b.direction
        else:
            d = np.column_stack([s.take(X) for s in b.distances])
            # a Sobol (Saltelli) design repeats each base row's distances in most of its D + 2 rows (only
            # 1 in 6 rows is new for the reference press): fit each distinct row once (row-wise exact). A calibration
            # fits none of the distances: its rows are all one, found without np.unique's sort (~0.3 ms a model call)
            if B and (d == d[0]).all():
                d_unique, back = d[:1], np.zeros(B, dtype=np.int64)
            else:
                d_unique, back = np.unique(d, axis=0, return_inverse=True)
            com, gnorm = _trilaterated(b.points, d_unique)
            com, gnorm = com[back.ravel()], gnorm[back.ravel()]
            bad = ~(gnorm <= GRADIENT_TOL)
            if bad.any():
                if invalid == "raise":
                    k = int(np.argmax(bad))
                    raise PressDataError("batch", f"set {k + offset}: bodies.{b.name}.com.distances_m", d[k].tolist(),
                                         "no centre of mass fits these distances (the least-squares trilateration "
                                         "did not converge)")
                ok &= ~bad
                com = np.where(bad[:, None], b.points.mean(axis=0), com)
        c = com - b.origin
        feats[:, 4 * i] = m
        feats[:, 4 * i + 1] = m * c[:, 0]
        feats[:, 4 * i + 2] = m * c[:, 1]
        feats[:, 4 * i + 3] = J + m * (c[:, 0] ** 2 + c[:, 1] ** 2)
        total_mass += m
    feats[:, -2] = psi.take(X) * (total_mass if balance_mass is None else balance_mass)
    feats[:, -1] = 1.0
    return feats, ok


# ------------------------------------------------------------------------------------------------
# evaluation


def _norms(Z: np.ndarray, r: int) -> np.ndarray:
    """Reaction magnitudes (..., r) from the output columns (..., 1 + 2 r)."""
    return np.sqrt(Z[..., 1 : 1 + r] ** 2 + Z[..., 1 + r :] ** 2)


def _no_friction(bm: BatchModel, feats: np.ndarray) -> np.ndarray:
    """Drive torque and reaction columns without any friction, (B, n, 1 + 2 r): one matrix product."""
    F, n, K = bm.base.shape
    return (feats @ bm.base.reshape(F, n * K)).reshape(len(feats), n, K)


def _fixed_point_numpy(bm: BatchModel, Z0, cr, cs, mu_r, mu_s):
    """Friction fixed point over (B, n) points with numpy; returns tau_d (B, n), iterations (B, n), ok."""
    r = bm.n_rev + 1
    Z0 = Z0.transpose(1, 0, 2)  # (n, B, K)
    Zc = Z0 + cr[None, :, None] * bm.visc[0][:, None] + cs[None, :, None] * bm.visc[1][:, None]
    mu = np.empty((len(cr), r))
    mu[:, :-1] = mu_r[:, None]
    mu[:, -1] = mu_s
    N = _norms(Z0, r)
    N_final = np.empty_like(N)
    done = np.zeros(N.shape[:2], dtype=bool)
    iters = np.zeros(N.shape[:2], dtype=np.int64)
    tol = bm.friction_tolerance
    f_prev = g_prev = None
    for it in range(2, bm.friction_max_iterations + 1):
        N_new = _norms(Zc + np.matmul(N * mu, bm.coul), r)
        f = N_new - N
        change = np.max(np.abs(f), axis=2)
        conv = (change <= tol * np.maximum(1.0, np.max(N_new, axis=2))) & ~done
        N_final[conv] = N_new[conv]
        iters[conv] = it
        done |= conv
        if done.all():
            break
        if f_prev is None:
            N = N_new
        else:  # Anderson(1), as the compiled kernel
            d = f - f_prev
            den, num = np.sum(d * d, axis=2), np.sum(f * d, axis=2)
            gam = np.where(den > 0.0, np.clip(num / np.where(den > 0.0, den, 1.0), -GAMMA_MAX, GAMMA_MAX), 0.0)
            N = N_new - gam[..., None] * (N_new - g_prev)
        f_prev, g_prev = f, N_new
    N_final[~done] = N[~done]
    tau = Zc[..., 0] + np.einsum("pbr,pr->pb", N_final * mu, bm.coul[..., 0])
    return tau.T, iters.T, done.T


def _backend(backend: str) -> str:
    if backend == "auto":
        return "numba" if numba is not None else "numpy"
    if backend == "numba" and numba is None:
        raise PressDataError("batch", "backend", backend, "needs the numba package (pip install numba); or use 'numpy'")
    if backend not in ("numba", "numpy"):
        raise PressDataError("batch", "backend", backend, "must be 'auto', 'numba' or 'numpy'")
    return backend


def evaluate_chunk(bm: BatchModel, X: np.ndarray, friction: bool = True, invalid: str = "raise",
                   backend: str = "auto", feats: tuple[np.ndarray, np.ndarray] | None = None,
                   offset: int = 0, motor: bool = True) -> ChunkResult:
    """Crank and motor torque of every set in X (B, D) at every crank angle of the grid.

    Friction is the fixed point of :func:`dynamics.inverse_dynamics`: start without friction, update
    the friction from the reactions until no reaction changes by more than tol * max(1, max N) in a
    pass, then evaluate the torque with the friction of the converged reactions. Unlike
    inverse_dynamics's plain iteration, each pass moves to the Anderson(1) combination of its last two
    maps (a weight per set and angle; ~30 % fewer passes); the converged reactions agree to the
    tolerance. Sets that :func:`features` marks invalid (``invalid="mask"``) give NaN rows. ``backend``:
    "numba" (a compiled loop per point, sets in parallel), "numpy" (vectorised over the chunk), or "auto"
    (numba when it is installed).
    ``feats``: the :func:`features` of X if the caller computed them already; ``offset``: the row number
    of X[0] in the caller's design, for error messages; ``motor``: False leaves Eq. 16 to the caller (the result's
    motor_torque None), which applies it to chunks of its own (calibration.identification.curves).
    """
    X = np.atleast_2d(np.asarray(X, dtype=float))
    feats, ok = features(bm, X, invalid, offset) if feats is None else feats
    B, n = len(X), bm.n_points
    Xv = X[ok]
    if not len(Xv):
        tau, iters = np.empty((0, n)), np.empty((0, n), dtype=np.int64)
    elif friction:
        first, back = _distinct_crank_rows(bm, Xv)
        Xd, fd = (Xv, feats[ok]) if back is None else (Xv[first], feats[ok][first])
        fric = (bm.c_r.take(Xd), bm.c_s.take(Xd), bm.mu_r.take(Xd), bm.mu_s.take(Xd))
        if _backend(backend) == "numba":
            tau, iters, done = fixed_point_numba(bm, fd, *fric)
        else:
            tau, iters, done = _fixed_point_numpy(bm, _no_friction(bm, fd), *fric)
        if not done.all():
            bd, p = np.argwhere(~done)[0]
            b = first[bd]  # its row in Xv
            if not np.isfinite(tau[bd, p]):  # overflowed: no iteration count helps, an absurd number in the data does
                raise SolverError(f"{bm.press.source}: the joint reactions at crank angle {math.degrees(bm.theta[p]):.2f} deg are not finite "
                                  f"numbers for parameter set {offset + np.flatnonzero(ok)[b]} (they overflowed): a value in the press "
                                  "data is far outside what a press can have; check gravity, masses, bearing radii, friction and "
                                  "balance values for a wrong unit or exponent")
            raise SolverError(f"friction/reaction fixed point did not converge at crank angle {math.degrees(bm.theta[p]):.2f} deg "
                              f"for parameter set {offset + np.flatnonzero(ok)[b]} after {bm.friction_max_iterations} iterations; "
                              "raise numerics.friction_max_iterations or check the friction data")
        tau, iters = (tau, iters) if back is None else (tau[back], iters[back])
    else:
        tau, iters = _no_friction(bm, feats[ok])[..., 0], np.ones((len(Xv), n), dtype=np.int64)
    if ok.all():  # the usual case: no copies
        crank, it_out = tau, iters
    else:
        crank = np.full((B, n), np.nan)
        crank[ok] = tau
        it_out = np.zeros((B, n), dtype=np.int64)
        it_out[ok] = iters
    return ChunkResult(crank, motor_torque_eq16(bm, X, crank) if motor else None, it_out)


_ROW_HASH = np.random.default_rng(20250917).integers(1, 2**63, 256, dtype=np.uint64) | np.uint64(1)  # odd multipliers, one a column


def _distinct_crank_rows(bm: BatchModel, X: np.ndarray) -> tuple[np.ndarray, np.ndarray | None]:
    """The rows of X (B, D) whose crank torque is computed: the first of each group of rows that differ only in the drive's
    parameters (gear inertia, efficiency, losses: they act in Eq. 16, after the crank torque), in order, and for each
    row of X the position of its group's row among them (None: every row is computed).

    A Sobol (Saltelli) design has such groups: the rows of a base point with the gear inertia's or the efficiency's column
    taken from the other matrix (2 rows in 30 for the reference press), as has a calibration's difference step in the
    efficiency. Each set's fixed point never mixes with the others' (tests), so its row gives the same bytes."""
    drive = {s.index for s in (bm.gear_inertia, bm.efficiency, bm.load_loss, bm.viscous, bm.coulomb_drag)} - {-1}
    every = np.arange(len(X))
    if not drive or len(X) < 2:
        return every, None
    cols = [i for i in range(X.shape[1]) if i not in drive]
    # grouped by a hash of the rows' bits (np.unique(axis=0) took ~3 ms per 256 rows, 3 % of a Sobol run; this ~0.1 ms),
    # then checked bit for bit: rows whose hashes collide but differ are all computed
    bits = np.ascontiguousarray(X[:, cols]).view(np.uint64)
    with np.errstate(over="ignore"):
        h = (bits * _ROW_HASH[: len(cols)]).sum(axis=1)  # modulo 2**64
    order = np.argsort(h, kind="stable")  # (np.unique's inverse and index cost more than the rest together)
    new = np.empty(len(X), dtype=bool)
    new[0], new[1:] = True, h[order[1:]] != h[order[:-1]]
    if new.all():
        return every, None
    first = np.sort(order[new])  # each group's first row, in the rows' order
    back = np.empty(len(X), dtype=np.int64)
    back[order] = np.cumsum(new) - 1  # group numbers by hash ...
    rank = np.empty(len(first), dtype=np.int64)
    rank[back[first]] = np.arange(len(first))
    back = rank[back]  # ... and by their first row
    if not np.array_equal(bits, bits[first[back]]):
        return every, None
    return first, back


def motor_torque_eq16(bm: BatchModel, X: np.ndarray, crank: np.ndarray) -> np.ndarray:
    """Eq. 16 per motor (N m) of the sets X (B, D) and their crank torques (B, n): :func:`motor.eq16`, (B, n).

    Many sets at once run through :func:`motor.eq16_loops` compiled (numba), the same operations in the same order
    as numpy's eq16 and so the same bytes (tests), without its five temporaries of (B, n) (8 ms of the
    command's serial time per 1024 sets, 0.5 s of a Sobol run at N = 2048); else :func:`motor.eq16` itself.
    """
    J, eta = bm.gear_inertia.take(X), bm.efficiency.take(X)
    k, c = bm.load_loss.take(X) * (1.0 / bm.loss_reference_torque), bm.viscous.take(X)
    d = bm.coulomb_drag.take(X)
    crank = np.asarray(crank, dtype=float)
    losses = bool(np.any(k) or np.any(c) or np.any(d))  # the compiled rows hold the paper's Eq. 16 only
    rows = compiled(eq16_loops) if crank.ndim == 2 and len(crank) >= EQ16_COMPILED_ROWS and not losses else None
    if rows is None:
        return eq16(crank, bm.theta_dot[None], bm.theta_ddot[None], J[:, None], eta[:, None], bm.gear_ratio, bm.motors,
                    motoring_at_zero(bm.standstill), (k[:, None], c[:, None], d[:, None]))
    out = np.empty_like(crank)
    rows(np.ascontiguousarray(crank), bm.theta_dot, bm.theta_ddot, np.ascontiguousarray(J, dtype=float),
         np.ascontiguousarray(eta, dtype=float), float(bm.gear_ratio), bm.motors * bm.gear_ratio, motoring_at_zero(bm.standstill), out)
    return out


EQ16_COMPILED_ROWS = 64  # from this many sets Eq. 16 runs compiled (when numba is installed)


def iter_chunks(bm: BatchModel, sets, chunk_size: int = DEFAULT_CHUNK, friction: bool = True,
                invalid: str = "raise", backend: str = "auto", motor: bool = True) -> Iterator[tuple[slice, ChunkResult]]:
    """Evaluate parameter sets chunk by chunk: yields (rows, result) with at most ``chunk_size`` rows
    (:func:`evaluate_chunk`; ``motor``: False, no Eq. 16).

    Memory: the results of one chunk (3 arrays of chunk_size * n_points), the features of up to
    FEATURE_BLOCK sets (computed ahead in one vectorised pass), and on the numpy path about five work
    arrays of chunk_size * n_points * (2 n_rev + 3) doubles (about 15 MB each for 256 sets, 360 points).
    """
    for rows, x, feats in feature_chunks(bm, sets, chunk_size, invalid):
        yield rows, evaluate_chunk(bm, x, friction, invalid, backend, feats=feats, offset=rows.start, motor=motor)


def feature_chunks(bm: BatchModel, sets, chunk_size: int = DEFAULT_CHUNK,
                   invalid: str = "raise") -> Iterator[tuple[slice, np.ndarray, tuple[np.ndarray, np.ndarray]]]:
    """The parameter sets chunk by chunk with their :func:`features`: yields (rows, X[rows], features of X[rows]) with
    at most ``chunk_size`` rows, the features computed ahead for up to FEATURE_BLOCK sets at once (what
    :func:`iter_chunks` evaluates; a caller that evaluates several models of one press on the same sets reuses them)."""
    X = parameter_array(bm, sets)
    if chunk_size < 1:
        raise PressDataError("batch", "chunk_size", chunk_size, "must be a positive number of parameter sets")
    for block in range(0, len(X), FEATURE_BLOCK):
        Xb = X[block : block + FEATURE_BLOCK]
        fb, okb = features(bm, Xb, invalid, offset=block)
        for start in range(0, len(Xb), chunk_size):
            sl = slice(start, min(start + chunk_size, len(Xb)))
            yield slice(block + sl.start, block + sl.stop), Xb[sl], (fb[sl], okb[sl])


def motor_torques(bm: BatchModel, sets, chunk_size: int = DEFAULT_CHUNK, friction: bool = True,
                  invalid: str = "raise", backend: str = "auto") -> np.ndarray:
    """Motor torque curves (B, n) per motor (N m) of the parameter sets; see :func:`parameter_array`."""
    X = parameter_array(bm, sets)
    out = np.empty((len(X), bm.n_points))
    for rows, res in iter_chunks(bm, X, chunk_size, friction, invalid, backend):
        out[rows] = res.motor_torque
    return out
