"""mode = "auto" (planning/modes.py): every mode the job allows planned, the fastest that keeps every limit kept, each
mode's rate (or why not) recorded; the registry takes a further mode."""
from __future__ import annotations

import dataclasses
import math

import pytest

from planning import modes
from press_io.errors import PlanningError
from planning.grid import planning_grid
from planning.path_dynamics import build_path_dynamics
from planning.planner import StrokeProblem, plan_stroke
from planning.settings import read_planning

JOB = "door-panel"


FIXED_DWELL_S = 1.7423  # the door panel's dwell at TDC before it stated its transfer (a job with dwell_s, no [planning.transfer])
# every plan here on the coarsest knots a job may state: what auto is checked for (which modes it plans, allows and
# keeps, the rates it records against each mode planned alone on the same knots, the outputs it writes) does not depend
# on the knots, and 5 degrees plans a fifth of the shipped 1-degree problem
COARSE = math.radians(5.0)


def _coarse(job):
    """The job's planning on COARSE knots."""
    return dataclasses.replace(read_planning(job), grid_step=COARSE)


@pytest.fixture(scope="module")
def setup(ref_model, job):
    """The door panel without its transfer (a job of dwell_s alone: here none), its knots and path dynamics."""
    spec = dataclasses.replace(_coarse(job), transfer=None, dwell=0.0)
    grid = planning_grid(ref_model, job.process, spec)
    return spec, grid, build_path_dynamics(ref_model, grid.theta, job.process, grid.contact_index)


@pytest.fixture(scope="module")
def each_mode(ref_model, job, setup):
    """The door panel without a transfer and without a dwell planned in each mode by itself."""
    spec, grid, pd = setup
    return {name: plan_stroke(StrokeProblem(ref_model, job.process, dataclasses.replace(spec, mode=name), grid, pd))
            for name in ("stop-at-top", "continuous")}


def test_auto_keeps_the_fastest_mode_and_records_every_mode(ref_model, job, setup, each_mode):
    """Without a dwell at TDC and without a transfer both turning modes are allowed: auto plans each and keeps the
    faster, with the rates each mode gives alone; the plan's line and compare's table say so. The pendulum is not
    allowed without [planning.transfer], and the record says why."""
    from planning.compare import modes_markdown
    from planning.report import modes_line

    spec, grid, pd = setup
    auto = modes.plan_in_mode(StrokeProblem(ref_model, job.process, dataclasses.replace(spec, mode="auto", dwell=0.0), grid, pd))
    line, table = modes_line(auto.modes), modes_markdown({"theoretical": auto.modes})
    for name, plan in each_mode.items():
        assert f"{name} {plan.strokes_per_min:.3f} spm" in line and f"| {name} | {plan.strokes_per_min:.3f} |" in table
    fastest = max(each_mode, key=lambda n: each_mode[n].strokes_per_min)
    assert auto.spec.mode == fastest == auto.modes["planned"]
    assert auto.strokes_per_min == pytest.approx(each_mode[fastest].strokes_per_min, rel=1e-9)
    for name, plan in each_mode.items():
        rec = auto.modes["modes"][name]
        assert rec["allowed"] and rec["keeps_every_limit"]
        assert rec["strokes_per_min"] == pytest.approx(plan.strokes_per_min, rel=1e-9)
    pend = auto.modes["modes"]["pendulum"]
    assert not pend["allowed"] and pend["strokes_per_min"] is None and "[planning.transfer]" in pend["why_not"]
    assert "pendulum not allowed" in line and "| pendulum | not allowed |" in table


def test_a_transfer_dwell_rules_continuous_out_and_a_broken_limit_is_not_kept(ref_model, job, setup, each_mode, monkeypatch):
    """With a fixed dwell at TDC (dwell_s, no transfer) continuous rotation is not allowed (the reason names planning.dwell_s); a registered
    mode whose plan breaks a limit is recorded and not kept even when faster, one that cannot be planned says why."""
    spec, grid, pd = setup
    fast = each_mode["continuous"]
    broken = dataclasses.replace(fast, peak_torque=2.0 * fast.peak_torque, spec=dataclasses.replace(fast.spec, mode="too-fast"))

    def refuse(*a, **k):
        raise PlanningError("no admissible stroke: a test mode")

    monkeypatch.setitem(modes.MODES, "too-fast", modes.Mode("too-fast", lambda *a, **k: broken, lambda s: None))
    monkeypatch.setitem(modes.MODES, "refused", modes.Mode("refused", refuse, lambda s: None))
    auto = modes.plan_in_mode(StrokeProblem(ref_model, job.process, dataclasses.replace(spec, mode="auto", dwell=FIXED_DWELL_S), grid, pd))
    rec = auto.modes["modes"]
    assert auto.spec.mode == "stop-at-top" and auto.dwell == FIXED_DWELL_S
    assert not rec["continuous"]["allowed"] and "planning.dwell_s" in rec["continuous"]["why_not"]
    assert rec["too-fast"]["strokes_per_min"] > auto.strokes_per_min and not rec["too-fast"]["keeps_every_limit"]
    assert "peak torque" in rec["too-fast"]["infeasible"]
    assert rec["refused"]["strokes_per_min"] is None and "a test mode" in rec["refused"]["infeasible"]


def test_auto_in_the_job_file_reads_and_needs_the_dwell(tmp_path):
    from importlib import resources

    from press_io.errors import ServoPressError
    from press_model.jobs import load_job

    text = resources.files("press_model.data").joinpath("door_panel.toml").read_text(encoding="utf-8")
    path = tmp_path / "job.toml"
    path.write_text(text.replace("[planning]\n", "[planning]\nmode = \"auto\"\n", 1), encoding="utf-8")
    assert read_planning(load_job(path)).mode == "auto"
    # without [planning.transfer] (its table's keys dropped with it) the dwell at TDC is the job's own, and required
    lines = [ln for ln in text.splitlines() if not ln.startswith(("dwell_s", "[planning.transfer]", "opening_height_m", "time_s"))]
    path.write_text("\n".join(lines).replace("[planning]", "[planning]\nmode = \"auto\"", 1), encoding="utf-8")
    with pytest.raises(ServoPressError) as exc:
        read_planning(load_job(path))
    assert "dwell_s" in str(exc.value)


@pytest.fixture(scope="module")
def door_auto(coarse_door_panel_auto):
    """The shipped door panel (its [planning.transfer]) in mode = "auto" on COARSE knots: the suite's plan
    (fixtures_suiteplan.py; test_compare_theoretical_beside reads it too), modes.plan_in_mode's plan_fastest of this job."""
    assert coarse_door_panel_auto.spec.grid_step == COARSE
    return coarse_door_panel_auto


@pytest.fixture(scope="module")
def stop_at_top(coarse_door_panel_plan):
    """The shipped door panel planned alone (stop-at-top, its transfer) on COARSE knots: the suite's plan
    (fixtures_suiteplan.py; other modules read it too), planning.planner.plan_stroke of this job."""
    assert coarse_door_panel_plan.spec.grid_step == COARSE and coarse_door_panel_plan.spec.mode == "stop-at-top"
    return coarse_door_panel_plan


def test_auto_with_the_transfer_plans_every_mode_and_records_the_pendulum_against_stop_at_top(ref_model, job, door_auto, stop_at_top):
    """With the door panel's transfer every mode is allowed: stop-at-top and the pendulum planned alone give the rates
    auto records, continuous is refused by the transfer's time (its stroke alone keeps the slide above the opening too
    briefly), the fastest that keeps every limit is kept, and the pendulum's gain (here a loss) against stop-at-top is
    the two rates'."""
    from planning.pendulum import plan_pendulum

    spec = _coarse(job)
    alone = {"stop-at-top": stop_at_top, "pendulum": plan_pendulum(ref_model, job.process, dataclasses.replace(spec, mode="pendulum"))}
    rec = door_auto.modes["modes"]
    assert set(rec) == {"stop-at-top", "continuous", "pendulum"} and all(r["allowed"] for r in rec.values())
    assert rec["continuous"]["strokes_per_min"] is None and "planning.transfer.time_s" in rec["continuous"]["infeasible"]
    for name, plan in alone.items():
        assert rec[name]["keeps_every_limit"] and modes.keeps_limits(ref_model, plan)[0]
        assert rec[name]["strokes_per_min"] == pytest.approx(plan.strokes_per_min, rel=1e-9)
    fastest = max(alone, key=lambda n: alone[n].strokes_per_min)
    assert door_auto.spec.mode == door_auto.modes["planned"] == fastest
    assert door_auto.strokes_per_min == pytest.approx(alone[fastest].strokes_per_min, rel=1e-9)
    sat, pend = alone["stop-at-top"].strokes_per_min, alone["pendulum"].strokes_per_min
    assert rec["pendulum"]["vs_stop_at_top_spm"] == pytest.approx(pend - sat, rel=1e-9)
    assert rec["pendulum"]["vs_stop_at_top_percent"] == pytest.approx(100.0 * (pend / sat - 1.0), rel=1e-9)


def test_auto_keeping_the_pendulum_writes_its_outputs_with_every_mode(ref_model, job, door_auto, stop_at_top, tmp_path, monkeypatch):
    """When the pendulum is the fastest mode that keeps every limit (here: the stop-at-top plan made to break the torque
    margin, continuous left out), `plan` writes the pendulum's outputs, and summary.json the modes and the pendulum's gain
    against the stop-at-top plan's rate."""
    import json

    from planning.report import plan_lines, run_plan

    sat = stop_at_top  # replace() below copies it
    broken = dataclasses.replace(sat, peak_torque=2.0 * sat.peak_torque)
    monkeypatch.setitem(modes.MODES, "stop-at-top", modes.Mode("stop-at-top", lambda *a, **k: broken, lambda s: None))
    monkeypatch.setitem(modes.MODES, "continuous", modes.Mode("continuous", None, lambda s: "left out by the test", periodic=True))
    spec = dataclasses.replace(_coarse(job), mode="auto")
    plan, info = run_plan(ref_model, job, spec, tmp_path, {})
    written = json.loads((tmp_path / "summary.json").read_text())
    assert plan.spec.mode == "pendulum" and written["mode"] == "pendulum" and written["mode_requested"] == "auto"
    assert written["modes"]["planned"] == "pendulum" and not written["modes"]["modes"]["stop-at-top"]["keeps_every_limit"]
    assert written["strokes_per_min"] == pytest.approx(door_auto.modes["modes"]["pendulum"]["strokes_per_min"], rel=1e-9)
    g = written["gain_over_stop_at_top"]
    assert g["stop_at_top_strokes_per_min"] == pytest.approx(sat.strokes_per_min, rel=1e-12)
    assert g["gain_spm"] == pytest.approx(written["strokes_per_min"] - sat.strokes_per_min, rel=1e-12)
    assert (tmp_path / "cam_master.csv").exists() and (tmp_path / "slide.png").exists()
    assert any(line.startswith("mode auto -> pendulum") for line in plan_lines(job.name, info, None, tmp_path))
