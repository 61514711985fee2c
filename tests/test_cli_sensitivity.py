"""servo-press sensitivity at a small N: the files, their columns and the screening rule's output."""
import csv
import json
import pytest

from in_process import servo_press  # noqa: E402 (tests/ is on sys.path, conftest.py)

pytestmark = pytest.mark.usefixtures("pyplot_imported")  # fixtures_suitecal.py: the figure workers start with matplotlib

RESP = ["Y_RMSE", "Y_PR", "Y_TL", "Y_Work"]


@pytest.fixture(scope="module")
def run(reference_sensitivity):
    """The folder of `sensitivity --n 64 --seed 5` (conftest.py: run once for the suite, read only)."""
    return reference_sensitivity[0]


def test_sobol_csv(run):
    with open(run / "sobol.csv") as fh:
        rows = list(csv.DictReader(fh))
    assert list(rows[0]) == ["response", "parameter", "S1", "S1_conf", "ST", "ST_conf"]
    assert sorted({r["response"] for r in rows}) == sorted(RESP)
    assert len(rows) == 4 * 28
    by = {(r["response"], r["parameter"]): float(r["ST"]) for r in rows}
    # the gear efficiency scales every torque sample: it must lead Y_RMSE at any N
    assert max(by, key=lambda k: by[k] if k[0] == "Y_RMSE" else -1) == ("Y_RMSE", "eta_gear")


def test_key_parameters_follow_the_rule(run):
    keys = json.loads((run / "key_parameters.json").read_text())
    assert keys["rule"].startswith("S_T > 0.05 on Y_RMSE or on Y_PR")
    with open(run / "sobol.csv") as fh:
        rows = list(csv.DictReader(fh))
    expected = {r["parameter"] for r in rows if r["response"] in ("Y_RMSE", "Y_PR") and float(r["ST"]) > 0.05}
    assert set(keys["key_parameters"]) == expected
    assert keys["provenance"]["seed"] == 5 and keys["provenance"]["n"] == 64  # the run's --seed and --n
    assert (run / "sobol_indices.png").stat().st_size > 10_000
    assert "paper" in (run / "paper_comparison.md").read_text()
    assert "of the paper's own press" not in (run / "paper_comparison.md").read_text()  # the reference press: the paper's own


def test_n_not_power_of_two_is_refused(tmp_path):
    r = servo_press("sensitivity", "--n", "1000", "--out", tmp_path)
    assert r.returncode == 2 and "power of two" in r.stderr and "Traceback" not in r.stderr


def test_another_press_on_the_shipped_cushion_test_is_told_to_give_its_own_load_case(crank_slider_sensitivity, tmp_path):
    """The default load case is the reference press's cushion test: on another press the key set of its own calibration
    run may differ (the key set depends on the load), so a warning says to give --job; with --job none is given. The
    run without --job is the suite's one (conftest.py: it exited 0)."""
    _, _, stderr = crank_slider_sensitivity
    assert "not crank-slider press" in stderr and "give --job" in stderr
    r = servo_press("sensitivity", "--press", "crank-slider", "--job", "crank-slider-cushion", "--n", "64", "--out",
                    tmp_path / "own")
    assert r.returncode == 0 and "give --job" not in r.stderr, r.stderr
