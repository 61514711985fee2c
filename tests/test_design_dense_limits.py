"""design-experiment checks each run's peak torque as `plan` does: on dense points (the run grid's knots and 1/4, 1/2,
3/4 of each step) and against the feed-forward limit (margin - feedback reserve), checked against a dense sweep of the
per-point Pinocchio model at the worst parameter draw (reference press, cushion-test job's [design])."""
from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from calibration.design.run_family import run_family
from calibration.design.runs import DEFAULT_FEEDBACK_RESERVE, DesignSettings, Evaluator, Run, parameter_draws, search, search_grid
from calibration.identification.problem import CalibrationProblem
from calibration.identification.settings import CalibrationSettings
from press_model.batch import evaluate_chunk, features
from press_model.cycle import motor_torque_at
from press_model.forces import NO_PROCESS
from press_model.jobs import load_job
from press_model.model import PressModel
from press_model.params import apply_overrides

# a run the 1-deg run grid passes (peak 22,227 N m at its worst draw, below 0.89 T_max = 22,250) and the dense points
# do not: the first run `design-experiment` chose on the reference press before it checked dense points
RUN_AT_THE_LIMIT = Run(11.8655, 0.69754, 131.163, 4.96108e6, 0.0528322)


@pytest.fixture(scope="module")
def evaluator(ref_model):
    job = load_job("cushion-test")
    cs, ds = CalibrationSettings.from_job(job), DesignSettings.from_job(job)
    press = ref_model.press
    problem = CalibrationProblem.from_press(press, cs.parameters, cs.weight, job.source)
    return Evaluator(run_family(press, ref_model), problem, ds, parameter_draws(problem, ds.draws, ds.seed), cs.correlation_limit, False)


def _sweep(ev, run, half_width_deg=0.5, step_deg=0.01):
    """The per-point model's largest |motor torque| (N m) at the worst draw of ``run``'s dense check, swept every
    ``step_deg`` within ``half_width_deg`` of the angle of its peak; and that dense peak."""
    peak = ev.dense_peak(run)
    bm = ev.dense_family.model(run.motion(), run.cushion_force_N, run.cushion_stroke_m)
    X = ev.problem.full_sets(bm, ev.draws)
    T = np.abs(evaluate_chunk(bm, X, feats=features(bm, X)).motor_torque)
    d, k = np.unravel_index(np.argmax(T), T.shape)
    assert T[d, k] == pytest.approx(peak, rel=1e-12)
    press = apply_overrides(ev.family.press, dict(zip(ev.problem.names, map(float, ev.draws[d]))))
    theta = bm.theta[k] + np.radians(np.arange(-half_width_deg, half_width_deg + 1e-9, step_deg))
    motion = run.motion()
    tq = motor_torque_at(PressModel(press), run.process() or NO_PROCESS, theta, motion.theta_dot(theta), motion.theta_ddot(theta))
    return float(np.max(np.abs(tq))), peak


def test_the_dense_points_find_the_peak_the_run_grid_misses(ref_model, evaluator):
    ev = evaluator
    limits = ev.settings.torque_limits(ref_model.press.motor.peak_torque)
    assert ev.settings.feedback_reserve == DEFAULT_FEEDBACK_RESERVE == 0.01  # the planner's, door_panel.toml
    grid = ev.check(RUN_AT_THE_LIMIT)
    assert grid.feasible and grid.peak_torque <= limits.feedforward  # the grid alone passes it
    sweep, dense = _sweep(ev, RUN_AT_THE_LIMIT)
    assert dense > limits.feedforward  # the dense points do not
    # and they see what a sweep of the per-point model sees, but for the torque just after die contact, which a 0.25-deg
    # point may reach late (22,473 against 22,423 N m here): inside the feedback reserve, as `plan`'s
    assert dense <= sweep <= dense + limits.peak_torque * limits.feedback_reserve


def test_a_search_whose_run_breaks_the_limit_on_the_dense_points_tightens_and_searches_again():
    """Crank-slider, small grid: the feed-forward limit set (by the reserve) between the grid peak and the dense peak of
    the run the grid search picks: the design re-searches, and its runs keep the limit on the dense points and, swept
    densely with the per-point model at their worst draw, the margin."""
    from importlib import resources

    from press_model.press_data import load_press

    press = load_press("crank-slider")
    pm = PressModel(press)
    job = load_job(str(resources.files("press_model.data").joinpath("crank_slider_cushion.toml")))
    cs = CalibrationSettings.from_job(job)
    problem = CalibrationProblem.from_press(press, cs.parameters, cs.weight, job.source)
    family = run_family(press, pm)

    def evaluator(reserve):
        ds = dataclasses.replace(DesignSettings.from_job(job), grid_levels=2, grid_phases=2, polish_evaluations=20, draws=2,
                                 feedback_reserve=reserve)
        return Evaluator(family, problem, ds, parameter_draws(problem, ds.draws, ds.seed), cs.correlation_limit, False)

    ev = evaluator(DEFAULT_FEEDBACK_RESERVE)
    gaps = [(ev.dense_peak(c.run), c.peak_torque) for c in search_grid(ev, ev.settings.runs).runs]
    dense, grid = max(gaps, key=lambda g: g[0] - g[1])
    assert dense > grid  # the grid misses part of that run's peak
    T_max, margin = press.motor.peak_torque, ev.settings.peak_torque_margin
    ev = evaluator(margin - 0.5 * (dense + grid) / T_max)  # the feed-forward limit halfway between
    limits = ev.settings.torque_limits(T_max)
    assert max(ev.dense_peak(c.run) for c in search_grid(ev, ev.settings.runs).runs) > limits.feedforward  # the grid alone fails
    res = search(ev, ev.settings.runs)
    assert ev.grid_limit is None and all(c.feasible for c in res.runs)
    for c in res.runs:
        assert c.dense_peak_torque <= limits.feedforward
        sweep, peak = _sweep(ev, c.run)
        assert peak == pytest.approx(c.dense_peak_torque, rel=1e-12) and peak <= sweep <= limits.verdict


def test_a_feedback_reserve_at_or_above_the_margin_is_refused(tmp_path, capsys):
    from importlib import resources

    from servo_press.cli import main

    text = resources.files("press_model.data").joinpath("cushion_test.toml").read_text(encoding="utf-8")
    job = tmp_path / "job.toml"
    assert "feedback_reserve" not in text  # the default, the planner's 0.01
    text = text.replace("\n[design]\n", "\n[design]\nfeedback_reserve = 0.45\npeak_torque_margin = 0.4\n")
    job.write_text(text, encoding="utf-8")
    assert main(["design-experiment", "--job", str(job), "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert "design.feedback_reserve = 0.45 is not valid: must be below peak_torque_margin = 0.4" in err and err.count("\n") == 1
