"""The master-position cam and the ISG/Beckhoff ASCII cam table of a plan (door panel on the reference press).

Checked against the time-based cam table (cam_table.csv: the same plan sampled every controller period in time,
mapped to the master by m = 360 t / cycle time), against its own derivative columns (integrated back to the
position), and against the ISG format's rules (equidistant ascending master over 0-360 deg, point count).
"""
from __future__ import annotations

import numpy as np
import pytest

from planning.cams import (
    ISG_UNIT_DEG,
    cycle_master,
    hermite_position,
    isg_cam_table,
    master_cam,
    master_points,
    master_speed_deg_s,
    read_isg_cam_table,
)
from planning.cam_error import NICE_STEPS_DEG, cam_error
from planning.errors import PlanningError
from planning.planner import plan_stroke
from planning.profile import cam_table
from planning.settings import read_planning
from press_model.jobs import load_job

TOLERANCE_CRANK_DEG = 0.05  # the bound: the master cam reproduces the time-based table to 0.05 crank degree


@pytest.fixture(scope="module")
def plan(ref_model):
    job = load_job("door-panel")
    return plan_stroke(ref_model, job.process, read_planning(job))


@pytest.fixture(scope="module")
def gear(ref_model):
    return ref_model.press.drive.gear_ratio


def _error_crank_deg(plan, gear, cam, interpolate):
    """Largest |motor position of the master cam - cam_table.csv's| over the time-based rows, in crank degrees."""
    tab = cam_table(plan, gear)
    m = cycle_master(tab["time_s"], plan.cycle_time)
    pos = interpolate(cam, m)
    return float(np.max(np.abs(pos - tab["motor_position_deg"]))) / gear


def _linear(cam, m):
    return np.interp(m, cam["master_deg"], cam["motor_position_deg"])


@pytest.mark.parametrize("step", [0.5, 1.0])
def test_master_cam_reproduces_the_time_based_cam_table(plan, gear, step):
    cam = master_cam(plan, gear, step)
    assert _error_crank_deg(plan, gear, cam, _linear) < TOLERANCE_CRANK_DEG  # linear between points (ISG Functiontype 1)
    assert _error_crank_deg(plan, gear, cam, hermite_position) < 1e-3  # with the velocity column, cubic between points


def test_a_coarse_master_step_breaks_the_bound_with_linear_interpolation(plan, gear):
    """The comparison can fail: at 4 deg per master step the chord between points is off by more than 0.05 crank deg."""
    assert _error_crank_deg(plan, gear, master_cam(plan, gear, 4.0), _linear) > TOLERANCE_CRANK_DEG


def test_cam_error_states_the_linear_cams_position_error_and_the_torque_it_implies(plan, gear, ref_model):
    """The position error is the one measured against cam_table.csv's rows; the implied torque converges on the plan's
    own feed-forward as the master step shrinks (the chords' speeds become the plan's) and grows with the step."""
    t_max = ref_model.press.motor.peak_torque
    errs = {step: cam_error(plan, gear, t_max, step) for step in (0.1, 0.5, 1.0, 4.0)}
    for step, e in errs.items():
        assert e.position_error_crank_deg == pytest.approx(_error_crank_deg(plan, gear, master_cam(plan, gear, step), _linear), rel=1e-9)
        assert e.torque_limit_Nm == pytest.approx(plan.spec.torque_margin * t_max)
    plan_peak = float(np.max(np.abs(cam_table(plan, gear)["feedforward_torque_Nm"])))
    assert errs[0.1].plan_peak_torque_Nm == pytest.approx(plan_peak, rel=1e-12)
    assert abs(errs[0.1].implied_torque_Nm - plan_peak) < 0.005 * plan_peak  # fine chords: the plan's torque
    assert abs(errs[0.1].cubic_torque_Nm - plan_peak) < 0.005 * plan_peak
    assert errs[0.1].implied_torque_Nm < errs[0.5].implied_torque_Nm < errs[1.0].implied_torque_Nm < errs[4.0].implied_torque_Nm
    assert not errs[4.0].position_ok and errs[0.5].position_ok


def test_a_90_degree_master_step_is_refused_before_planning(tmp_path, capsys):
    from importlib import resources

    from press_model.commands.cli import main
    from press_model.limits import run_limits

    text = resources.files("press_model.data").joinpath("door_panel.toml").read_text(encoding="utf-8")
    job = tmp_path / "job.toml"
    assert "[planning]" in text
    job.write_text(text.replace("[planning]", "[planning.cam]\nmaster_step_deg = 90\n\n[planning]", 1), encoding="utf-8")
    assert main(["plan", "--job", str(job), "--out", str(tmp_path / "x")]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"servo-press: error: {job}: planning.cam.master_step_deg = 90")
    assert f"must be at most {run_limits().max_cam_master_step_deg:g} deg (max_cam_master_step_deg in press_model/data/run_limits.toml)" in err
    assert err.count("\n") == 1 and not (tmp_path / "x").exists()  # one line, before the planning


def test_a_linear_cam_beyond_t_max_is_refused_naming_the_largest_step_that_passes(plan, gear, ref_model):
    """With a T_max just above what the 0.5-deg cam implies, the 1-deg cam breaks it: refused, with the step that passes."""
    import re

    from planning.cam_error import checked_cam_error
    from planning.cams import CamSettings
    from press_model.errors import PressDataError

    t_max = cam_error(plan, gear, ref_model.press.motor.peak_torque, 0.5).implied_torque_Nm + 1.0
    assert checked_cam_error(plan, gear, t_max, CamSettings(0.5, 1, 720), "job.toml").ok
    with pytest.raises(PressDataError) as exc:
        checked_cam_error(plan, gear, t_max, CamSettings(1.0, 1, 720), "job.toml")
    text = str(exc.value)
    assert "planning.cam.master_step_deg = 1.0 is not valid: following its linear interpolation's chords takes at least" in text
    step = float(re.search(r"use master_step_deg = ([0-9.]+)", text).group(1))
    assert cam_error(plan, gear, t_max, step).ok
    assert all(not cam_error(plan, gear, t_max, s).ok for s in NICE_STEPS_DEG if step < s <= 1.0)


def test_master_cam_spans_one_cycle_from_zero_to_gear_ratio_turns(plan, gear):
    cam = master_cam(plan, gear, 0.5)
    m, pos, vel = cam["master_deg"], cam["motor_position_deg"], cam["motor_velocity_deg_per_master_deg"]
    assert m[0] == 0.0 and m[-1] == 360.0 and m.size == 721 and np.allclose(np.diff(m), 0.5, rtol=0, atol=1e-12)
    assert pos[0] == pytest.approx(0.0, abs=1e-9) and pos[-1] == pytest.approx(360.0 * gear, rel=1e-12)
    assert np.all(np.diff(pos) >= -1e-9)  # the motor never turns back
    dwell = m > 360.0 * plan.stroke_time / plan.cycle_time + 1e-9
    assert dwell.any() and np.all(vel[dwell] == 0.0) and np.all(pos[dwell] == pos[-1])  # held at TDC in the dwell
    assert vel[0] == pytest.approx(0.0, abs=1e-9)  # stop-at-top: starts from rest
    assert master_speed_deg_s(plan) * plan.cycle_time == pytest.approx(360.0)


def test_velocity_and_acceleration_columns_are_the_derivatives_of_the_position(plan, gear):
    """Integrated over the master by the trapezoid rule they give the position and velocity back, within the rule's
    error bound h^3 |y''| / 12 per step, summed, for the integrand y (y'' from the next column's differences per step)."""
    cam = master_cam(plan, gear, 0.25)
    m, pos, vel, acc = (cam[k] for k in ("master_deg", "motor_position_deg", "motor_velocity_deg_per_master_deg",
                                          "motor_accel_deg_per_master_deg2"))
    h = 0.25

    def trapezoid(y):
        return np.concatenate(([0.0], np.cumsum(0.5 * (y[1:] + y[:-1]) * np.diff(m))))

    bound_pos = h * h * np.sum(np.abs(np.diff(acc))) / 12.0  # the integrand is vel: vel'' = acc' ~ diff(acc) / h
    assert 0 < np.max(np.abs(trapezoid(vel) - pos)) <= bound_pos
    assert bound_pos / gear < TOLERANCE_CRANK_DEG  # crank deg: the check is finer than the bound the cam must meet
    bound_vel = h * np.sum(np.abs(np.diff(acc, 2))) / 12.0  # the integrand is acc: acc'' ~ diff(acc, 2) / h^2
    assert np.max(np.abs(vel[0] + trapezoid(acc) - vel)) <= bound_vel
    assert bound_vel < 0.01 * np.max(np.abs(vel))


def test_isg_cam_table_holds_the_crank_position_in_its_units(plan, gear):
    cam = master_cam(plan, gear, 0.5)
    text = isg_cam_table(cam, gear, "door outer panel, stop-at-top", 7, 720, ("SYNTHETIC? no: a plan",))
    header, crank = read_isg_cam_table(text)
    assert header == {"Tablename": "door_outer_panel_stop-at-top", "Tabletype": "3", "Table-ID": "7", "Functiontype": "1",
                      "Lines": "720"}
    assert crank.size == 720  # 0 .. 359.5 deg of master; 360 is 0 of the next turn
    np.testing.assert_allclose(crank, cam["motor_position_deg"][:-1] / gear, rtol=0, atol=ISG_UNIT_DEG / 2 + 1e-12)
    assert all(line.lstrip("-").isdigit() for line in text.split("Begintable\n")[1].split("\nEndTable")[0].splitlines())


def test_isg_limits_are_checked(plan, gear):
    cam = master_cam(plan, gear, 0.5)
    with pytest.raises(PlanningError, match="720 interpolation points exceed isg_max_lines = 360"):
        isg_cam_table(cam, gear, "x", 1, 360, ())
    shuffled = dict(cam, master_deg=cam["master_deg"][::-1].copy())
    with pytest.raises(PlanningError, match="must ascend in equal steps from 0 to 360 deg"):
        isg_cam_table(shuffled, gear, "x", 1, 720, ())
    with pytest.raises(PlanningError, match="Table-ID 0"):
        isg_cam_table(cam, gear, "x", 0, 720, ())
    with pytest.raises(PlanningError, match="master_step_deg = 0.7 is not valid: it must divide 360 deg"):
        master_points(0.7)


# --- through the CLI: `servo-press plan` writes both cam files ---------------------------------------------------------
def test_plan_writes_the_master_cam_which_reproduces_its_time_based_cam_table(tmp_path, capsys):
    import csv
    import json

    from press_model.commands.cli import main

    out = tmp_path / "plan"
    assert main(["plan", "--job", "door-panel", "--out", str(out)]) == 0
    err = capsys.readouterr().err

    def columns(name):
        with open(out / name, newline="") as fh:
            rows = list(csv.reader(fh))
        return {k: np.array([float(r[i]) for r in rows[1:]]) for i, k in enumerate(rows[0])}

    cam, tab = columns("cam_master.csv"), columns("cam_table.csv")
    s = json.loads((out / "summary.json").read_text())["cam_master_csv"]
    gear = 32.0  # the reference press
    assert list(cam) == ["master_deg", "motor_position_deg", "motor_velocity_deg_per_master_deg", "motor_accel_deg_per_master_deg2"]
    assert s["master_step_deg"] == 0.5 and cam["master_deg"].size == s["points"] == 721  # door_panel.toml [planning.cam]
    assert s["master_speed_deg_s"] * s["cycle_time_s"] == pytest.approx(360.0)
    m = cycle_master(tab["time_s"], s["cycle_time_s"])
    lin = np.interp(m, cam["master_deg"], cam["motor_position_deg"])
    assert np.max(np.abs(lin - tab["motor_position_deg"])) / gear < TOLERANCE_CRANK_DEG
    # the interpolation's error stated in the summary and the ISG file's header: the position error as measured here
    ip = s["interpolation"]
    assert ip["linear_position_error_crank_deg"] == pytest.approx(np.max(np.abs(lin - tab["motor_position_deg"])) / gear, abs=1e-6)  # CSV: 10 digits
    isg_text = (out / "cam_master_isg.txt").read_text(encoding="utf-8")
    assert f"crank within {ip['linear_position_error_crank_deg']:.4f} deg of the plan" in isg_text
    assert f"up to {ip['linear_implied_peak_torque_Nm']:,.0f} N m" in isg_text
    assert ("implies at least" in err) == (not ip["linear_within_torque_margin"])  # a warning iff beyond the margin
    assert ("deg off the plan" in err) == (not ip["linear_within_tracking_tolerance"])
    header, crank = read_isg_cam_table(isg_text)
    assert header["Lines"] == "720" and header["Table-ID"] == "1"
    np.testing.assert_allclose(crank, cam["motor_position_deg"][:-1] / gear, rtol=0, atol=1e-4)  # CSV has 10 digits


def test_a_job_whose_cam_step_exceeds_the_isg_size_is_refused_before_planning(tmp_path, capsys):
    from importlib import resources

    from press_model.commands.cli import main

    text = resources.files("press_model.data").joinpath("door_panel.toml").read_text(encoding="utf-8")
    job = tmp_path / "job.toml"
    assert "[planning]" in text
    job.write_text(text.replace("[planning]", "[planning.cam]\nmaster_step_deg = 0.25\n\n[planning]", 1), encoding="utf-8")
    assert main(["plan", "--job", str(job), "--out", str(tmp_path / "x")]) == 2
    err = capsys.readouterr().err
    assert "planning.cam.master_step_deg = 0.25 is not valid: gives 1440 points a turn, more than isg_max_lines = 720" in err
    assert err.count("\n") == 1 and not (tmp_path / "x").exists()
