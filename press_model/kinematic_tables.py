"""Per-point kinematics on crank grids, computed once per press geometry and kept on disk.

A synthetic log (:mod:`calibration.synthetic.experiment`) evaluates the per-point Pinocchio model on a fine crank grid
for every new truth, and its force channel needs the slide's heights and the force steps of the job's process. The
positions, velocities and accelerations at fixed crank angles and speeds, the heights and the die-contact angle depend
on the linkage's geometry only, not on the truth's masses, inertias, friction or drive: they are kept in the
content-keyed disk cache (:func:`press_model.disk_cache.cached_arrays`) under a key of that geometry as the parsed
model holds it (:func:`geometry_key`), so another truth on the same press reuses them and only the inverse dynamics
runs again. The cached values are the per-point solves' own (the same operations in the same order), bit for bit.
`calibrate` reads a job's force steps and its grid's slide heights from here too (identification/run.py, log_problem),
and every batch-model build its grid's positions (:func:`grid_positions`, press_model/batch.py), and every plan's path
dynamics its knots' kinematics (:func:`knot_kinematics`, planning/path_dynamics.py).
"""
from __future__ import annotations

import hashlib
import math

import numpy as np

from .disk_cache import array_digest, cached_arrays, code_key
from .kinematics import KinState, acceleration, force_step_angles, grid_heights, solve_position, state_at, velocity, warm_start
from .model import PressModel, Workspace

_STATE_ARRAYS = ("q", "v", "a", "height", "height_dot", "height_ddot")
_KNOT_ARRAYS = ("q", "v1", "a1", "ab", "height")


def geometry_key(pm: PressModel) -> dict:
    """What the kinematics of ``pm`` depends on, read from the built model: every joint's and frame's placement and
    parent, the loop cuts, the drive row and offset, the guide axis, the Newton settings and the assembly sweep (the
    warm starts and BDC); with the code and the library versions (:func:`press_model.disk_cache.code_key`). Masses,
    inertias, friction, balance and drive constants are not in it. Returns a JSON-able dict."""
    m, h = pm.model, hashlib.sha256()
    for i in range(m.njoints):
        h.update(f"{m.names[i]}|{m.joints[i].shortname()}|{m.parents[i]}|".encode())
        h.update(np.ascontiguousarray(m.jointPlacements[i].homogeneous, dtype=float).tobytes())
    for f in m.frames:
        h.update(f"{f.name}|{f.parentJoint}|".encode())
        h.update(np.ascontiguousarray(f.placement.homogeneous, dtype=float).tobytes())
    asm, num = pm.assembly, pm.press.numerics
    for a in (pm.crank_row, pm.axis, asm.thetas, asm.qs):
        h.update(np.ascontiguousarray(a, dtype=float).tobytes())
    scalars = [pm.slide_frame, [(c.first_frame, c.second_frame) for c in pm.cuts], repr(pm.press.drive.angle_offset),
               repr(num.position_tolerance_m), num.newton_max_iterations, sorted(dict(pm.press.assembly_angles).items()),
               [repr(x) for x in (asm.s_bdc, asm.stroke, asm.theta_bdc, asm.theta_tdc)]]
    h.update(repr(scalars).encode())
    return {"geometry": h.hexdigest()[:32], **code_key()}


def grid_states(pm: PressModel, geometry: dict, theta: np.ndarray, theta_dot: np.ndarray,
                theta_ddot: np.ndarray) -> list[KinState]:
    """Kinematic states (:func:`press_model.kinematics.state_at`, warm-started point to point from one workspace as
    :func:`press_model.cycle.motor_torque_at` does) at crank angles ``theta`` (rad) with speeds ``theta_dot`` (rad/s) and
    accelerations ``theta_ddot`` (rad/s^2); ``geometry``: :func:`geometry_key` of ``pm``."""
    def solve() -> dict:
        ws = Workspace(pm)
        ws.q_last = None
        rows = [state_at(pm, ws, float(th), float(w), float(al)) for th, w, al in zip(theta, theta_dot, theta_ddot)]
        return {k: np.array([getattr(st, k) for st in rows]) for k in _STATE_ARRAYS}

    key = {**geometry, "grid": [array_digest(theta), array_digest(theta_dot), array_digest(theta_ddot)]}
    z = cached_arrays("kinematics", key, _STATE_ARRAYS, solve)
    q, v, a = (np.array(z[k], dtype=float) for k in ("q", "v", "a"))
    return [KinState(float(th), float(w), float(al), q[p], v[p], a[p], float(z["height"][p]), float(z["height_dot"][p]),
                     float(z["height_ddot"][p])) for p, (th, w, al) in enumerate(zip(theta, theta_dot, theta_ddot))]


def grid_positions(pm: PressModel, theta: np.ndarray) -> np.ndarray:
    """Tree coordinates q (n, nv; rad, m) closing the loops at the crank angles ``theta`` (rad), each solved from the one
    before as :func:`press_model.kinematics.state_at` warm-starts them in a fresh workspace (the first from the assembly
    sweep): the same numbers, bit for bit, kept on disk by the press geometry (:func:`geometry_key`) and the grid. A
    ``state_at`` started from one of them closes at its first check: one loop closure a point instead of Newton's three
    or four (the batch model's build, :func:`press_model.batch.build_batch_model`, ~15 % of its CPU)."""
    def solve() -> dict:
        ws, out = Workspace(pm), np.empty((len(theta), pm.nv))
        for p, th in enumerate(theta):
            out[p] = solve_position(pm, ws, float(th), warm_start(pm, float(th)) if p == 0 else out[p - 1])
        return {"q": out}

    z = cached_arrays("kinematics", {**geometry_key(pm), "positions": array_digest(theta)}, ("q",), solve)
    return np.array(z["q"], dtype=float)


def knot_kinematics(pm: PressModel, theta: np.ndarray) -> list[tuple]:
    """Per crank angle of ``theta`` (rad, increasing): (q, v1, a1, ab, height), the tree coordinates closing the loops
    (rad, m), the tree velocities per unit crank speed, the tree accelerations per unit crank acceleration at rest and
    the bias accelerations per unit crank speed squared, and the slide height above BDC (m): what a plan's path
    dynamics (planning.path_dynamics.build_path_dynamics) needs of the linkage at its knots. Solved point to point from
    one fresh workspace (:func:`press_model.kinematics.state_at`'s warm starts) and kept on disk by the press geometry
    (:func:`geometry_key`) and the knots: the same numbers, bit for bit, for every plan of the job on this press or on
    any press of its geometry (another truth of masses, friction or drive), ~60 % of a path dynamics' build."""
    def solve() -> dict:
        ws, nv = Workspace(pm), pm.nv
        rows = {k: [] for k in _KNOT_ARRAYS}
        for th in theta:
            st = state_at(pm, ws, float(th), 0.0, 0.0)
            v1 = velocity(pm, ws, st.q, 1.0)
            rows["q"].append(st.q)
            rows["v1"].append(v1)
            rows["a1"].append(acceleration(pm, ws, st.q, np.zeros(nv), 1.0))  # per unit theta_ddot at rest
            rows["ab"].append(acceleration(pm, ws, st.q, v1, 0.0))  # bias per unit theta_dot^2
            rows["height"].append(st.height)
        return {k: np.array(v, dtype=float) for k, v in rows.items()}

    z = cached_arrays("kinematics", {**geometry_key(pm), "knots": array_digest(theta)}, _KNOT_ARRAYS, solve)
    q, v1, a1, ab = (np.array(z[k], dtype=float) for k in ("q", "v1", "a1", "ab"))
    return [(q[k], v1[k], a1[k], ab[k], float(z["height"][k])) for k in range(len(theta))]


def force_steps(pm: PressModel, geometry: dict, process) -> list[float]:
    """:func:`press_model.kinematics.force_step_angles` (rad: die contact, BDC) of ``process`` on ``pm``, kept on disk by
    ``geometry`` (:func:`geometry_key`) and the die-contact height; an empty list without a process force. A contact
    outside the stroke is refused as there (never stored)."""
    if max(process.forces) <= 0.0 or process.contact_height <= 0.0:
        return []
    key = {**geometry, "contact_height": repr(float(process.contact_height))}
    z = cached_arrays("kinematics", key, ("steps",), lambda: {"steps": np.array(force_step_angles(pm, process))})
    return [float(a) for a in z["steps"]]


def heights_table(pm: PressModel, geometry: dict, theta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """:func:`press_model.kinematics.grid_heights` (slide height above BDC in m, its rate dH/dtheta in m/rad) at the crank
    angles ``theta`` (rad), kept on disk by ``geometry`` (:func:`geometry_key`) and the grid."""
    def solve() -> dict:
        h, hd = grid_heights(pm, theta)
        return {"height": h, "height_rate": hd}

    z = cached_arrays("kinematics", {**geometry, "heights": array_digest(theta)}, ("height", "height_rate"), solve)
    return np.array(z["height"], dtype=float), np.array(z["height_rate"], dtype=float)


def step_grid(n: int, steps: list[float], one_sided: float) -> np.ndarray:
    """The crank grid (rad) of ``n`` equal steps over [0, 2 pi] with points ``one_sided`` rad before and after each of
    ``steps``, sorted and unique: linear interpolation on it never smears a force step across a cell."""
    theta = list(np.linspace(0.0, 2.0 * math.pi, n + 1))
    for a in steps:
        theta += [a - one_sided, a + one_sided]
    return np.unique(np.array(theta))
