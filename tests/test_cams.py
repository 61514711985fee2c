"""The master-position cam and the ISG/Beckhoff cam table of a plan (door panel on the reference press).

Checked against the time-based cam table (cam_table.csv: the same plan sampled every controller period in time,
mapped to the master by m = 360 t / cycle time), against its own derivative columns (integrated back to the
position), and against the ISG format's rules (equidistant ascending master over 0-360 deg, point count).
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from planning.cams import (
    LINEAR,
    PER_PERIOD,
    QUINTIC,
    cam_master_points,
    cam_table_points,
    central_differences,
    controller_times,
    declared_interpolation,
    isg_points,
    play,
    played_torque,
    quintic_segments,
)
from planning.cams import (
    POLYNOM5_MM,
    cycle_master,
    hermite_position,
    isg_cam_table,
    master_cam,
    master_points,
    master_speed_deg_s,
    read_isg_cam_table,
)
from planning.cams import NICE_STEPS_DEG, cam_error
from press_io.errors import PlanningError
from planning.profile import cam_table, reference
from press_model.jobs import load_job


TOLERANCE_CRANK_DEG = 0.05  # the bound: the master cam reproduces the time-based table to 0.05 crank degree


@pytest.fixture(scope="module")
def plan(door_panel_plan):
    return door_panel_plan  # the shipped door panel's plan (conftest.py: planned once a session)


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
    assert _error_crank_deg(plan, gear, cam, _linear) < TOLERANCE_CRANK_DEG  # linear between points (position only)
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


def _door_panel_with_master_step(tmp_path, step_deg: float):
    """A copy of the shipped door-panel job with [planning.cam] master_step_deg set."""
    from importlib import resources

    text = resources.files("press_model.data").joinpath("door_panel.toml").read_text(encoding="utf-8")
    job = tmp_path / "job.toml"
    assert "[planning]" in text
    job.write_text(text.replace("[planning]", f"[planning.cam]\nmaster_step_deg = {step_deg:g}\n\n[planning]", 1), encoding="utf-8")
    return job


def test_a_90_degree_master_step_is_refused_before_planning(tmp_path, capsys):
    from servo_press.cli import main
    from press_model.limits import run_limits

    job = _door_panel_with_master_step(tmp_path, 90)
    assert main(["plan", "--job", str(job), "--out", str(tmp_path / "x")]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"servo-press: error: {job}: planning.cam.master_step_deg = 90")
    assert f"must be at most {run_limits().max_cam_master_step_deg:g} deg (max_cam_master_step_deg in press_model/data/run_limits.toml)" in err
    assert err.count("\n") == 1 and not (tmp_path / "x").exists()  # one line, before the planning


def test_a_linear_cam_beyond_t_max_is_refused_naming_the_largest_step_that_passes(plan, gear, ref_model):
    """With a T_max just above what the 0.5-deg cam implies, the 1-deg cam breaks it: refused, with the step that passes."""
    import re

    from planning.cams import checked_cam_error
    from planning.cams import CamSettings
    from press_io.errors import PressDataError

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


def test_isg_cam_table_holds_the_crank_motion_point_by_point(plan, gear):
    cam = master_cam(plan, gear, 0.5)
    text = isg_cam_table(cam, gear, "door outer panel, stop-at-top", 7, 720, ("SYNTHETIC? no: a plan",))
    header, cols = read_isg_cam_table(text)
    assert header == {"Tablename": "door_outer_panel_stop-at-top", "Table-ID": "7", "Functiontype": "6", "Lines": "720"}
    assert cols["SlavePos"].size == 720  # 0 .. 359.5 deg of master; 360 is 0 of the next turn, the slave one turn on
    np.testing.assert_array_equal(cols["PointIndex"], np.arange(1, 721))
    assert np.all(cols["FunctionType"] == POLYNOM5_MM) and np.all(cols["RelIndexNextPoint"] == 1)
    np.testing.assert_allclose(cols["MasterPos"], cam["master_deg"][:-1], rtol=1e-10, atol=0)
    for col, key in (("SlavePos", "motor_position_deg"), ("SlaveVelo", "motor_velocity_deg_per_master_deg"),
                     ("SlaveAcc", "motor_accel_deg_per_master_deg2")):
        np.testing.assert_allclose(cols[col], cam[key][:-1] / gear, rtol=1e-9, atol=1e-12)
    for statement in ("# interpolation: quintic", "# wrap: endless positive", "HLI_CI_ENDLESS_POSITIVE (16#20)", "# phase: the first point is master 0"):
        assert statement in text


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
def test_plan_writes_the_master_cam_which_reproduces_its_time_based_cam_table(door_panel_plan_run):
    import csv
    import json

    out, _, err = door_panel_plan_run  # `plan --job door-panel --out out` (conftest.py: run once a session)

    def columns(name):
        with open(out / name, newline="") as fh:
            rows = list(csv.reader(line for line in fh if not line.startswith("#")))
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
    # the linear interpolation's error (a positions-only import) stated in the summary and the ISG file's header
    ip = s["linear_interpolation"]
    assert ip["linear_position_error_crank_deg"] == pytest.approx(np.max(np.abs(lin - tab["motor_position_deg"])) / gear, abs=1e-6)  # CSV: 10 digits
    isg_text = (out / "cam_master_isg.txt").read_text(encoding="utf-8")
    assert f"crank within {ip['linear_position_error_crank_deg']:.4f} deg of the plan" in isg_text
    assert f"up to {ip['linear_implied_peak_torque_Nm']:,.0f} N m" in isg_text
    # no file declares linear interpolation: what it would give is stated (above), not warned about
    assert "imply at least" not in err and "deg off the plan" not in err
    assert "played as it declares" not in err  # the files as they declare hold the margin
    header, cols = read_isg_cam_table(isg_text)
    assert header["Lines"] == "720" and header["Table-ID"] == "1"
    np.testing.assert_allclose(cols["SlavePos"], cam["motor_position_deg"][:-1] / gear, rtol=0, atol=1e-4)  # CSV has 10 digits


def test_a_job_whose_cam_step_exceeds_the_isg_size_is_refused_before_planning(tmp_path, capsys):
    from servo_press.cli import main

    job = _door_panel_with_master_step(tmp_path, 0.25)
    assert main(["plan", "--job", str(job), "--out", str(tmp_path / "x")]) == 2
    err = capsys.readouterr().err
    assert "planning.cam.master_step_deg = 0.25 is not valid: gives 1440 points a turn, more than isg_max_lines = 720" in err
    assert err.count("\n") == 1 and not (tmp_path / "x").exists()


# --- every cam file played as its header declares, at the controller's period, holds the torque margin ------------------
@pytest.fixture(scope="module")
def written(door_panel_written):
    return door_panel_written[0]  # the plan's outputs (conftest.py: written once a session)


def _csv_columns(text):
    import csv

    rows = list(csv.reader(line for line in text.splitlines() if not line.startswith("#")))
    return {k: np.array([float(r[i]) for r in rows[1:]]) for i, k in enumerate(rows[0])}


def _played(plan, gear, name, text, use_columns=True):
    """(played set-points in crank deg, their torque in N m) of a written cam file, played as its header declares."""
    kind = declared_interpolation(text)
    if name == "cam_master_isg.txt":
        points, per_crank = isg_points(read_isg_cam_table(text)[1]), 1.0
    elif name == "cam_master.csv":
        points, per_crank = cam_master_points(_csv_columns(text)), gear
    else:
        points, per_crank = cam_table_points(_csv_columns(text)), gear
    pl = play(kind, points, plan.cycle_time, plan.spec.controller_period, 360.0 * per_crank, use_columns)
    crank = {k: pl[k] / per_crank for k in ("position", "speed", "accel")}
    return crank, played_torque(plan, crank["position"], crank["speed"], crank["accel"])


@pytest.mark.parametrize("name, kind", [("cam_table.csv", PER_PERIOD), ("cam_master.csv", QUINTIC), ("cam_master_isg.txt", QUINTIC)])
def test_every_cam_file_played_as_it_declares_holds_the_margin(ref_model, plan, gear, written, name, kind):
    """Each file's header names its interpolation; played that way every controller period (2 ms), the feed-forward
    the plan's model gives at the played set-points stays within 0.9 T_max; the motion is the plan's (0.01 crank deg)."""
    text = (written / name).read_text(encoding="utf-8")
    assert declared_interpolation(text) == kind
    limit = plan.spec.torque_limits(ref_model.press.motor.peak_torque).verdict
    for use_columns in ((True, False) if kind == PER_PERIOD else (True,)):  # a per-period table: its columns, or position differences
        crank, torque = _played(plan, gear, name, text, use_columns)
        assert np.max(np.abs(torque)) <= limit, (name, use_columns, np.max(np.abs(torque)) / ref_model.press.motor.peak_torque)
        ref = reference(plan, controller_times(plan.cycle_time, plan.spec.controller_period))
        assert np.max(np.abs(crank["position"] - np.degrees(ref["theta"] - plan.pd.theta[0]))) < 0.01


def test_the_played_peak_is_the_per_point_model_s(ref_model, plan, gear, written):
    """The played torque of the ISG table at its largest instants against Pinocchio's per-point inverse dynamics (Eq. 16
    on the crank torque) at the same played angle, speed and acceleration: within 0.5 % of T_max, and within the margin."""
    from press_model.dynamics import inverse_dynamics, slide_loads
    from press_model.kinematics import state_at
    from press_model.model import Workspace
    from press_model.motor import motor_torque

    crank, torque = _played(plan, gear, "cam_master_isg.txt", (written / "cam_master_isg.txt").read_text(encoding="utf-8"))
    T_max = ref_model.press.motor.peak_torque
    ws, loads = Workspace(ref_model), slide_loads(ref_model, load_job("door-panel").process)
    contact = plan.grid.special["die_contact"]
    theta = plan.pd.theta[0] + np.radians(crank["position"])
    # beside die contact the plan's torque takes the forming side of the force step across the segment: left out
    top = [k for k in np.argsort(-np.abs(torque)) if abs(theta[k] - contact) > np.radians(1.0)][:3]
    for k in top:
        sd, sdd = math.radians(crank["speed"][k]), math.radians(crank["accel"][k])
        tau = inverse_dynamics(ref_model, ws, state_at(ref_model, ws, float(theta[k]), sd, sdd), loads).crank_torque
        T = float(motor_torque(ref_model.press.drive, tau, sd, sdd))
        assert abs(T - torque[k]) < 5e-3 * T_max and abs(T) <= plan.spec.torque_limits(T_max).verdict


def test_a_point_table_played_linearly_breaks_the_margin(ref_model, plan, gear):
    """Why the ISG table carries derivatives: the same cam as positions only, interpolated linearly at 0.5 deg per master
    step and differenced at 2 ms as a drive that takes positions does, steps the speed at every point: far above T_max."""
    cam = master_cam(plan, gear, 0.5)
    points = {"master": cam["master_deg"], "position": cam["motor_position_deg"] / gear}
    pl = play(LINEAR, points, plan.cycle_time, plan.spec.controller_period, 360.0)
    peak = np.max(np.abs(played_torque(plan, pl["position"], pl["speed"], pl["accel"])))
    assert peak > 1.5 * ref_model.press.motor.peak_torque


def test_quintic_segments_reproduce_a_quintic_and_its_derivatives():
    """Points of one quintic with its exact derivatives: the segments between them are that quintic everywhere."""
    rng = np.random.default_rng(3)
    c = rng.normal(size=6)
    poly = np.polynomial.Polynomial(c)
    master = np.array([0.0, 0.7, 1.5, 3.0])
    m = np.linspace(0.0, 3.0, 97)
    p, dp, ddp = quintic_segments(master, poly(master), poly.deriv()(master), poly.deriv(2)(master), m)
    np.testing.assert_allclose(p, poly(m), atol=1e-10)
    np.testing.assert_allclose(dp, poly.deriv()(m), atol=1e-9)
    np.testing.assert_allclose(ddp, poly.deriv(2)(m), atol=1e-8)


def test_central_differences_wrap_endlessly_and_are_exact_on_a_parabola():
    """Set-points of p = t^2 every 0.5 s up to t = 2, the next cycle's first one (p(2.5) = 6.25) the first plus the turn:
    exact speed and acceleration inside and at the last set-point, which takes its successor from the wrap."""
    t = np.arange(5) * 0.5
    speed, accel = central_differences(t * t, 0.5, 6.25)
    np.testing.assert_allclose(speed[1:-1], 2.0 * t[1:-1])
    np.testing.assert_allclose(accel[1:-1], 2.0)
    assert speed[-1] == pytest.approx(2.0 * t[-1]) and accel[-1] == pytest.approx(2.0)


def test_a_cam_file_without_its_interpolation_is_refused():
    with pytest.raises(ValueError, match="no '# interpolation: "):
        declared_interpolation("time_s,motor_position_deg\n0,0\n")


def test_a_cam_whose_master_step_breaks_the_margin_played_is_named_in_a_warning(ref_model, plan, gear, written):
    """At 4 deg per master step the quintic segments are too long for the motion: played at 2 ms they break 0.9 T_max,
    and the plan's warnings name the master cam and the ISG file (the 0.5-deg files of `written`: no warning)."""
    import json

    from planning.report import played_cam_warnings

    info = json.loads((written / "summary.json").read_text())
    assert played_cam_warnings(info) == []
    cam = master_cam(plan, gear, 4.0)
    pl = play(QUINTIC, cam_master_points(cam), plan.cycle_time, plan.spec.controller_period, 360.0 * gear)
    peak = float(np.max(np.abs(played_torque(plan, pl["position"] / gear, pl["speed"] / gear, pl["accel"] / gear))))
    assert peak > plan.spec.torque_limits(ref_model.press.motor.peak_torque).verdict
    info["cam_master_csv"]["played_peak_torque_Nm"] = info["cam_master_csv"]["isg_file"]["played_peak_torque_Nm"] = peak
    lines = played_cam_warnings(info)
    assert [ln.split(" ")[0] for ln in lines] == ["cam_master.csv", "cam_master_isg.txt"]
    assert "lower [planning.cam] master_step_deg" in lines[0] and f"{peak:,.0f} N m" in lines[0]



@pytest.mark.parametrize("extra", ["", "[planning.hold]\nbottom_dwell_s = 0.5\n"], ids=["no stop", "hold at BDC"])
def test_a_continuous_plans_cam_files_played_as_they_declare_hold_the_margin(ref_model, gear, tmp_path, extra, continuous_door_panel_plan):
    """Continuous mode: the crank moves through the cycle's wrap and the cycle time is no whole number of controller
    periods. cam_table.csv takes a whole number (its motion a few 1e-4 slower, stated), so a drive stepping its rows and
    differencing the positions sees no short last step; every file played as it declares stays within 0.9 T_max. The
    plans are the suite's (fixtures_suiteplan.py: test_planning and test_planning_stops read them too)."""
    from planning.report import write_plan_outputs

    job, p = continuous_door_panel_plan(extra)
    period = p.spec.controller_period
    assert p.spec.mode == "continuous" and p.dwell == 0.0
    assert 0.01 < (p.cycle_time / period) % 1.0 < 0.99  # the case: the cycle ends between two controller ticks
    write_plan_outputs(ref_model, job, p, tmp_path / "out", {}, "test")
    limit = p.spec.torque_limits(ref_model.press.motor.peak_torque).verdict
    for name in ("cam_table.csv", "cam_master.csv", "cam_master_isg.txt"):
        text = (tmp_path / "out" / name).read_text(encoding="utf-8")
        for use_columns in ((True, False) if declared_interpolation(text) == PER_PERIOD else (True,)):
            _, torque = _played(p, gear, name, text, use_columns)
            assert np.max(np.abs(torque)) <= limit, (name, use_columns, np.max(np.abs(torque)) / ref_model.press.motor.peak_torque)
    tab = _csv_columns((tmp_path / "out" / "cam_table.csv").read_text(encoding="utf-8"))
    n = round(p.cycle_time / period + 0.5)
    np.testing.assert_allclose(tab["time_s"], np.arange(n + 1) * period, rtol=0, atol=1e-12)
