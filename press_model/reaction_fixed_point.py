"""The friction/reaction fixed point of one state's inverse dynamics, as one loop over a few numbers.

:func:`press_model.dynamics.inverse_dynamics` alternates friction (Eqs. 10, 12, from the reaction magnitudes) and the
linear solve for the drive torque, loop forces and reactions (:meth:`press_model.dynamics.StatePrep.solve`) until the
reactions settle (:func:`press_model.dynamics.reactions_settled`'s rule), ~10 rounds a point. In numpy each round was
~25 calls on 2- to 9-element arrays, costing far more than the arithmetic; here the rounds are plain loops compiled by
numba (:func:`press_model.jit.compiled`), the same operations as StatePrep's up to the order of a few sums (round-off:
a test checks the compiled loop against StatePrep's iteration and against itself run as plain Python).
"""
from __future__ import annotations

import math

import numpy as np

from .jit import compiled

CONVERGED, NOT_FINITE, NOT_CONVERGED = 0, 1, 2


def friction_constants(pm) -> tuple:
    """The press's constants the fixed point reads (a tuple, built once per model): the joints' rows of the tree
    coordinates, the maps from cut and slide forces to the tree joints' forces, where each revolute joint's reaction is
    read (tree joint or cut, -1: not there), the bearing radii (m) and the guide axis (x, y)."""
    rm = pm.reaction_map
    return (np.ascontiguousarray(pm.joint_rows, dtype=float), np.ascontiguousarray(rm.cut_coef, dtype=float),
            np.ascontiguousarray(rm.slide_coef, dtype=float), np.asarray(rm.revolute_tree, dtype=np.int64),
            np.asarray(rm.revolute_cut, dtype=np.int64), np.ascontiguousarray(pm.bearing_radii, dtype=float),
            np.ascontiguousarray(pm.axis[:2], dtype=float))


def fixed_point_settings(pm, f_ext: float, height_dot: float, friction: bool) -> np.ndarray:
    """The scalars of :func:`reaction_fixed_point`: slide force (N), slide speed (m/s), mu_r, c_r, mu_s, c_s, the
    tolerance, the most iterations (0: no friction, the frictionless solve only) and the guide's tree joint."""
    fr, num = pm.press.friction, pm.press.numerics
    return np.array([f_ext, height_dot, fr.mu_r, fr.c_r, fr.mu_s, fr.c_s, num.friction_tolerance,
                     num.friction_max_iterations if friction else 0, pm.reaction_map.guide_tree], dtype=float)


def solve_fixed_point(consts: tuple, A_inv, base_rhs, u_s, P, w, settings, out):
    """:func:`reaction_fixed_point` compiled by numba where it is installed, else as plain Python; the same arguments."""
    return (compiled(reaction_fixed_point) or reaction_fixed_point)(consts, A_inv, base_rhs, u_s, P, w, settings, out)


def reaction_fixed_point(consts, A_inv, base_rhs, u_s, P, w, settings, out):
    """(drive torque N m, guide normal N, guide friction N, iterations, status, last change N) of the fixed point, with
    the reaction magnitudes (N) in ``out[0]`` and the joints' friction torques (N m) in ``out[1]``.

    ``consts``: :func:`friction_constants`; ``A_inv`` the inverse of [drive row; loop Jacobian]^T, ``base_rhs`` the RNEA
    torques less the slide force's, ``u_s`` the slide's row, ``P`` the tree joints' transmitted forces (world x, y, N),
    ``w`` the joints' relative speeds (rad/s), ``settings``: :func:`fixed_point_settings`. Status: CONVERGED; NOT_FINITE
    (a reaction overflowed: the values are those of the round that did); NOT_CONVERGED (the most iterations were run).
    Without friction (most iterations 0) the frictionless solve, one iteration. Friction at the converged reactions,
    so the torque and the friction returned agree."""
    joint_rows, cut_coef, slide_coef, rev_tree, rev_cut, radii, axis = consts
    f_ext, height_dot, mu_r, c_r, mu_s, c_s, tol = (settings[0], settings[1], settings[2], settings[3], settings[4],
                                                    settings[5], settings[6])
    max_it, guide = int(settings[7]), int(settings[8])
    nv, n_rev, n_tree, n_cut = A_inv.shape[0], w.shape[0], P.shape[0], cut_coef.shape[1]
    n_rev_now, tau_f = out[0], out[1]  # filled in place: the caller's arrays
    new_rev = np.empty(n_rev)
    g = np.empty(nv)
    x = np.empty(nv)
    R = np.empty((n_tree, 2))
    for j in range(n_rev):
        tau_f[j] = 0.0
        n_rev_now[j] = 0.0
    f_s = 0.0
    n_s = 0.0
    change = 0.0
    it = 1
    rnd = 0
    closing = False
    while True:
        if rnd > 0:  # friction at the last reactions (Eqs. 10, 12)
            for j in range(n_rev):
                sgn = 1.0 if w[j] > 0.0 else (-1.0 if w[j] < 0.0 else w[j] * 0.0)
                tau_f[j] = -(mu_r * radii[j] * n_rev_now[j] + c_r * abs(w[j])) * sgn
            sgn = 1.0 if height_dot > 0.0 else (-1.0 if height_dot < 0.0 else height_dot * 0.0)
            f_s = -(mu_s * n_s + c_s * abs(height_dot)) * sgn
        # drive torque and loop forces for this friction (StatePrep.solve)
        for i in range(nv):
            gen = 0.0
            for j in range(n_rev):
                gen += joint_rows[j, i] * tau_f[j]
            g[i] = base_rhs[i] - (gen + u_s[i] * f_s)
        for i in range(nv):
            s = 0.0
            for k in range(nv):
                s += A_inv[i, k] * g[k]
            x[i] = s
        if closing:  # the torque at the friction of the converged reactions
            return x[0], n_s, f_s, it, CONVERGED, change
        # the tree joints' forces, then the reaction magnitudes
        for t in range(n_tree):
            for d in range(2):
                s = P[t, d]
                for c in range(n_cut):
                    s -= cut_coef[t, c] * x[1 + 2 * c + d]
                R[t, d] = s - slide_coef[t] * f_ext * axis[d]
        for j in range(n_rev):
            if rev_tree[j] >= 0:
                new_rev[j] = math.sqrt(R[rev_tree[j], 0] ** 2 + R[rev_tree[j], 1] ** 2)
            else:
                new_rev[j] = math.sqrt(x[1 + 2 * rev_cut[j]] ** 2 + x[2 + 2 * rev_cut[j]] ** 2)
        along = R[guide, 0] * axis[0] + R[guide, 1] * axis[1]
        new_s = math.sqrt((R[guide, 0] - along * axis[0]) ** 2 + (R[guide, 1] - along * axis[1]) ** 2)
        finite = math.isfinite(new_s)
        big = 1.0
        change = abs(new_s - n_s)
        for j in range(n_rev):
            finite = finite and math.isfinite(new_rev[j])
            big = max(big, new_rev[j])
            change = max(change, abs(new_rev[j] - n_rev_now[j]))
            n_rev_now[j] = new_rev[j]
        n_s = new_s
        it = rnd + 1
        if not finite:
            return x[0], n_s, f_s, it, NOT_FINITE, change
        if max_it == 0:  # no friction: the frictionless solve is the answer
            return x[0], n_s, f_s, 1, CONVERGED, 0.0
        # reactions_settled's rule from the second round: every change below tol x the largest reaction (at least 1 N)
        if rnd > 0 and change <= tol * max(big, new_s):
            closing = True
        elif it >= max_it:
            return x[0], n_s, f_s, it, NOT_CONVERGED, change
        rnd += 1
