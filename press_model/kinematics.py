"""Closed-loop kinematics: positions by Newton on the loop closures, then velocities and accelerations.

The unknowns are the tree coordinates q (one per body). The equations are the two planar components
of every cut joint's closure plus the drive row (crank angle = offset + theta_c). The out-of-plane row
of a revolute cut is identically zero and is never formed.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from press_io.errors import AssemblyError, PressDataError
from .gesv import solve_columns
from .jit import compiled
from .press_data import FRAME

# ``PressModel`` and ``Workspace`` in the annotations are press_model.model's, named not imported: model
# imports this module to check the assembly on construction.

LWA = pin.ReferenceFrame.LOCAL_WORLD_ALIGNED


@dataclass(frozen=True)
class Assembly:
    """Result of the full-turn assembly sweep. Positions are along the guide axis (m), angles in rad."""

    thetas: np.ndarray
    qs: np.ndarray
    s_bdc: float  # slide position at bottom dead centre
    stroke: float  # m
    theta_bdc: float
    theta_tdc: float


@dataclass
class KinState:
    """Kinematic state at one crank angle. q, v, a are tree coordinates (rad or m) and their rates."""

    theta: float
    theta_dot: float
    theta_ddot: float
    q: np.ndarray
    v: np.ndarray
    a: np.ndarray
    height: float  # slide height above BDC, m
    height_dot: float  # m/s (positive up)
    height_ddot: float  # m/s^2


def loop_terms(pm: PressModel, data, q: np.ndarray):
    """Loop residual (2 per cut, m) and the full constraint matrix K = [loop Jacobian; drive row] (m per rad or m).

    Leaves ``data`` with the joint Jacobians and the frame placements at q. The cut points' planar Jacobian rows are
    Pinocchio's LOCAL_WORLD_ALIGNED frame Jacobians (getFrameJacobian: data.J's columns of the joints supporting the
    point, shifted to it) formed from data.J in one compiled loop (:func:`loop_rows`): the same numbers, bit for bit, as
    the per-frame calls (a test checks), which cost a Python round trip each.
    """
    m = pm.model
    pin.computeJointJacobians(m, data, q)
    pin.updateFramePlacements(m, data)
    # each cut point's placement as updateFramePlacement returns it (the same product again): a third cheaper than
    # indexing data.oMf, which copies the placement first
    p = np.array([pin.updateFramePlacement(m, data, f).translation for f in pm.cut_frames])
    res, K = np.empty(pm.n_loop_rows), np.empty((pm.nv, pm.nv))
    (compiled(loop_rows) or loop_rows)(data.J, p, pm.cut_support, pm.crank_row, res, K)
    return res, K


def loop_rows(J, p, support, crank_row, res, K) -> None:
    """Fill ``res`` (m) and ``K`` (loop_terms') from the world-frame joint Jacobians ``J`` (6 x nv, Pinocchio's data.J),
    the cut points' positions ``p`` (first, second per cut; m) and the columns each point's Jacobian has (``support``).

    getFrameJacobian's LOCAL_WORLD_ALIGNED column is v_O - p x omega; the tree is planar (omega = (0, 0, J[5]), p_z = 0),
    so its x, y rows are J[0] - p_y J[5] and J[1] + p_x J[5], the same floating-point operations. Plain loops, for
    :func:`press_model.jit.compiled`."""
    nv = J.shape[1]
    for c in range(res.shape[0] // 2):
        a, b = 2 * c, 2 * c + 1
        res[2 * c] = p[a, 0] - p[b, 0]
        res[2 * c + 1] = p[a, 1] - p[b, 1]
        for k in range(nv):
            xa = J[0, k] - p[a, 1] * J[5, k] if support[a, k] else 0.0
            ya = J[1, k] + p[a, 0] * J[5, k] if support[a, k] else 0.0
            xb = J[0, k] - p[b, 1] * J[5, k] if support[b, k] else 0.0
            yb = J[1, k] + p[b, 0] * J[5, k] if support[b, k] else 0.0
            K[2 * c, k] = xa - xb
            K[2 * c + 1, k] = ya - yb
    for k in range(nv):
        K[nv - 1, k] = crank_row[k]


def crank_body_angle(pm: PressModel, theta_c: float) -> float:
    return pm.press.drive.angle_offset + theta_c


def solve_position(pm: PressModel, ws: Workspace, theta_c: float, q0: np.ndarray | None = None) -> np.ndarray:
    """Tree coordinates q (rad, m) that close every loop at crank angle theta_c (rad).

    Warm-starts from ``q0`` or the workspace's last solution, and leaves the constraint matrix at the returned q in
    ``ws.K_last`` (loop_terms'). Raises :class:`AssemblyError` naming the crank angle and the loop that cannot close.
    """
    q = np.array(q0 if q0 is not None else (ws.q_last if ws.q_last is not None else initial_guess(pm)), dtype=float)
    target = crank_body_angle(pm, theta_c)
    tol = pm.press.numerics.position_tolerance_m
    res_norm = np.inf
    update = compiled(newton_update) or newton_update
    for _ in range(pm.press.numerics.newton_max_iterations):
        res, K = loop_terms(pm, ws.data, q)
        try:
            res_norm, status = update(K, res, pm.crank_row, target, tol, q)
            if status == _NOT_FINITE:  # numpy's solve, as before: it takes non-finite numbers (LAPACK's compiled one refuses them)
                full = np.append(res, pm.crank_row @ q - target)
                step = np.linalg.solve(K, -full)
                big = np.max(np.abs(step))
                q = q + (step if big < 0.5 else step * 0.5 / big)
        except np.linalg.LinAlgError:
            _fail(pm, theta_c, res, "its loop equations are singular there (a dead point)", q)
        if status == _CLOSED:
            ws.q_last, ws.K_last = q, K
            return q
    res, _ = loop_terms(pm, ws.data, q)
    _fail(pm, theta_c, res, f"Newton did not converge (residual {res_norm:.3g} m)", q)


_CLOSED, _STEPPED, _NOT_FINITE = 0, 1, 2


def newton_update(K, res, crank_row, target, tol, q):
    """One Newton step of :func:`solve_position` on q in place: (the largest residual of the loops and the drive, m or rad;
    _CLOSED if it is below ``tol`` and q is left as it is, _STEPPED after the step, _NOT_FINITE with q untouched if a
    number is not finite). The step solves K step = -(res; crank_row q - target) by LAPACK's gesv
    (:func:`press_model.gesv.solve_columns`), damped to 0.5 in its largest entry so Newton cannot jump to the other
    assembly branch. Plain loops, for :func:`press_model.jit.compiled`; raises numpy's LinAlgError where K is singular."""
    n = q.shape[0]
    full = np.empty((n, 1))  # one right-hand side, as a column: solve_columns' one signature
    drive = 0.0
    for k in range(n):
        drive += crank_row[k] * q[k]
    for k in range(n - 1):
        full[k, 0] = res[k]
    full[n - 1, 0] = drive - target
    norm = 0.0
    finite = True
    for k in range(n):
        a = abs(full[k, 0])
        if norm == norm and (a > norm or a != a):  # a NaN, once met, stays: np.max's rule
            norm = a
        finite = finite and math.isfinite(full[k, 0])
        for j in range(n):
            finite = finite and math.isfinite(K[k, j])
    if norm < tol:
        return norm, _CLOSED
    if not finite:
        return norm, _NOT_FINITE
    for k in range(n):
        full[k, 0] = -full[k, 0]
    step = solve_columns(K, full)
    big = 0.0
    for k in range(n):
        big = max(big, abs(step[k, 0]))
    for k in range(n):
        q[k] = q[k] + (step[k, 0] if big < 0.5 else step[k, 0] * 0.5 / big)
    return norm, _STEPPED


def _fail(pm: PressModel, theta_c: float, res: np.ndarray, why: str, q: np.ndarray | None = None):
    """Raise AssemblyError naming the crank angle and the loop(s) that cannot close.

    After a failed Newton solve the gap is spread over every loop that shares a body, so each loop is
    tried on its own (only its closure plus the drive, by a least-squares solve): the loops that cannot
    close even alone are the culprits.
    """
    culprits = _open_loops(pm, theta_c, q) if q is not None else []
    if not culprits and len(res):
        per_cut = [float(np.hypot(*res[2 * i : 2 * i + 2])) for i in range(len(pm.cuts))]
        culprits = [(pm.cuts[int(np.argmax(per_cut))].name, max(per_cut))]
        if len(pm.cuts) > 1 and "dead point" not in why:  # a dead point is a closed loop whose links line up
            why += "; every loop closes on its own, so the loops sharing this joint's bodies conflict"
    parts = []
    for name, gap in culprits:
        j = pm.press.joints[name]
        # a closed loop (at a dead point) has no gap worth naming
        shown = f", gap {gap:.4g} m" if gap > pm.press.numerics.position_tolerance_m else ""
        parts.append(f"the loop closed at joint {name} ({'.'.join(j.first)} to {'.'.join(j.second)}{shown})")
    loop = "; ".join(parts) if parts else "the tree"
    raise AssemblyError(
        f"{pm.press.source}: the linkage does not assemble at crank angle {math.degrees(theta_c) % 360:.2f} deg: "
        f"{loop}: {why}. Check the link lengths and frame points of that loop, or the [assembly] body angles."
    )


def _open_loops(pm: PressModel, theta_c: float, q0: np.ndarray) -> list[tuple[str, float]]:
    """Cut joints whose loop cannot close by itself at theta_c, with the smallest gap reached (m)."""
    data = pm.model.createData()
    target = crank_body_angle(pm, theta_c)
    out = []
    for i, cut in enumerate(pm.cuts):
        rows = [2 * i, 2 * i + 1]
        # a local least-squares solve can stop where the gap is not smallest: keep the best of two starts
        gap = min(_isolated_gap(pm, data, rows, target, start) for start in (q0, initial_guess(pm)))
        if gap > 1e-6:  # well above the least-squares tolerance, well below any real misfit
            out.append((cut.name, gap))
    return out


def _isolated_gap(pm: PressModel, data, rows, target: float, q0) -> float:
    """Smallest gap (m) of one loop closure over the free coordinates, the crank held at ``target``."""
    from scipy.optimize import least_squares

    def fun(q):
        res, _ = loop_terms(pm, data, q)
        return np.append(res[rows], 1e3 * (pm.crank_row @ q - target))

    def jac(q):
        _, K = loop_terms(pm, data, q)
        return np.vstack([K[rows], 1e3 * pm.crank_row])

    q = least_squares(fun, np.array(q0, dtype=float), jac=jac, method="trf", xtol=1e-12, ftol=1e-12, max_nfev=200).x
    res, _ = loop_terms(pm, data, q)
    return float(np.hypot(*res[rows]))


def initial_guess(pm: PressModel) -> np.ndarray:
    """Tree coordinates from the press file's approximate body angles (the branch choice)."""
    q = np.zeros(pm.nv)
    angles = dict(pm.press.assembly_angles)
    angles[FRAME] = 0.0
    for t in pm.tree.joints:
        if t.kind == "revolute":
            q[pm.tree_joint_v[t.name]] = angles.get(t.child, 0.0) - angles.get(t.parent, 0.0)
    return q


def velocity(pm: PressModel, ws: Workspace, q: np.ndarray, theta_dot: float, K: np.ndarray | None = None) -> np.ndarray:
    """Tree velocities (rad/s, m/s) for crank speed theta_dot (rad/s); ``K``: loop_terms' constraint matrix at q where
    the caller has it."""
    if K is None:
        _, K = loop_terms(pm, ws.data, q)
    rhs = np.zeros(pm.nv)
    rhs[-1] = theta_dot
    return linear_solve(K, rhs)


def _bias_acceleration(pm: PressModel, data, q, v) -> np.ndarray:
    """Loop rows of dK/dt * v (m/s^2): the relative classical acceleration of each cut at zero q_ddot."""
    m = pm.model
    pin.forwardKinematics(m, data, q, v, np.zeros(pm.nv))
    pin.updateFramePlacements(m, data)
    out = np.empty(pm.n_loop_rows)
    for i, c in enumerate(pm.cuts):
        out[2 * i : 2 * i + 2] = (
            pin.getFrameClassicalAcceleration(m, data, c.first_frame, LWA).linear[:2]
            - pin.getFrameClassicalAcceleration(m, data, c.second_frame, LWA).linear[:2]
        )
    return out


def acceleration(pm: PressModel, ws: Workspace, q, v, theta_ddot: float, K: np.ndarray | None = None) -> np.ndarray:
    """Tree accelerations (rad/s^2, m/s^2) for crank acceleration theta_ddot (rad/s^2); ``K``: loop_terms' constraint
    matrix at q where the caller has it."""
    bias = _bias_acceleration(pm, ws.data, q, v)
    if K is None:
        _, K = loop_terms(pm, ws.data, q)
    rhs = np.append(-bias, theta_ddot)  # the drive row is linear in q, so it has no bias term
    return linear_solve(K, rhs)


def linear_solve(K: np.ndarray, rhs: np.ndarray) -> np.ndarray:
    """np.linalg.solve(K, rhs) (``rhs`` a vector or a matrix; K's unit over rhs's): LAPACK's gesv compiled
    (:func:`press_model.gesv.solve_columns`; numpy's call costs ten times the arithmetic of a 7 x 7 system) where every
    number is finite, else numpy's (LAPACK's compiled call does not check them). A matrix comes back column-major."""
    solve = compiled(_finite_solve)
    if solve is not None:
        columns = np.ascontiguousarray(rhs if rhs.ndim == 2 else rhs.reshape(-1, 1), dtype=float)
        x, ok = solve(np.ascontiguousarray(K, dtype=float), columns)  # C-contiguous float64: one compiled signature
        if ok:
            return x if rhs.ndim == 2 else x.ravel()
    return np.linalg.solve(K, rhs)


def _finite_solve(K, B):
    """(K^-1 B column-major, True), or (an unset array of B's shape, False) without solving where a number of K or B is
    not finite; B (n, m) (the identity: numpy's inv is the same gesv). For :func:`press_model.jit.compiled`."""
    n, m = K.shape[0], B.shape[1]
    for i in range(n):
        for j in range(n):
            if not math.isfinite(K[i, j]):
                return np.empty((m, n)).T, False
        for j in range(m):
            if not math.isfinite(B[i, j]):
                return np.empty((m, n)).T, False
    return solve_columns(K, B), True


def slide_position(pm: PressModel, data, q) -> float:
    """Slide point position along the guide axis (m), absolute."""
    pin.framesForwardKinematics(pm.model, data, q)
    return float(pm.axis[:2] @ data.oMf[pm.slide_frame].translation[:2])


def slide_motion(pm: PressModel, data, q, v, a) -> tuple[float, float, float]:
    """Slide position, velocity and acceleration along the guide axis (m, m/s, m/s^2)."""
    m = pm.model
    pin.forwardKinematics(m, data, q, v, a)
    pin.updateFramePlacements(m, data)
    pos = pm.axis @ data.oMf[pm.slide_frame].translation
    vel = pm.axis @ pin.getFrameVelocity(m, data, pm.slide_frame, LWA).linear
    acc = pm.axis @ pin.getFrameClassicalAcceleration(m, data, pm.slide_frame, LWA).linear
    return float(pos), float(vel), float(acc)


def state_at(pm: PressModel, ws: Workspace, theta: float, theta_dot: float, theta_ddot: float, q0=None) -> KinState:
    """Full kinematic state at crank angle theta (rad) with crank speed and acceleration."""
    if q0 is None:
        q0 = warm_start(pm, theta) if ws.q_last is None else ws.q_last
    q = solve_position(pm, ws, theta, q0)
    v = velocity(pm, ws, q, theta_dot, ws.K_last)  # the position solve's last constraint matrix is the one at q
    a = acceleration(pm, ws, q, v, theta_ddot, ws.K_last)
    s, sd, sdd = slide_motion(pm, ws.data, q, v, a)
    return KinState(theta, theta_dot, theta_ddot, q, v, a, s - pm.assembly.s_bdc, sd, sdd)


def warm_start(pm: PressModel, theta: float) -> np.ndarray:
    """Configuration of the assembly sweep nearest to crank angle theta: a start on the right branch."""
    asm = pm.assembly
    k = int(np.argmin(np.abs(np.angle(np.exp(1j * (asm.thetas - theta))))))
    return asm.qs[k]


def assembly_sweep(pm: PressModel, ws: Workspace) -> Assembly:
    """Solve the linkage over a whole crank turn and locate BDC and TDC.

    Raises :class:`AssemblyError` if a loop cannot close, if the mechanism passes a dead point, or if it
    does not return to its starting configuration (a change of assembly branch).
    """
    from scipy.optimize import minimize_scalar

    press = pm.press
    start = press.assembly_crank_angle
    n = max(8, int(math.ceil(2 * math.pi / math.radians(press.numerics.assembly_check_step_deg))))
    thetas = start + np.arange(n + 1) * (2 * math.pi / n)
    q = solve_position(pm, ws, start, initial_guess(pm))
    qs, dets, conds = [], [], []
    for th in thetas:
        q = solve_position(pm, ws, th, q)
        _, K = loop_terms(pm, ws.data, q)
        sv = np.linalg.svd(K, compute_uv=False)
        conds.append(sv[0] / sv[-1] if sv[-1] > 0 else np.inf)
        dets.append(np.linalg.det(K))
        qs.append(q.copy())
    qs = np.array(qs)
    dets = np.array(dets)
    for k in range(1, len(thetas)):
        if np.sign(dets[k]) != np.sign(dets[0]) or conds[k] > 1e9:
            res, _ = loop_terms(pm, ws.data, qs[k])
            _fail(pm, thetas[k], res, "the mechanism passes a dead point (its constraint matrix turns singular) and may change branch")
    wrap = qs[-1] - qs[0]
    diff = np.where(_revolute_mask(pm), np.angle(np.exp(1j * wrap)), wrap)
    if np.max(np.abs(diff)) > 1e-6:
        res, _ = loop_terms(pm, ws.data, qs[-1])
        _fail(pm, thetas[-1], res, "after one crank turn the linkage does not return to its starting configuration (branch change)")
    thetas, qs = thetas[:-1], qs[:-1]
    s = np.array([slide_position(pm, ws.data, qk) for qk in qs])

    def s_at(th):
        k = int(np.argmin(np.abs(np.angle(np.exp(1j * (thetas - th))))))
        return slide_position(pm, ws.data, solve_position(pm, ws, th, qs[k]))

    h = 2 * math.pi / n
    k_min, k_max = int(np.argmin(s)), int(np.argmax(s))
    bdc = minimize_scalar(s_at, bounds=(thetas[k_min] - h, thetas[k_min] + h), method="bounded", options={"xatol": 1e-10})
    tdc = minimize_scalar(lambda th: -s_at(th), bounds=(thetas[k_max] - h, thetas[k_max] + h), method="bounded", options={"xatol": 1e-10})
    s_bdc, s_tdc = float(bdc.fun), float(-tdc.fun)
    ws.q_last = None
    return Assembly(thetas, qs, s_bdc, s_tdc - s_bdc, float(bdc.x) % (2 * math.pi), float(tdc.x) % (2 * math.pi))


def height_at(pm: PressModel, ws: Workspace, theta: float) -> float:
    """Slide height above BDC (m) at crank angle theta (rad, any turn: the height is periodic)."""
    theta = theta % (2 * math.pi)
    return slide_position(pm, ws.data, solve_position(pm, ws, theta, warm_start(pm, theta))) - pm.assembly.s_bdc


def height_crossing(pm: PressModel, ws: Workspace, height: float, lo: float, hi: float) -> float:
    """Crank angle (rad) in [lo, hi] where the slide height above BDC equals ``height`` (m).

    The height minus ``height`` must change sign across the bracket (one crossing on a half stroke).
    """
    from scipy.optimize import brentq

    root = brentq(lambda t: height_at(pm, ws, t) - height, lo, hi, xtol=1e-13, rtol=1e-14, maxiter=200)
    ws.q_last = None
    return float(root)


def downstroke_crossing(pm: PressModel, ws: Workspace, height: float) -> float:
    """Crank angle (rad, in [0, 2 pi)) where the slide passes ``height`` (m above BDC) moving down.

    The downstroke runs from TDC to BDC in increasing crank angle; raises :class:`PressDataError` if the
    height is not inside the stroke.
    """
    asm = pm.assembly
    if not 0.0 < height < asm.stroke:
        raise PressDataError(pm.press.source, "height", height, f"must lie inside the stroke, 0 < H < {asm.stroke:.4f} m")
    start = asm.theta_tdc
    span = (asm.theta_bdc - asm.theta_tdc) % (2 * math.pi)
    th = start + np.linspace(0.0, span, 181)
    h = np.array([height_at(pm, ws, float(t)) for t in th]) - height
    k = int(np.flatnonzero(h <= 0.0)[0])  # H falls monotonically from TDC to BDC
    return height_crossing(pm, ws, height, th[k - 1], th[k]) % (2 * math.pi)


def grid_heights(pm: PressModel, theta) -> tuple[np.ndarray, np.ndarray]:
    """(slide height H in m, its rate per unit crank speed dH/dtheta in m/rad) at each crank angle of ``theta`` (rad):
    the two arguments of a process force (Eq. 14) along a turn, whatever the crank speed (its sign is the rate's)."""
    ws = pm.workspace()
    ws.q_last = None
    th = np.asarray(theta, dtype=float)
    h, hd = np.empty(th.size), np.empty(th.size)
    for p, a in enumerate(th):
        st = state_at(pm, ws, float(a), 1.0, 0.0)
        h[p], hd[p] = st.height, st.height_dot
    return h, hd


def force_step_angles(pm: PressModel, process) -> list[float]:
    """Crank angles (rad) where a process force (Eq. 14) switches: die contact (on) and BDC (off, the slide
    turns up); none for a job without a process force."""
    if max(process.forces) <= 0.0 or process.contact_height <= 0.0:
        return []
    check_contact_in_stroke(pm, process)
    return [downstroke_crossing(pm, pm.workspace(), process.contact_height), pm.assembly.theta_bdc]


def check_contact_in_stroke(pm: PressModel, process) -> None:
    """Refuse a process force whose die contact lies above the press's stroke (the force would act over the whole
    downstroke), naming the job file's field rather than the press: the job was written for another press."""
    if max(process.forces) > 0.0 and not process.contact_height < pm.assembly.stroke:
        raise PressDataError(process.source, "process.contact_height_m", process.contact_height,
                             f"must lie inside the stroke of the press {pm.press.name}, 0 < H < {pm.assembly.stroke:.4f} m "
                             "(die contact on the way down); check the job's [process] against this press")


def _revolute_mask(pm: PressModel) -> np.ndarray:
    mask = np.zeros(pm.nv, dtype=bool)
    for t in pm.tree.joints:
        mask[pm.tree_joint_v[t.name]] = t.kind == "revolute"
    return mask
