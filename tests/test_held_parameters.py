"""A calibration of a subset of the job's parameters checks the ones it holds (calibration/identification/held.py): each
held parameter is a score test beside the adequacy's suspects, its column the model curve's derivative along it.

Without a press model first (a curve and its known misfit): the test's implied size is the held parameter's error and
freeing it takes the lack of fit back to the noise. Then on a SYNTHETIC log of the reference press whose J_gear is 10 %
above the press file's (every other parameter at its file value): a calibration of the sensitivity's four (eta_gear,
mu_r, m8, psi) holding J_gear names it, and frees it unless told not to."""
from __future__ import annotations

import json
import re
from importlib import resources

import numpy as np
import pytest

import in_process  # noqa: E402 (tests/ is on sys.path, conftest.py)
from calibration.identification.adequacy import Candidate, Suspects, assess
from press_model.cycle import crank_grid

TH = crank_grid(1.0)
CURVE = 8000.0 * np.sin(TH) + 3000.0 * np.cos(2 * TH) + 1500.0 * np.sin(3 * TH + 0.4)
MASK = np.abs(TH - 2.0) > 0.3  # a die-contact-like window left out
J_TRUE = 1.10 * 54.4  # kg m^2: the reference press's J_gear 10 % up


def test_held_column_names_the_misfit_and_freeing_it_restores_the_fit():
    """The model misses the log by 3 units of a held parameter's column (a smooth curve of its own, no combination of
    the calibrated parameters' columns): its score test implies a change of 3 within its 4 standard errors, it is
    significant, and the lack-of-fit F once it is freed falls to the noise's: F is 1 + misfit / noise variance of the mean,
    here 1 + (120 / sqrt 2)^2 / (150^2 / 3) = 1.96 held and 1 freed, each to about 0.1 (its standard deviation on some 330
    points: sqrt(2 / 330 + 2 / 660)), so 0.3 apart from either is three of them."""
    rng = np.random.default_rng(3)
    J = np.column_stack([np.sin(TH), np.cos(2 * TH)]) * 1000.0  # two calibrated parameters' columns
    z = 40.0 * np.sin(5 * TH + 0.3)  # N m per unit of the held parameter
    Y = CURVE + 3.0 * z + rng.normal(0.0, 150.0, (3, TH.size))
    held = Candidate("k_held", "k_held held at 1", z[:, None], "1", 1.0, held=1.0)
    a = assess(Y, Y.mean(axis=0), CURVE, MASK, 2, 0.01, Suspects(J, [held]))
    t = a.tests[0]
    assert t.held == 1.0 and t.significant and not a.adequate
    assert abs(t.size - 3.0) < 4.0 * t.size_std
    assert abs(a.lack_of_fit_ratio - 1.96) < 0.3 and abs(t.lof_if_freed - 1.0) < 0.3


def test_held_parameter_at_its_true_value_is_not_named():
    """The same log with the held parameter right (no misfit along its column): no held parameter is named."""
    rng = np.random.default_rng(4)
    J = np.column_stack([np.sin(TH), np.cos(2 * TH)]) * 1000.0
    z = 40.0 * np.sin(5 * TH + 0.3)
    Y = CURVE + rng.normal(0.0, 150.0, (3, TH.size))
    a = assess(Y, Y.mean(axis=0), CURVE, MASK, 2, 0.01, Suspects(J, [Candidate("k_held", "k_held held at 1", z[:, None], "1", 1.0,
                                                                            held=1.0)]))
    assert a.adequate and not a.tests[0].significant


@pytest.fixture(scope="module")
def j_gear_log(tmp_path_factory):
    """A SYNTHETIC cushion-test log (seed 5) of the reference press with J_gear 10 % above its file value, and the
    cushion-test job without bootstrap refits (the Jacobian intervals: the held test does not use them) with the
    adequacy's free_held set as the test asks."""
    d = tmp_path_factory.mktemp("held")
    (d / "truth.json").write_text(json.dumps({"J_gear": J_TRUE}), encoding="utf-8")
    r = in_process.servo_press("experiment", "--truth", d / "truth.json", "--seed", "5", "--out", d / "log.csv")
    assert r.returncode == 0, r.stderr
    text = resources.files("press_model.data").joinpath("cushion_test.toml").read_text(encoding="utf-8")
    for free in ("true", "false"):
        (d / f"job_{free}.toml").write_text(
            text + f"\n[calibration.bootstrap]\nrefits = 0\n\n[calibration.adequacy]\nfree_held = {free}\n", encoding="utf-8")
    return d


def _calibrate(d, free: str):
    r = in_process.servo_press("calibrate", "--log", d / "log.csv", "--job", d / f"job_{free}.toml", "--parameters",
                               "eta_gear,mu_r,m8,psi", "--method", "least-squares", "--out", d / f"cal_{free}")
    assert r.returncode == 0 and "Traceback" not in r.stderr, r.stderr
    return r, json.loads((d / f"cal_{free}" / "calibrated.json").read_text(encoding="utf-8"))


def test_subset_calibration_names_the_held_parameter_that_is_wrong(j_gear_log):
    """free_held = false: the subset is kept, and a WARNING names J_gear (held at 54.4, the log implying about its
    truth) and no other held parameter (psi, m8 and mu_s of the job's six are held at their true values)."""
    r, cal = _calibrate(j_gear_log, "false")
    warned = [w for w in cal["warnings"] if w.startswith("HELD PARAMETER WRONG")]
    assert len(warned) == 1 and "J_gear held at 54.4" in warned[0] and "mu_s" not in warned[0], cal["warnings"]
    assert "HELD PARAMETER WRONG" in r.stderr
    assert set(cal["parameters"]) == {"eta_gear", "mu_r", "m8", "psi"}
    tests = cal["adequacy"]["score_tests"]
    assert tests["J_gear"]["significant"] and tests["J_gear"]["held_value"] == pytest.approx(54.4)
    implied = tests["J_gear"]["held_value"] + tests["J_gear"]["size"]
    assert abs(implied - J_TRUE) < 4.0 * tests["J_gear"]["size_std"]  # the size the log implies is the error, to its noise
    assert not tests["mu_s"]["significant"]


def test_subset_calibration_frees_the_held_parameter_that_is_wrong(j_gear_log):
    """By default J_gear is freed and the fit repeated: calibrated.json holds it, its interval holds the truth, and a
    WARNING says what freeing it did."""
    r, cal = _calibrate(j_gear_log, "true")
    assert "J_gear" in cal["parameters"] and "mu_s" not in cal["parameters"]
    lo, hi = cal["intervals"]["J_gear"]
    assert lo <= J_TRUE <= hi
    freed = cal["held_parameters"]
    assert list(freed["freed"]) == ["J_gear"] and freed["held"] == ["mu_s"]
    said = freed["statement"]
    assert said.startswith("HELD PARAMETER FREED") and "J_gear held at 54.4" in said and re.search(r"RMSE [\d.]+ -> [\d.]+ N m", said)
    assert f"WARNING: {said}" in r.stderr
    # a fit freed to adequacy is one to trust: the statement is not among the warnings `plan` repeats
    assert cal["adequacy"]["adequate"] and not any(w.startswith("HELD PARAMETER") for w in cal["warnings"])
