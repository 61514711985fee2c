"""Bad parameter values: ``--params``, ``--calibrated``, ``--truth`` and ``--baseline`` (JSON objects or result files).

The readers :func:`press_model.params.read_overrides` / ``apply_overrides`` (and ``read_intervals``): unknown names,
values outside their range or not numbers, text that is neither JSON nor a file, and result files made on another
press are refused with the field, the value and the fix. Property-based fuzzing with random JSON: a press whose
overrides lie inside their ranges, or a PressDataError.
"""
from __future__ import annotations

import json
import math

import pytest
from hypothesis import event, given, settings, strategies as st

from press_io.errors import PressDataError
from press_model.params import apply_overrides, read_overrides
from press_model.press_data import load_press
from bad_input_helpers import FIXED, cli, refused, check, run_cli, assert_clean_error

pytestmark = pytest.mark.usefixtures("pyplot_imported")  # fixtures_suitecal.py: the figure workers start with matplotlib


def test_unknown_parameter_override(press):
    with pytest.raises(PressDataError) as info:
        apply_overrides(press, {"m99": 1.0})
    check(str(info.value), "--params: m99 = 1.0", "is not a parameter of this press", "known: J_gear, eta_gear")


def test_override_out_of_range(press):
    with pytest.raises(PressDataError) as info:
        apply_overrides(press, {"m8": 1.0e6})
    check(str(info.value), "m8 = 1000000.0", "must lie in its range [21416.5, 39773.5] kg")
    with pytest.raises(PressDataError, match=r"eta_gear = 1\.2 .*range \[0\.7, 0\.99\]"):
        apply_overrides(press, {"eta_gear": 1.2})


@pytest.mark.parametrize("value", ["heavy", True, None, [1.0]])
def test_override_not_a_number(press, value):
    with pytest.raises(PressDataError) as info:
        apply_overrides(press, {"m8": value})
    check(str(info.value), f"m8 = {value!r}", "must be a finite number")


def test_override_nan_is_out_of_range(press):
    with pytest.raises(PressDataError, match="m8 = nan .*must lie in its range"):
        apply_overrides(press, {"m8": math.nan})


def test_valid_override_applies(press):
    assert apply_overrides(press, {"m8": 32940})._get("bodies.slide.mass_kg") == 32940.0
    assert read_overrides('{"parameters": {"m8": 32940}}') == {"m8": 32940}


def test_bad_json_params():
    with pytest.raises(PressDataError) as info:
        read_overrides('{"m8": 32940')
    check(str(info.value), "--params: <json> = '{\"m8\": 32940'", "is not valid JSON", "at character")


def test_params_neither_json_nor_file():
    with pytest.raises(PressDataError) as info:
        read_overrides("m8=32940")
    check(str(info.value), "--params = 'm8=32940'", "must be a JSON object such as", "or the path of a JSON file")


def test_read_overrides_refuses_a_file_not_an_object(tmp_path):
    f = tmp_path / "p.json"
    f.write_text("[1, 2]", encoding="utf-8")
    with pytest.raises(PressDataError) as info:
        read_overrides(str(f))
    check(str(info.value), str(f), "<top level> = 'list'", "must be a JSON object")


def test_params_file_not_utf8(tmp_path):
    f = tmp_path / "p.json"
    f.write_bytes(b'{"m8": 32940, "note": "\xff"}')
    with pytest.raises(PressDataError) as info:
        read_overrides(str(f))
    check(str(info.value), "--params = ", "p.json", "must be a UTF-8 text file")


def test_cli_bad_params(tmp_path):
    proc = run_cli("simulate", "--press", "crank-slider", "--params", '{"m3": 1e9}', "--out", str(tmp_path / "out"))
    assert_clean_error(proc, "m3 = 1000000000.0", "must lie in its range [5600, 10400] kg")


def test_params_invalid_json(capsys, work):
    refused(cli(capsys, "simulate", "--params", '{"m8": 32940,}', "--out", work.out), "--params: <json>", "is not valid JSON")
    work.unchanged()


def test_params_file_not_an_object(capsys, work):
    path = work.root / "params.json"
    path.write_text("[32940, 0.9]", encoding="utf-8")
    work.snap()
    refused(cli(capsys, "simulate", "--params", path, "--out", work.out),
            str(path), "<top level> = 'list'", 'must be a JSON object such as {"m8": 32940}')
    work.unchanged()


def test_params_neither_json_nor_a_file(capsys, work):
    refused(cli(capsys, "simulate", "--params", "m8=32940", "--out", work.out),
            "--params = 'm8=32940'", "must be a JSON object such as", "or the path of a JSON file")
    work.unchanged()


def test_params_text_too_long_for_a_file_name(capsys, work):
    refused(cli(capsys, "simulate", "--params", "[" + ", ".join(["1.0"] * 100) + "]", "--out", work.out),
            "--params = '[1.0, 1.0", "...", "1.0]'", "must be a JSON object")  # shortened: its start and its end
    work.unchanged()


def test_params_unknown_parameter(capsys, work):
    refused(cli(capsys, "simulate", "--params", '{"m99": 1}', "--out", work.out),
            "--params: m99 = 1", "is not a parameter of this press; known: J_gear, eta_gear")
    work.unchanged()


def test_params_value_outside_its_range(capsys, work):
    refused(cli(capsys, "simulate", "--params", '{"eta_gear": 1.5}', "--out", work.out),
            "--params: eta_gear = 1.5", "must lie in its range [0.7, 0.99]")
    work.unchanged()


def test_params_value_not_a_number(capsys, work):
    refused(cli(capsys, "simulate", "--params", '{"m8": "heavy"}', "--out", work.out), "--params: m8 = 'heavy'", "must be a finite number")
    work.unchanged()


def test_params_value_a_boolean(capsys, work):
    refused(cli(capsys, "simulate", "--params", '{"m8": true}', "--out", work.out), "--params: m8 = True", "must be a finite number")
    work.unchanged()


def test_params_value_nan(capsys, work):
    refused(cli(capsys, "simulate", "--params", '{"m8": NaN}', "--out", work.out), "--params: m8 = nan", "must lie in its range")
    work.unchanged()


def test_experiment_truth_outside_its_range(capsys, work):
    refused(cli(capsys, "experiment", "--truth", '{"eta_gear": 1.5}', "--out", work.out / "log.csv"),
            "truth: eta_gear = 1.5", "must lie in its range [0.7, 0.99]")
    work.unchanged()


def test_experiment_truth_naming_an_unknown_parameter(capsys, work):
    refused(cli(capsys, "experiment", "--truth", '{"eta_gearbox": 0.9}', "--out", work.out / "log.csv"),
            "truth: eta_gearbox = 0.9", "is not a parameter of this press; known: J_gear, eta_gear")
    work.unchanged()


def test_experiment_truth_not_json(capsys, work):
    refused(cli(capsys, "experiment", "--truth", "{eta_gear: 0.9}", "--out", work.out / "log.csv"), "<json>", "is not valid JSON")
    work.unchanged()


# results made on another press, and empty requests
@pytest.fixture(scope="module")
def reference_summary(simulate_run):
    """summary.json of a reference-press simulate: a result file with the 28 parameters and the press fingerprint (the
    suite's `simulate --step-deg 10`, fixtures_suitecal.py; read only)."""
    return simulate_run / "summary.json"


def test_params_file_made_on_another_press(capsys, work, reference_summary):
    rec = json.loads(reference_summary.read_text(encoding="utf-8"))
    other = load_press("crank-slider").fingerprint
    refused(cli(capsys, "simulate", "--press", "crank-slider", "--params", reference_summary, "--out", work.out),
            str(reference_summary), f"press_fingerprint = '{rec['press_fingerprint']}'", f"has fingerprint {other}",
            "use the same --press as the run that wrote the file")
    work.unchanged()
    code, _, err = cli(capsys, "simulate", "--params", reference_summary, "--step-deg", "10", "--out", work.out)
    assert code == 0, err  # on its own press it is accepted


def test_calibrated_file_made_on_another_press_in_compare(capsys, work):
    path = work.root / "calibrated.json"
    path.write_text(json.dumps({"parameters": {"eta_gear": 0.85}, "press": "another", "press_fingerprint": "sha256:0123456789abcdef"}))
    work.snap()
    refused(cli(capsys, "compare", "--calibrated", path, "--out", work.out), "press_fingerprint = 'sha256:0123456789abcdef'",
            "made on another press (another)", load_press().fingerprint)
    work.unchanged()


def test_compare_with_an_empty_calibrated_object(capsys, work):
    refused(cli(capsys, "compare", "--calibrated", "{}", "--out", work.out), "--calibrated = '{}'", "names no parameter",
            "both plans would be the theoretical one")
    work.unchanged()  # no empty --out folder either


def test_compare_with_malformed_intervals_is_refused_not_planned_without_its_robust_row(capsys, work):
    path = work.root / "calibrated.json"
    path.write_text(json.dumps({"parameters": {"eta_gear": 0.85}, "intervals": {"eta_gear": [0.9, 0.8]}}))
    work.snap()
    refused(cli(capsys, "compare", "--calibrated", path, "--out", work.out), "intervals.eta_gear = [0.9, 0.8]", "low <= high")
    work.unchanged()


def test_monitor_baseline_that_is_no_file(capsys, work):
    # however deep the folder (a test's own tmp folder under two xdist workers is 80 characters), the file name is shown
    refused(cli(capsys, "monitor", "--logs", str(work.root), "--baseline", str(work.root / "nope.json"), "--out", work.out),
            "--baseline", "nope.json", "must be a JSON object", "or the path of a JSON file")
    work.unchanged()


def test_compare_with_a_calibrated_value_outside_its_range_makes_no_folder(capsys, work):
    refused(cli(capsys, "compare", "--calibrated", '{"eta_gear": 1.5}', "--out", work.out), "eta_gear = 1.5", "must lie in its range")
    work.unchanged()


_RANGES = {p.name: (p.low, p.high) for p in load_press("reference").parameters.values()}
_NAMES = sorted(_RANGES)


_JSON_LEAF = st.one_of(st.none(), st.booleans(), st.integers(-(2**70), 2**70), st.floats(allow_nan=True, allow_infinity=True),
                       st.text(max_size=6))


_JSON = st.recursive(_JSON_LEAF, lambda inner: st.one_of(st.lists(inner, max_size=3),
                                                         st.dictionaries(st.one_of(st.sampled_from(_NAMES), st.text(max_size=5)),
                                                                         inner, max_size=3)), max_leaves=8)


_PARAMS = st.one_of(
    _JSON.map(lambda v: json.dumps(v, allow_nan=True)),
    st.dictionaries(st.sampled_from(_NAMES), st.one_of(_JSON_LEAF, st.floats(0.0, 1e5)), max_size=4)
    .map(lambda d: json.dumps({"parameters": d} if len(d) % 2 else d, allow_nan=True)),
    st.text(max_size=40).map(lambda s: "{" + s),
    # values near and inside each parameter's range: u = 0 is the low end, u = 1 the high end
    st.dictionaries(st.sampled_from(_NAMES), st.floats(-0.1, 1.1), min_size=1, max_size=6)
    .map(lambda d: json.dumps({n: _RANGES[n][0] + u * (_RANGES[n][1] - _RANGES[n][0]) for n, u in d.items()})),
)


@settings(max_examples=1000, **FIXED)
@given(_PARAMS)
def test_random_json_as_params_gives_a_press_or_a_press_data_error(press, text):
    try:
        changed = apply_overrides(press, read_overrides(text))
    except PressDataError as exc:
        event("refused")
        assert " is not valid: " in str(exc) and "\n" not in str(exc)
        return
    event("applied")
    values = changed.parameter_values()
    for name, value in read_overrides(text).items():
        p = press.parameters[name]
        assert values[name] == pytest.approx(float(value)) and p.low - 1e-9 * abs(p.low) <= values[name] <= p.high + 1e-9 * abs(p.high)


def test_the_robust_box_is_the_joint_region_when_the_result_has_one(press, tmp_path):
    """A plan that must hold for the press reads the box of all parameters at once; an older result, its intervals."""
    from press_model.params import read_intervals, read_joint_box

    rec = {"parameters": {"eta_gear": 0.842, "mu_r": 0.012},
           "intervals": {"eta_gear": [0.835, 0.849], "mu_r": [0.011, 0.013]},
           "joint_region": {"box": {"eta_gear": [0.831, 0.853], "mu_r": [0.0105, 0.0135]}}}
    path = tmp_path / "calibrated.json"
    path.write_text(json.dumps(rec))
    assert read_intervals(str(path), press)[1]["eta_gear"] == (0.835, 0.849)
    _, box, kind = read_joint_box(str(path), press)
    assert box["eta_gear"] == (0.831, 0.853) and kind == "joint region"
    del rec["joint_region"]
    path.write_text(json.dumps(rec))
    _, box, kind = read_joint_box(str(path), press)
    assert box["eta_gear"] == (0.835, 0.849) and kind == "per-parameter intervals"
    rec["joint_region"] = {"box": [0.8, 0.9]}
    path.write_text(json.dumps(rec))
    with pytest.raises(PressDataError, match="joint_region.box"):
        read_joint_box(str(path), press)
