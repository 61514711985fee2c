"""Planning with the drive losses Eq. 16 leaves out ([drive.losses], press_model/motor.py): toppra's rows and the
jerk-limited stage's rows, branch bound and thermal integrand take them; `compare` plans a calibration with them; the
plan holds the margin played back on a model with the same losses, and its torque is eq16 with the losses at its own
speeds and accelerations on the per-point Pinocchio model (a second formulation, not the planner's path dynamics)."""
from __future__ import annotations

import csv
import json
import math
import re
from importlib import resources
from pathlib import Path

import numpy as np
import pytest

import press_model.data
from servo_press.cli import main
from press_model.dynamics import inverse_dynamics, slide_loads
from press_model.jobs import load_job
from press_model.kinematics import state_at
from press_model.model import PressModel, Workspace
from press_model.motor import eq16, motor_torque
from press_model.press_data import load_press

JOB = "door-panel"
FILE_LOSSES = {"load_loss_at_rated": 0.06, "viscous_Nms_per_rad": 4.0}  # the press file's: the theoretical plan's
CALIBRATED = {"k_load": 0.08, "c_drive": 6.0, "eta_gear": 0.917}  # what a calibration with the losses on reports
# the coarsest knots a job may state, for the stages whose checks hold on any knots (a fifth of the shipped grid's problem)
COARSE_DEG = 5.0
COMPARE_DEG = 2.0  # compare's knots (compared): the relations its tests read hold on any knots
RATED = 9900.0  # N m: a motor rated just above the plans' cycle RMS (about 9,800 N m with these losses), so the thermal row binds


def lossy_press_text(rated: float = RATED) -> str:
    """reference_press.toml with [drive.losses] switched on at FILE_LOSSES and the motors rated ``rated`` N m."""
    text = resources.files("press_model.data").joinpath("reference_press.toml").read_text()
    text, n = re.subn(r"(?m)(^\[drive\.losses\][^\[]*?^)enabled = false", r"\1enabled = true", text)  # [drive.losses]' own switch
    for key, value in FILE_LOSSES.items():
        text, m = re.subn(rf"(?m)^{key} = 0\.0", f"{key} = {value}", text)
        n += m
    text, m = re.subn(r"(?m)^rated_torque_Nm = [0-9.]+", f"rated_torque_Nm = {rated}", text)
    assert n + m == 4, "reference_press.toml changed: update this test's edits"
    return text


@pytest.fixture(scope="module")
def compared(tmp_path_factory):
    """`compare` (playback on) of the door panel on the press with losses, with a calibration that has them. On
    COMPARE_DEG knots (half the shipped grid's problem): what the tests read holds on any knots (each row at its own
    feed-forward limit, the calibrated row's playback within the margin, profile.csv's torque eq16 with the losses at its
    own rows, the thermal row binding at RATED without re-solves: the stage's rows and integrand are the losses', not the
    knots')."""
    work = tmp_path_factory.mktemp("losses")
    (work / "lossy.toml").write_text(lossy_press_text())
    press = load_press(work / "lossy.toml")
    # a calibrated.json as `calibrate --parameters ...,k_load,c_drive` writes it: made on this press, its values
    (work / "calibrated.json").write_text(json.dumps({"press_fingerprint": press.fingerprint, "parameters": CALIBRATED}))
    out = work / "cmp"
    # RATED was set at the door panel's fixed dwell (1.7423 s): the job at that dwell, without its transfer window
    text = (Path(press_model.data.__file__).parent / "door_panel.toml").read_text(encoding="utf-8")
    text = text[:text.index("\n[planning.transfer]")].replace("[planning]\n", f"[planning]\ngrid_step_deg = {COMPARE_DEG}\n", 1)
    (work / "job.toml").write_text(text + "\ndwell_s = 1.7423\n", encoding="utf-8")
    assert main(["compare", "--press", str(work / "lossy.toml"), "--job", str(work / "job.toml"), "--calibrated", str(work / "calibrated.json"),
                 "--out", str(out)]) == 0
    return press, out


def _read(path):
    with open(path, newline="") as fh:
        rows = list(csv.reader(fh))
    return rows[0], np.array(rows[1:], float)


def test_compare_plans_a_calibration_with_drive_losses_and_the_playback_holds_the_margin(compared):
    press, out = compared
    rec = json.loads((out / "comparison.json").read_text())
    assert {k: rec["parameters"]["calibrated"][k] for k in CALIBRATED} == CALIBRATED
    assert rec["parameters"]["theoretical"]["k_load"] == FILE_LOSSES["load_loss_at_rated"]
    th, cal = rec["rows"]
    # each plan sits at the feed-forward limit (margin - reserve = 0.89) under its own model, the losses included
    assert 0.889 < th["peak_ratio_theoretical_model"] <= 0.89 + 1e-9 and 0.889 < cal["peak_ratio_calibrated_model"] <= 0.89 + 1e-9
    # the oracle: the calibrated plan played back through the forward dynamics of the model with the same losses
    pb = rec["playback"]
    assert pb["verdict"]["ok"] and pb["peak_torque_ratio"] <= 0.9
    head, p = _read(out / "calibrated" / "playback.csv")
    assert np.max(np.abs(p[:, head.index("motor_torque_Nm")])) <= 0.9 * press.motor.peak_torque
    # larger losses on the calibrated press: the theoretical plan breaks its margin there, the calibrated one is slower
    assert th["peak_ratio_calibrated_model"] > 0.9 and cal["strokes_per_min"] < th["strokes_per_min"]


def test_planned_torque_is_eq16_with_the_losses_at_the_plans_own_speeds(compared):
    """profile.csv's torque = eq16 (called with the losses' numbers) of the per-point Pinocchio crank torque at each
    row's own angle, speed and acceleration; the same without the losses is far off (they are in the plan)."""
    press, out = compared
    cal = press.with_overrides(CALIBRATED)
    pm = PressModel(cal)
    d = cal.drive
    head, p = _read(out / "calibrated" / "profile.csv")
    summary = json.loads((out / "calibrated" / "summary.json").read_text())
    th = np.radians(p[:, head.index("crank_angle_deg")])
    w, a, T = (p[:, head.index(c)] for c in ("crank_speed_rad_s", "crank_accel_rad_s2", "motor_torque_Nm"))
    steps = np.radians([summary["grid"]["special_angles_deg"][k] for k in ("die_contact", "bdc")])
    moving = np.flatnonzero((w > 0.2) & (p[:, 0] < summary["stroke_time_s"]))
    # away from the force steps (die contact, BDC): the profile interpolates across them (its knots carry the forming side)
    far = [k for k in moving if np.all(np.abs((th[k] - steps + math.pi) % (2 * math.pi) - math.pi) > math.radians(1.5))]
    rows = far[:: max(1, len(far) // 40)]
    ws, loads = Workspace(pm), slide_loads(pm, load_job(JOB).process)
    ours, paper = [], []
    for k in rows:
        st = state_at(pm, ws, float(th[k]), float(w[k]), float(a[k]))
        tau = inverse_dynamics(pm, ws, st, loads).crank_torque
        args = (tau, w[k], a[k], d.gear_inertia, d.efficiency, d.gear_ratio, d.motors, True)
        ours.append(float(eq16(*args, (d.load_loss_at_rated / cal.motor.rated_torque, d.viscous, 0.0))))
        paper.append(float(eq16(*args)))
    err = np.abs(np.array(ours) - T[rows])
    assert np.max(err) < 5e-3 * press.motor.peak_torque, np.max(err)
    assert np.max(np.abs(np.array(paper) - T[rows])) > 10.0 * np.max(err)


def test_thermal_row_with_the_losses_binds_and_holds_without_re_solves(compared):
    """Motors rated just above the plans' RMS: the stage's thermal row (its integrand with the losses) binds, the full
    model's RMS is within the rating at the first solve (an integrand without the losses would have under-estimated
    it and needed re-solves with a tightened bound), and the played cycle's RMS too."""
    press, out = compared
    s = json.loads((out / "calibrated" / "summary.json").read_text())
    assert s["binding_constraints"]["thermal_rms"].startswith("binding")
    assert s["solver"]["thermal_iterations"] == 0
    assert 0.998 * RATED <= s["rms_torque_Nm"] <= RATED
    assert s["playback"]["cycle_rms_Nm"] <= RATED


def test_toppra_rows_with_losses_are_eq16_at_the_held_speed(press):
    """MotorTorqueLimit with the losses: at the speed the viscous loss is held at (the previous profile's), its two
    rows keep the limit exactly where |eq16| (the losses on) does, at random (x, u), at both ends of each segment."""
    from planning.toppra_solve import MotorTorqueLimit
    from planning.grid import planning_grid
    from planning.path_dynamics import build_path_dynamics
    from planning.settings import read_planning
    from press_model.press_data import read_press

    raw = press.raw()
    raw["drive"]["losses"].update(enabled=True, load_loss_at_rated=0.15, viscous_Nms_per_rad=10.0)
    pm = PressModel(read_press(raw, "test press"))
    job = load_job(JOB)
    spec = read_planning(job)
    grid = planning_grid(pm, job.process, spec)
    idx = np.arange(0, len(grid.theta), 9)
    pd = build_path_dynamics(pm, grid.theta[idx], job.process)
    drive, L = pm.press.drive, 22250.0
    rng = np.random.default_rng(11)
    const = pd.g + pd.proc + rng.normal(0, 2e4, pd.n)
    still = np.zeros(pd.n, bool)
    still[0] = still[-1] = True
    speed = rng.uniform(0.0, 1.2, pd.n)
    speed[still] = 0.0
    a, b, c, F, h, _, _ = MotorTorqueLimit(drive, pd.m, pd.c, const, const, L, still, speed).compute_constraint_params(None, pd.theta)
    assert np.allclose(F, np.eye(4)) and np.allclose(h, L)
    d = np.diff(pd.theta)
    # the physical branch: eq16's braking form turns at B = -eta n u / (2 k) (here at -18,900 N m of motor torque: the
    # most the gear passes back); beyond it the rows refuse even where eq16 would come back within the limit
    branch = np.where(still, -np.inf, -drive.efficiency * drive.motors * drive.gear_ratio / (2.0 * drive.load_loss_per_Nm))
    m_eff = pd.m + drive.gear_inertia * drive.gear_ratio**2
    agree, beyond = [], 0
    for _ in range(40):
        x = speed**2 * rng.uniform(0.5, 1.5, pd.n)  # the inertial terms at x, the viscous loss at the held speed
        u = rng.uniform(-40.0, 40.0, pd.n)
        x1 = np.append(x[:-1] + 2 * d * u[:-1], 0.0)  # knot i+1 reached with u_i from x_i
        for half, xx, sl in ((0, x, slice(None)), (2, x1, slice(None, -1))):
            kn = np.arange(pd.n)[sl] + (half // 2)  # the knot each row is at
            rows = a[sl, half:half + 2] * u[sl, None] + b[sl, half:half + 2] * x[sl, None] + c[sl, half:half + 2]
            crank = pd.m[kn] * u[sl] + pd.c[kn] * xx[sl] + const[kn]
            T = motor_torque(drive, crank, speed[kn], u[sl])
            on = crank + (m_eff[kn] - pd.m[kn]) * u[sl] >= branch[kn]
            agree.append(np.array_equal((np.max(rows, axis=1) <= L)[on], (np.abs(T) <= L)[on]))
            assert np.all(np.max(rows, axis=1)[~on] > L)
            beyond += int((~on).sum())
            assert 0 < np.mean(np.abs(T[on]) <= L) < 1
    assert all(agree) and beyond > 0


def test_branch_rows_left_out_where_they_cannot_bind_change_no_optimum(press):
    """The stage leaves the physical-branch rows out where the braking form's bound keeps a band around the branch's
    end infeasible (planning.limits.branch_can_bind); the same stage with every branch row in (no torque cap)
    reaches the same stroke, on a press whose gear passes back at most eta^2 / (4 k) = 28,400 N m per motor (k_load = 0.1).
    On COARSE_DEG knots: the band is the drive's, and the two stages' common optimum holds on any knots."""
    import dataclasses

    from planning.evaluation import Member
    from planning.limits import Limits, Region
    from planning.jerk_stage import JerkStage, solve_jerk_limited
    from planning.planner import StrokeProblem, plan_stroke, planning_limit
    from planning.settings import read_planning
    from press_model.press_data import read_press

    raw = press.raw()
    raw["drive"]["losses"].update(enabled=True, load_loss_at_rated=0.1, viscous_Nms_per_rad=4.0)
    pm = PressModel(read_press(raw, "test press"))
    job = load_job(JOB)
    spec = dataclasses.replace(read_planning(job), grid_step=math.radians(COARSE_DEG))
    plan = plan_stroke(StrokeProblem.build(pm, job.process, dataclasses.replace(spec, crank_jerk=math.inf)))  # toppra's stroke: the stage's start
    still = np.zeros(plan.pd.n, bool)
    still[0] = still[-1] = True
    stage = JerkStage(pm, Limits.declare(pm, spec, plan.grid, plan.pd, still).over(Region([Member(plan.pd, pm.press.drive, pm.press.friction)])), spec)
    level = planning_limit(pm, spec) * (1.0 - 2.0e-5)
    screened, p1 = solve_jerk_limited(stage.limits, stage.evaluate, level, plan.profile, stage.settings)
    every, p2 = solve_jerk_limited(dataclasses.replace(stage.limits, torque_cap=math.inf), stage.evaluate, level,
                                   plan.profile, stage.settings)
    assert p1.branch_rows == [False] and p2.branch_rows == [True]
    assert every.profile.stroke_time == pytest.approx(screened.profile.stroke_time, abs=1e-6)


def test_robust_plan_takes_the_drive_losses_at_their_worst_side_and_holds_every_corner(tmp_path):
    """A box over eta_gear, k_load and c_drive: the losses raise T_m on both rows as friction does, so the LP holds the
    centre and one motoring and one braking worst case (high losses and low efficiency, low losses and high
    efficiency), not every corner's pair; the plan's all-corner check on the full model is the proof it holds. On
    COARSE_DEG knots: the worst sides are the losses' signs, and the all-corner check holds on any knots."""
    import dataclasses
    import time

    from planning.robust import Box, plan_robust
    from planning.settings import read_planning
    from press_model.params import apply_overrides

    (tmp_path / "lossy.toml").write_text(lossy_press_text(13500.0))
    press = load_press(tmp_path / "lossy.toml")
    pm = PressModel(apply_overrides(press, CALIBRATED))
    job = load_job(JOB)
    spec = dataclasses.replace(read_planning(job), grid_step=math.radians(COARSE_DEG))
    intervals = {"eta_gear": (0.90, 0.93), "k_load": (0.06, 0.10), "c_drive": (4.0, 8.0)}
    box = Box.from_calibration(pm.press, CALIBRATED, intervals, "test", "joint region")
    t0 = time.perf_counter()
    res = plan_robust(pm, job.process, spec, box, plan_nominal=False)
    seconds = time.perf_counter() - t0
    motoring, braking = ({k: float(v) for k, v in re.findall(r"(\w+)=([-0-9.e+]+)", m.label)} for m in res.members[1:3])
    assert len(res.members) == 3 + 2 * res.cuts  # the centre and the two worst cases (by the corners of k_load and c_drive: 2^2 x 2 + 1 = 9)
    assert motoring == {"eta_gear": 0.90, "k_load": 0.10, "c_drive": 8.0}
    assert braking == {"eta_gear": 0.93, "k_load": 0.06, "c_drive": 4.0}
    limit = spec.torque_limits(press.motor.peak_torque).feedforward
    assert len(res.corner_peaks) == 8 and max(p for _, p in res.corner_peaks) <= limit * (1.0 + 1e-6)
    print(f"robust plan with the losses over 3 parameters: {seconds:.1f} s, {len(res.members)} members, {res.cuts} cuts")


def test_robust_members_drive_and_friction_are_the_press_files_read_with_the_corners_values(tmp_path):
    """The robust plan's members take the centre's drive and friction with the corner's scalars set, not the press file
    read again per corner (planning.robust._Builder): they equal what the reader makes of the file with those values, for
    every scalar the box may hold (efficiency, gear inertia, the [drive.losses] and both friction coefficients). On
    COARSE_DEG knots: a member's drive and friction are scalars read from the file, the knots' path dynamics only
    carried along."""
    import dataclasses

    from planning.grid import planning_grid
    from planning.path_dynamics import build_path_dynamics
    from planning.robust import Box, _Builder
    from planning.settings import read_planning
    from press_model.params import apply_overrides

    (tmp_path / "lossy.toml").write_text(lossy_press_text())
    press = load_press(tmp_path / "lossy.toml")
    centre = {**CALIBRATED, "J_gear": 60.6, "mu_r": 0.012, "mu_s": 0.085}
    pm = PressModel(apply_overrides(press, centre))
    job = load_job(JOB)
    grid = planning_grid(pm, job.process, dataclasses.replace(read_planning(job), grid_step=math.radians(COARSE_DEG)))
    pd = build_path_dynamics(pm, grid.theta, job.process, grid.contact_index)
    intervals = {"eta_gear": (0.90, 0.93), "k_load": (0.06, 0.10), "c_drive": (4.0, 8.0), "J_gear": (58.0, 63.0),
                 "mu_r": (0.010, 0.014), "mu_s": (0.07, 0.10)}
    box = Box.from_calibration(pm.press, centre, intervals, "test", "joint region")
    builder = _Builder(pm, job.process, grid.theta, grid.contact_index, pd, centre)
    for corner in box.corners()[::7]:
        values = {**centre, **corner}
        member = builder.member(values, "corner")
        read = pm.press.with_overrides(values, "test")
        assert member.drive == read.drive and member.friction == read.friction, corner
        assert member.drive.has_losses and member.drive.efficiency == corner["eta_gear"]
