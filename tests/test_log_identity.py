"""Which drive logs are one recording (calibration/traces/log_identity.py), and the joint fit's settings of several jobs.

The logs are cut from one SYNTHETIC log of ``servo-press experiment`` (seed 0) and a second recording of the same
motion (seed 1: other noise). The share of shared samples is known by construction: a log's first half shares all
its samples with the whole log, the whole log half of its samples with that half; the seed-1 recording shares none.
"""
from __future__ import annotations

import shutil

import pytest

from calibration.identification.settings import joint_settings_warning
from calibration.traces.drive_log import read_drive_log
from calibration.traces.log_identity import refuse_duplicates, shared_share, validation_share
from servo_press.cli import main
from press_io.errors import PressDataError
from press_model.jobs import load_job
from press_model.press_data import load_press

PRESS = load_press()


@pytest.fixture(scope="module")
def recordings(tmp_path_factory, synthetic_log):
    d = tmp_path_factory.mktemp("identity")
    shutil.copyfile(synthetic_log, d / "seed0.csv")  # `experiment --seed 0` (conftest.py: written once a session)
    assert main(["experiment", "--seed", "1", "--out", str(d / "seed1.csv")]) == 0
    lines = (d / "seed0.csv").read_text(encoding="utf-8").splitlines()
    head = sum(1 for ln in lines if not ln[:1].isdigit())
    rows = lines[head:]
    (d / "half.csv").write_text("\n".join(lines[:head] + rows[:len(rows) // 2]) + "\n", encoding="utf-8")
    read = (lambda name: read_drive_log(d / name, PRESS.drive.gear_ratio, PRESS.motor.rated_torque))
    return {name: read(f"{name}.csv") for name in ("seed0", "seed1", "half")}


def test_the_share_of_shared_samples_is_that_of_the_construction(recordings):
    whole, half, other = (recordings[k].samples for k in ("seed0", "half", "seed1"))
    assert shared_share(half, whole, 1e-6) == 1.0
    assert shared_share(whole, half, 1e-6) == pytest.approx(len(half) / len(whole), abs=1.0 / len(whole))
    assert shared_share(other, whole, 1e-6) == 0.0  # the same motion, other noise: no sample the same


def test_a_part_of_a_fitted_recording_is_refused_as_a_second_log_and_half_a_validation_is_returned(recordings):
    with pytest.raises(PressDataError, match="is the recording of --log"):
        refuse_duplicates([recordings["seed0"], recordings["half"]])
    refuse_duplicates([recordings["seed0"], recordings["seed1"]])
    assert validation_share([recordings["half"]], recordings["seed0"]) == pytest.approx(0.5, abs=1e-3)
    assert validation_share([recordings["seed0"]], recordings["seed1"]) == 0.0
    with pytest.raises(PressDataError, match="holds the samples of the fitted log"):
        validation_share([recordings["seed1"], recordings["seed0"]], recordings["half"])


def test_jobs_whose_calibration_settings_differ_are_named_in_one_warning(tmp_path):
    from importlib import resources

    text = resources.files("press_model.data").joinpath("cushion_test.toml").read_text(encoding="utf-8")
    other = tmp_path / "other.toml"
    assert "\nparameters = " in text  # [calibration] leaves weight to its default, 0.3
    other.write_text(text.replace("\nparameters = ", "\nweight = 0.25\nparameters = ", 1), encoding="utf-8")
    first, second = load_job("cushion-test"), load_job(other)
    assert joint_settings_warning([first, first]) is None
    warning = joint_settings_warning([first, second])
    assert f"{other}: calibration.weight" in warning and f"the first job's ({first.source})" in warning and "\n" not in warning


def test_lone_matching_samples_are_chance_and_not_counted():
    """Two recordings of a noise-free motion whose torque noise agrees at lone samples (as it does by chance about
    once in 10^4 samples) share nothing; a stretch of two or more samples in a row is shared."""
    import numpy as np

    t = np.arange(1000) / 500.0
    a = np.column_stack([t, (t * 68.4) % 360.0, 600.0 + 0.0 * t, 5000.0 + 100.0 * np.sin(7.0 * t)])
    b = a.copy()
    b[:, 3] += 50.0
    b[::10, 3] = a[::10, 3]  # lone agreements
    assert shared_share(a, b, 1e-6) == 0.0
    b[503:598, 3] = a[503:598, 3]  # a shared stretch of 95 samples (apart from the lone ones at 500 and 600)
    assert shared_share(a, b, 1e-6) == pytest.approx(0.095)
