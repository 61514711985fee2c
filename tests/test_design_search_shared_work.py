"""The design search's shared work gives the numbers it would compute alone: the run family's compiled sums against
numpy's sum, the kernel run once per distinct kernel row against every set evaluated, and a run screened out on its
draws' curves against the full check it gets once a limit lets it in (reference press, cushion-test job's [design])."""
from __future__ import annotations

import math

import numpy as np
import pytest

from calibration.design.information import draw_columns, draw_sets
from calibration.design.run_family import _family_sums_numpy, family_sums
from calibration.design.report import design_evaluator
from calibration.design.runs import DesignSettings, Run
from calibration.identification.process_force import FORCE_STEP
from press_model.batch import evaluate_chunk, features
from press_model.jit import compiled
from press_model.jobs import load_job
from press_model.motion import ModulatedSpeed

RUNS = [Run(13.0, 0.55, 200.0, 2.2e6, 0.12), Run(6.0, 0.0, 0.0, 0.0, 0.3), Run(9.5, 0.7, 75.0, 4.0e6, 0.06)]


def _bits(a):
    return np.ascontiguousarray(a, dtype=float).view(np.int64)


@pytest.fixture(scope="module")
def evaluator(ref_model):
    """The cushion-test job's design evaluator, as design-experiment makes it (its logged force's stated accuracy too)."""
    job = load_job("cushion-test")
    ds = DesignSettings.from_job(job)
    return design_evaluator(ref_model.press, job, None, ref_model, ds.noise(job.source), ds)


@pytest.mark.parametrize("run", RUNS)
def test_family_models_are_numpys_sum_to_the_bit(evaluator, run):
    fam = evaluator.family
    motion = run.motion()
    forces = (run.cushion_force_N, run.cushion_force_N * (1.0 + FORCE_STEP)) if run.cushion_force_N > 0 else (0.0,)
    models = fam.models(motion, forces, run.cushion_stroke_m)
    one = fam.one
    td, tdd = motion.theta_dot(one.theta), motion.theta_ddot(one.theta)
    active = (one.height <= run.cushion_stroke_m) & (one.height >= 0.0) & (one.height_dot <= 0.0)
    c0, cvv, ca, cf = fam.parts["base_pt"]
    along = lambda x: np.asarray(x).reshape(-1, 1, 1)  # noqa: E731
    for force, bm in zip(forces, models):
        expected = c0 + along(td**2) * cvv + along(tdd) * ca + along(np.where(active, force, 0.0)) * cf
        assert np.array_equal(_bits(bm.base_pt), _bits(expected))
        assert np.array_equal(_bits(bm.base), _bits(expected.transpose(1, 0, 2)))
        assert np.array_equal(bm.visc_pt, one.visc_pt * td.reshape(-1, 1, 1)) and np.array_equal(bm.height_dot, one.height_dot * td)
        assert bm.period == pytest.approx(60.0 / run.strokes_per_min)
    assert np.array_equal(_bits(fam.model(motion, forces[0], run.cushion_stroke_m).base_pt), _bits(models[0].base_pt))
    if compiled(family_sums) is not None:  # the compiled loop and its numpy stand-in give the same numbers
        flat = [a.reshape(len(td), -1) for a in (c0, cvv, ca, cf)]
        f = np.array([np.where(active, force, 0.0) for force in forces])
        a, b = (np.empty((len(forces), *flat[0].shape)) for _ in range(2))
        compiled(family_sums)(*flat, td**2, tdd, f, a)
        _family_sums_numpy(*flat, td**2, tdd, f, b)
        assert np.array_equal(_bits(a), _bits(b))


def test_sets_that_share_kernel_inputs_share_the_crank_torque_to_the_bit(evaluator):
    """The gear's efficiency and inertia enter Eq. 16 only: their Jacobian sets have their draw's kernel row, and the
    columns from the distinct rows equal those of every set evaluated."""
    ev = evaluator
    bm = ev.family.model(ModulatedSpeed.from_spm(11.0, 0.4, math.radians(80.0)), 1.5e6, 0.15)
    sets = draw_sets(bm, ev.problem, ev.draws)
    shared = [n for n in ev.problem.names if n in ("eta_gear", "J_gear")]
    assert shared  # the cushion-test job calibrates both
    assert len(np.unique(sets.kernel_row)) == len(sets.X) - 2 * len(shared) * len(ev.draws)
    T = evaluate_chunk(bm, sets.X, feats=features(bm, sets.X)).motor_torque
    per = 2 * len(sets.steps) + 1
    for d, cols in enumerate(draw_columns(bm, sets)):
        assert np.array_equal(_bits(cols.torque), _bits(T[d * per]))
        again = draw_columns(bm, draw_sets(bm, ev.problem, ev.draws[d][None]))[0]
        assert np.array_equal(_bits(cols.J), _bits(again.J)) and np.array_equal(_bits(cols.Z), _bits(again.Z))


def test_a_screened_run_gets_its_full_check_once_a_limit_lets_it_in(evaluator):
    ev = evaluator
    run = Run(12.5, 0.3, 140.0, 3.0e6, 0.2)
    ev.grid_limit = 1.0  # N m: every run breaks it
    try:
        screened = ev.check(run, screen=True)
        asked = ev.check(run)  # a caller without screen gets the information of an infeasible run too
    finally:
        ev.grid_limit = None
    assert not screened.feasible and screened.info is None and screened.columns is None
    assert not asked.feasible and asked.info is not None
    ev._memo.clear()
    ev.grid_limit = 1.0
    try:
        assert ev.check(run, screen=True).info is None
    finally:
        ev.grid_limit = None
    full = ev.check(run, screen=True)  # the limit lets it in: its full check
    assert full.feasible and full.info is not None
    assert np.array_equal(_bits(full.info), _bits(asked.info))
    bm, more = ev.family.models(run.motion(), (run.cushion_force_N, run.cushion_force_N * (1.0 + FORCE_STEP)), run.cushion_stroke_m)
    direct = ev.check_model(run, bm, more=more)
    assert np.array_equal(_bits(full.info), _bits(direct.info))
    assert np.array_equal(_bits(full.accuracy.E), _bits(direct.accuracy.E)) and np.array_equal(_bits(full.peak[0]), _bits(direct.peak[0]))
    assert (full.peak_torque, full.rms_torque, full.max_motor_speed, full.points) == (
        direct.peak_torque, direct.rms_torque, direct.max_motor_speed, direct.points)
    assert (screened.peak_torque, screened.rms_torque) == (full.peak_torque, full.rms_torque)
