"""`servo-press plan` / `compare` end to end, and the forward-dynamics playback of a plan."""
from __future__ import annotations

import csv
import dataclasses
import json

import pytest

from planning.playback import play_back
from planning.settings import read_planning
from servo_press.cli import main
from press_model.jobs import load_job

PROFILE_COLUMNS = ["time_s", "crank_angle_deg", "crank_speed_rad_s", "crank_accel_rad_s2", "slide_height_m",
                   "slide_velocity_m_s", "motor_torque_Nm", "motor_speed_rpm"]
SUMMARY_KEYS = {"strokes_per_min", "cycle_time_s", "stroke_time_s", "dwell_s", "peak_torque_Nm", "peak_torque_ratio",
                "rms_torque_Nm", "binding_constraints", "parameters", "versions"}


def test_plan_outputs_are_complete_and_byte_identical_on_rerun(tmp_path, capsys, door_panel_plan_run):
    # the first run is the suite's `plan --job door-panel --out FOLDER` (conftest.py: run once, perhaps by the other
    # worker's process), the rerun this test's own
    first, first_stdout, _ = door_panel_plan_run
    outs = [first, tmp_path / "b"]
    assert main(["plan", "--job", "door-panel", "--out", str(outs[1])]) == 0
    assert "spm" in first_stdout and "spm" in capsys.readouterr().out
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


CALIBRATION = {"parameters": {"eta_gear": 0.842, "psi": 1.06, "mu_r": 0.012, "m8": 32940, "J_gear": 60.6, "mu_s": 0.085},
               "intervals": {"eta_gear": [0.835, 0.849], "mu_r": [0.011, 0.013]},
               "joint_region": {"box": {"eta_gear": [0.833, 0.851], "mu_r": [0.0105, 0.0135]}}}
VERDICT = {"adequacy": {"adequate": False}, "warnings": ["MODEL NOT ADEQUATE for the log: a drive loss the model lacks\nmore detail", "m8 on a bound"]}


def test_compare_writes_table_and_cross_evaluation(tmp_path, capsys, door_panel_plan_run):
    cal = tmp_path / "calibrated.json"
    cal.write_text(json.dumps({**CALIBRATION, **VERDICT}))
    out = tmp_path / "cmp"
    assert main(["compare", "--calibrated", str(cal), "--no-verify", "--out", str(out)]) == 0
    captured = capsys.readouterr()
    printed = captured.out
    assert "11.4 -> 11.6" in printed and "rows: calibrated = robust over the calibration's joint region" in printed
    # the calibration's verdict: one WARNING naming the file and what it means for the margin, and the record
    warnings = [ln for ln in captured.err.splitlines() if ln.startswith(f"WARNING: {cal}")]
    assert len(warnings) == 1 and "NOT ADEQUATE" in warnings[0] and "margin is not guaranteed" in warnings[0]
    with open(out / "comparison.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))
    assert [r["plan"] for r in rows] == ["theoretical", "calibrated", "calibrated-nominal"]
    th, rb, ca = rows  # the calibrated row is the robust plan; calibrated-nominal the calibrated values alone
    th_sum = json.loads((out / "theoretical" / "summary.json").read_text())
    assert float(th["strokes_per_min"]) == pytest.approx(th_sum["strokes_per_min"])
    # one plan, one rate: the theoretical row is `plan --job door-panel`'s plan, and both commands print its rate alike
    from planning.profile import rate_text

    rate = rate_text(th_sum["strokes_per_min"])
    assert rate in door_panel_plan_run[1] and f"theoretical plan: {rate}" in printed
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
    # compare plans the nominal plan anyway: the cost is the two plans' difference, not an estimate
    assert rec["robust"]["spm_cost"] == pytest.approx(float(ca["strokes_per_min"]) - float(rb["strokes_per_min"]))
    assert rec["robust"]["nominal_calibrated_is"].startswith("planned")
    assert set(rec["rows_are"]) == {"theoretical", "calibrated", "calibrated-nominal"}
    assert rec["calibration_verdict"] == {"source": str(cal), "adequate": False, "warnings": 2,
                                          "first_warning": "MODEL NOT ADEQUATE for the log: a drive loss the model lacks"}
    assert json.loads((out / "calibrated" / "summary.json").read_text())["calibration_verdict"]["adequate"] is False
    # the robust plan holds for every parameter at once: over the joint region, not the per-parameter intervals
    assert rec["robust"]["box_kind"] == "joint region"
    assert rec["robust"]["box"] == {"eta_gear": [0.833, 0.851], "mu_r": [0.0105, 0.0135]}
    for f in ("comparison.md", "comparison.png", "torque.png", "speed.png", "comparison.json",
              "theoretical/profile.csv", "calibrated/summary.json", "calibrated-nominal/cam_table.csv"):
        assert (out / f).is_file(), f
    assert "calibrated-nominal: planned at the calibrated values alone" in (out / "comparison.md").read_text()
    assert rec["paper"]["strokes_per_min_calibrated"] == 11.6 and "versions" in rec


def _corner_peak_per_point(folder, calibration, share=0.85, most=40):
    """The largest |T_m| / T_max of a plan's profile.csv rows (those within ``share`` of T_max at the calibrated values,
    at most ``most`` of them) at every corner of the calibration's joint region, by the per-point Pinocchio model
    (kinematics, inverse dynamics with friction, Eq. 16): independent of the planner's knot evaluation."""
    import itertools
    import math

    from press_model.dynamics import inverse_dynamics, slide_loads
    from press_model.kinematics import state_at
    from press_model.model import PressModel, Workspace
    from press_model.motor import motor_torque
    from press_model.press_data import load_press

    with open(folder / "profile.csv", newline="") as fh:
        rows = [r for r in csv.DictReader(fh) if abs(float(r["motor_torque_Nm"])) >= share * 25000.0]
    rows = rows[::max(1, len(rows) // most)]
    press, job = load_press(None), load_job("door-panel")
    box = calibration["joint_region"]["box"]
    peak = 0.0
    for corner in itertools.product(*box.values()):
        pc = PressModel(press.with_overrides({**calibration["parameters"], **dict(zip(box, corner))}))
        ws, loads = Workspace(pc), slide_loads(pc, job.process)
        for r in rows:
            th, sd, sdd = math.radians(float(r["crank_angle_deg"])), float(r["crank_speed_rad_s"]), float(r["crank_accel_rad_s2"])
            tau = inverse_dynamics(pc, ws, state_at(pc, ws, th, sd, sdd), loads).crank_torque
            peak = max(peak, abs(float(motor_torque(pc.press.drive, tau, sd, sdd))) / pc.press.motor.peak_torque)
    return peak


def test_plan_from_a_calibration_is_robust_by_default_and_nominal_on_request(tmp_path, capsys):
    cal = tmp_path / "calibrated.json"
    cal.write_text(json.dumps(CALIBRATION))
    assert main(["plan", "--params", str(cal), "--out", str(tmp_path / "default")]) == 0
    captured = capsys.readouterr()
    assert str(cal) not in captured.err and "--nominal" not in captured.err  # an adequate calibration without warnings
    s = json.loads((tmp_path / "default" / "summary.json").read_text())
    r = s["robust"]
    # robust over the joint region without any flag; every corner keeps the feed-forward limit (0.89 T_max)
    assert r["box_kind"] == "joint region" and r["corners_checked"] == 4 and r["worst_corner_peak_ratio"] <= 0.89 + 1e-9
    assert r["worst_case_per_segment"] and "calibration_verdict" not in s
    assert r["spm_cost"] == pytest.approx(r["strokes_per_min_nominal_calibrated"] - s["strokes_per_min"]) and r["spm_cost"] > 0
    assert r["nominal_calibrated_is"].startswith("estimated")
    assert set(r["cost_driver"]["shares"]) == {"eta_gear", "mu_r"} and sum(r["cost_driver"]["shares"].values()) == pytest.approx(1.0)
    assert "design-experiment" in captured.out and f"cost driver {r['cost_driver']['parameter']}" in captured.out
    # the written profile, played per point at every corner of the region, keeps the margin
    assert _corner_peak_per_point(tmp_path / "default", CALIBRATION) <= 0.9

    cal.write_text(json.dumps({**CALIBRATION, **VERDICT}))
    assert main(["plan", "--params", str(cal), "--nominal", "--out", str(tmp_path / "nominal")]) == 0
    err = capsys.readouterr().err
    n = json.loads((tmp_path / "nominal" / "summary.json").read_text())
    assert "robust" not in n and n["calibration_verdict"]["warnings"] == 2
    over = n["nominal_over_region"]
    # the nominal plan sits at the limit at the centre, so a worse corner of the region takes it above
    assert over["corners_checked"] == 4 and over["peak_ratio"] > n["peak_torque_ratio"]
    assert _corner_peak_per_point(tmp_path / "nominal", CALIBRATION) == pytest.approx(over["peak_ratio"], rel=5e-3)
    nominal = [ln for ln in err.splitlines() if ln.startswith("WARNING: --nominal")]
    assert len(nominal) == 1 and f"reaches {over['peak_ratio']:.3f} T_max" in nominal[0] and "margin 0.9 T_max" in nominal[0]
    verdict = [ln for ln in err.splitlines() if ln.startswith(f"WARNING: {cal}")]
    assert len(verdict) == 1 and "NOT ADEQUATE" in verdict[0]
    # the robust plan is slower than the nominal one by what the summary reported (an estimate within 0.2 % of rate)
    assert n["strokes_per_min"] == pytest.approx(r["strokes_per_min_nominal_calibrated"], rel=2e-3)
    assert main(["plan", "--params", str(cal), "--nominal", "--robust", "--out", str(tmp_path / "both")]) == 2
    assert "contradict" in capsys.readouterr().err


def test_feed_forward_alone_tracks_the_plan_in_forward_dynamics(ref_model, door_panel_plan):
    """Open-loop playback (no PD) of the plan's motor torque through Pinocchio's constrained dynamics follows
    the planned crank angle: the plan's torque is consistent with the forward model (second formulation)."""
    job = load_job("door-panel")
    spec = dataclasses.replace(read_planning(job), playback_bandwidth=0.0)  # no feedback: kp = kd = 0
    plan = door_panel_plan  # the shipped plan (conftest.py: once a session); the planner does not read the playback's bandwidth
    _, info = play_back(ref_model, job, spec, plan, t_end=0.6)
    assert info["max_tracking_error_deg"] < 0.05
    assert info["max_loop_gap_m"] < 1e-6
    assert info["max_pd_correction_Nm"] == 0.0
