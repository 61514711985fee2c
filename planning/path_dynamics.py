"""The press's dynamics along the crank-angle path, precomputed once per plan on the planning grid.

The mechanism has one degree of freedom, so the toppra path parameter s is the crank angle theta_c (rad)
itself, x = theta_dot^2 and u = theta_ddot. At every grid knot the kinematics are solved once
per press geometry (:func:`press_model.kinematic_tables.knot_kinematics`, kept on disk), and the model's RNEA terms are taken at three states,
(theta_dot, theta_ddot) = (0, 0), (0, 1) and (1, 0): the tree accelerations are K^-1 e theta_ddot plus a
bias quadratic in theta_dot, so every RNEA torque and transmitted joint force is

    g + theta_ddot * (acc - g) + theta_dot^2 * (vel - g)

exactly. Without friction the crank torque is then the affine path dynamics of toppra,

    tau(s) = m(s) u + c(s) x + g(s) + tau_proc(s),

and :func:`full_crank_torque` runs the friction/reaction fixed point of
:func:`press_model.dynamics.inverse_dynamics` (same equations, same tolerance) vectorised over all knots
for any (theta_dot, theta_ddot) profile, which is what makes the friction fixed point and the thermal loop
of the planner cheap. A test checks both against the per-point Pinocchio path.

Model/Data split: :class:`PathDynamics` is immutable after :func:`build_path_dynamics`; its one derived field,
:attr:`PathDynamics.friction_maps`, is built on first use.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from functools import cached_property

import numpy as np

from press_io.errors import SolverError
from press_model.dynamics import StatePrep, slide_loads
from press_model.forces import NO_PROCESS, ProcessForce
from press_model.jit import compiled
from press_model.kinematic_tables import knot_kinematics
from press_model.model import PressModel, Workspace

STANDS = 1.0e-6  # m/rad: below this |dH/dtheta| the slide stands at a knot (BDC; planning.evaluation.DH_STILL)


@dataclass(frozen=True, eq=False)
class PathDynamics:
    """Per-knot constants of the press along s = theta_c (arrays over the n knots; SI units).

    ``m, c, g, proc``: the frictionless crank torque tau = m u + c x + g + proc (N m per rad/s^2, per
    (rad/s)^2, N m, N m); ``proc`` is the process force's share with the slide moving in the forward
    (theta_dot > 0) direction. ``height`` (m above BDC) and ``dh`` = dH/dtheta (m/rad).
    """

    pm: PressModel
    theta: np.ndarray  # rad, knots (strictly increasing)
    height: np.ndarray  # m
    dh: np.ndarray  # m/rad
    process_force: np.ndarray  # N, up on the slide, forward running
    balance_force: np.ndarray  # N
    m: np.ndarray
    c: np.ndarray
    g: np.ndarray
    proc: np.ndarray
    # terms of the vectorised friction fixed point
    A_inv: np.ndarray  # (n, nv, nv)
    u_s: np.ndarray  # (n, nv)
    tau_terms: np.ndarray  # (3, n, nv): RNEA torque at rest, per unit theta_ddot, per unit theta_dot^2
    P_terms: np.ndarray  # (3, n, n_tree, 2): transmitted tree-joint forces, same split
    w1: np.ndarray  # (n, n_rev): relative joint speeds per unit theta_dot
    q: np.ndarray  # (n, nv) tree coordinates
    # per knot (q, v1, a1, ab, height): the knot kinematics, reused by a press of the same geometry (``like``)
    kinematics: list = field(default_factory=list, repr=False)
    # None: the crank turns forward. A number (kg m^2, 2 J_gear u^2): a swing the crank turns BACK through, planned as its
    # time reversal (:func:`reversed_swing`): every torque negated so that Eq. 16 of the forward-running plan gives minus
    # the real motor torque (its bracket tau + J_gear u^2 theta_ddot is odd once the gear's term is carried over)
    reversed_inertia: float | None = None

    @property
    def n(self) -> int:
        return len(self.theta)

    @cached_property
    def friction_maps(self) -> tuple[np.ndarray, np.ndarray]:
        """Per knot, the solve's response to unit friction inputs (X_phi, (n, nv, n_phi)) and the normal vectors'
        (VX, (n, n_normals, 2, n_phi)); they depend on the geometry only, so they are built once per path dynamics."""
        return _friction_maps(self)

    @cached_property
    def fixed_point_maps(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """What every call of :func:`full_crank_torques` on these knots shares, whatever the profile and friction: the
        rows of the normals (:func:`_normal_rows`), their x then y components' order, :attr:`friction_maps`' VX in that
        order ((n, 2 n_normals, n_phi), contiguous) and the process force's share of the drive torque per newton (N m / N).
        Built once per path dynamics: copying VX into that order cost each call more than its fixed point (the planner
        calls it ~1,200 times a `reproduce`)."""
        rows = _normal_rows(self.pm)
        k = len(rows)
        xy = np.r_[0:2 * k:2, 1:2 * k:2]
        VXf = np.ascontiguousarray(self.friction_maps[1].reshape(self.n, 2 * k, -1)[:, xy])
        proc_gain = -np.einsum("nj,nj->n", self.A_inv[:, 0, :], self.u_s)
        return rows, xy, VXf, proc_gain


def build_path_dynamics(pm: PressModel, theta: np.ndarray, process: ProcessForce, contact_index: int | None = None,
                        like: PathDynamics | None = None) -> PathDynamics:
    """Precompute :class:`PathDynamics` on the knots ``theta`` (rad, increasing).

    ``contact_index``: the knot at die contact; the force steps there, and it is evaluated on the forming
    side (force on), which is the side that limits. ``like``: path dynamics of a press with the same
    geometry on the same knots (only masses, inertias, balance, drive or friction differ, as at the corners
    of a calibration box): its knot kinematics are reused instead of solved again; without it they are read from the
    disk cache by the press geometry and the knots (:func:`press_model.kinematic_tables.knot_kinematics`), solved there
    the first time.
    """
    ws = Workspace(pm)
    loads0 = slide_loads(pm, NO_PROCESS)
    nv = pm.nv
    out = {k: [] for k in ("height", "dh", "proc_force", "bal", "A_inv", "u_s", "tau", "P", "w1", "q")}
    # the knots' kinematics depend on the geometry alone: solved once per press geometry and knots, kept on disk
    kin = like.kinematics if like is not None and like.kinematics else knot_kinematics(pm, np.asarray(theta, float))
    for k, (q, v1, a1, ab, height) in enumerate(kin):
        st = _Kin(height)
        p_rest = StatePrep(pm, ws, q, np.zeros(nv), np.zeros(nv), st.height, 0.0, loads0)
        p_acc = p_rest.at(a1)
        p_vel = p_rest.moving(v1, ab)  # same q: the loop Jacobian and the solve matrix are p_rest's
        taus = [p.base_rhs + p.u_s * p.f_ext for p in (p_rest, p_acc, p_vel)]
        Ps = [p.P for p in (p_rest, p_acc, p_vel)]
        dh = float(p_rest.u_s @ v1)  # dH/dtheta: slide speed along the guide per unit crank speed
        h = st.height
        if contact_index is not None and k == contact_index:
            h = min(h, process.contact_height)  # round-off must not switch the force off at its own step
        fproc = float(process(h, -1.0 if dh < 0 else (1.0 if dh > 0 else 0.0)))
        out["height"].append(st.height)
        out["dh"].append(dh)
        out["proc_force"].append(fproc)
        out["bal"].append(p_rest.balance)
        out["A_inv"].append(p_rest.A_inv)
        out["u_s"].append(p_rest.u_s)
        out["tau"].append([taus[0], taus[1] - taus[0], taus[2] - taus[0]])
        out["P"].append([Ps[0], Ps[1] - Ps[0], Ps[2] - Ps[0]])
        out["w1"].append(pm.joint_rows @ v1)
        out["q"].append(q.copy())
    A_inv = np.array(out["A_inv"])
    u_s = np.array(out["u_s"])
    tau = np.transpose(np.array(out["tau"]), (1, 0, 2))
    P = np.transpose(np.array(out["P"]), (1, 0, 2, 3))
    bal = np.array(out["bal"])
    fproc = np.array(out["proc_force"])
    row0 = A_inv[:, 0, :]  # the drive torque is the first unknown of the solve
    m = np.einsum("nj,nj->n", row0, tau[1])
    c = np.einsum("nj,nj->n", row0, tau[2])
    g = np.einsum("nj,nj->n", row0, tau[0] - u_s * bal[:, None])
    proc = -np.einsum("nj,nj->n", row0, u_s) * fproc
    pd = PathDynamics(pm, np.asarray(theta, float), np.array(out["height"]), np.array(out["dh"]), fproc, bal,
                      m, c, g, proc, A_inv, u_s, tau, P, np.array(out["w1"]), np.array(out["q"]), list(kin))
    return pd


@dataclass(frozen=True)
class _Kin:
    height: float


def frictionless_crank_torque(pd: PathDynamics, theta_dot, theta_ddot) -> np.ndarray:
    """tau = m u + c x + g + proc at every knot (N m at the crank), forward running, no friction."""
    td = np.asarray(theta_dot, float)
    return pd.m * np.asarray(theta_ddot, float) + pd.c * td * td + pd.g + pd.proc


@dataclass
class FullResult:
    """Full-model evaluation along a profile at the knots (arrays over knots)."""

    crank_torque: np.ndarray  # N m, with friction
    friction_torque: np.ndarray  # N m: crank_torque minus the frictionless affine part
    joint_reactions: np.ndarray  # (n, n_rev) N
    guide_normal: np.ndarray  # N


def full_crank_torque(pd: PathDynamics, theta_dot, theta_ddot, process_on: np.ndarray | None = None, friction=None,
                      guide_sign: np.ndarray | None = None) -> FullResult:
    """Crank torque with the friction/reaction fixed point (Eqs. 10-12) at every knot (N m): :func:`full_crank_torques` for
    the one friction ``friction`` (None: the press's)."""
    return full_crank_torques(pd, theta_dot, theta_ddot, [friction], process_on, guide_sign)[0]


def full_crank_torques(pd: PathDynamics, theta_dot, theta_ddot, frictions, process_on: np.ndarray | None = None,
                       guide_sign: np.ndarray | None = None) -> list[FullResult]:
    """Crank torque with the friction/reaction fixed point (Eqs. 10-12) at every knot (N m).

    Same equations and convergence rule as :func:`press_model.dynamics.inverse_dynamics`, vectorised
    over the knots. ``process_on`` (bool per knot) defaults to the forward-running process force;
    ``friction`` (a :class:`press_model.press_data.Friction`) replaces the press's friction data (the
    friction parameters do not enter the precomputed terms). ``guide_sign`` (per knot, +1 / -1, 0 = from
    the speed) sets the direction of the guide friction where the slide stands at the knot (TDC, BDC).

    At a prescribed motion the solve's unknowns (drive torque, loop forces) and so the reaction vectors are
    affine in the friction inputs phi (joint torques, guide force), and phi is affine in the reaction
    magnitudes n (Eqs. 10, 12): the fixed point n <- |W0 + W n| runs on maps built once per call, with the
    friction-independent parts of W (:attr:`PathDynamics.friction_maps`) built once per path dynamics.

    ``frictions``: a list of friction data (None: the press's); returns one :class:`FullResult` per entry. Everything up
    to the friction inputs is shared, and the fixed points run side by side, each stopping at the iteration it would
    stop at alone (the same values as one call per friction).
    """
    pm = pd.pm
    rm = pm.reaction_map
    td = np.asarray(theta_dot, float)
    tdd = np.asarray(theta_ddot, float)
    x = td * td
    fproc = pd.process_force if process_on is None else np.where(process_on, pd.process_force, 0.0)
    f_ext = pd.balance_force + fproc
    tau0 = pd.tau_terms[0] + tdd[:, None] * pd.tau_terms[1] + x[:, None] * pd.tau_terms[2]
    P = pd.P_terms[0] + tdd[:, None, None] * pd.P_terms[1] + x[:, None, None] * pd.P_terms[2]
    axis2 = pm.axis[:2]
    sol0 = np.einsum("nij,nj->ni", pd.A_inv, tau0 - pd.u_s * f_ext[:, None])
    lam0 = sol0[:, 1:].reshape(len(td), -1, 2)
    R0 = P - np.einsum("tc,ncd->ntd", rm.cut_coef, lam0) - (rm.slide_coef[None, :, None] * f_ext[:, None, None]) * axis2[None, None, :]
    rg = R0[:, rm.guide_tree]
    guide0 = rg - (rg @ axis2)[:, None] * axis2[None, :]
    rows, xy, VXf, proc_gain = pd.fixed_point_maps
    V0 = np.concatenate([R0, lam0, guide0[:, None, :]], axis=1)[:, rows]  # (n, n_normals, 2)
    X_phi = pd.friction_maps[0]
    # friction inputs from the normals: phi = phi_v + D n
    speeds = np.concatenate([td[:, None] * pd.w1, (td * pd.dh)[:, None]], axis=1)
    if pd.reversed_inertia is not None:  # the time-reversed swing: the joints and the guide move the other way
        speeds = -speeds
    sgn = np.sign(speeds)
    if guide_sign is not None:
        sgn[:, -1] = np.where(np.asarray(guide_sign) != 0, np.sign(guide_sign), sgn[:, -1])
    frs = [pm.press.friction if f is None else f for f in frictions]
    mu = np.array([np.append(fr.mu_r * pm.bearing_radii, fr.mu_s) for fr in frs])[:, None, :]  # (F, 1, j)
    visc = np.array([np.append(np.full(len(pm.bearing_radii), fr.c_r), fr.c_s) for fr in frs])[:, None, :]
    phi_v = -visc * np.abs(speeds) * sgn  # (F, n, j)
    D = -mu * sgn
    n, k = len(td), V0.shape[1]
    # the rows of the reaction vectors' x components first, then their y components (``xy``, VXf): |.| of contiguous halves
    W0 = V0.reshape(n, 2 * k)[:, xy] + (VXf @ phi_v[..., None])[..., 0]  # (F, n, 2k)
    W = VXf * D[:, :, None, :]  # (F, n, 2k, j)
    normals = np.broadcast_to(np.sqrt(V0[..., 0] ** 2 + V0[..., 1] ** 2), (len(frs), n, k)).copy()
    tol = pm.press.numerics.friction_tolerance
    loop = compiled(_normals_fixed_point)
    if loop is not None:  # the same iteration per knot, compiled: numpy's batched 2k x k products cost 4x its loop
        change = np.empty(normals.shape[:2])
        scale = np.empty(normals.shape[:2])
        active = loop(np.ascontiguousarray(W0), np.ascontiguousarray(W), normals, tol, pm.press.numerics.friction_max_iterations,
                      change, scale)
    else:
        active, change, scale = _normals_numpy(W0, W, normals, tol, pm.press.numerics.friction_max_iterations)
    if active.any():
        f = int(np.flatnonzero(active)[0])
        bad = int(np.argmax(change[f] / scale[f]))
        raise SolverError(f"friction/reaction fixed point did not converge at crank angle {math.degrees(pd.theta[bad]) % 360:.2f} deg; "
                          "raise numerics.friction_max_iterations or check the friction data")
    phi = phi_v + D * normals  # friction at the converged reactions
    tau_d = sol0[:, 0] - np.einsum("nj,fnj->fn", X_phi[:, 0, :], phi)
    proc = proc_gain * fproc
    if pd.reversed_inertia is not None:  # the time-reversed swing: the real crank torque above, the plan's is its mirror
        tau_d = -tau_d - pd.reversed_inertia * tdd
        proc = -proc
    affine = pd.m * tdd + pd.c * x + pd.g + proc
    return [FullResult(t, t - affine, nm[:, :-1], nm[:, -1]) for t, nm in zip(tau_d, normals)]


def _normals_numpy(W0, W, normals, tol: float, max_iterations: int):
    """The fixed point n <- |W0 + W n| of :func:`full_crank_torques` in place on ``normals`` (F, n, k), each friction's
    stopping at the first iteration where every knot's normals change by at most ``tol`` x max(1, their largest).
    Returns (per friction: not converged, the last iteration's change and scale per friction and knot)."""
    k = normals.shape[2]
    active = np.ones(len(normals), bool)  # the frictions whose fixed point has not yet stopped
    for _ in range(max_iterations):
        y = W0 + (W @ normals[..., None])[..., 0]
        y *= y
        new = np.sqrt(y[..., :k] + y[..., k:])  # no overflow to guard against (np.hypot's scaling costs 3x here)
        change = np.abs(new - normals).max(axis=2)
        scale = np.maximum(1.0, new.max(axis=2))
        normals[active] = new[active]
        active &= ~np.all(change <= tol * scale, axis=1)
        if not active.any():
            break
    return active, change, scale


def _normals_fixed_point(W0, W, normals, tol, max_iterations, change, scale):
    """:func:`_normals_numpy` as loops for :func:`press_model.jit.compiled` (the same iterations per friction, each knot's
    2k x k product summed in order): ``change`` and ``scale`` (F, n) are filled with the last iteration's. Returns per
    friction whether it did not converge."""
    F, n, k2 = W0.shape
    k = k2 // 2
    active = np.ones(F, np.bool_)
    new = np.empty(k)
    for f in range(F):
        for _ in range(max_iterations):
            done = True
            for i in range(n):
                big = 0.0
                for r in range(k):
                    sx = 0.0
                    sy = 0.0
                    for c in range(k):
                        sx += W[f, i, r, c] * normals[f, i, c]
                        sy += W[f, i, r + k, c] * normals[f, i, c]
                    sx += W0[f, i, r]  # the product first, as numpy's W0 + W @ n
                    sy += W0[f, i, r + k]
                    new[r] = math.sqrt(sx * sx + sy * sy)
                    big = max(big, new[r])
                ch = 0.0
                for r in range(k):
                    ch = max(ch, abs(new[r] - normals[f, i, r]))
                    normals[f, i, r] = new[r]
                change[f, i] = ch
                scale[f, i] = max(1.0, big)
                if ch > tol * scale[f, i]:
                    done = False
            if done:
                active[f] = False
                break
    return active


def reversed_swing(pd: PathDynamics, process: ProcessForce, contact_index: int | None, gear_inertia: float,
                   gear_ratio: float) -> PathDynamics:
    """The path dynamics of a swing the crank turns BACK through the knots of ``pd``, in its time reversal.

    The crank runs theta(t) = theta_f(T - t) for a forward-running profile theta_f on the same knots: the speed changes
    sign, the acceleration does not, so the rigid-body torque m u + c x + g is the same at the mirrored instant; the
    friction opposes the real (backward) motion, and the process force acts where the slide, coming down the other side
    of BDC, is below die contact (``contact_index``, the knot of die contact on that side; the force steps on there).
    Returned in the planner's forward-running form: every crank torque negated and the gear's 2 J_gear u^2 theta_ddot
    taken off, so that the bracket B' = -B of Eq. 16 and the forward-running motor torque is minus the real one (Eq. 16
    is odd in (B, theta_dot)): |T_m| and T_m^2, the limits and the thermal RMS, are the real ones. ``gear_inertia`` in
    kg m^2 (J_gear of the drive), ``gear_ratio`` u.
    """
    import dataclasses

    h = pd.height.copy()
    if contact_index is not None:
        h[contact_index] = min(h[contact_index], process.contact_height)  # round-off must not switch the force off at its own step
    dh = -pd.dh  # the slide's real speed per unit of the plan's (forward-running) crank speed; pd.dh stays H's slope
    moving = np.where(np.abs(dh) < STANDS, 0.0, np.sign(dh))  # the slide stands at BDC: the force acts there
    fproc = np.array([float(process(hk, d)) for hk, d in zip(h, moving)])
    row0 = pd.A_inv[:, 0, :]
    proc = -np.einsum("nj,nj->n", row0, pd.u_s) * fproc
    j2 = 2.0 * gear_inertia * gear_ratio * gear_ratio
    return dataclasses.replace(pd, process_force=fproc, m=-pd.m - j2, c=-pd.c, g=-pd.g, proc=-proc, reversed_inertia=j2)


def _normal_rows(pm: PressModel) -> np.ndarray:
    """Rows of [tree-joint forces; cut-joint forces; guide transverse force] whose magnitudes are the normals
    (revolute joints in press-file order, then the guide)."""
    rm = pm.reaction_map
    n_tree, n_cut = len(pm.tree_names), len(pm.cuts)
    return np.append(np.where(rm.revolute_tree >= 0, rm.revolute_tree, n_tree + rm.revolute_cut), n_tree + n_cut)


def _friction_maps(pd: PathDynamics):
    """The value of :attr:`PathDynamics.friction_maps` (built once per path dynamics)."""
    pm = pd.pm
    rm = pm.reaction_map
    n = pd.n
    n_phi = len(pm.bearing_radii) + 1
    Phi = np.empty((n, pm.nv, n_phi))
    Phi[:, :, :-1] = pm.joint_rows.T[None]
    Phi[:, :, -1] = pd.u_s
    X_phi = np.einsum("nij,njk->nik", pd.A_inv, Phi)  # sol = sol0 - X_phi phi
    lam_phi = -X_phi[:, 1:, :].reshape(n, -1, 2, n_phi)
    R_phi = -np.einsum("tc,ncdk->ntdk", rm.cut_coef, lam_phi)
    axis2 = pm.axis[:2]
    proj = np.eye(2) - np.outer(axis2, axis2)
    guide = np.einsum("de,nek->ndk", proj, R_phi[:, rm.guide_tree])
    VX = np.concatenate([R_phi, lam_phi, guide[:, None]], axis=1)[:, _normal_rows(pm)]
    return X_phi, VX
