"""Planning inputs that used to crash, run without end or mislead, through the real `servo-press plan`.

Each case is the door-panel job (or the reference press) edited the way a careless user edits it: a mode the front
cannot sweep, the transfer's documented "no requirement", a motor too weak for the part, an absurd rate, count or
limit. What must hold: no traceback; either a plan (exit 0) or one line with exit 2 naming the field, the value and
the fix, and nothing left behind.
"""
from __future__ import annotations

import json

from bad_input_helpers import DOOR_TEXT, REF_TEXT, cli, refused  # noqa: E402 (tests/ is on sys.path, conftest.py)

OPENING = "opening_height_m = 0.70\n"
TIME = "time_s = 2.0\n"


def job(tmp_path, text: str, name="job.toml"):
    path = tmp_path / name
    path.write_text(text, encoding="utf-8")
    return path


def door(*edits: tuple[str, str], extra: str = "") -> str:
    """door_panel.toml with text edits (old, new) and ``extra`` appended (a table of its own)."""
    text = DOOR_TEXT
    for old, new in edits:
        assert old in text, old
        text = text.replace(old, new, 1)
    return text + extra


MODE = ("[planning]\n", "[planning]\nmode = \"{}\"\n")
# the cases that plan a whole stroke to check an input's handling (a dwell or opening read, a warning, a refusal from the
# toppra stage) plan it on the coarsest knots a job may state: what they check is decided by the job's transfer, the press
# file or the calibration's box, or (the weak motor) names whatever angle the path dynamics fail at, so it does not
# depend on the knots; a 5-degree grid plans in about a third of the shipped 1-degree grid's time
COARSE = ("[planning]\n", "[planning]\ngrid_step_deg = 5.0\n")


def mode(name: str) -> tuple[str, str]:
    return MODE[0], MODE[1].format(name)


def planned(result, out) -> dict:
    """A plan that ran: exit 0, no traceback, summary.json written; returns it."""
    code, _, err = result
    assert code == 0 and "Traceback" not in err, err
    return json.loads((out / "summary.json").read_text(encoding="utf-8"))


# --- the tracebacks -----------------------------------------------------------------------------------------------


def test_pareto_in_pendulum_mode_is_refused_naming_the_mode(capsys, tmp_path):
    path = job(tmp_path, door(mode("pendulum"), extra="\n[planning.power]\npareto_points = 2\n"))
    refused(cli(capsys, "plan", "--job", path, "--pareto", "--out", tmp_path / "out"),
            "planning.mode = 'pendulum'", "--pareto", "stop-at-top")
    assert not (tmp_path / "out").exists()


def test_an_empty_transfer_table_plans_with_no_requirement(capsys, tmp_path):
    """Both keys default to 0, "no requirement": the slide is at or above BDC all stroke, so no dwell is needed."""
    path = job(tmp_path, door(COARSE, (OPENING, ""), (TIME, "")))
    s = planned(cli(capsys, "plan", "--job", path, "--out", tmp_path / "out"), tmp_path / "out")
    assert s["dwell_s"] == 0.0
    tr = s["transfer"]
    assert tr["opening_height_m"] == 0.0 and tr["time_above_while_moving_s"] == s["stroke_time_s"]


def test_a_zero_opening_in_auto_mode_plans(capsys, tmp_path):
    """opening_height_m = 0 with the job's 2 s: the whole stroke is above the opening (3.3 s), so no dwell at all."""
    path = job(tmp_path, door(mode("auto"), COARSE, (OPENING, "opening_height_m = 0\n")))
    s = planned(cli(capsys, "plan", "--job", path, "--out", tmp_path / "out"), tmp_path / "out")
    assert s["dwell_s"] == 0.0 and s["modes"]["modes"]["stop-at-top"]["dwell_at_tdc_s"] == 0.0


def test_a_pendulum_on_a_motor_too_weak_for_the_part_names_the_angle_and_torque(capsys, tmp_path):
    press = job(tmp_path, REF_TEXT.replace("peak_torque_Nm = 25000.0", "peak_torque_Nm = 9000.0", 1)
                .replace("rated_torque_Nm = 13500.0", "rated_torque_Nm = 8000.0", 1), "weak.toml")
    path = job(tmp_path, door(mode("pendulum"), COARSE))
    line = refused(cli(capsys, "plan", "--press", press, "--job", path, "--out", tmp_path / "out"),
                   "infeasible job: at crank angle", "N m per motor", "motor.peak_torque_Nm", "pendulum mode")
    assert "stronger motors" in line
    assert not (tmp_path / "out").exists()


def test_a_target_rate_of_a_millionth_stroke_per_minute_is_refused(capsys, tmp_path):
    path = job(tmp_path, door(extra="\n[planning.power]\ntarget_strokes_per_min = 1e-6\n"))
    refused(cli(capsys, "plan", "--job", path, "--out", tmp_path / "out"),
            "planning.power.target_strokes_per_min = 1e-06", "must be 0 (off) or at least 0.01667", "max_dwell_s")
    assert not (tmp_path / "out").exists()


# --- the bounds ---------------------------------------------------------------------------------------------------


def test_a_million_pareto_points_are_refused(capsys, tmp_path):
    path = job(tmp_path, door(extra="\n[planning.power]\npareto_points = 1000000\n"))
    refused(cli(capsys, "plan", "--job", path, "--pareto", "--out", tmp_path / "out"),
            "planning.power.pareto_points = 1000000", "<= 50")
    assert not (tmp_path / "out").exists()


def test_a_grid_limit_of_1e308_is_refused_not_printed_in_309_digits(capsys, tmp_path):
    path = job(tmp_path, door(extra="\n[planning.power]\ngrid_peak_limit_W = 1e308\n"))
    refused(cli(capsys, "plan", "--job", path, "--out", tmp_path / "out"),
            "planning.power.grid_peak_limit_W = 1e+308", "<= 1000000000.0")
    assert not (tmp_path / "out").exists()


# --- the messages -------------------------------------------------------------------------------------------------


def test_a_misspelt_transfer_table_is_named_not_answered_with_add_dwell(capsys, tmp_path):
    """Without [planning.transfer] stop-at-top needs dwell_s; the typo is the mistake, and is named with the fix."""
    path = job(tmp_path, door(("\n[planning.transfer]\n", "\n[planning.transfr]\n")))
    line = refused(cli(capsys, "plan", "--job", path, "--out", tmp_path / "out"),
                   "planning.transfr", "did you mean 'transfer'?")
    assert "dwell_s" not in line
    path = job(tmp_path, door(mode("pendulum"), ("\n[planning.transfer]\n", "\n[planning.transfr]\n")), "pendulum.toml")
    line = refused(cli(capsys, "plan", "--job", path, "--out", tmp_path / "out"), "planning.transfr", "did you mean 'transfer'?")
    assert "needs [planning.transfer]" not in line  # pendulum mode: the typo is named, not the table it misspells
    path = job(tmp_path, door((OPENING, ""), (TIME, ""), ("\n[planning.transfer]\n", "\n")), "no_transfer.toml")
    # no table at all and no dwell: the dwell is still required
    refused(cli(capsys, "plan", "--job", path, "--out", tmp_path / "out"), "planning.dwell_s", "add 'dwell_s'")


def test_an_opening_at_the_stroke_as_printed_is_the_full_opening(capsys, tmp_path):
    """The stroke is 1.4016698 m; the refusal printed it as 1.401670, so 1.40167 is that stroke, the slide at TDC: the
    stroke's moving time counts nothing above it and the dwell is the whole transfer time."""
    path = job(tmp_path, door(COARSE, (OPENING, "opening_height_m = 1.40167\n")))
    s = planned(cli(capsys, "plan", "--job", path, "--out", tmp_path / "out"), tmp_path / "out")
    assert s["transfer"]["time_above_while_moving_s"] == 0.0 and s["dwell_s"] == 2.0
    path = job(tmp_path, door((OPENING, "opening_height_m = 1.40168\n")), "above.toml")
    refused(cli(capsys, "plan", "--job", path, "--out", tmp_path / "out2"), "opening_height_m = 1.40168", "at most the press's stroke")


def test_a_grid_limit_with_storage_on_says_the_storage_is_left_out(capsys, tmp_path):
    press = job(tmp_path, REF_TEXT.replace("enabled = false                       # chosen: the reference press has no capacitor bank",
                                                "enabled = true  # on: what a bank buys", 1), "storage.toml")
    path = job(tmp_path, door(COARSE, extra="\n[planning.power]\ngrid_peak_limit_W = 1.7e6\n"))
    code, _, err = cli(capsys, "plan", "--press", press, "--job", path, "--out", tmp_path / "out")
    assert code == 0 and "Traceback" not in err, err
    warned = [ln for ln in err.splitlines() if "grid_peak_limit_W = 1.700 MW" in ln and "storage" in ln]
    assert len(warned) == 1 and "left out" in warned[0], err
    summary = json.loads((tmp_path / "out" / "summary.json").read_text(encoding="utf-8"))
    assert summary["energy"]["grid_limit_leaves_out_storage_W"] == 3.0e6


def test_a_robust_box_wider_than_the_press_file_is_clipped_to_the_press_files_range(capsys, tmp_path):
    """m8's range in reference_press.toml is [21416.5, 39773.5] kg; the calibrated press (m8 = 32940) has its range re-centred
    on the value ([23058, 42822]). A box reaching 44,000 kg is clipped to the press file's own range, which the warning names."""
    cal = tmp_path / "calibrated.json"
    cal.write_text(json.dumps({"parameters": {"m8": 32940.0}, "joint_region": {"box": {"m8": [31000.0, 44000.0]}}}))
    path = job(tmp_path, door(COARSE))  # the door panel, the command's default job, on coarse knots (COARSE: the box is clipped before planning)
    code, _, err = cli(capsys, "plan", "--job", path, "--params", cal, "--out", tmp_path / "out")
    assert code == 0 and "Traceback" not in err, err
    line = next(ln for ln in err.splitlines() if "box of m8" in ln)
    assert "press file's sensitivity range [21416.5, 39773.5]" in line and "holds over [31000, 39773.5] only" in line, line


def test_the_first_door_panel_job_without_planning_is_told_what_the_table_must_hold(capsys, tmp_path):
    """The first door-panel job (tests/data/history, [job] and [process] only) cannot be planned on defaults alone: the
    default mode, stop-at-top, needs the job's own dwell or transfer (no default: it is the job's). The refusal says so."""
    from pathlib import Path

    first = Path(__file__).parent / "data" / "history" / "door_panel" / "0b53cd0.toml"
    assert "planning" not in first.read_text(encoding="utf-8")
    refused(cli(capsys, "plan", "--job", first, "--out", tmp_path / "out"),
            "planning = '<missing>'", "dwell_s", "[planning.transfer]", "every other key has a default")
    assert not (tmp_path / "out").exists()
