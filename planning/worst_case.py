"""The worst corner of a parameter box per segment: two torque-row sets (motoring, braking) instead of every corner.

A robust plan (:mod:`planning.robust`) must keep |T_m| <= L for every corner of the calibration's box. Its
members come in two groups that share their drive's efficiency and their friction side (the monotone rule:
low eta and high friction where the motors drive, high eta and low friction where they brake) and differ in
the affine parameters (masses, balance, gear inertia). At fixed friction the crank torque B is affine in
those, so on a segment the largest motoring row B k_mot (and the largest braking row -B k_brk) over the group
is at one of its members, the one on the side of each parameter that the sign of dB/dp there picks. Which
one is read off the members' own rows at the current profile (the sign rule without differencing: the
member whose row is largest is the corner the signs point at); so the optimal-control stage carries per
segment one motoring and one braking worst case, not 2^k corners x 2 row sets, and the choice is made again
at every friction re-solve (:class:`WorstCase`); the fixed point's residual is taken on the corners a solve used. A choice is kept unless another member's row beats it by
more than ``HYSTERESIS`` of the largest row (a tie would otherwise flip between re-solves). After the
friction fixed point the stage checks every member's rows at the solution (:meth:`WorstCase.holds`) and
re-solves while one is broken; the robust plan then verifies all 2^n corners on the full model (its
cutting-plane loop).

Units: N m (crank torque B, motor torque per motor), rad, s.
"""
from __future__ import annotations

import dataclasses

import numpy as np

from press_model.motor import torque_row_factors

from .evaluation import CHECKS

HYSTERESIS = 1.0e-7  # relative to the largest row: a member replaces the one chosen on a segment only if its row is larger by more (the stage's TORQUE_TOLERANCE is 1e-6)


def _states(prof, theta):
    """Per segment the crank speed w, acceleration a and angle fraction f at its two knots and its 1/4, 1/2, 3/4
    checks (5 x N each), on the profile's cubic in time (the stage's own transcription, planning.optimal)."""
    sd = np.asarray(prof.sd, float)
    u_r, u_l = prof.knot_accels()
    a0, a1 = np.asarray(u_r, float)[:-1], np.asarray(u_l, float)[1:]
    w0, w1 = sd[:-1], sd[1:]
    h = np.asarray(prof.dt, float)
    h = np.where(np.isfinite(h), h, 0.0)
    dth = np.diff(np.asarray(theta, float))
    d = a1 - a0
    W, A, F = [w0], [a0], [np.zeros_like(w0)]
    for q in CHECKS:
        W.append(w0 + a0 * q * h + d * q * q * h / 2.0)
        A.append(a0 + q * d)
        F.append(np.clip((w0 * q * h + a0 * q * q * h * h / 2.0 + d * q**3 * h * h / 6.0) / dth, 0.0, 1.0))
    W.append(w1), A.append(a1), F.append(np.ones_like(w0))
    return np.array(W), np.array(A), np.array(F)


def segment_torques(r, prof, theta) -> np.ndarray:
    """The crank-side bracket B = tau + J_gear u^2 theta_ddot (N m) of the rows ``r`` (:class:`planning.optimal.TorqueRows`)
    at every segment's two knots and three checks along ``prof`` (5 x N: knot i, the checks, knot i+1), with the
    stage's interpolation of m, c and the rest between the segment's ends."""
    W, A, F = _states(prof, theta)
    j = r.drive.gear_inertia * r.drive.gear_ratio**2
    m_l, c_l, sl_l = r.left
    m0, m1 = r.m[:-1] + j, np.asarray(m_l)[1:] + j
    c0, c1 = r.c[:-1], np.asarray(c_l)[1:]
    fr0, fl1 = r.fixed_right[:-1], r.fixed_left[1:]
    s0, s1 = r.slope[:-1], np.asarray(sl_l)[1:]
    return ((m0 + F * (m1 - m0)) * A + (c0 + F * (c1 - c0)) * W * W
            + (1.0 - F) * (fr0 + s0 * A) + F * (fl1 + s1 * A))


def row_values(r, prof, theta, standstill) -> tuple[np.ndarray, np.ndarray]:
    """(motoring row B k_mot, braking row -B k_brk) in N m per motor at the 5 x N points of :func:`segment_torques`
    (the press file's standstill factors at the knots where the crank rests, as the stage's bounds)."""
    B = segment_torques(r, prof, theta)
    ks_m, ks_b = torque_row_factors(r.drive, standstill)
    km, kb = torque_row_factors(r.drive, np.zeros(len(standstill), bool))
    k_mot = np.vstack([ks_m[:-1], km[:-1], km[:-1], km[:-1], ks_m[1:]])
    k_brk = np.vstack([ks_b[:-1], kb[:-1], kb[:-1], kb[:-1], ks_b[1:]])
    return B * k_mot, -B * k_brk


ROW_OF_KIND = {"motoring": 0, "braking": 1}  # which of row_values' two rows a group's worst case is taken on

class WorstCase:
    """Per segment, the group's worst member for one row type, as one :class:`planning.optimal.TorqueRows`.

    ``groups``: [(row type "motoring" or "braking", member indices)]; the members of a group share their drive's
    efficiency, ratio, motors and standstill rule (they may differ in the gear inertia, carried into m here).
    Members in no group enter the stage as themselves, before the worst cases (the first member, the press the plan
    is for, stays first)."""

    def __init__(self, groups, theta, standstill):
        self.groups = [(kind, list(idx)) for kind, idx in groups]
        self.theta, self.standstill = np.asarray(theta, float), np.asarray(standstill, bool)
        self.choice = [None] * len(self.groups)  # per group, the member index chosen per segment
        self.full = None  # every member's rows at the last profile composed
        self.kept = None  # the stage's rows at the last profile with the choice made before it (the fixed point's residual)

    def ungrouped(self, n_members: int) -> list[int]:
        grouped = {i for _, idx in self.groups for i in idx}
        return [i for i in range(n_members) if i not in grouped]

    def compose(self, rows: list, prof) -> list:
        """The stage's rows: the ungrouped members' own, then per group its worst case along ``prof``."""
        self.full = rows
        out = [rows[i] for i in self.ungrouped(len(rows))]
        kept = list(out)
        for g, (kind, idx) in enumerate(self.groups):
            vals = np.array([np.max(row_values(rows[i], prof, self.theta, self.standstill)[ROW_OF_KIND[kind]], axis=0)
                             for i in idx])  # (members, N)
            best = np.argmax(vals, axis=0)
            prev = self.choice[g]
            kept.append(_combine([rows[i] for i in idx], best if prev is None else prev))
            if prev is not None:
                cols = np.arange(vals.shape[1])
                keep = vals[best, cols] <= vals[prev, cols] + HYSTERESIS * np.max(np.abs(vals))
                best = np.where(keep, prev, best)
            self.choice[g] = best
            out.append(_combine([rows[i] for i in idx], best))
        self.kept = kept
        return out

    def holds(self, prof, level: float, tolerance: float) -> bool:
        """Whether every member's rows (of the last :meth:`compose`) keep ``level`` (N m per motor) within the relative
        ``tolerance`` at every segment's knots and checks along ``prof``."""
        for r in self.full:
            mot, brk = row_values(r, prof, self.theta, self.standstill)
            if max(float(np.max(mot)), float(np.max(brk))) > level * (1.0 + tolerance):
                return False
        return True

    def counts(self) -> dict:
        """Per group, how many segments each member is the worst case on (member index -> segments)."""
        return {f"{kind} {g}": {int(i): int(n) for i, n in zip(*np.unique(np.asarray(idx)[self.choice[g]], return_counts=True))}
                for g, (kind, idx) in enumerate(self.groups) if self.choice[g] is not None}


def _combine(rows: list, pick: np.ndarray):
    """One TorqueRows whose segment s is ``rows[pick[s]]``'s (its knot-s right side and knot-(s+1) left side); the
    gear inertia of each carried into m (the drive's set to 0), the drives otherwise alike."""
    d0 = rows[0].drive
    for r in rows[1:]:
        d = r.drive
        if (d.efficiency, d.gear_ratio, d.motors, d.standstill) != (d0.efficiency, d0.gear_ratio, d0.motors, d0.standstill):
            raise ValueError("worst-case group: its members' drives differ in more than the gear inertia")
    n = len(rows[0].m)
    right = np.concatenate([pick, [pick[-1]]])  # the last knot starts no segment: any member's values
    left = np.concatenate([[pick[0]], pick])  # the first knot ends no segment
    K = np.arange(n)

    def take(name, side):
        return np.array([getattr(r, name) for r in rows])[side, K]

    jr = np.array([r.drive.gear_inertia * r.drive.gear_ratio**2 for r in rows])
    lefts = [r.left for r in rows]
    m_l = np.array([lf[0] for lf in lefts])[left, K] + jr[left]
    c_l = np.array([lf[1] for lf in lefts])[left, K]
    s_l = np.array([lf[2] for lf in lefts])[left, K]
    return dataclasses.replace(
        rows[0], m=take("m", right) + jr[right], c=take("c", right), rest_right=take("rest_right", right),
        rest_left=take("rest_left", left), slope=take("slope", right), u_right=take("u_right", right), u_left=take("u_left", left),
        drive=dataclasses.replace(d0, gear_inertia=0.0), m_left=m_l, c_left=c_l, slope_left=s_l)
