"""A hand-edited calibrated.json is read strictly by what plans from it: its verdict's types are checked (the string
"false" is not an adequate calibration, a lone warning string is not dropped), a calibration result that lost its
region or its calibrated values is refused with the field named, and a box that leaves a calibrated parameter out, or an
edited value in it, is named as the joint region's."""
from __future__ import annotations

import json

import pytest

from press_io.errors import PressDataError
from press_model.calibration_verdict import calibration_verdict
from press_model.params import JsonInput, joint_box_of, overrides_of, read_intervals

from bad_input_helpers import cli, refused

PARAMS = {"eta_gear": 0.842, "m8": 32940.0}
RESULT = {"parameters": PARAMS,
          "intervals": {"eta_gear": [0.835, 0.849], "m8": [32000.0, 33900.0]},
          "joint_region": {"box": {"eta_gear": [0.831, 0.853], "m8": [31800.0, 34100.0]}},
          "adequacy": {"adequate": True}, "warnings": [], "press_fingerprint": "0123abcd"}


def edited(**changes) -> dict:
    rec = json.loads(json.dumps(RESULT))
    for key, value in changes.items():
        if value is None:
            del rec[key]
        else:
            rec[key] = value
    return rec


def refusal(fn, *parts) -> str:
    with pytest.raises(PressDataError) as info:
        fn()
    msg = str(info.value)
    assert "\n" not in msg
    for p in parts:
        assert p in msg, f"{p!r} not in {msg}"
    return msg


def test_adequate_as_a_string_is_refused_not_read_as_adequate():
    rec = edited(adequacy={"adequate": "false"})
    refusal(lambda: calibration_verdict(rec, "cal.json"), "cal.json", "adequacy.adequate = 'false'", "true or false")
    refusal(lambda: calibration_verdict(edited(adequacy="no"), "cal.json"), "adequacy = 'no'")
    refusal(lambda: calibration_verdict(edited(adequacy={"p_value": 0.1}), "cal.json"), "adequacy.adequate", "<missing>")
    assert calibration_verdict(edited(adequacy={"adequate": False}), "cal.json")["adequate"] is False


def test_warnings_as_a_string_is_refused_not_dropped():
    refusal(lambda: calibration_verdict(edited(warnings="m8 on its range bound"), "cal.json"),
            "warnings = 'm8 on its range bound'", "list of strings")
    refusal(lambda: calibration_verdict(edited(warnings=[3]), "cal.json"), "warnings = [3]")
    assert calibration_verdict(edited(warnings=["m8 on its bound"]), "cal.json")["warnings"] == 1


def test_plan_refuses_a_calibration_whose_adequacy_was_edited_to_a_string(capsys, work):
    path = work.root / "calibrated.json"
    path.write_text(json.dumps(edited(adequacy={"adequate": "false"}, press_fingerprint=None)), encoding="utf-8")
    work.snap()
    refused(cli(capsys, "plan", "--job", "door-panel", "--params", path, "--out", work.out),
            "calibrated.json: adequacy.adequate = 'false'", "true or false")
    work.unchanged()


def test_a_calibration_result_without_its_region_is_refused_not_planned_at_its_values_alone():
    doc = JsonInput(edited(intervals=None, joint_region=None), "cal.json")
    for required in (False, True):
        refusal(lambda: joint_box_of(doc, required), "cal.json: joint_region = '<missing>'", "intervals are missing",
                "\"parameters\" object")
    _, box, kind = joint_box_of(JsonInput(edited(joint_region=None), "cal.json"), False)  # an older result: its intervals
    assert kind == "per-parameter intervals" and box["m8"] == (32000.0, 33900.0)
    assert joint_box_of(JsonInput(dict(PARAMS), "--params"), False)[1] is None  # overrides written by hand: no region
    assert joint_box_of(JsonInput({"parameters": PARAMS, "adequacy": {"adequate": True}}, "x.json"), False)[1] is None


def test_a_box_that_leaves_a_calibrated_parameter_out_is_refused_naming_it():
    rec = edited()
    del rec["joint_region"]["box"]["m8"]
    refusal(lambda: joint_box_of(JsonInput(rec, "cal.json"), False), "joint_region.box = 'without m8'", "m8 has no [low, high]")
    rec = edited()
    del rec["intervals"]["m8"]
    rec.pop("joint_region")
    refusal(lambda: joint_box_of(JsonInput(rec, "cal.json"), True), "intervals = 'without m8'")
    rec.pop("press_fingerprint")  # a box written by hand may hold some of the parameters
    assert set(joint_box_of(JsonInput(rec, "cal.json"), True)[1]) == {"eta_gear"}


def test_an_edited_joint_region_value_is_named_as_the_joint_regions(tmp_path):
    rec = edited()
    rec["joint_region"]["box"]["eta_gear"] = [0.9, 0.8]
    msg = refusal(lambda: joint_box_of(JsonInput(rec, "cal.json"), True), "joint_region.box.eta_gear = [0.9, 0.8]")
    assert "intervals.eta_gear" not in msg
    path = tmp_path / "cal.json"
    path.write_text(json.dumps(edited()), encoding="utf-8")
    assert read_intervals(str(path))[1]["eta_gear"] == (0.835, 0.849)  # the per-parameter intervals read as before


def test_a_calibration_result_without_parameters_is_refused_for_them():
    msg = refusal(lambda: overrides_of(JsonInput(edited(parameters=None), "cal.json")), "cal.json: parameters = '<missing>'")
    assert "is not a parameter" not in msg and "intervals =" not in msg
