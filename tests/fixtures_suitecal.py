"""Fixtures of the tests of calibration inputs, refusals and outputs (test_bad_inputs_*, test_drive_log_errors,
test_output_path_*, ...), shared across their modules (conftest.py's ``pytest_plugins``; tests/ is on sys.path)."""
from __future__ import annotations

from importlib import resources

import pytest

SIX = 'parameters = ["eta_gear", "psi", "mu_r", "m8", "J_gear", "mu_s"]'


@pytest.fixture(scope="session")
def eta_gear_only_job(tmp_path_factory):
    """The shipped cushion-test job reduced to the cheapest calibration that still reads, checks and writes everything:
    ``[calibration] parameters = ["eta_gear"]`` (one parameter and none held back, so no held parameter is
    score-tested, freed and refitted: calibration/identification/held.py), ``[calibration.bootstrap] refits = 0``,
    ``[calibration.recording] estimate = false`` and ``[calibration.least_squares] starts = 1``. Its path (read only).

    For tests that check what is decided before the fit, which reads none of these settings: the drive log's reader
    (calibrated.json's ``log.warnings``: rows dropped, sorted or repaired, by their file lines), a refusal of the log
    or of ``--out``, the files a run writes. Its [process], [motion] and [experiment] tables are the shipped ones. A
    warm calibration with it costs ~2 s of CPU against ~16 s for ``--parameters eta_gear`` on the shipped job, whose
    five held parameters the log disagrees with are freed and the fit repeated, bootstrap and all."""
    text = resources.files("press_model.data").joinpath("cushion_test.toml").read_text(encoding="utf-8")
    assert text.count(SIX) == 1 and "[calibration.bootstrap]" not in text and "[calibration.recording]" not in text
    assert "[calibration.least_squares]" not in text  # the shipped job takes the defaults of the three tables
    text = text.replace(SIX, 'parameters = ["eta_gear"]')
    path = tmp_path_factory.mktemp("eta-gear-only") / "cushion_test.toml"
    path.write_text(text + "\n[calibration.bootstrap]\nrefits = 0\n\n[calibration.recording]\nestimate = false\n\n"
                    "[calibration.least_squares]\nstarts = 1\n", encoding="utf-8")
    return path


@pytest.fixture(scope="session")
def pyplot_imported():
    """matplotlib.pyplot imported in this process, once. `simulate` and `sensitivity` fork a figure worker at their start
    that imports matplotlib first (press_model.plots.figure_worker, ~0.35 s of CPU), refused runs included; forked from
    a process that holds it already, the worker starts with it. The figures are the same bytes either way. For the
    modules that run these commands many times in this process (``pytestmark = pytest.mark.usefixtures(...)``)."""
    from press_model.plots import pyplot

    pyplot()


@pytest.fixture(scope="session")
def clean_log_calibrated(heavy_results, synthetic_log, no_bootstrap_job):
    """``servo-press calibrate --log LOG --job JOB --method least-squares --out FOLDER/cal`` on conftest.py's
    synthetic_log (seed 0, unedited) with its no_bootstrap_job (the six parameters, no refits), run once for the suite
    (heavy_results.py) in the process of the worker that runs it: (FOLDER/cal, (exit code, stdout, stderr)). For the
    tests that read the warnings of the clean log's fit (test_bad_inputs_calibration, test_force_column_messages).
    Read only."""
    from in_process import servo_press

    job_text = no_bootstrap_job.read_text(encoding="utf-8")

    def calibrate(folder):
        job = folder / "cushion_test.toml"
        job.write_text(job_text, encoding="utf-8")
        r = servo_press("calibrate", "--log", synthetic_log, "--job", job, "--method", "least-squares", "--out", folder / "cal")
        return r.returncode, r.stdout, r.stderr

    folder, result = heavy_results.get("clean-log-calibrated", calibrate, job_text)
    return folder / "cal", result


def _simulate(folder):
    from in_process import servo_press

    r = servo_press("simulate", "--step-deg", "10", "--out", folder / "run")
    assert r.returncode == 0 and "Traceback" not in r.stderr, r.stderr


@pytest.fixture(scope="session")
def simulate_run(heavy_results):
    """The folder of ``servo-press simulate --step-deg 10 --out FOLDER/run``, run once for the suite (heavy_results.py):
    for the tests that need a simulate result folder to refuse, replace or read the record of. Its record names no
    path (files by their relative names, sizes and SHA-256), so a copy (``shutil.copytree``) is the folder a run would
    have written there. Read only: copy it to change it."""
    folder, _ = heavy_results.get("simulate-step-10", _simulate)
    return folder / "run"
