"""The process force of a calibration (calibration/identification/process_force.py): a logged force column replaces the
job's nominal curve in the model, its timing is checked against the job's die contact, and without the column the
calibration says how far a 1 % error of the job's force moves the estimate. The truth is the SYNTHETIC log's: the cushion's
true force is scaled away from the job's (calibration/synthetic/effects.py ``cushion_force_scale``)."""
import dataclasses
import json
import math

import numpy as np
import pytest
from scipy.interpolate import CubicSpline

from calibration.identification.inputs import read_log
from calibration.identification.console import warning_lines
from calibration.identification.process_force import FORCE_WARNING, logged_force
from calibration.identification.run import calibrate
from calibration.identification.settings import CalibrationSettings
from press_model.settings_fields import replaced
from calibration.synthetic.experiment import ExperimentSettings, truth_path, with_log_effects, write_experiment
from calibration.traces.channel_map import parse_channel_map
from calibration.traces.drive_log import grid_rows, read_log_rows
from calibration.traces.trace_log import read_trace_rows
from press_io.errors import PressDataError
from press_model.jobs import load_job
from press_model.press_data import load_press
from press_model.kinematics import grid_heights
from press_model.model import PressModel

JOB = "cushion-test"
TRUTH = {"eta_gear": 0.83, "mu_r": 0.0125, "mu_s": 0.08}


def settings(job):
    return CalibrationSettings.from_job(job).process_force


def experiment(press, job, path, **items):
    """The job's SYNTHETIC log with ``items`` (effects and the force channel's [experiment] keys) in place of its own."""
    write_experiment(press, job, TRUTH, 1, path, settings=with_log_effects(ExperimentSettings.from_job(job), items))
    return path


def eta_error(press, job, rows, settings=None) -> tuple[float, object]:
    settings = settings if settings is not None else CalibrationSettings.from_job(job)
    cal = calibrate(press, job, rows, ["aco"], 0, settings=replaced(settings, {"bootstrap.refits": 0}), progress=False)
    return cal.best.x[cal.objective.problem.names.index("eta_gear")] / TRUTH["eta_gear"] - 1.0, cal


def exact_force(job) -> CalibrationSettings:
    """The job's [calibration] with its force taken as exact (``job_force_tolerance`` 0)."""
    cs = CalibrationSettings.from_job(job)
    return dataclasses.replace(cs, process_force=dataclasses.replace(cs.process_force, job_force_tolerance=0.0))


@pytest.fixture(scope="module")
def unlogged(press, job, tmp_path_factory):
    """``unlogged(scale)``: the job's SYNTHETIC log (seed 1, TRUTH) with the true cushion force ``scale`` times the
    job's and no force column, read, and its calibration with the job's force taken as exact: (rows, (the eta_gear
    error, the calibration)), made once a scale for the module. The force column's noise has a stream of its own
    (calibration/synthetic/experiment.py), so its samples are those of the log with the column: both tests below read
    this one calibration."""
    made = {}

    def get(scale):
        if scale not in made:
            path = tmp_path_factory.mktemp("unlogged") / "log.csv"
            rows = read_log_rows(experiment(press, job, path, cushion_force_scale=scale, process_force_logged=False))
            made[scale] = rows, eta_error(press, job, rows, exact_force(job))
        return made[scale]

    return get


@pytest.mark.parametrize("scale", [0.96, 1.04])
def test_a_logged_force_puts_eta_gear_within_2_percent_whatever_the_job_says(press, job, tmp_path, unlogged, scale):
    """The true cushion force 4 % off the job's, logged with 1 % noise: eta_gear within 2 % of its truth; the same log
    without the column (the job's force taken as exact) is off by about 4 x the stated 1 % sensitivity. That
    calibration is the module's one of the log written without the column (``unlogged``), its samples this log's."""
    path = experiment(press, job, tmp_path / "log.csv", cushion_force_scale=scale, process_force_noise_of_peak=0.01)
    rows = read_log_rows(path)
    assert rows.force_N is not None
    err, cal = eta_error(press, job, rows)
    assert abs(err) < 0.02, err
    rec = cal.process_force["logs"][0]
    assert rec["source"].startswith("logged") and abs(rec["scale_to_job"] - scale) < 0.005
    blind = dataclasses.replace(rows, force_N=None)
    blind_rows, (err_blind, cal_blind) = unlogged(scale)
    assert blind_rows.force_N is None and np.array_equal(blind_rows.data, blind.data)  # the same samples, the column left out
    assert abs(err_blind) > 0.025, err_blind  # the job's force taken as exact: wrong ...
    per_percent = cal_blind.process_force["sensitivity"]["relative_shift"]["eta_gear"]
    predicted = 100.0 * (scale - 1.0) * per_percent  # ... by what the calibration says a force error does
    assert abs(err_blind - predicted) < 0.25 * abs(predicted), (err_blind, predicted)
    assert "cannot be told apart from the parameters" in cal_blind.process_force_line
    if scale > 1.0:  # a stated tolerance of the job's force carries its move of the estimate into the intervals
        cs = CalibrationSettings.from_job(job)
        cs = dataclasses.replace(cs, process_force=dataclasses.replace(cs.process_force, job_force_tolerance=0.05))
        _, cal_tol = eta_error(press, job, blind, cs)
        i = cal_tol.objective.problem.names.index("eta_gear")
        sd = cal_tol.process_force["interval_sd"]["eta_gear"]
        assert sd == pytest.approx(abs(cal_tol.process_force["sensitivity"]["shift"]["eta_gear"]) * 5.0 / 1.959964, rel=1e-6)
        assert cal_tol.uncertainty.joint_low[i] <= TRUTH["eta_gear"] <= cal_tol.uncertainty.joint_high[i]
        assert not cal_blind.uncertainty.joint_low[i] <= TRUTH["eta_gear"] <= cal_blind.uncertainty.joint_high[i]


def test_a_log_without_the_force_column_warns_when_the_stated_force_accuracy_leaves_eta_gear_uncertain(press, job, unlogged):
    """The true cushion force 4 % above the job's, not logged: the job's stated force accuracy (cushion_test.toml, 3 %)
    moves eta_gear by more than [calibration.process_force] warning_shift (2 %), so the calibration WARNS once, naming
    the missing column, each move and the plan's peak torque; the force scale is one of the score tests. Taken as
    exact (tolerance 0) the same fit gives no such warning (the module's one calibration of it so, ``unlogged``)."""
    rows, (_, cal_exact) = unlogged(1.04)
    err, cal = eta_error(press, job, rows)
    assert err < -0.02, err  # wrong ...
    warns = [w for w in warning_lines(cal.warnings) if w.startswith(f"WARNING: {FORCE_WARNING}")]  # ... and warned
    assert len(warns) == 1 and "no process_force_N column" in warns[0], cal.warnings
    pf = cal.process_force
    per_percent = pf["sensitivity"]["relative_shift"]["eta_gear"]
    tol = pf["job_force_tolerance"]
    assert tol == CalibrationSettings.from_job(job).process_force.job_force_tolerance > 0.0 and pf["warned"]
    assert f"eta_gear uncertain by +-{100.0 * abs(per_percent) * 100.0 * tol:.1f} %" in warns[0]
    assert "T_max" in warns[0] and "margin" in warns[0]
    assert "process_force_scale" in [t.name for t in cal.adequacy.tests]
    assert not any(w.startswith(FORCE_WARNING) for w in cal_exact.warnings) and not cal_exact.process_force["warned"]


@pytest.fixture(scope="module")
def grid(press, job):
    pm = PressModel(press)
    theta = np.radians(np.arange(360.0))
    h, hd = grid_heights(pm, theta)
    return theta, (h, hd), np.asarray(job.process(h, hd), float)


def test_the_logged_force_is_averaged_and_smoothed_without_smearing_die_contact(job, grid):
    theta, heights, F = grid
    rng = np.random.default_rng(0)
    strokes = F[None, :] * 1.03 + rng.normal(0.0, 0.01 * F.max(), size=(3, F.size))
    lf = logged_force("log", theta, strokes, heights, job.process, settings(job))
    on = F > 0
    err = lf.curve - 1.03 * F
    assert np.sqrt(np.mean(err ** 2)) < 0.5 * 0.01 * F.max() / math.sqrt(3)  # averaged, then smoothed (filter gain 0.39)
    assert np.max(np.abs(err)) < 0.01 * F.max()  # no step smeared onto its neighbours
    assert abs(lf.scale - 1.03) < 0.002 and lf.rise_deg == lf.job_rise_deg and not lf.warnings
    assert np.allclose(lf.process(*heights), lf.curve)  # the model's force at the grid points is the curve
    assert on[np.degrees(lf.steps[0]).astype(int) + 1] and not on[np.degrees(lf.steps[0]).astype(int)]


def test_a_force_rising_away_from_die_contact_is_named_or_refused(job, grid):
    theta, heights, F = grid
    lf = logged_force("log", theta, np.roll(F, 5)[None, :], heights, job.process, settings(job))
    assert len(lf.warnings) == 1 and "5.0 deg apart" in lf.warnings[0]
    with pytest.raises(PressDataError, match=r"process_force_N.*must lie within 10 deg of the job's"):
        logged_force("log", theta, np.roll(F, 20)[None, :], heights, job.process, settings(job))
    with pytest.raises(PressDataError, match=r"process_force_N.*must be positive.*multiply it by -1"):
        logged_force("log", theta, -F[None, :], heights, job.process, settings(job))


def test_a_channel_map_reads_the_force_in_kN_and_percent_of_its_rated_force(press, tmp_path):
    n = 4000
    t = np.arange(n) * 0.002
    angle = np.mod(t * 70.0, 360.0)
    speed = np.full(n, 70.0 / 6.0 * press.drive.gear_ratio)
    force_kN = 1000.0 + 100.0 * np.sin(t)
    lines = ["Time;Angle;Speed;Torque;Force"] + [f"{a:.6f};{b:.6f};{c:.6f};{d:.3f};{e:.6f}" for a, b, c, d, e in
                                                  zip(t, angle, speed, np.full(n, 5000.0), force_kN)]
    path = tmp_path / "trace.csv"
    path.write_text("\n".join(lines) + "\n")
    for unit, extra, factor in (("kN", "", 1000.0), ("%", ", rated_N = 2.0e6", 2.0e4)):
        cmap = parse_channel_map({"press": press.name, "channels": {
            "crank_angle_deg": {"name": "Angle", "unit": "deg"},
            "motor_speed_rpm": {"name": "Speed", "unit": "rpm", "side": "motor"},
            "motor_torque_Nm": {"name": "Torque", "unit": "N*m"}, "time_s": {"name": "Time", "unit": "s"},
            "process_force_N": {"name": "Force", "unit": unit, **({"rated_N": 2.0e6} if extra else {})}}}, "map.toml")
        rows = read_trace_rows(path, cmap, press)
        assert np.allclose(rows.force_N, force_kN * factor)
    with pytest.raises(PressDataError, match="rated_N"):
        parse_channel_map({"press": press.name, "channels": {
            "crank_angle_deg": {"name": "Angle", "unit": "deg"},
            "motor_speed_rpm": {"name": "Speed", "unit": "rpm", "side": "motor"},
            "motor_torque_Nm": {"name": "Torque", "unit": "N*m"}, "process_force_N": {"name": "Force", "unit": "%"}}}, "map.toml")


def test_the_force_column_is_gridded_with_the_log(press, job, tmp_path):
    """Written by the SYNTHETIC experiment without noise and read back: each turn's gridded force is the true force
    (1.02 x the job's) at the grid angles, and a log without the column has none."""
    path = experiment(press, job, tmp_path / "log.csv", cushion_force_scale=1.02, process_force_noise_of_peak=0.0)
    log = grid_rows(read_log(path, press), press.drive.gear_ratio, press.motor.rated_torque)
    assert "process_force_N" in next(line for line in path.read_text().splitlines() if not line.startswith("#"))
    pm = PressModel(press)
    h, hd = grid_heights(pm, log.theta)
    truth = 1.02 * np.asarray(job.process(h, hd), float)
    jump = np.abs(truth - np.roll(truth, 1)) > 0.1 * truth.max()
    near_step = jump | np.roll(jump, -1)  # a grid point beside a step interpolates across it
    ok = ~near_step & np.all(np.isfinite(log.stroke_force), axis=0)
    assert np.allclose(log.stroke_force[:, ok], truth[ok], rtol=0, atol=1e-3 * truth.max())
    plain = experiment(press, job, tmp_path / "plain.csv", process_force_logged=False)
    assert grid_rows(read_log(plain, press), press.drive.gear_ratio, press.motor.rated_torque).stroke_force is None


def test_the_experiment_logs_the_true_cushion_force_with_its_channel_noise(press, job, tmp_path):
    """As `servo-press experiment` writes the cushion test (the job's [experiment]): the log carries process_force_N, the
    true force (here 3 % above the job's) plus white noise of process_force_noise_of_peak times its peak, recorded in the
    header and the sidecar; [experiment] process_force_logged = false leaves the column out.

    The slide's height at each of the log's ~7,900 samples is the loop closure's (grid_heights) on the 1-degree grid
    through a periodic cubic spline: 2e-9 m off the loop closure at the samples themselves, which cost 4.6 s of CPU
    against 0.3 s, the same samples inside and the same noise figures. A sample the spline could put on the other side
    of a force step lies beside that step, which the check leaves out; the experiment's own heights are linear between
    the points of another grid (0.5 degree, with the steps' angles)."""
    st = ExperimentSettings.from_job(job)
    assert st.force_logged and 0.0 < st.force_noise_of_peak < 0.02
    path = experiment(press, job, tmp_path / "log.csv", cushion_force_scale=1.03)
    rows = read_log_rows(path)
    assert rows.force_N is not None
    sidecar = json.loads(truth_path(path).read_text())["effects"]
    sigma = st.force_noise_of_peak * 1.03 * max(job.process.forces)
    assert sidecar["process_force_logged"] and sidecar["process_force_noise_sigma_N"] == pytest.approx(sigma)
    assert any(line.startswith("# process_force_N:") for line in path.read_text().splitlines()[:8])
    pm = PressModel(press)
    grid = np.radians(np.arange(0.0, 361.0))  # the turn closed: the spline is periodic
    h_grid, _ = grid_heights(pm, grid[:-1])
    height = CubicSpline(grid, np.append(h_grid, h_grid[0]), bc_type="periodic")
    theta = np.mod(np.radians(rows.data[:, 1]), 2.0 * math.pi)
    h, hd = height(theta), height(theta, 1)  # the slide's rate at the sample: the crank turns forward at every sample
    truth = 1.03 * np.asarray(job.process(h, hd), float)
    off = rows.force_N - truth
    inside = np.abs(truth - np.roll(truth, 1)) + np.abs(truth - np.roll(truth, -1)) == 0.0  # not beside a step
    assert np.std(off[inside]) == pytest.approx(sigma, rel=0.05) and abs(np.mean(off[inside])) < 0.1 * sigma
    dropped = experiment(press, job, tmp_path / "dropped.csv", process_force_logged=False)
    assert read_log_rows(dropped).force_N is None
    assert not json.loads(truth_path(dropped).read_text())["effects"]["process_force_logged"]


@pytest.mark.parametrize("line, shown", [("process_force_noise_of_peak = -0.01", "experiment.process_force_noise_of_peak = -0.01"),
                                         ("process_force_noise_of_peak = 0.5", "experiment.process_force_noise_of_peak = 0.5"),
                                         ('process_force_logged = "yes"', "experiment.process_force_logged")])
def test_a_bad_force_channel_setting_of_the_experiment_is_refused_naming_it(tmp_path, line, shown):
    from importlib import resources

    from press_model.jobs import load_job

    text = resources.files("press_model.data").joinpath("cushion_test.toml").read_text(encoding="utf-8")
    key = line.split(" = ")[0]
    text = "\n".join(line if ln.startswith(f"{key} = ") else ln for ln in text.splitlines())
    path = tmp_path / "job.toml"
    path.write_text(text, encoding="utf-8")
    with pytest.raises(PressDataError) as exc:
        ExperimentSettings.from_job(load_job(str(path)))
    assert shown in str(exc.value) and str(path) in str(exc.value)


def test_a_grid_point_whose_bin_straddles_die_contact_takes_the_force_of_its_own_side(job, grid):
    """A die contact between two grid points leaves the bin of the point before it partly loaded (here 46 % of the step,
    so the grid angle itself lies before contact): the model's force there is the unloaded side's, not a share of the
    step no crank angle has; a bin loaded for more than half takes the loaded side's force."""
    theta, heights, F = grid
    k = int(np.flatnonzero(F > 0)[0])  # the first loaded grid point of the job's curve
    for share, loaded in ((0.46, False), (0.6, True)):
        strokes = np.repeat(F[None, :], 3, axis=0)
        strokes[:, k - 1] = share * F[k]  # the interpolated stroke mean across the step
        binned = strokes[0].copy()
        lf = logged_force("log", theta, strokes, heights, job.process, settings(job), binned)
        assert lf.curve[k - 1] == pytest.approx(F[k] if loaded else 0.0, abs=1e-6 * F[k])
        assert abs(math.degrees(lf.steps[0]) - (k - (1.5 if loaded else 0.5))) < 1e-9


@pytest.mark.parametrize("share", [0.46, 0.54])
def test_a_grid_point_at_the_slides_reversal_takes_the_force_of_its_own_direction_whatever_the_noise(share):
    """On the crank-slider press BDC is the 180-degree grid point: its bin is half downstroke (loaded) and half upstroke
    (unloaded), so its mean lies at half the step and the force channel's noise decides which side is nearer. The point
    takes the side its own direction gives (dH/dtheta <= 0 there: the downstroke's, as the job's curve does), with the
    mean a little below half the step as a little above; by the nearer side, the noise moved mu_s of a log 0.07 -> 0.11."""
    press, job = load_press("crank-slider"), load_job("crank-slider-cushion")
    theta = np.radians(np.arange(360.0))
    heights = grid_heights(PressModel(press), theta)
    F = np.asarray(job.process(*heights), float)
    k = 180
    assert abs(heights[1][k]) < 1e-12 and F[k - 1] > 0.0 and F[k] > 0.0 and F[k + 1] == 0.0  # BDC on the grid, loaded there
    strokes = np.repeat(F[None, :], 3, axis=0)
    strokes[:, k] = share * F[k - 1]
    lf = logged_force("log", theta, strokes, heights, job.process, settings(job), strokes[0].copy())
    assert lf.curve[k] == pytest.approx(F[k], abs=1e-6 * F[k])
    assert np.allclose(lf.process(*heights), lf.curve)
