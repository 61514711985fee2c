"""`simulate --playback` says when its open-loop turn ends far off the plan instead of printing the number alone.

At the default 1-degree step, the cushion's force step in a linearly interpolated torque table drives the open-loop
playback 56 deg off by the end of the turn (0.17 deg at 0.25 deg): a number the summary printed without a word.
"""
from __future__ import annotations

import json

from servo_press.cli import main
from servo_press.simulate import playback_warning


def test_a_playback_that_ends_far_off_is_warned(tmp_path, capsys):
    assert main(["simulate", "--playback", "--out", str(tmp_path / "s")]) == 0
    err = capsys.readouterr().err
    pb = json.loads((tmp_path / "s" / "summary.json").read_text())["playback"]
    assert abs(pb["final_crank_angle_error_deg"]) > 1.0  # the case of the issue: -56 deg at 1-degree step
    assert pb["warning"] and f"WARNING: {pb['warning']}" in err and "--step-deg 0.25" in err


def test_a_playback_within_the_limit_is_not_warned():
    assert playback_warning(0.17, 0.25) is None and playback_warning(-0.99, 1.0) is None
    assert "ends the turn +1.5 deg off" in playback_warning(1.5, 1.0)
