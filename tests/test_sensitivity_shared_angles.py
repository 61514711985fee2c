"""Two load cases of one design evaluated together (calibration/sensitivity/load_cases.py, press_model/batch_angles.py):
the angles they share are the ones where the process force is zero, a model at some of its angles gives the full
model's torques there, and the joint evaluator gives each case's responses as its own evaluator does, bit for bit."""
from dataclasses import replace

import numpy as np
import pytest

from calibration.sensitivity import sobol as S
from calibration.sensitivity.load_cases import cases_evaluator
from calibration.sensitivity.report import KERNEL_CHUNK, _batch_model, load_case, response_evaluator
from press_model.batch import evaluate_chunk
from press_model.batch_angles import alike_angles, at_angles


@pytest.fixture(scope="module")
def no_load_and_cushion(ref_model):
    return [_batch_model(ref_model, load_case(job)) for job in ("no-load", "cushion-test")]


@pytest.fixture(scope="module")
def design(ref_model):
    return S.sample(S.problem(ref_model.press), 8, 3)  # 240 rows: several kernel blocks, the compiled responses


def test_the_cases_compute_alike_exactly_where_the_cushion_pushes_on_nothing(no_load_and_cushion):
    no_load, cushion = no_load_and_cushion
    force = np.asarray(load_case("cushion-test").job.process(cushion.height, cushion.height_dot), dtype=float)
    alike = alike_angles(no_load, cushion)
    assert np.array_equal(alike, force == 0.0)
    assert 0 < alike.sum() < len(alike)
    assert alike_angles(cushion, cushion).all()


def test_models_that_differ_in_a_constant_of_every_angle_share_no_angle(no_load_and_cushion):
    no_load, cushion = no_load_and_cushion
    assert not alike_angles(no_load, replace(cushion, gear_ratio=cushion.gear_ratio * 2)).any()
    assert not alike_angles(no_load, replace(cushion, friction_tolerance=cushion.friction_tolerance / 2)).any()
    assert not alike_angles(no_load, at_angles(cushion, np.arange(10))).any()


def test_a_model_at_some_angles_gives_the_full_models_torques_there(no_load_and_cushion, design):
    cushion = no_load_and_cushion[1]
    angles = np.flatnonzero(~alike_angles(*no_load_and_cushion))
    full = evaluate_chunk(cushion, design[:40])
    part = evaluate_chunk(at_angles(cushion, angles), design[:40])
    assert part.crank_torque.shape == (40, len(angles))
    assert part.crank_torque.tobytes() == full.crank_torque[:, angles].tobytes()
    assert np.array_equal(part.iterations, full.iterations[:, angles])


def test_the_joint_evaluator_gives_each_cases_own_responses_to_the_bit(no_load_and_cushion, design):
    joint = cases_evaluator(no_load_and_cushion, KERNEL_CHUNK)(design)
    assert joint.shape == (len(design), 8)
    for k, bm in enumerate(no_load_and_cushion):
        alone = response_evaluator(bm)(design)
        assert joint[:, 4 * k : 4 * k + 4].tobytes() == alone.tobytes()
    # the cases differ: the cushion's 5 MN show in its responses, so no column was copied from the other case
    assert not np.allclose(joint[:, :4], joint[:, 4:])


def test_a_case_that_shares_no_angle_is_computed_whole(no_load_and_cushion, design):
    no_load, cushion = no_load_and_cushion
    other = replace(cushion, friction_tolerance=cushion.friction_tolerance / 4)
    joint = cases_evaluator([no_load, other], KERNEL_CHUNK)(design[:80])
    assert joint[:, 4:].tobytes() == response_evaluator(other)(design[:80]).tobytes()
