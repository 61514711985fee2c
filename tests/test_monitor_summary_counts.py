"""The monitor's summary line counts its parameter alarms (one a parameter of one log) and says over how many
parameters they fall, so that "3 parameter alarms" followed by two listed lines (the first alarm of each of two
parameters) does not read as one alarm lost."""
from __future__ import annotations

from pathlib import Path

from calibration.fleet.monitor_report import monitor_lines


def _alarm(log, parameter):
    return {"kind": "parameter_change", "log": log, "recorded": "", "parameter": parameter, "reason": f"{parameter} moved"}


def _lines(alarms):
    rec = {"alarms": alarms, "synthetic_logs": True, "logs": 3, "press": "p", "calibrated": 3, "failed": []}
    return monitor_lines({"calibrated": 3, "reused": 0}, rec, Path("out"), 1.0)


def test_alarms_over_fewer_parameters_say_so_and_list_the_first_of_each():
    lines = _lines([_alarm("a.csv", "m8"), _alarm("b.csv", "m8"), _alarm("b.csv", "mu_r")])
    assert "3 parameter alarms on 2 parameters (the first of each below, every one in alarms.json)" in lines[0], lines[0]
    assert [ln for ln in lines[1:] if ln.startswith("  alarm from")] == ["  alarm from a.csv: m8 moved", "  alarm from b.csv: mu_r moved"]


def test_one_alarm_a_parameter_needs_no_explanation():
    lines = _lines([_alarm("a.csv", "m8"), _alarm("a.csv", "mu_r")])
    assert "2 parameter alarms, 0 poor fits" in lines[0], lines[0]
