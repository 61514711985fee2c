"""Designing the calibration experiment: the run family's sums against models built directly, the information
matrix's invariants, the exchange against brute force, and `design-experiment` end to end on the crank-slider."""
from __future__ import annotations

import itertools
import json
import math
from importlib import resources

import numpy as np
import pytest

from calibration.design.information import log_det, nuisance_columns, predict
from calibration.design.runs import RunStack, exchange, criterion
from calibration.identification.problem import CalibrationProblem
from press_model.batch import build_batch_model, motor_torques
from press_model.forces import NO_PROCESS, ProcessForce
from press_model.motion import ModulatedSpeed
from press_model.press_data import load_press


@pytest.fixture(scope="module")
def slider():
    from calibration.design.run_family import run_family

    press = load_press("crank-slider")
    return press, run_family(press)


@pytest.mark.parametrize("spm, depth, phase, force, stroke", [(23.0, 0.55, 200.0, 2.2e5, 0.12), (9.0, 0.0, 0.0, 0.0, 0.1)])
def test_run_family_equals_a_model_built_for_the_run(slider, spm, depth, phase, force, stroke):
    press, fam = slider
    motion = ModulatedSpeed.from_spm(spm, depth, math.radians(phase))
    process = ProcessForce(stroke, (stroke, 0.0), (force, force)) if force > 0 else NO_PROCESS
    direct = build_batch_model(press, motion, process, pm=fam.pm)
    summed = fam.model(motion, force, stroke)
    X = direct.low + (direct.high - direct.low) * np.random.default_rng(3).random((4, direct.n_params))
    T1, T2 = motor_torques(summed, X), motor_torques(direct, X)
    assert np.max(np.abs(T1 - T2)) <= 1e-9 * np.max(np.abs(T2))
    assert summed.period == pytest.approx(60.0 / spm)


def test_all_draws_in_one_batch_give_each_draw_its_own_columns_to_the_bit(slider):
    """draw_columns evaluates every draw's curve and Jacobian sets in one batch with features made once; each draw's
    columns must be those of separate batch calls (motor_torques of the draw, curve_jacobian of its sets)."""
    from calibration.design.information import NUISANCE_UNIT, draw_columns, draw_sets
    from calibration.identification.uncertainty import curve_jacobian

    press, fam = slider
    bm = fam.model(ModulatedSpeed.from_spm(17.0, 0.4, math.radians(80.0)), 1.5e5, 0.1)
    problem = CalibrationProblem.from_press(press, ("eta_gear", "mu_r", "J_gear"), 0.3)
    draws = problem.low + (problem.high - problem.low) * np.random.default_rng(5).random((3, 3))
    got = draw_columns(bm, draw_sets(bm, problem, draws))
    span = problem.high - problem.low

    def torques(P):
        return motor_torques(bm, problem.full_sets(bm, P))

    for x, cols in zip(draws, got):
        T = torques(x[None])[0]
        assert np.array_equal(cols.torque, T)
        assert np.array_equal(cols.J, curve_jacobian(torques, span, x) * span)
        assert np.array_equal(cols.Z, nuisance_columns(bm.theta, bm.theta_dot, T) * np.array(NUISANCE_UNIT))
    assert not np.array_equal(got[0].torque, got[1].torque)  # the draws differ, so equality above says something


def test_nuisance_columns_are_the_first_order_shift_of_the_curve():
    theta = np.linspace(0.0, 2.0 * np.pi, 720, endpoint=False)
    omega = 1.0 + 0.4 * np.cos(theta)
    curve = lambda th: 1000.0 * np.sin(th) + 300.0 * np.cos(3.0 * th)  # noqa: E731
    delta = 1e-4  # rad of encoder offset: the logged curve is T(theta - delta)
    Z = nuisance_columns(theta, omega, curve(theta))
    assert np.allclose(curve(theta - delta) - curve(theta), delta * Z[:, 1], atol=1e-3)
    d = 1e-4  # s of channel delay: the torque logged at theta is the one of theta - omega d
    assert np.allclose(curve(theta - omega * d) - curve(theta), d * Z[:, 0], atol=1e-3)


def _problem(k):
    return CalibrationProblem(tuple(f"p{i}" for i in range(k)), np.zeros(k), np.full(k, 2.0), np.ones(k), 0.3)


def test_repeating_a_run_narrows_every_interval_by_sqrt_two():
    rng = np.random.default_rng(0)
    A = rng.normal(size=(360, 5))
    F = A.T @ A
    one, two = predict(F, _problem(5), 360, 0.95), predict(2.0 * F, _problem(5), 720, 0.95)
    q1, q2 = one.half_width / one.std, two.half_width / two.std  # t-quantiles of 355 and 715 dof
    assert np.allclose(two.std, one.std / math.sqrt(2.0), rtol=1e-10)
    assert np.allclose(two.half_width / one.half_width, q2 / q1 / math.sqrt(2.0), rtol=1e-10)
    assert np.allclose(two.correlation, one.correlation)
    assert log_det(2.0 * F) == pytest.approx(log_det(F) + 5 * math.log(2.0))


def test_exchange_finds_the_brute_force_best_pair():
    rng = np.random.default_rng(7)
    C, D, m, k = 9, 2, 4, 3
    infos = np.empty((C, D, m, m))
    for c in range(C):
        for d in range(D):
            A = rng.normal(size=(6, m)) * rng.uniform(0.2, 2.0, size=m)
            infos[c, d] = A.T @ A
    best = max(itertools.combinations_with_replacement(range(C), 2),
               key=lambda ij: criterion((infos[ij[0]] + infos[ij[1]])[None], k, 0.9)[0])
    got = exchange(RunStack.plain(infos), 2, k, 0.9)
    assert criterion((infos[got[0]] + infos[got[1]])[None], k, 0.9)[0] == pytest.approx(
        criterion((infos[best[0]] + infos[best[1]])[None], k, 0.9)[0])


def test_correlation_beyond_the_limit_is_penalised():
    F = np.array([[1.0, 0.95, 0.0], [0.95, 1.0, 0.0], [0.0, 0.0, 1.0]])  # information: the estimates correlate -0.95
    plain = np.mean(np.linalg.slogdet(F)[1])
    assert criterion(F[None, None], 2, 0.99)[0] == pytest.approx(plain)
    assert criterion(F[None, None], 2, 0.9)[0] < plain - 10.0


@pytest.fixture(scope="module")
def fast_job(tmp_path_factory):
    """The shipped crank-slider cushion job with a small candidate grid and polish (the test's time, not its physics).
    The design's polish is 20 Nelder-Mead evaluations, not the default 300: what the test reads (the files, the progress
    and VERIFY lines, each run within the limits for every draw, the joint half-widths at most each run's own, the
    aims' next steps) holds for any runs the search returns; on this grid both polishes return the same two runs
    (0.2 against 1.3-2.1 s of CPU for the design, warm)."""
    text = resources.files("press_model.data").joinpath("crank_slider_cushion.toml").read_text(encoding="utf-8")
    assert text.count("\n[design]\n") == 1 and "[calibration.aco]" not in text
    # the first polish_evaluations is the colony's (a calibration's), the second the design's
    text = text.replace("\n[design]\n", "\n[calibration.aco]\npolish_evaluations = 20\n\n[design]\ngrid_levels = 2\ngrid_phases = 2\n"
                        "draws = 2\npolish_evaluations = 20\n", 1)
    path = tmp_path_factory.mktemp("job") / "slider_design.toml"
    path.write_text(text, encoding="utf-8")
    return path


def test_design_experiment_on_the_crank_slider(fast_job, tmp_path, capsys):
    from calibration.synthetic.experiment import ExperimentSettings, write_experiment
    from calibration.identification.settings import CalibrationSettings
    from servo_press.cli import main
    from press_model.jobs import load_job, make_motion

    out = tmp_path / "design"
    assert main(["design-experiment", "--press", "crank-slider", "--job", str(fast_job), "--out", str(out)]) == 0
    printed = capsys.readouterr()
    assert "VERIFY OK" in printed.out
    # progress on stderr (one line per phase when it is no terminal): the design, each run's playback, the outputs
    assert "[design-experiment] design of the job's [design] runs" in printed.err
    assert "[design-experiment] playback of run 1/2" in printed.err and "[design-experiment] outputs" in printed.err
    rec = json.loads((out / "prediction.json").read_text())
    press = load_press("crank-slider")
    names = rec["parameters"]
    assert set(rec["design"]["half_widths"]) == set(names) == set(rec["cushion_test"]["half_widths"])
    for r in rec["design"]["runs"]:
        assert r["within_limits_for_every_draw"] and r["playback"]["verdict"]["ok"]
        assert r["peak_motor_torque_Nm"] <= 0.9 * press.motor.peak_torque
        assert r["playback"]["peak_motor_torque_Nm"] <= 0.9 * press.motor.peak_torque
        job = load_job(out / r["folder"] / "job.toml")  # a job `experiment` and `calibrate --job` read
        assert CalibrationSettings.from_job(job).parameters == tuple(names)  # what `calibrate --job` fits: what was designed for
        motion = make_motion(job.motion, job.source)
        assert motion.period == pytest.approx(60.0 / r["strokes_per_min"], rel=1e-6)
        prof = np.genfromtxt(out / r["folder"] / "profile.csv", delimiter=",", names=True)
        assert prof["time_s"][-1] == pytest.approx(motion.period, rel=1e-8)  # 10 significant digits in the CSV
        assert prof["crank_angle_deg"][-1] == pytest.approx(360.0, abs=1e-6)
        cam_text = (out / r["folder"] / "cam_table.csv").read_text(encoding="utf-8")
        assert cam_text.startswith("# interpolation: per-period: one row per controller period")
        cam = np.genfromtxt(out / r["folder"] / "cam_table.csv", delimiter=",", names=True, skip_header=1)
        assert cam["motor_position_deg"][-1] == pytest.approx(360.0 * press.drive.gear_ratio, rel=1e-6)
        prov = write_experiment(press, job, ExperimentSettings.from_job(job).truth, 5, tmp_path / f"{r['folder']}.csv")
        assert prov["synthetic"]
    # two runs together tell more than either alone: every predicted half-width is at most each run's own
    for n in names:
        assert all(rec["design"]["half_widths"][n] <= r["alone"]["half_widths"][n] * (1 + 1e-9) for r in rec["design"]["runs"])
    assert (out / "report.md").read_text().count("VERIFY OK") == len(rec["design"]["runs"])
    # every aim the prediction misses ends with the next step, in report.md and on the console
    aim = rec["aim"]
    missed = [k for k, v in aim.items() if v is False]
    report = (out / "report.md").read_text()
    for k in missed:
        line = next(ln for ln in report.splitlines() if ln.startswith(f"- {k.replace('_', ' ')}: NO"))
        assert "next, " in line, line
        assert f"aim {k.replace('_', ' ')}: NO" in printed.out
    assert (out / "design.png").stat().st_size > 0


def test_more_design_runs_than_the_run_limit_are_refused_before_anything_runs(fast_job, tmp_path, capsys):
    from servo_press.cli import main
    from press_model.limits import run_limits

    too_many = run_limits().max_runs + 1
    job = tmp_path / "many_runs.toml"
    job.write_text(fast_job.read_text(encoding="utf-8").replace("\n[design]\n", f"\n[design]\nruns = {too_many}\n", 1), encoding="utf-8")
    for argv, field in ((["--job", str(fast_job), "--runs", str(too_many)], "--runs"), (["--job", str(job)], "design.runs")):
        assert main(["design-experiment", "--press", "crank-slider", *argv, "--out", str(tmp_path / "out")]) == 2
        err = capsys.readouterr().err
        assert f"{field} = {too_many} is not valid" in err and "max_runs in press_model/data/run_limits.toml" in err, err
        assert err.count("\n") == 1 and not (tmp_path / "out").exists()


def test_a_job_without_a_design_table_is_refused(tmp_path, capsys):
    from servo_press.cli import main

    text = resources.files("press_model.data").joinpath("cushion_test.toml").read_text(encoding="utf-8")
    job = tmp_path / "no_design.toml"
    job.write_text(text[:text.index("[design]")], encoding="utf-8")
    assert main(["design-experiment", "--job", str(job), "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert "design" in err and "is missing" in err and "cushion_test.toml" in err and err.count("\n") == 1
    assert not (tmp_path / "out").exists()


def test_a_runs_job_file_names_the_parameters_the_design_was_made_for(tmp_path):
    """A design for four of the job's six parameters writes run_N/job.toml whose [calibration] parameters are those four
    (what `calibrate --job` fits), its other settings the base job's, and a comment naming the two held."""
    from types import SimpleNamespace

    from calibration.design.report import run_job
    from calibration.design.runs import Run
    from calibration.identification.settings import CalibrationSettings
    from press_model.jobs import load_job

    job = load_job("crank-slider-cushion")
    four = ("eta_gear", "mu_r", "m3", "psi")
    design = SimpleNamespace(job=job, press=load_press("crank-slider"), draws=np.zeros((2, 4)),
                             result=SimpleNamespace(runs=(None, None)), problem=SimpleNamespace(names=four),
                             calibration=CalibrationSettings.from_job(job))
    check = SimpleNamespace(run=Run(20.0, 0.3, 120.0, 2.0e5, 0.1), peak_torque=1000.0, dense_peak_torque=None,
                            rms_torque=500.0, max_motor_speed=40.0)
    path = tmp_path / "job.toml"
    path.write_text(run_job(design, 1, check), encoding="utf-8")
    cs = CalibrationSettings.from_job(load_job(path))
    assert cs.parameters == four
    assert cs.weight == CalibrationSettings.from_job(job).weight
    assert "J_gear, mu_s held at the press file's values" in path.read_text(encoding="utf-8")


def test_every_missed_aim_ends_with_its_next_step():
    from calibration.design.report import aim_next_steps

    aim = {"correlation_limit": 0.9, "interval_width_limit": 0.5,
           "design_max_abs_correlation": {"value": 0.95, "pair": ["eta_gear", "mu_r"]},
           "design_widest": {"parameter": "J_gear", "width_share_of_range": 0.6}, "widest_interval_ratio": 1.8,
           "all_correlations_below_limit": False, "all_intervals_under_width_limit": False, "widest_at_least_3x_narrower": False}
    lines = aim_next_steps(aim, 2)
    assert len(lines) == 3 and all(": NO; " in ln and "next, " in ln for ln in lines)
    assert "eta_gear and mu_r" in lines[0] and "J_gear" in lines[1] and "--runs 4" in lines[2]
    # a design whose widest interval is wider than the cushion test's says so, not "0.4x narrower"
    assert "2.5x wider than the cushion test's" in aim_next_steps({**aim, "widest_interval_ratio": 0.4}, 2)[2]
    assert aim_next_steps({**aim, "all_correlations_below_limit": True, "all_intervals_under_width_limit": True,
                           "widest_at_least_3x_narrower": True}, 2) == []
