"""Stops on the way ([planning.hold], [planning.pause]; planning/hold.py): the static torque held, against virtual work;
the stop in the cycle's thermal RMS (a longer hold heats more, the limit binds); the written profile, the cams and the
playback holding it."""
from __future__ import annotations

import dataclasses
import math
from importlib import resources

import numpy as np
import pinocchio as pin
import pytest

from planning.grid import planning_grid
from planning.cams import master_cam
from planning.hold import StopRequest, stop_spans
from planning.path_dynamics import build_path_dynamics
from planning.planner import StrokeProblem, plan_stroke, thermal_limit
from planning.profile import cam_table, sample_plan
from planning.settings import read_planning
from press_model.forces import BalanceForce
from press_model.jobs import load_job
from press_model.kinematics import height_at, state_at
from press_model.model import PressModel, Workspace
from press_model.motor import motor_torque
from press_model.press_data import load_press


JOB = "door-panel"


def _job(tmp_path, extra: str):
    text = resources.files("press_model.data").joinpath("door_panel.toml").read_text(encoding="utf-8")
    path = tmp_path / "job.toml"
    path.write_text(text + "\n" + extra, encoding="utf-8")
    return load_job(path)


def _with_stops(spec, *stops):
    return dataclasses.replace(spec, stops=tuple(StopRequest(*s) for s in stops))


@pytest.fixture(scope="module")
def spec(job):
    return read_planning(job)


def _virtual_work_torque(pm, job, theta, d=1e-5):
    """Crank torque (N m) that holds the linkage still at ``theta`` by virtual work, from positions alone: the rise of
    the potential energy of gravity per radian, and the slide's upward forces (balance, the downstroke's process force)
    times dH/dtheta. Central differences on the assembled positions, no dynamics."""
    ws = Workspace(pm)
    data = pm.model.createData()

    def com_height(th):
        q = state_at(pm, ws, th, 0.0, 0.0).q
        c = pin.centerOfMass(pm.model, data, q)
        return -float(np.dot(pm.model.gravity.linear, c)) / float(np.linalg.norm(pm.model.gravity.linear))

    mass = pin.computeTotalMass(pm.model)
    g = float(np.linalg.norm(pm.model.gravity.linear))
    dz = (com_height(theta + d) - com_height(theta - d)) / (2 * d)
    h = height_at(pm, ws, theta)
    dh = (height_at(pm, ws, theta + d) - height_at(pm, ws, theta - d)) / (2 * d)
    up = float(BalanceForce.from_press(pm.press, pm.assembly.stroke)(h)) + float(job.process(np.array([h]), np.array([-1.0]))[0])
    return mass * g * dz - up * dh


def test_stop_torque_is_the_static_torque_by_virtual_work(ref_model, job, spec):
    """The crank torque a stop holds (the full model at rest, process force on) equals virtual work's on the positions
    alone, at a hold 15 mm above BDC under the 6 MN forming force and a pause above die contact; the motor torque lies
    in Eq. 16's band at it (the motors driving the load, the load driving the motors). On 5-degree knots: each stop is a
    knot of its own, its torque the full model's at that knot whatever the others."""
    s = _with_stops(dataclasses.replace(spec, grid_step=math.radians(5.0)), ("hold", 0.015, 0.5), ("pause", 0.25, 0.2))
    grid = planning_grid(ref_model, job.process, s)
    pd = build_path_dynamics(ref_model, grid.theta, job.process, grid.contact_index)
    from planning.hold import stops_on_grid

    stops = stops_on_grid(pd, ref_model.press.drive, grid, s.stops)
    assert [st.name for st in stops] == ["pause", "hold"]
    for st in stops:
        assert st.height == pytest.approx({"hold": 0.015, "pause": 0.25}[st.name], abs=1e-9)  # a knot of its own
        ref = _virtual_work_torque(ref_model, job, st.theta)
        assert st.crank_torque == pytest.approx(ref, rel=2e-5, abs=5.0), st.name
        drive = ref_model.press.drive
        hi, lo = (float(motor_torque(drive, st.crank_torque, v, 0.0)) for v in (1e-6, -1e-6))
        assert min(lo, hi) < st.torque < max(lo, hi)
    hold = next(st for st in stops if st.name == "hold")
    assert hold.process_force == pytest.approx(6.0e6) and hold.crank_torque > 1e5  # the force through the linkage


@pytest.fixture(scope="module")
def held(ref_model, job, spec):
    """The door panel with a hold 15 mm above BDC of 0.2 s and of 1.0 s (its holding torque above the cycle RMS), at its
    fixed dwell at TDC before [planning.transfer] (1.7423 s: with the transfer's dwell, 0 s beside these stops, the cycle
    RMS is above the hold's torque). On 5-degree knots (the coarsest a job may state): the stop's torque, its time in the
    RMS and in the written tables, and the thermal limit binding hold on any knots."""
    fixed = dataclasses.replace(spec, dwell=1.7423, transfer=None, grid_step=math.radians(5.0))
    # one problem for both: a stop's knot is where its height is (its time does not move it), so the knots and their
    # path dynamics are the same
    problem = StrokeProblem.build(ref_model, job.process, _with_stops(fixed, ("hold", 0.015, 0.2)))
    out = {}
    for t in (0.2, 1.0):
        held_spec = _with_stops(fixed, ("hold", 0.015, t))
        grid = planning_grid(ref_model, job.process, held_spec)
        assert np.array_equal(grid.theta, problem.grid.theta) and grid.contact_index == problem.grid.contact_index
        out[t] = plan_stroke(problem.using(held_spec))
    return out


def test_hold_counts_in_the_thermal_rms_and_the_limit_binds(job, spec, held):
    """The cycle RMS includes the hold at its static torque: a longer hold (its torque above the RMS) raises it by what
    the hold's time adds (a second quadrature on profile.csv's samples gives the same), and a motor rated below the long
    hold's RMS makes the thermal limit bind: the plan slows and keeps it."""
    short, long_ = held[0.2], held[1.0]
    hold = long_.stops[0]
    assert abs(hold.torque) > long_.rms_torque
    assert long_.rms_torque > short.rms_torque
    # the same RMS from the written 2 ms samples (trapezoids), the hold's samples included
    cols = sample_plan(long_, 32.0)
    t, tq = cols["time_s"], cols["motor_torque_Nm"]
    rms = math.sqrt(float(np.sum(np.diff(t) * (tq[1:] ** 2 + tq[:-1] ** 2) / 2.0)) / long_.cycle_time)
    assert rms == pytest.approx(long_.rms_torque, rel=2e-3)
    press = load_press()
    rated = round(0.98 * long_.rms_torque, 1)
    pm = PressModel(dataclasses.replace(press, motor=dataclasses.replace(press.motor, rated_torque=rated)))
    hot = plan_stroke(StrokeProblem(pm, job.process, _with_stops(long_.spec, ("hold", 0.015, 1.0)), long_.grid, long_.pd))
    assert hot.thermal_binding and hot.rms_torque <= thermal_limit(pm, hot.spec) * (1 + 1e-9)
    assert hot.strokes_per_min < long_.strokes_per_min


def test_profile_and_cams_hold_the_stop(held):
    """profile.csv and cam_table.csv stand still at the stop's angle for its time, at its holding torque; the stroke's
    time is the motion's plus the stop's."""
    p = held[1.0]
    st = p.stops[0]
    assert p.stroke_time == pytest.approx(p.profile.stroke_time + 1.0, abs=1e-12)
    cols = sample_plan(p, 32.0)
    at = np.flatnonzero(np.abs(np.radians(cols["crank_angle_deg"]) - st.theta) < 1e-9)
    span = cols["time_s"][at[-1]] - cols["time_s"][at[0]]
    assert span == pytest.approx(1.0, abs=2 * p.spec.sample_time)
    inside = at[1:-1]
    assert np.all(cols["crank_speed_rad_s"][inside] == 0.0) and np.all(cols["crank_accel_rad_s2"][inside] == 0.0)
    assert np.allclose(cols["motor_torque_Nm"][inside], st.torque)
    cam = cam_table(p, 32.0)
    assert np.ptp(cam["motor_position_deg"][inside]) == 0.0
    # the master cam (one master turn per cycle) stands still over the stop's share of the master, at its velocity 0
    (t0, t1, _), = stop_spans(p)
    master = master_cam(p, 32.0, 0.5)
    on = (master["master_deg"] > 360.0 * t0 / p.cycle_time + 1e-9) & (master["master_deg"] < 360.0 * t1 / p.cycle_time - 1e-9)
    assert on.sum() >= int(0.5 * 360.0 * 1.0 / p.cycle_time / 0.5)  # about half the points the stop's time spans
    assert np.ptp(master["motor_position_deg"][on]) == 0.0 and np.all(master["motor_velocity_deg_per_master_deg"][on] == 0.0)
    assert master["motor_position_deg"][on][0] == pytest.approx(32.0 * np.degrees(st.theta - p.pd.theta[0]), abs=1e-9)


def test_hold_at_bdc_and_pause_play_back_within_every_limit(ref_model, job, spec):
    """The door panel with a 1 s hold at BDC and a 0.2 s pause at 0.25 m, played back through the forward dynamics:
    every limit holds (torque margin, tracking, loop gap, thermal RMS over the played cycle, hold included). Planned on
    5-degree knots: the limits a playback holds are the plan's on any knots."""
    from planning.playback import play_back

    coarse = dataclasses.replace(spec, grid_step=math.radians(5.0))
    p = plan_stroke(StrokeProblem.build(ref_model, job.process, _with_stops(coarse, ("hold", 0.0, 1.0), ("pause", 0.25, 0.2))))
    assert [st.name for st in p.stops] == ["pause", "hold"]
    cols, info = play_back(ref_model, job, p.spec, p)
    assert info["verdict"]["ok"], info["verdict"]["line"]
    assert info["played_s"] == pytest.approx(p.cycle_time)
    assert info["cycle_rms_Nm"] == pytest.approx(p.rms_torque, rel=0.01)


def test_pause_without_height_is_refused(tmp_path):
    from press_io.errors import ServoPressError

    job = _job(tmp_path, "[planning.pause]\ntime_s = 0.3\n")
    with pytest.raises(ServoPressError) as exc:
        read_planning(job)
    assert "planning.pause.height_m" in str(exc.value) and "0.0" in str(exc.value)


def test_a_continuous_hold_at_bdc_plays_back_within_the_tracking_tolerance(ref_model, continuous_door_panel_plan):
    """Continuous mode, 0.5 s at BDC under the 6 MN: the crank arrives under full force, stands, and leaves. The die's
    force stays on the standing slide (it acts on the slide moving down: a creep back must not drop it), so the played
    crank stays within the tracking tolerance while it stands and as it leaves. The plan is the suite's
    (fixtures_suiteplan.py: test_cams plays its cam files)."""
    from planning.playback import play_back

    job, p = continuous_door_panel_plan("[planning.hold]\nbottom_dwell_s = 0.5\n")
    pm = ref_model
    assert p.spec.mode == "continuous" and [st.name for st in p.stops] == ["hold"] and p.stops[0].process_force > 0
    cols, info = play_back(pm, job, p.spec, p)
    assert info["max_tracking_error_deg"] < p.spec.tracking_tolerance_deg, info["verdict"]["line"]
    assert info["verdict"]["ok"], info["verdict"]["line"]
