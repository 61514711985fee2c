"""What `servo-press plan` writes is read back by the commands that take it, and its summary names what binds.

The sensitivity reader of a planned profile used to refuse plan's own profile.csv: the jerk-limited stroke
creeps to its end angle and reached the reader's 1e-5 deg tolerance while still moving, so a moving sample
was taken as the turn's end (the reader's tests used hand-made profiles only). And the plan summary named
"none" as binding in every phase of every jerk-limited plan, because the time between limits outvoted them.
"""
from __future__ import annotations

import json

import pytest

from servo_press.cli import main


@pytest.fixture(scope="module")
def plan(door_panel_plan_run):
    return door_panel_plan_run[0]  # `plan --job door-panel`'s folder (conftest.py: run once a session)


def test_sensitivity_reads_the_profile_plan_wrote(plan, tmp_path, capsys):
    capsys.readouterr()
    code = main(["sensitivity", "--job", "door-panel", "--profile", str(plan / "profile.csv"), "--n", "64", "--out", str(tmp_path / "s")])
    err = capsys.readouterr().err
    assert code == 0 and "error" not in err, err
    case = json.loads((tmp_path / "s" / "run.json").read_text())["load_case"]
    assert "profile.csv" in json.dumps(case)


def test_the_read_turn_is_the_planned_stroke(plan):
    from press_model.profile_motion import read_profile_motion

    motion = read_profile_motion(plan / "profile.csv")
    summary = json.loads((plan / "summary.json").read_text())
    assert motion.period == pytest.approx(summary["stroke_time_s"], rel=1e-6)  # the turn ends where the dwell starts


def test_the_plan_summary_names_the_limits_that_bind(plan, capsys):
    summary = json.loads((plan / "summary.json").read_text())
    b = summary["binding_constraints"]
    for phase in ("approach", "forming_window", "return"):
        shares = {k: v for k, v in b[phase]["active_time_share"].items() if k != "none"}
        top = max(shares, key=shares.get)
        # the dominant limit is the one active longest, whatever share of the phase moves between limits
        assert b[phase]["dominant"] == (top if shares[top] >= 0.05 else "none")
    assert b["approach"]["dominant"] == "motor_speed"  # the door panel's approach runs at the motor's top speed
    assert b["forming_window"]["dominant"] == "forming_slide_speed"
