"""`servo-press plan` / `compare` end to end, and the forward-dynamics playback of a plan."""
from __future__ import annotations

import csv
import dataclasses
import json

import pytest

from planning.planner import plan_stroke
from planning.playback import play_back
from planning.settings import read_planning
from press_model.commands.cli import main
from press_model.jobs import load_job

PROFILE_COLUMNS = ["time_s", "crank_angle_deg", "crank_speed_rad_s", "crank_accel_rad_s2", "slide_height_m",
                   "slide_velocity_m_s", "motor_torque_Nm", "motor_speed_rpm"]
SUMMARY_KEYS = {"strokes_per_min", "cycle_time_s", "stroke_time_s", "dwell_s", "peak_torque_Nm", "peak_torque_ratio",
                "rms_torque_Nm", "binding_constraints", "parameters", "versions"}


def test_plan_outputs_are_complete_and_byte_identical_on_rerun(tmp_path, capsys):
    outs = [tmp_path / "a", tmp_path / "b"]
    for out in outs:
        assert main(["plan", "--job", "door-panel", "--out", str(out)]) == 0
    assert "spm" in capsys.readouterr().out
    names = sorted(p.name for p in outs[0].iterdir())
    assert names == [".servo-press-run.json", "cam_master.csv", "cam_master_isg.txt", "cam_table.csv", "power.csv", "power.png",
                     "profile.csv", "speed.png", "summary.json", "torque.png"]
    for name in names:
        assert (outs[0] / name).read_bytes() == (outs[1] / name).read_bytes(), name
    with open(outs[0] / "profile.csv", newline="") as fh:
        assert next(csv.reader(fh)) == PROFILE_COLUMNS
    s = json.loads((outs[0] / "summary.json").read_text())
    assert SUMMARY_KEYS <= set(s)
    assert s["peak_torque_ratio"] == pytest.approx(s["peak_torque_Nm"] / 25000.0)
    assert s["cycle_time_s"] == pytest.approx(s["stroke_time_s"] + s["dwell_s"])
    assert set(s["binding_constraints"]) >= {"approach", "forming_window", "return", "dwell", "thermal_rms"}


def test_plan_refuses_a_job_without_planning_section(tmp_path, capsys):
    assert main(["plan", "--job", "cushion-test", "--out", str(tmp_path / "x")]) == 2
    err = capsys.readouterr().err
    assert err.startswith("servo-press: error:") and "[planning]" in err and "Traceback" not in err
    assert not (tmp_path / "x").exists()


def test_compare_writes_table_and_cross_evaluation(tmp_path, capsys):
    cal = tmp_path / "calibrated.json"
    cal.write_text(json.dumps({"parameters": {"eta_gear": 0.842, "psi": 1.06, "mu_r": 0.012, "m8": 32940,
                                              "J_gear": 60.6, "mu_s": 0.085},
                               "intervals": {"eta_gear": [0.835, 0.849], "mu_r": [0.011, 0.013]},
                               "joint_region": {"box": {"eta_gear": [0.833, 0.851], "mu_r": [0.0105, 0.0135]}}}))
    out = tmp_path / "cmp"
    assert main(["compare", "--calibrated", str(cal), "--no-verify", "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "11.4 -> 11.6" in printed and "robust plan over the calibration's joint region" in printed
    with open(out / "comparison.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))
    assert [r["plan"] for r in rows] == ["theoretical", "calibrated", "robust"]
    th, ca, rb = rows
    th_sum = json.loads((out / "theoretical" / "summary.json").read_text())
    assert float(th["strokes_per_min"]) == pytest.approx(th_sum["strokes_per_min"])
    assert th_sum["jerk_limit"]["kept"] and th_sum["jerk_limit"]["stroke_time_without_jerk_limit_s"] < th_sum["stroke_time_s"]
    # each plan sits just under the feed-forward limit (margin - feedback reserve = 0.89) under its own model
    assert 0.88 < float(th["peak_ratio_theoretical_model"]) <= 0.89 + 1e-9
    assert 0.88 < float(ca["peak_ratio_calibrated_model"]) <= 0.89 + 1e-9
    assert ca["within_margin_calibrated_model"] == "yes"
    # the robust plan keeps further below the limit at the box's centre, and costs rate: it is the optimum under
    # more torque rows than the calibrated plan's (the centre's rows among them)
    assert float(rb["peak_ratio_calibrated_model"]) < float(ca["peak_ratio_calibrated_model"])
    assert float(rb["strokes_per_min"]) <= float(ca["strokes_per_min"]) * (1 + 1e-6)
    rec = json.loads((out / "comparison.json").read_text())
    assert rec["robust"]["corners_checked"] == 4 and rec["robust"]["worst_corner_peak_ratio"] <= 0.89 + 1e-9
    # the robust plan holds for every parameter at once: over the joint region, not the per-parameter intervals
    assert rec["robust"]["box_kind"] == "joint region"
    assert rec["robust"]["box"] == {"eta_gear": [0.833, 0.851], "mu_r": [0.0105, 0.0135]}
    for f in ("comparison.md", "comparison.png", "torque.png", "speed.png", "comparison.json",
              "theoretical/profile.csv", "calibrated/summary.json", "robust/cam_table.csv"):
        assert (out / f).is_file(), f
    rec = json.loads((out / "comparison.json").read_text())
    assert rec["paper"]["strokes_per_min_calibrated"] == 11.6 and "versions" in rec


def test_feed_forward_alone_tracks_the_plan_in_forward_dynamics(ref_model):
    """Open-loop playback (no PD) of the plan's motor torque through Pinocchio's constrained dynamics follows
    the planned crank angle: the plan's torque is consistent with the forward model (second formulation)."""
    job = load_job("door-panel")
    spec = dataclasses.replace(read_planning(job), playback_bandwidth=0.0)  # no feedback: kp = kd = 0
    plan = plan_stroke(ref_model, job.process, spec)
    _, info = play_back(ref_model, job, spec, plan, t_end=0.6)
    assert info["max_tracking_error_deg"] < 0.05
    assert info["max_loop_gap_m"] < 1e-6
    assert info["max_pd_correction_Nm"] == 0.0
