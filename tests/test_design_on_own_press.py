"""`design-experiment` on a press that is not a shipped one makes the estimate better: the crank-slider edited as a user's
press (slide 9,200 kg instead of 8,000, a 22:1 gear instead of 20:1) with its cushion job's default search. The
designed runs' SYNTHETIC logs (truth the job's [experiment.truth], each of the six a few per cent off its file value),
calibrated together as the report says, hold every truth in their joint 95 % region and narrow the widest interval of
the job's own cushion test calibrated alone.

The job's own run is a candidate of the search (calibration/design/runs.py): on this press the coarse grid alone gave
two runs predicted wider than the cushion test for four of the six parameters. The logged force's stated accuracy
(1.5 % of scale) confounds mu_s with the force's scale: no pair of the coarse grid (2 levels, 2 phases) separates them
(best predicted 88.5 % of mu_s's range), the default search does (docs/validation.md)."""
from __future__ import annotations

import json
import re
from importlib import resources

import pytest

import in_process  # noqa: E402 (tests/ is on sys.path, conftest.py)


def run(cwd, *argv):
    r = in_process.servo_press(*argv, cwd=cwd)
    assert r.returncode == 0 and "Traceback" not in r.stderr, f"servo-press {' '.join(map(str, argv))}: {r.stderr}"
    return r


@pytest.fixture(scope="module")
def designed(tmp_path_factory):
    d = tmp_path_factory.mktemp("own_design")
    press = resources.files("press_model.data").joinpath("crank_slider.toml").read_text(encoding="utf-8")
    press, n1 = re.subn(r"^mass_kg = 8000\.0(?=\s)", "mass_kg = 9200.0", press, count=1, flags=re.M)
    press, n2 = re.subn(r"^gear_ratio = 20\.0(?=\s)", "gear_ratio = 22.0", press, count=1, flags=re.M)
    assert n1 == n2 == 1
    (d / "slider.toml").write_text(press.replace('name = "crank-slider press', 'name = "my slider press', 1), encoding="utf-8")
    job = resources.files("press_model.data").joinpath("crank_slider_cushion.toml").read_text(encoding="utf-8")
    job = job.replace("\n[design]\n", "\n[calibration.aco]\npolish_evaluations = 20\n\n[design]\n", 1)
    (d / "job.toml").write_text(job, encoding="utf-8")
    run(d, "design-experiment", "--press", "slider.toml", "--job", "job.toml", "--no-verify", "--out", "design")
    for i in (1, 2):
        run(d, "experiment", "--press", "slider.toml", "--job", f"design/run_{i}/job.toml", "--seed", str(i), "--out", f"run{i}.csv")
    run(d, "experiment", "--press", "slider.toml", "--job", "job.toml", "--seed", "3", "--out", "cushion.csv")
    run(d, "calibrate", "--press", "slider.toml", "--log", "run1.csv", "--job", "design/run_1/job.toml", "--log", "run2.csv",
        "--job", "design/run_2/job.toml", "--method", "least-squares", "--out", "cal_runs")
    run(d, "calibrate", "--press", "slider.toml", "--log", "cushion.csv", "--job", "job.toml", "--method", "least-squares",
        "--out", "cal_cushion")
    return d


def _read(path):
    return json.loads(path.read_text(encoding="utf-8"))


def test_the_designed_runs_joint_calibration_holds_every_truth(designed):
    """The joint region (a 95 % statement about all six at once) of the runs' calibration holds each truth, and the
    calibration is adequate for both logs."""
    cal = _read(designed / "cal_runs" / "calibrated.json")
    truth = _read(designed / "run1.truth.json")["truth"]
    assert cal["adequacy"]["adequate"]
    box = cal["joint_region"]["box"]
    assert all(box[n][0] <= truth[n] <= box[n][1] for n in cal["parameters"]), (box, truth)


def test_the_designed_runs_narrow_the_cushion_tests_widest_interval(designed):
    """The widest interval (share of its calibration range) of the runs' calibration is narrower than the cushion test's,
    as the design predicted (prediction.json: its widest at most the cushion test's)."""
    runs, single = (_read(designed / f / "calibrated.json") for f in ("cal_runs", "cal_cushion"))
    pred = _read(designed / "design" / "prediction.json")

    def widest(cal):
        return max((b - a) / (cal["bounds"][n][1] - cal["bounds"][n][0]) for n, (a, b) in cal["intervals"].items())

    assert pred["aim"]["widest_interval_ratio"] >= 1.0
    assert widest(runs) < widest(single), (runs["intervals"], single["intervals"])
