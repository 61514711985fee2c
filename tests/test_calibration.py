"""Calibration (Section 3.4, 4.1-4.2): synthetic experiment, Eq. 28, solvers, intervals, and the CLI.

The synthetic logs here are made from truths of the tests' own, never the default one (Table 4)."""
import json
import math
from dataclasses import replace

import numpy as np
import pytest

from calibration.traces.drive_log import read_drive_log
from calibration.synthetic.experiment import ExperimentSettings, synthetic_log, write_experiment
from calibration.identification.problem import CalibrationProblem, objective
from calibration.identification.run import calibrate
from calibration.identification.speed_fit import crank_motion
from calibration.identification.settings import CalibrationSettings
from calibration.identification.uncertainty import jacobian
from servo_press.calibrate import write_outputs
from servo_press.cli import main
from press_model.cycle import motor_torque_at

# a truth of this test file's own (synthetic): every key parameter off its theoretical value and off Table 4
OWN_TRUTH = {"eta_gear": 0.875, "psi": 1.21, "mu_r": 0.02, "m8": 28500.0, "J_gear": 49.0, "mu_s": 0.15}
SIX = ("eta_gear", "psi", "mu_r", "m8", "J_gear", "mu_s")
JOB = "cushion-test"  # the shipped job the `job` fixture (conftest.py) reads


@pytest.fixture(scope="module")
def own_log(tmp_path_factory, press, job):
    path = tmp_path_factory.mktemp("exp") / "own.csv"
    write_experiment(press, job, OWN_TRUTH, 11, path)
    return path


@pytest.fixture(scope="module")
def own_calibration(press, job, own_log):
    cs = CalibrationSettings.from_job(job)
    return calibrate(press, job, own_log, [cs.default_method], seed=3, progress=False)


def test_calibration_recovers_own_truth(own_calibration):
    """Acceptance: eta_gear and psi within 2 %, RMSE at least halved."""
    cal = own_calibration
    got = dict(zip(cal.objective.problem.names, cal.best.x))
    for name in ("eta_gear", "psi"):
        assert got[name] == pytest.approx(OWN_TRUTH[name], rel=0.02), name
    assert cal.after["rmse_Nm"] <= 0.5 * cal.before["rmse_Nm"]
    # a better fit than theory on the thermal figure too
    assert abs(cal.after["thermal_error"]) < abs(cal.before["thermal_error"])


def test_intervals_cover_the_truth_for_identified_parameters(own_calibration):
    """The reported (bootstrap) intervals: the Jacobian's are least squares', narrower than Eq. 28's estimator scatters
    (its peak term pins the fit to a noisy peak), a labelled second opinion only."""
    cal = own_calibration
    u, b = cal.uncertainty, cal.bootstrap
    for n, lo, hi in zip(u.names, b.low, b.high):
        if n in ("eta_gear", "psi"):
            assert lo <= OWN_TRUTH[n] <= hi, (n, lo, hi)
    assert np.allclose(u.correlation, u.correlation.T) and np.allclose(np.diag(u.correlation), 1.0)
    assert any("identified" in s for s in u.statements)


def test_objective_matches_per_point_model_on_the_log_motion(press, job, own_log):
    """The batch objective's torque on the log's own (fitted) motion equals the Pinocchio per-point path."""
    from press_model.batch import build_batch_model
    from press_model.model import PressModel

    log = read_drive_log(own_log, press.drive.gear_ratio, press.motor.rated_torque)
    motion = crank_motion(log, CalibrationSettings.from_job(job))
    bm = build_batch_model(press, motion, job.process)
    prob = CalibrationProblem.from_press(press, SIX, 0.3)
    obj = objective(prob, bm, log.torque)
    P = np.array([[OWN_TRUTH[n] for n in SIX]])
    T_batch = obj.torques(P)[0]
    pm = PressModel(press.with_overrides(OWN_TRUTH, "test"))
    th = bm.theta[::15]
    T_point = motor_torque_at(pm, job.process, th, motion.theta_dot(th), motion.theta_ddot(th))
    assert np.max(np.abs(T_batch[::15] - T_point)) < 1e-6 * np.max(np.abs(T_point))
    assert obj(prob.theoretical[None])[0] == pytest.approx(1.0)  # Eq. 28 is normalised by the theoretical values


def test_noise_free_experiment_reads_back_as_the_model(press, job, tmp_path):
    """With the unmodelled effects switched off, log -> grid gives the truth's model torque: checks the
    time inversion, the interpolation across the die-contact step and the reader together."""
    from press_model.jobs import make_motion
    from press_model.model import PressModel

    quiet = replace(ExperimentSettings.from_job(job), noise_sigma=0.0, oscillation=0.0)
    res = synthetic_log(press, job, OWN_TRUTH, 0, quiet)
    c = res["columns"]
    from calibration.traces.drive_log import write_drive_log

    path = tmp_path / "quiet.csv"
    write_drive_log(path, c["time_s"], c["crank_angle_deg"], c["motor_speed_rpm"], c["motor_torque_Nm"], ["synthetic test log"])
    log = read_drive_log(path, press.drive.gear_ratio, press.motor.rated_torque)
    motion = make_motion(job.motion, job.source)
    pm = PressModel(press.with_overrides(OWN_TRUTH, "test"))
    th = log.theta
    want = motor_torque_at(pm, job.process, th, motion.theta_dot(th), motion.theta_ddot(th))
    # a grid point closer to a force step than one sample (0.14 deg) mixes both sides of the step in the
    # samples' linear interpolation, as it would in a real log: 71 deg lies 0.07 deg before die contact
    from press_model.kinematics import force_step_angles

    far = np.ones(len(th), dtype=bool)
    for a in force_step_angles(pm, job.process):
        far &= np.abs(np.angle(np.exp(1j * (th - a)))) > math.radians(0.2)
    assert (~far).sum() <= 2
    assert np.max(np.abs(log.torque - want)[far]) < 2.0  # N m: the 0.25-deg model table and 3-decimal file
    assert np.max(np.abs(log.crank_speed - motion.theta_dot(th))) < 1e-6
    assert log.synthetic


def test_experiment_is_labelled_and_reproducible(press, job, tmp_path):
    a, b = tmp_path / "a" / "log.csv", tmp_path / "b" / "log.csv"
    write_experiment(press, job, OWN_TRUTH, 5, a)
    write_experiment(press, job, OWN_TRUTH, 5, b)
    assert a.read_bytes() == b.read_bytes()
    assert (tmp_path / "a" / "log.truth.json").read_bytes() == (tmp_path / "b" / "log.truth.json").read_bytes()
    assert "SYNTHETIC" in a.read_text().splitlines()[0]
    truth = json.loads((tmp_path / "a" / "log.truth.json").read_text())
    assert truth["synthetic"] is True and truth["seed"] == 5 and truth["truth"] == OWN_TRUTH
    write_experiment(press, job, OWN_TRUTH, 6, b)
    assert a.read_bytes() != b.read_bytes()  # the seed drives the noise


def test_jacobian_matches_a_directional_difference(press, job, own_calibration):
    obj = own_calibration.objective
    x = own_calibration.best.x
    J = jacobian(obj, x)
    d = 1e-3 * (obj.problem.high - obj.problem.low)
    fd = (obj.residuals(x + d) - obj.residuals(x - d)) / 2.0
    assert np.max(np.abs(J @ d - fd)) < 1e-3 * np.max(np.abs(fd))


@pytest.fixture(scope="module")
def own_outputs(press, job, own_calibration, tmp_path_factory):
    """calibrate's folder of ``own_calibration`` (seed 3) as write_outputs writes it, once for the two tests that read
    it: (the folder, the record it returns). Read only."""
    out = tmp_path_factory.mktemp("own-outputs")
    return out, write_outputs(own_calibration, press, job, 3, out)


def test_calibrated_json_and_tables(own_outputs):
    tmp_path, rec = own_outputs
    on_disk = json.loads((tmp_path / "calibrated.json").read_text())
    assert list(on_disk["parameters"]) == list(SIX)
    assert set(on_disk["intervals"]) == set(SIX)
    for key in ("rmse_before_Nm", "rmse_after_Nm", "peak_error_before_Nm", "peak_error_after_Nm",
                "thermal_error_before", "thermal_error_after"):
        assert math.isfinite(on_disk["metrics"][key])
    assert on_disk["log"]["synthetic"] is True and "versions" in on_disk
    md = (tmp_path / "table4.md").read_text()
    assert "SYNTHETIC" in md and "1366.9" in md
    assert (tmp_path / "figure5.png").stat().st_size > 10_000
    assert rec["parameters"] == on_disk["parameters"]


def test_calibrated_json_feeds_simulate(own_outputs, tmp_path):
    """simulate on a 10-degree grid: the parameters it reads from calibrated.json and records are the same on any grid
    (the default 1-degree simulation costs ~1 s of CPU more)."""
    cal = own_outputs[0]
    assert main(["simulate", "--params", str(cal / "calibrated.json"), "--step-deg", "10", "--out", str(tmp_path / "sim")]) == 0
    used = json.loads((tmp_path / "sim" / "summary.json").read_text())["parameters"]
    got = json.loads((cal / "calibrated.json").read_text())["parameters"]
    assert all(used[k] == pytest.approx(v) for k, v in got.items())


@pytest.mark.parametrize("args, needle", [
    (["--method", "simplex"], "invalid choice"),
    (["--parameters", "eta_gear,nonsense"], "nonsense"),
    (["--parameters", "missing_file.json"], "missing_file.json"),
])
def test_calibrate_cli_refuses_bad_requests(own_log, tmp_path, capsys, args, needle):
    with pytest.raises(SystemExit) if "simplex" in args else _nothing():
        code = main(["calibrate", "--log", str(own_log), *args, "--out", str(tmp_path / "o")])
        assert code == 2
    err = capsys.readouterr().err
    assert needle in err and "Traceback" not in err


def test_calibrate_cli_never_overwrites_the_log(own_log, tmp_path, capsys):
    before = own_log.read_bytes()
    out = own_log.parent / "calibrated.json"
    out.write_bytes(b"")  # make --out/calibrated.json a file that exists ... but is not the log
    assert main(["calibrate", "--log", str(out), "--out", str(own_log.parent)]) == 2
    assert own_log.read_bytes() == before
    assert "input file" in capsys.readouterr().err


class _nothing:
    def __enter__(self):
        return self

    def __exit__(self, *exc):
        return False
