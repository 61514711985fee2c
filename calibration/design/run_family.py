"""The batch model of any calibration run of one press at the cost of a few array sums: a run family.

A calibration run is a continuous crank rotation theta_dot(theta) > 0 and a cushion that pushes up on the slide
with a constant force F while the slide moves down below the height H_c. For such runs every array of the batch
model (:class:`press_model.batch.BatchModel`) is, at each crank angle, linear in (1, theta_dot^2, theta_ddot, F x
[H <= H_c]) or in theta_dot alone:

* the inverse dynamics of the rigid linkage (its ``base`` rows) are M(q) a + c(q, v) with v = J(theta) theta_dot and
  a = J theta_ddot + J' theta_dot^2: linear in theta_ddot and theta_dot^2 at a fixed angle;
* the process force enters one row as L_f(q) F: linear in F where it acts;
* the viscous friction terms (``visc``) are linear in the joint speeds, so in theta_dot;
* the Coulomb terms (``coul``) and the reaction map depend on the angle and on the signs of the joint speeds only,
  which a forward-turning crank does not change.

So four models built once (:func:`run_family`) give every run's model by weighted sums (:meth:`RunFamily.model`):
(theta_dot, theta_ddot) = (1, 0), (1, 1), (2, 0) rad/s, rad/s^2 without process force, and (1, 0) with a unit
force over the whole downstroke. A test checks the sums against models built directly for random runs. The
design search (:mod:`calibration.design.runs`) evaluates thousands of runs this way; building each directly
would take about a second.
"""
from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from press_model.batch import BatchModel, ConstantMotion, build_batch_model, motion_terms
from press_model.forces import NO_PROCESS, ProcessForce
from press_model.jit import compiled
from press_model.model import PressModel
from press_model.press_data import PressData


# base_pt is the one array that is 1 + theta_dot^2 + theta_ddot + process force terms (RunFamily.parts);
# base and visc are base_pt and visc_pt with the crank angle second (batch.build_batch_model): a run's model holds them
# as views of those, the same numbers, rather than sums of their own (half of the sums of a design search's 800 runs)
_SPEED = ("visc_pt", "height_dot")  # arrays proportional to theta_dot


@dataclass(frozen=True, eq=False)
class RunFamily:
    """The four basis models of one press (see the module docstring)."""

    press: PressData
    pm: PressModel
    one: BatchModel  # theta_dot = 1, theta_ddot = 0, no process force
    parts: dict  # "base_pt" -> (constant, per theta_dot^2, per theta_ddot, per N of process force)
    stroke: float  # m

    def model(self, motion, force_N: float = 0.0, contact_height_m: float = 0.0) -> BatchModel:
        """The batch model of a run: crank ``motion`` (theta_dot > 0 everywhere), cushion force ``force_N`` (N, up on the
        slide) while the slide moves down below ``contact_height_m`` (m above BDC)."""
        return self.models(motion, (force_N,), contact_height_m)[0]

    def models(self, motion, forces_N, contact_height_m: float = 0.0) -> list[BatchModel]:
        """The batch models of runs of one crank ``motion`` and one cushion stroke ``contact_height_m`` (m above BDC) with
        the cushion forces ``forces_N`` (N, each > 0, or one 0: no cushion), e.g. a run and its force a step higher: one
        pass over the family's arrays gives all; every array but the force's sum is shared (read-only)."""
        bm = self.one
        th = bm.theta
        td, tdd = np.asarray(motion.theta_dot(th), float), np.asarray(motion.theta_ddot(th), float)
        if not np.all(td > 0.0):
            raise ValueError("a run family holds continuous forward rotation only (theta_dot > 0 at every grid angle)")
        forces_N = [float(f) for f in forces_N]
        active = ((bm.height <= contact_height_m) & (bm.height >= 0.0) & (bm.height_dot <= 0.0) if max(forces_N) > 0.0
                  else np.zeros(len(th), bool))
        f = np.array([np.where(active, force, 0.0) for force in forces_N])
        shared = {"visc_pt": np.ascontiguousarray(bm.visc_pt * td.reshape(-1, 1, 1)), "height_dot": bm.height_dot * td,
                  "theta_dot": td, "theta_ddot": tdd}
        shared["visc"] = shared["visc_pt"].transpose(1, 0, 2)
        sums = {}
        for name, (c0, cvv, ca, cf) in self.parts.items():  # the crank angle first
            out = np.empty((len(forces_N),) + c0.shape)
            flat = [a.reshape(len(th), -1) for a in (c0, cvv, ca, cf)]
            (compiled(family_sums) or _family_sums_numpy)(*flat, td**2, tdd, f, out.reshape(len(forces_N), len(th), -1))
            sums[name] = out
        for a in (*shared.values(), *sums.values()):
            a.setflags(write=False)
        return [replace(bm, period=float(motion.period), **shared, **{name: v[j] for name, v in sums.items()},
                        base=sums["base_pt"][j].transpose(1, 0, 2)) for j in range(len(forces_N))]


def family_sums(c0, cvv, ca, cf, td2, tdd, f, out):
    """out[j, p, i] = c0[p, i] + td2[p] cvv[p, i] + tdd[p] ca[p, i] + f[j, p] cf[p, i]: a run's array of the family
    (:meth:`RunFamily.models`) at crank angle p for the cushion forces f[j] (N), theta_dot^2 ``td2`` and theta_ddot ``tdd``
    at each angle; the arrays (angles, entries). Plain loops for :func:`press_model.jit.compiled`: the sum is numpy's
    left to right, term by term (the same numbers as :func:`_family_sums_numpy`, tests), read once for all the forces
    where numpy made four temporaries of the ~1.3 MB array per model (a fifth of a design search's time)."""
    for p in range(c0.shape[0]):
        a = td2[p]
        b = tdd[p]
        for i in range(c0.shape[1]):
            x = c0[p, i] + a * cvv[p, i]
            x = x + b * ca[p, i]
            for j in range(f.shape[0]):
                out[j, p, i] = x + f[j, p] * cf[p, i]


def _family_sums_numpy(c0, cvv, ca, cf, td2, tdd, f, out):
    """:func:`family_sums` in numpy (without numba)."""
    for j in range(f.shape[0]):
        out[j] = c0 + td2[:, None] * cvv + tdd[:, None] * ca + f[j][:, None] * cf


def run_family(press: PressData, pm: PressModel | None = None, step_deg: float = 1.0) -> RunFamily:
    """Build the four basis models of ``press`` on a crank grid of ``step_deg`` (about four model builds, a few seconds
    at 1 deg; the disk cache keeps them)."""
    pm = pm or PressModel(press)
    stroke = float(pm.assembly.stroke)
    # 1 N wherever the slide moves down below the top of the stroke (a job's contact must lie inside the stroke; the
    # runs' cushions act far lower, so the top's last nanometre never counts)
    top = stroke * (1.0 - 1e-9)
    unit = ProcessForce(top, (top, 0.0), (1.0, 1.0))

    def build(v, a, process):
        return build_batch_model(press, ConstantMotion(v, a), process, step_deg=step_deg, pm=pm)

    m1, mf = build(1.0, 0.0, NO_PROCESS), build(1.0, 0.0, unit)
    vv, ca = motion_terms(press, pm, step_deg)  # per theta_dot^2 and per theta_ddot, from the models of (1, 0), (1, 1), (2, 0)
    a1, af = np.asarray(m1.base_pt, float), np.asarray(mf.base_pt, float)
    parts = {"base_pt": (a1 - vv, vv, ca, af - a1)}
    return RunFamily(press, pm, m1, parts, stroke)
