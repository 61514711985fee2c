"""Fixtures of the tests of identification statistics (test_logged_force_accuracy, test_recording*, ...), shared across
their modules and with the others that read the same result (conftest.py's ``pytest_plugins``; tests/ is on sys.path)."""
from __future__ import annotations

import pytest


def _twin_drive_experiment(folder):
    from in_process import servo_press

    r = servo_press("experiment", "--seed", TWIN_SEED, "--effect", f"motor1_share={TWIN_SHARE}", "--out", folder / "logs" / "twin.csv")
    assert r.returncode == 0, r.stderr


TWIN_SEED, TWIN_SHARE = 7, 0.53  # the twin-drive log's seed and motor 1's share of the total torque (motor 2: 0.47)


@pytest.fixture(scope="session")
def twin_drive_log(heavy_results):
    """A SYNTHETIC twin-drive log, `servo-press experiment --seed 7 --effect motor1_share=0.53` (the cushion test's
    truth, motor 1 carrying 53 % of the torque), written once for the suite (heavy_results.py): its path, alone in its
    folder with its truth sidecar. Read only."""
    folder, _ = heavy_results.get("experiment-twin-drive", _twin_drive_experiment, TWIN_SEED, TWIN_SHARE)
    return folder / "logs" / "twin.csv"


def one_stroke_settings(job):
    """The job's [experiment] for one stroke on a 1-degree model grid, without noise, ringing or any effect: the plain
    log the tests of single effects compare with (test_log_effects, test_drag_and_backlash_suspects)."""
    import dataclasses
    import math

    from calibration.synthetic.effects import LogEffects
    from calibration.synthetic.experiment import ExperimentSettings

    return dataclasses.replace(ExperimentSettings.from_job(job), strokes=1, model_step=math.radians(1.0), noise_sigma=0.0,
                               oscillation=0.0, effects=LogEffects())


def _one_stroke_plain(folder):
    from calibration.synthetic.experiment import synthetic_log
    from press_model.jobs import load_job
    from press_model.press_data import load_press

    job = load_job("cushion-test")
    return synthetic_log(load_press(), job, {}, 5, one_stroke_settings(job))["columns"]


@pytest.fixture(scope="session")
def one_stroke_plain_log(heavy_results):
    """The columns (name -> array) of the SYNTHETIC cushion-test log of ``one_stroke_settings`` on the reference press,
    the job's truth, seed 5, made once for the suite (heavy_results.py). Read only."""
    return heavy_results.get("one-stroke-plain-log", _one_stroke_plain)[1]
