"""Fixtures of the tests of identification statistics (test_logged_force_accuracy, test_recording*, ...), shared across
their modules and with the others that read the same result (conftest.py's ``pytest_plugins``; tests/ is on sys.path)."""
from __future__ import annotations

import pytest


def _calibrate(log, *argv):
    """What heavy_results stores: the command ``calibrate --log LOG *argv --out FOLDER/cal`` run in this process,
    made in the empty FOLDER it is given: (its stdout, its stderr)."""
    from in_process import servo_press

    def make(folder):
        r = servo_press("calibrate", "--log", log, *argv, "--out", folder / "cal")
        assert r.returncode == 0, r.stderr
        return r.stdout, r.stderr

    return make


@pytest.fixture(scope="session")
def seed_0_calibration(heavy_results, synthetic_log):
    """`servo-press calibrate --log LOG --out FOLDER` on the SYNTHETIC seed-0 log (the ``synthetic_log`` fixture), the
    shipped cushion-test job as it is (its method, its bootstrap's refits), run once for the suite in the process of the
    worker that runs it (heavy_results.py): (FOLDER, its stdout, its stderr). Read only: a test that changes the folder
    copies it first."""
    folder, (stdout, stderr) = heavy_results.get("calibrate-seed-0", _calibrate(synthetic_log), str(synthetic_log))
    return folder / "cal", stdout, stderr
