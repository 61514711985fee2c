"""Several drive logs in one calibration (calibration/identification/joint.py, `calibrate --log A --job a --log B --job b`): Eq. 28 over
the logs end to end against its per-log pieces, the pairing of logs and jobs, and a joint fit on two SYNTHETIC logs."""
import json
import math
from pathlib import Path

import numpy as np
import pytest

from calibration.synthetic.experiment import write_experiment
from calibration.identification.joint import joint_objective
from calibration.identification.problem import CalibrationProblem
from calibration.identification.inputs import read_log
from calibration.identification.run import log_problem
from calibration.identification.settings import CalibrationSettings
from calibration.identification.inputs import FitChoice, LogFormat
from servo_press.calibrate import calibrate_job
from press_io.errors import ServoPressError
from press_model.jobs import load_job
from press_model.press_data import load_press

TRUTH = {"eta_gear": 0.86, "psi": 1.1, "mu_r": 0.018, "m8": 30500.0, "J_gear": 55.0, "mu_s": 0.1}  # this file's own


@pytest.fixture(scope="module")
def two_logs(tmp_path_factory):
    press, a, b = load_press(), load_job("cushion-test"), load_job("cushion-validation")
    d = tmp_path_factory.mktemp("joint")
    write_experiment(press, a, TRUTH, 41, d / "a.csv")  # SYNTHETIC, seeds 41 and 42, TRUTH above
    write_experiment(press, b, TRUTH, 42, d / "b.csv")
    return press, a, b, d / "a.csv", d / "b.csv"


def test_joint_eq28_is_built_from_the_logs_pieces(two_logs):
    """Y_RMSE over the logs end to end is the root mean of the logs' squared RMSEs weighted by the points each compares
    (outside its die-contact window); the peak is the
    largest of the logs'; the torque curves are the logs' own, end to end."""
    press, a, b, la, lb = two_logs
    cs = CalibrationSettings.from_job(a)
    prob = CalibrationProblem.from_press(press, cs.parameters, cs.weight)
    pa, pb = log_problem(press, a, cs, prob, read_log(la, press)).objective, log_problem(press, b, cs, prob, read_log(lb, press)).objective
    j = joint_objective(prob, [pa, pb])
    P = np.vstack([prob.theoretical, prob.low + 0.3 * (prob.high - prob.low)])
    T = j.torques(P)
    assert np.array_equal(T, np.hstack([pa.torques(P), pb.torques(P)]))
    ra, rb = pa.parts(pa.torques(P))[0], pb.parts(pb.torques(P))[0]
    na, nb = pa.peak_points.sum(), pb.peak_points.sum()
    assert np.allclose(j.parts(T)[0], np.sqrt((na * ra ** 2 + nb * rb ** 2) / (na + nb)), rtol=1e-12)
    assert j.measured_peak == max(pa.measured_peak, pb.measured_peak)
    assert j(prob.theoretical[None])[0] == pytest.approx(1.0)  # normalised by the theoretical values, as for one log
    assert j.bm.theta[pa.bm.n_points] == pytest.approx(2 * math.pi)  # the second log's grid after the first's turn


def test_jobs_pair_with_logs_or_one_serves_all(two_logs, tmp_path):
    with pytest.raises(ServoPressError, match="--job given 2 times for 3 --log"):
        calibrate_job(None, ["cushion-test", "cushion-test"], ["a", "b", "c"], None, LogFormat(), FitChoice(), str(tmp_path / "o"))


def test_two_logs_fitted_jointly(two_logs, tmp_path):
    """Both SYNTHETIC logs (two motions) in one least-squares fit: one parameter set, a verdict per log, both logs in
    calibrated.json, the truth's eta_gear within 2 %."""
    press, a, b, la, lb = two_logs
    job = str(tmp_path / "fast.toml")
    text = (Path(__file__).parents[1] / "press_model" / "data" / "cushion_test.toml").read_text()
    assert "[design]" in text and "\n[calibration]\n" in text
    text = text.replace("\n[calibration]\n", '\n[calibration]\ndefault_method = "least-squares"\n', 1)
    text = text.replace("[design]", '[calibration.bootstrap]\nrefits = 0\n\n[calibration.least_squares]\nstarts = 1\n\n[design]', 1)
    open(job, "w").write(text)
    _, lines = calibrate_job(None, [job, "cushion-validation"], [str(la), str(lb)], None, LogFormat(), FitChoice(), str(tmp_path / "out"))
    assert lines[0].startswith(f"SYNTHETIC log {la}, {lb}: ")
    rec = json.loads((tmp_path / "out" / "calibrated.json").read_text())
    assert [lg["source"] for lg in rec["logs"]] == [str(la), str(lb)]
    assert len(rec["adequacy"]["per_log"]) == 2 and rec["nuisance"]["logs"] == 2
    assert abs(rec["parameters"]["eta_gear"] / TRUTH["eta_gear"] - 1) < 0.02
    assert rec["logs"][1]["synthetic"]
