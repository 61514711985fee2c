"""mode = "auto" (planning/modes.py): every mode the job allows planned, the fastest that keeps every limit kept, each
mode's rate (or why not) recorded; the registry takes a further mode."""
from __future__ import annotations

import dataclasses

import pytest

from planning import modes
from planning.errors import PlanningError
from planning.grid import planning_grid
from planning.path_dynamics import build_path_dynamics
from planning.planner import plan_stroke
from planning.settings import read_planning

JOB = "door-panel"


@pytest.fixture(scope="module")
def setup(ref_model, job):
    spec = read_planning(job)
    grid = planning_grid(ref_model, job.process, spec)
    return spec, grid, build_path_dynamics(ref_model, grid.theta, job.process, grid.contact_index)


@pytest.fixture(scope="module")
def each_mode(ref_model, job, setup):
    """The door panel without a transfer dwell planned in each mode by itself."""
    spec, grid, pd = setup
    return {name: plan_stroke(ref_model, job.process, dataclasses.replace(spec, mode=name, dwell=0.0), pd=pd, grid=grid)
            for name in ("stop-at-top", "continuous")}


def test_auto_keeps_the_fastest_mode_and_records_every_mode(ref_model, job, setup, each_mode):
    """Without a dwell at TDC both modes are allowed: auto plans each and keeps the faster, with the rates each mode
    gives alone; the plan's line and compare's table say so."""
    from planning.compare import modes_markdown
    from planning.report import modes_line

    spec, grid, pd = setup
    auto = plan_stroke(ref_model, job.process, dataclasses.replace(spec, mode="auto", dwell=0.0), pd=pd, grid=grid)
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


def test_a_transfer_dwell_rules_continuous_out_and_a_broken_limit_is_not_kept(ref_model, job, setup, each_mode, monkeypatch):
    """With the job's dwell at TDC continuous rotation is not allowed (the reason names planning.dwell_s); a registered
    mode whose plan breaks a limit is recorded and not kept even when faster, one that cannot be planned says why."""
    spec, grid, pd = setup
    fast = each_mode["continuous"]
    broken = dataclasses.replace(fast, peak_torque=2.0 * fast.peak_torque, spec=dataclasses.replace(fast.spec, mode="too-fast"))

    def refuse(*a, **k):
        raise PlanningError("no admissible stroke: a test mode")

    monkeypatch.setitem(modes.MODES, "too-fast", modes.Mode("too-fast", lambda *a, **k: broken, lambda s: None))
    monkeypatch.setitem(modes.MODES, "refused", modes.Mode("refused", refuse, lambda s: None))
    auto = plan_stroke(ref_model, job.process, dataclasses.replace(spec, mode="auto"), pd=pd, grid=grid)
    rec = auto.modes["modes"]
    assert auto.spec.mode == "stop-at-top" and auto.dwell == spec.dwell > 0
    assert not rec["continuous"]["allowed"] and "planning.dwell_s" in rec["continuous"]["why_not"]
    assert rec["too-fast"]["strokes_per_min"] > auto.strokes_per_min and not rec["too-fast"]["keeps_every_limit"]
    assert "peak torque" in rec["too-fast"]["infeasible"]
    assert rec["refused"]["strokes_per_min"] is None and "a test mode" in rec["refused"]["infeasible"]


def test_auto_in_the_job_file_reads_and_needs_the_dwell(tmp_path):
    from importlib import resources

    from press_model.errors import ServoPressError
    from press_model.jobs import load_job

    text = resources.files("press_model.data").joinpath("door_panel.toml").read_text(encoding="utf-8")
    path = tmp_path / "job.toml"
    path.write_text(text.replace("[planning]\n", "[planning]\nmode = \"auto\"\n", 1), encoding="utf-8")
    assert read_planning(load_job(path)).mode == "auto"
    lines = [ln for ln in text.splitlines() if not ln.startswith("dwell_s")]
    path.write_text("\n".join(lines).replace("[planning]", "[planning]\nmode = \"auto\"", 1), encoding="utf-8")
    with pytest.raises(ServoPressError) as exc:
        read_planning(load_job(path))
    assert "dwell_s" in str(exc.value)
