"""Calibration inputs that used to crash, or to calibrate garbage and report it as precise, through the real CLI.

Each case runs ``servo-press calibrate`` (in this process) on the SYNTHETIC log of ``servo-press experiment``
(seed 0, the cushion-test job's truth, Table 4), edited the way a real log goes wrong: a torque column scaled
by a factor the sign-and-scale check lets through, one absurd torque sample, an absurd time stamp. What must
hold: no traceback; a refusal is one line naming the line or field; a fit that cannot be trusted says so
(warnings in stderr and in calibrated.json) and never labels an estimate on its range bound "identified". The clean log's
fit, whose warnings alone are read, runs without the bootstrap's refits, which give the intervals and their labels and
never a warning (conftest.py's no_bootstrap_job; not for a subset such as --parameters eta_gear: without the refits
its held parameters are freed otherwise, and it took longer). The warnings of the log's reader (an absurd sample
dropped, a torque above the motor's peak), decided before any fit, come from the cheapest calibration that runs
through: eta_gear alone with none held back (fixtures_suitecal.py's eta_gear_only_job).
"""
from __future__ import annotations

import json
import re
from pathlib import Path

import pytest

from bad_input_helpers import cli, refused  # noqa: E402 (tests/ is on sys.path, conftest.py)


# [calibration] tables appended to a shipped cushion-test job (which sets neither) for the tests whose assertions are about
# labels, warnings and the presence of an interval, not about an interval's width or an estimate's accuracy
FEWER_REFITS_ONE_START = "\n[calibration.bootstrap]\nrefits = 19\n\n[calibration.least_squares]\nstarts = 1\n"


def calibrated(result, out: Path) -> dict:
    code, _, err = result
    assert code == 0 and "Traceback" not in err and "RuntimeWarning" not in err, err
    return json.loads((out / "calibrated.json").read_text())


@pytest.fixture(scope="module")
def log(synthetic_log) -> Path:
    """The SYNTHETIC drive log of `servo-press experiment` (seed 0; conftest.py: written once a session, read only)."""
    return synthetic_log


def edited(log: Path, tmp_path: Path, edit, name="edited.csv") -> Path:
    """The log with ``edit(row index, cells)`` applied to every data row (cells: time, angle, speed, torque)."""
    lines = log.read_text().splitlines()
    out, k = [], 0
    for ln in lines:
        if ln[:1].isdigit() or ln[:1] == "-":
            cells = ln.split(",")
            edit(k, cells)
            ln = ",".join(cells)
            k += 1
        out.append(ln)
    path = tmp_path / name
    path.write_text("\n".join(out) + "\n")
    return path


def test_one_parameter_calibrates_with_an_interval(capsys, log, tmp_path):
    """--parameters eta_gear on a job whose list is eta_gear alone: a one-parameter fit and its bootstrap. On the
    shipped job's six, the five held would be score-tested and those the log disagrees with (psi) freed and the fit
    repeated, a two-parameter fit at eight times the CPU (tests/test_held_parameters.py tests that).

    What is asserted is that a bootstrap interval comes out around the estimate (no crash), not its width: 19 refits,
    whose 95 % basic interval spans the largest to the smallest refit (calibration/identification/bootstrap.py, the
    (R+1) rule) as 39 do, and one least-squares start give one as the job's 40 refits and 4 starts do, at ~half the CPU."""
    from importlib import resources

    text = resources.files("press_model.data").joinpath("cushion_test.toml").read_text(encoding="utf-8")
    six = 'parameters = ["eta_gear", "psi", "mu_r", "m8", "J_gear", "mu_s"]'
    assert text.count(six) == 1 and "[calibration.bootstrap]" not in text and "[calibration.least_squares]" not in text
    job = tmp_path / "eta_gear.toml"
    job.write_text(text.replace(six, 'parameters = ["eta_gear"]') + FEWER_REFITS_ONE_START, encoding="utf-8")
    rec = calibrated(cli(capsys, "calibrate", "--log", log, "--job", job, "--parameters", "eta_gear", "--method", "least-squares",
                         "--out", tmp_path / "cal"), tmp_path / "cal")
    lo, hi = rec["intervals"]["eta_gear"]
    assert 0.7 <= lo < rec["parameters"]["eta_gear"] < hi <= 0.99  # a bootstrap interval, not a crash


def test_a_parameter_named_twice_is_refused_where_it_was_written(capsys, log, tmp_path):
    line = refused(cli(capsys, "calibrate", "--log", log, "--parameters", "eta_gear,mu_r,eta_gear", "--out", tmp_path / "c"),
                   "--parameters", "names eta_gear twice")
    assert "cushion_test.toml" not in line


def test_validating_on_the_fitted_log_is_refused(capsys, log, tmp_path):
    refused(cli(capsys, "calibrate", "--log", log, "--validate", log, "--out", tmp_path / "c"), "--validate", "is the log that is fitted")
    copy = tmp_path / "copy.csv"
    copy.write_text("# another header comment\n" + log.read_text())
    refused(cli(capsys, "calibrate", "--log", log, "--validate", copy, "--out", tmp_path / "c"), "a copy of the data")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["copy.csv"]


def test_a_torque_scale_error_inside_the_scale_check_is_not_called_identified(capsys, log, tmp_path):
    """Torque x 1.6: the sign-and-scale check (k in [0.33, 3]) lets it through; the fit pins parameters on their
    bounds. Those are labelled as such, and the adequacy verdict names the misfit (the on-bound parameters' columns
    cannot absorb it). The shipped job with 19 bootstrap refits and one least-squares start: which parameters end on
    a bound is the fit's (a 60 % torque error pins them from any start), and the labels' rule, the bound warning and
    the verdict are the same with any number of refits (the refits give the other labels' intervals alone)."""
    from importlib import resources

    job = tmp_path / "cushion_test.toml"
    job.write_text(resources.files("press_model.data").joinpath("cushion_test.toml").read_text(encoding="utf-8")
                   + FEWER_REFITS_ONE_START, encoding="utf-8")
    path = edited(log, tmp_path, lambda k, c: c.__setitem__(3, f"{float(c[3]) * 1.6:.3f}"))
    result = cli(capsys, "calibrate", "--log", path, "--job", job, "--method", "least-squares", "--out", tmp_path / "c")
    rec = calibrated(result, tmp_path / "c")
    text = " ".join(rec["identifiability"])
    assert "on a range bound, not identified: " in text
    on_bound = text.split("on a range bound, not identified: ")[1].split(";")[0].split(", ")
    for s in rec["identifiability"]:  # a parameter on its bound is in no other label
        if s.startswith(("identified", "poorly identified")):
            assert not any(f"{n} (" in s for n in on_bound), s
    assert any("ended on a bound of the calibration range" in w for w in rec["warnings"])
    assert any(w.startswith("MODEL NOT ADEQUATE") for w in rec["warnings"]) and not rec["adequacy"]["adequate"]
    assert "ended on a bound" in result[2]


def test_the_clean_log_gets_no_trust_warning(clean_log_calibrated):
    """The clean log's fit (`calibrate --job` no_bootstrap_job `--method least-squares`), run once for the suite
    (fixtures_suitecal.py: test_force_column_messages reads it too)."""
    out, result = clean_log_calibrated
    rec = calibrated(result, out)
    assert not any("bound" in w or "NOT ADEQUATE" in w for w in rec["warnings"]), rec["warnings"]


def first_data_line(log) -> int:
    """The file line (from 1) of the log's first data row: after its comment lines and its header."""
    return next(i for i, ln in enumerate(log.read_text().splitlines(), 1) if ln[:1].isdigit())


@pytest.mark.parametrize("value", ["1e300", "-1e300", "1e9"])
@pytest.mark.parametrize("row", [1000, 7894])  # between grid points, and the last row
def test_one_absurd_torque_sample_is_dropped_and_named(capsys, log, tmp_path, value, row, eta_gear_only_job):
    """The warning is the drive-log reader's (calibrated.json's log.warnings), decided while the rows are read, before
    any fit: the calibration runs with fixtures_suitecal.py's eta_gear_only_job (eta_gear alone and none held back, no
    bootstrap, no recording estimate, one start), whose settings the reader does not read. Each case is a log of its
    own: two absurd rows in one log would be one warning, "Dropped 2 rows"."""
    path = edited(log, tmp_path, lambda k, c: c.__setitem__(3, value) if k == row else None)
    result = cli(capsys, "calibrate", "--log", path, "--method", "least-squares", "--job", eta_gear_only_job, "--out", tmp_path / "c")
    rec = calibrated(result, tmp_path / "c")
    line = row + first_data_line(log)
    assert any(w.startswith("Dropped 1 row whose torque is beyond 2 x the motor's peak torque") and f"line {line}," in w
               for w in rec["log"]["warnings"]), rec["log"]["warnings"]


def test_torque_above_the_motors_peak_is_named(capsys, log, tmp_path, eta_gear_only_job):
    """The drive-log reader's warning, decided before any fit: calibrated with eta_gear_only_job, as the absurd samples
    above."""
    path = edited(log, tmp_path, lambda k, c: c.__setitem__(3, "40000") if k == 2000 else None)
    rec = calibrated(cli(capsys, "calibrate", "--log", path, "--method", "least-squares", "--job", eta_gear_only_job,
                         "--out", tmp_path / "c"), tmp_path / "c")
    assert any("exceeds the motor's peak torque T_max = 25000 N m" in w and f"line {2000 + first_data_line(log)}," in w
               for w in rec["log"]["warnings"]), rec["log"]["warnings"]


@pytest.mark.parametrize("value", ["1e20", "99999"])
def test_an_absurd_last_time_stamp_is_refused_by_its_line(capsys, log, tmp_path, value):
    n = sum(1 for ln in log.read_text().splitlines() if ln[:1].isdigit())
    path = edited(log, tmp_path, lambda k, c: c.__setitem__(0, value) if k == n - 1 else None)
    refused(cli(capsys, "calibrate", "--log", path, "--out", tmp_path / "c"), f"lines {first_data_line(log) + n - 2} and {first_data_line(log) + n - 1}, time_s",
            "a corrupt time stamp")


def test_a_jobs_contact_height_above_the_stroke_names_the_job(capsys, log, tmp_path):
    from importlib import resources

    text = resources.files("press_model.data").joinpath("cushion_test.toml").read_text(encoding="utf-8")
    job = tmp_path / "tall.toml"
    job.write_text(text.replace("contact_height_m = 0.30", "contact_height_m = 5.0", 1))
    assert "contact_height_m = 5.0" in job.read_text()
    for argv in (["calibrate", "--log", log], ["experiment"], ["sensitivity", "--n", "1024"]):
        out = tmp_path / ("o.csv" if argv[0] == "experiment" else "o")
        line = refused(cli(capsys, *argv, "--job", job, "--out", out), "tall.toml: process.contact_height_m = 5.0",
                       "must lie inside the stroke")
        assert "with truth" not in line and "reference_press" not in line


def test_the_worked_examples_key_set_is_labelled_by_one_rule_and_its_misfit_named(capsys, log, tmp_path):
    """The README's worked example: the key set its sensitivity step chooses on the reference press (eta_gear, mu_r,
    m8), calibrated as written (the default ant colony) on the SYNTHETIC seed-0 log, whose truth also moves psi,
    J_gear and mu_s. The fit once put m8 on its bound with a zero-width interval, labelled "identified". Whatever
    the estimate: a parameter within 0.1 % of its range from a bound is labelled on-bound, never identified, and
    every identified parameter has an interval of non-zero width; the three held at their theoretical values leave
    a misfit the adequacy test names (MODEL NOT ADEQUATE in stderr and in the warnings). The subset is kept as given
    (``[calibration.adequacy] free_held = false``; by default the held parameters the log disagrees with are freed:
    tests/test_held_parameters.py), and the held-parameter warning names one of the three.

    The colony is a smaller one (20 ants, 25 iterations, a 150-evaluation polish) and the bootstrap 19 refits: the
    assertions hold whatever the estimate (one rule labels every parameter where it ends, and three parameters held at
    values the SYNTHETIC truth moves leave a misfit any fit of the other three leaves), so not on the colony's size."""
    from importlib import resources

    job = tmp_path / "keep_subset.toml"
    job.write_text(resources.files("press_model.data").joinpath("cushion_test.toml").read_text(encoding="utf-8")
                   + "\n[calibration.adequacy]\nfree_held = false\n\n[calibration.aco]\nants = 20\niterations = 25\n"
                   "polish_evaluations = 150\n\n[calibration.bootstrap]\nrefits = 19\n", encoding="utf-8")
    result = cli(capsys, "calibrate", "--log", log, "--job", job, "--parameters", "eta_gear,mu_r,m8", "--out", tmp_path / "cal")
    rec = calibrated(result, tmp_path / "cal")
    labels = {}  # parameter -> its one label ("identified: m8 (3.8 % of its range).")
    for s in rec["identifiability"]:
        kind, _, rest = s.partition(": ")
        if kind in ("on a range bound, not identified", "poorly identified", "identified only in combination", "identified"):
            for name in re.findall(r"(\w+) \(", rest.split(";")[0]):
                assert name not in labels, rec["identifiability"]  # one label each
                labels[name] = kind
    assert set(labels) == {"eta_gear", "mu_r", "m8"}, rec["identifiability"]
    for name, kind in labels.items():
        low, high = rec["bounds"][name]
        value = rec["parameters"][name]
        on_bound = min(value - low, high - value) <= 1e-3 * (high - low)
        assert (kind == "on a range bound, not identified") == on_bound, (name, kind, value, low, high)
        if kind.startswith("identified"):
            lo, hi = rec["intervals"][name]
            assert lo < value < hi and hi - lo > 1e-6 * (high - low), (name, lo, hi)
    assert any(w.startswith("MODEL NOT ADEQUATE") for w in rec["warnings"]), rec["warnings"]
    assert "WARNING: MODEL NOT ADEQUATE" in result[2]
    held = [w for w in rec["warnings"] if w.startswith("HELD PARAMETER WRONG FOR THIS LOG")]
    assert len(held) == 1 and re.search(r"\b(psi|J_gear|mu_s) held at", held[0]), rec["warnings"]
