"""Clean SYNTHETIC logs (no effect the model lacks): the estimate carries no bias of the method's own, and the
adequacy test raises no alarm whatever the motion.

The truths are this file's own (synthetic), never the default one (Table 4)."""
from dataclasses import replace

import numpy as np
import pytest

import calibration.synthetic.experiment as experiment
from calibration.identification.run import calibrate
from calibration.identification.speed_fit import crank_motion
from calibration.identification.settings import CalibrationSettings
from press_model.settings_fields import replaced
from calibration.synthetic.experiment import ExperimentSettings, synthetic_log, write_experiment
from calibration.synthetic.motions import TwoSpeedMotion
from calibration.traces.drive_log import columns_rows, grid_rows
from press_model.cycle import motor_torque_at
from press_model.jobs import make_motion
from press_model.kinematics import force_step_angles
from press_model.model import PressModel

TRUTH = {"eta_gear": 0.86, "psi": 1.12, "mu_r": 0.016, "m8": 31000.0, "J_gear": 55.0, "mu_s": 0.11}
JOB = "cushion-test"  # the shipped job the `job` fixture (conftest.py) reads


def test_grid_points_beside_a_force_step_take_the_log_on_the_models_side(press, job):
    """Gridded with the force steps, a noise-free log is the truth's model torque at every grid point, the ones a
    sample step from die contact and BDC included (interpolated across the step, 71 deg took 1.7 kN m of contact)."""
    quiet = replace(ExperimentSettings.from_job(job), noise_sigma=0.0, oscillation=0.0)
    c = synthetic_log(press, job, TRUTH, 0, quiet)["columns"]
    data = np.column_stack([c["time_s"], np.mod(c["crank_angle_deg"], 360.0), c["motor_speed_rpm"], c["motor_torque_Nm"]])
    rows = columns_rows("quiet.csv", ["synthetic test log"], data, np.arange(len(data)) + 1, ())
    pm = PressModel(press.with_overrides(TRUTH, "test"))
    steps = force_step_angles(pm, job.process)
    motion = make_motion(job.motion, job.source)
    g = press.drive.gear_ratio, press.motor.rated_torque
    plain, sided = grid_rows(rows, *g), grid_rows(rows, *g, force_steps_deg=np.degrees(steps))
    th = sided.theta
    want = motor_torque_at(pm, job.process, th, motion.theta_dot(th), motion.theta_ddot(th))
    assert np.max(np.abs(plain.torque - want)) > 1000.0  # the grid point before die contact, interpolated across it
    # at most one sample step (0.14 deg) from the grid point on its own side: the torque's slope there times that
    assert np.max(np.abs(sided.torque - want)) < 30.0


@pytest.mark.parametrize("ringing", [False, True], ids=["no ringing", "die-contact ringing"])
def test_noise_free_log_gives_the_truth_with_or_without_die_contact_ringing(press, job, tmp_path, ringing):
    """No noise: every error is the method's. The grid point next to die contact pulled J_gear 2 % low; the ringing
    after contact, left in Y_RMSE, 5 % low."""
    base = ExperimentSettings.from_job(job)
    log = tmp_path / "quiet.csv"
    write_experiment(press, job, TRUTH, 0, log, settings=replace(base, noise_sigma=0.0, oscillation=base.oscillation if ringing else 0.0))
    cal = calibrate(press, job, log, ["least-squares"], settings=replaced(CalibrationSettings.from_job(job), {"bootstrap.refits": 0}), seed=0, progress=False)
    got = dict(zip(cal.objective.problem.names, cal.best.x))
    assert got["J_gear"] == pytest.approx(TRUTH["J_gear"], rel=0.005)
    for n in ("eta_gear", "psi", "m8"):
        assert got[n] == pytest.approx(TRUTH[n], rel=0.001), n


@pytest.mark.parametrize("ramp_deg, seed", [(30.0, 5), (15.0, 0)], ids=["30-degree ramps", "15-degree ramps"])
def test_clean_log_of_a_two_speed_motion_is_adequate(press, job, tmp_path, monkeypatch, ramp_deg, seed):
    """The crank acceleration taken from the log's own samples: a fixed 24 harmonics left the changes of speed an
    acceleration error the adequacy test called NOT ADEQUATE on a clean log, and with 15-degree ramps so did the 178
    harmonics a 1-degree grid holds (3.7 % of the peak acceleration where a ramp ends, F = 1.36 on this log)."""
    # SYNTHETIC motion: 0.6 rad/s from 30 to 200 deg, 2.0 rad/s elsewhere, raised-cosine ramps
    motion = TwoSpeedMotion(0.6, 2.0, 30.0, 200.0, ramp_deg)
    monkeypatch.setattr(experiment, "make_motion", lambda spec, source: motion)
    log = tmp_path / "two_speed.csv"
    write_experiment(press, job, TRUTH, seed, log)
    cs = CalibrationSettings.from_job(job)
    cal = calibrate(press, job, log, ["least-squares"], settings=replaced(cs, {"bootstrap.refits": 0}), seed=0, progress=False)
    assert cal.adequacy.adequate, cal.adequacy.reasons
    th = cal.log.theta
    truth = motion.theta_ddot(th)
    assert np.max(np.abs(crank_motion(cal.log, cs).theta_ddot(th) - truth)) < 0.02 * np.max(np.abs(truth))


# SYNTHETIC truth for the crank-slider example press, this file's own (inside each calibration range)
CRANK_SLIDER_TRUTH = {"eta_gear": 0.9, "psi": 1.1, "mu_r": 0.02, "m3": 8600.0, "J_gear": 0.55, "mu_s": 0.1}


def _crank_slider():
    from press_model.jobs import load_job
    from press_model.press_data import load_press

    return load_press("crank-slider"), load_job("crank-slider-cushion")


def test_grid_point_on_a_force_step_takes_the_loaded_side_as_eq_14_does():
    """The crank-slider's BDC lies on a grid point (180 deg). Eq. 14 counts a step's own angle as loaded (H <= H_p, the
    slide moving down or standing), so the model has the cushion's friction there; the gridded noise-free log must too
    (it took the sample after BDC, 99 N m off, which pulled eta_gear 1.6 % and mu_s 46 % low)."""
    press, job = _crank_slider()
    quiet = replace(ExperimentSettings.from_job(job), noise_sigma=0.0, oscillation=0.0, force_logged=False)
    c = synthetic_log(press, job, CRANK_SLIDER_TRUTH, 0, quiet)["columns"]
    data = np.column_stack([c["time_s"], np.mod(c["crank_angle_deg"], 360.0), c["motor_speed_rpm"], c["motor_torque_Nm"]])
    rows = columns_rows("quiet.csv", ["synthetic test log"], data, np.arange(len(data)) + 1, ())
    pm = PressModel(press.with_overrides(CRANK_SLIDER_TRUTH, "test"))
    steps = force_step_angles(pm, job.process)
    assert np.degrees(steps[1]) == pytest.approx(180.0, abs=1e-9)  # BDC on the 1-degree grid: the case at stake
    motion = make_motion(job.motion, job.source)
    log = grid_rows(rows, press.drive.gear_ratio, press.motor.rated_torque, force_steps_deg=np.degrees(steps))
    th = log.theta
    want = motor_torque_at(pm, job.process, th, motion.theta_dot(th), motion.theta_ddot(th))
    # the interpolation's own error is 0.02 N m; the nearest loaded sample alone, up to 0.14 deg before BDC, was 6 N m off
    assert np.max(np.abs(log.torque - want)) < 1.0


def test_noise_free_crank_slider_log_gives_the_truth():
    """No noise, no ringing, on the press whose BDC lies on a grid point: every error is the method's."""
    import tempfile
    from pathlib import Path

    press, job = _crank_slider()
    quiet = replace(ExperimentSettings.from_job(job), noise_sigma=0.0, oscillation=0.0, force_noise_of_peak=0.0)
    with tempfile.TemporaryDirectory() as tmp:
        log = Path(tmp) / "quiet.csv"
        write_experiment(press, job, CRANK_SLIDER_TRUTH, 0, log, settings=quiet)
        cal = calibrate(press, job, log, ["least-squares"], settings=replaced(CalibrationSettings.from_job(job), {"bootstrap.refits": 0}), seed=0, progress=False)
    got = dict(zip(cal.objective.problem.names, cal.best.x))
    assert got["eta_gear"] == pytest.approx(CRANK_SLIDER_TRUTH["eta_gear"], rel=0.001)
    for n in ("psi", "m3"):
        assert got[n] == pytest.approx(CRANK_SLIDER_TRUTH[n], rel=0.002), n


def test_logged_force_takes_the_torques_side_at_die_contact_just_before_a_grid_point(tmp_path):
    """A fast designed run of the crank-slider (40 spm, die contact at 133.97 deg, 0.03 deg before a grid point, about
    three samples a degree): the logged force, read across the step, left that grid point a quarter of the force and the
    model's force was snapped unloaded there while the torque's grid point was loaded (1.97 kN m at one point). Noise-
    free, the model at the truth must follow the gridded log everywhere it is fitted."""
    from calibration.identification.inputs import read_log
    from calibration.identification.problem import CalibrationProblem
    from calibration.identification.run import log_problem
    from press_model.jobs import load_job

    press, _ = _crank_slider()
    src = resources_text("crank_slider_cushion.toml")
    src = src.replace("strokes_per_min = 20.0", "strokes_per_min = 40.0").replace("speed_depth = 0.4", "speed_depth = 0.7")
    src = src.replace("slow_angle_deg = 150.0", "slow_angle_deg = 180.0")
    src = src.replace("contact_height_m = 0.10", "contact_height_m = 0.09").replace("heights_m = [0.10, 0.0]", "heights_m = [0.09, 0.0]")
    path = tmp_path / "fast_run.toml"
    path.write_text(src)
    job = load_job(str(path))
    quiet = replace(ExperimentSettings.from_job(job), noise_sigma=0.0, oscillation=0.0, force_noise_of_peak=0.0)
    log = tmp_path / "fast_run.csv"
    write_experiment(press, job, CRANK_SLIDER_TRUTH, 1, log, settings=quiet)
    cs = CalibrationSettings.from_job(job)
    prob = CalibrationProblem.from_press(press, cs.parameters, cs.weight)
    lp = log_problem(press, job, cs, prob, read_log(log, press))
    assert lp.force is not None  # the model runs on the logged force
    o = lp.objective
    truth = np.array([CRANK_SLIDER_TRUTH[n] for n in prob.names])
    r = o.residuals(truth)
    steps = np.array(force_step_angles(PressModel(press), job.process))
    near = np.min(np.abs(np.angle(np.exp(1j * (o.bm.theta[:, None] - steps[None, :])))), axis=1) <= np.radians(2.0)
    assert np.max(np.abs(r[near])) < 5.0  # 1.2 N m left at BDC, on the step: the line through two samples 0.5 deg apart
    assert np.max(np.abs(r)) < 20.0  # elsewhere: 8.7 N m at TDC (no step there; not chased here), 0.2 N m or less beside it


def resources_text(name: str) -> str:
    from importlib import resources

    return resources.files("press_model.data").joinpath(name).read_text(encoding="utf-8")


@pytest.fixture(scope="module")
def ringing_log(tmp_path_factory):
    """``ringing_log(frequency_Hz, decay_s)``: the path of the noise-free SYNTHETIC crank-slider log (CRANK_SLIDER_TRUTH,
    seed 0, the job's [experiment] without noise on the torque or the force) with die-contact ringing of that frequency
    and decay, written once a ringing for the module (the job's own ringing is read by two tests)."""
    made = {}

    def get(frequency_Hz, decay_s):
        if (frequency_Hz, decay_s) not in made:
            press, job = _crank_slider()
            ringing = replace(ExperimentSettings.from_job(job), noise_sigma=0.0, force_noise_of_peak=0.0,
                              frequency=frequency_Hz, decay=decay_s)
            made[frequency_Hz, decay_s] = tmp_path_factory.mktemp("ringing") / "ringing.csv"
            write_experiment(press, job, CRANK_SLIDER_TRUTH, 0, made[frequency_Hz, decay_s], settings=ringing)
        return made[frequency_Hz, decay_s]

    return get


@pytest.mark.parametrize("frequency_Hz, decay_s", [(15.0, 0.03), (12.0, 0.04), (22.0, 0.02)],
                         ids=["job's ringing", "12 Hz 40 ms", "22 Hz 20 ms"])
def test_measured_peak_just_after_the_die_contact_window_does_not_read_the_ringing(ringing_log, frequency_Hz, decay_s):
    """The crank-slider job's peak lies on the first point after the die-contact window, and the peak filter's window
    reaches into it: on a noise-free log with ringing the filtered measured peak read the ringing (+2.8 N m at 15 Hz,
    -2.5 N m at 12 Hz). The ringing, fitted in the log with its frequency and decay unknown, is removed first."""
    from calibration.identification.inputs import read_log
    from calibration.identification.peak import filter_curve
    from calibration.identification.problem import CalibrationProblem
    from calibration.identification.run import log_problem

    press, job = _crank_slider()
    cs = CalibrationSettings.from_job(job)
    prob = CalibrationProblem.from_press(press, cs.parameters, cs.weight)
    lp = log_problem(press, job, cs, prob, read_log(ringing_log(frequency_Hz, decay_s), press, "N*m", None))
    o = lp.objective
    truth = o.torques(np.array([[CRANK_SLIDER_TRUTH[n] for n in prob.names]]))[0]
    filtered = filter_curve(o.bm.theta, truth, lp.steps, cs.peak_filter_window_deg, cs.peak_filter_order)
    jm = int(np.flatnonzero(o.peak_points)[np.argmax(np.abs(filtered[o.peak_points]))])
    assert o.peak_points[jm - 1] == False  # noqa: E712  the case at stake: the peak on the window's first point after
    assert lp.peak.value_Nm == pytest.approx(abs(filtered[jm]), abs=0.1)
    assert lp.ringing.frequency_Hz == pytest.approx(frequency_Hz, rel=0.02)


def test_noise_free_crank_slider_log_with_ringing_gives_eta_gear(ringing_log):
    """Eq. 28 with its peak term (the job's method) on a noise-free log with the job's die-contact ringing: the ringing
    read by the peak filter put eta_gear 0.14-0.28 % low."""
    press, job = _crank_slider()
    cs = CalibrationSettings.from_job(job)
    st = ExperimentSettings.from_job(job)
    log = ringing_log(st.frequency, st.decay)  # the job's ringing: the log the peak test above reads too
    cal = calibrate(press, job, log, [cs.default_method], settings=replaced(CalibrationSettings.from_job(job), {"bootstrap.refits": 0}), seed=0, progress=False)
    got = dict(zip(cal.objective.problem.names, cal.best.x))
    assert got["eta_gear"] == pytest.approx(CRANK_SLIDER_TRUTH["eta_gear"], rel=0.0005)
