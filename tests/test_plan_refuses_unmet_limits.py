"""A plan that cannot keep a limit the job states (the grid peak of [planning.power], the jerk limit) is no result:
`plan` exits 2 with one line naming the limit and what the plan reaches, writes nothing, and an earlier plan in the same
--out folder stays byte for byte as it was. The jobs fail fast: IPOPT is given a few iterations on a 5-degree grid (the
coarsest a job may state: the refusals, their wording and the folder kept do not depend on the knots)."""
from __future__ import annotations

import shutil
from importlib import resources

from in_process import servo_press


def _job(tmp_path, extra: str) -> str:
    text = resources.files("press_model.data").joinpath("door_panel.toml").read_text(encoding="utf-8")
    text = text.replace("[planning]\n", "[planning]\ngrid_step_deg = 5.0\n", 1)
    path = tmp_path / "job.toml"
    path.write_text(text + "\n[planning.solver]\noptimal_max_iterations = 5\n" + extra, encoding="utf-8")
    return str(path)


def _snapshot(folder) -> dict:
    return {p.relative_to(folder): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


def _refused_into_an_earlier_plan(tmp_path, door_panel_plan_run, job: str):
    """Copy the session's door-panel plan into ``tmp_path/out``, plan ``job`` into it; returns (result, the folder's
    files before)."""
    out = tmp_path / "out"
    shutil.copytree(door_panel_plan_run[0], out)
    before = _snapshot(out)
    r = servo_press("plan", "--job", job, "--out", out)
    assert r.returncode == 2, (r.returncode, r.stderr)
    said = [ln for ln in r.stderr.splitlines() if not ln.startswith("[plan]")]  # the progress lines aside
    assert "Traceback" not in r.stderr and len(said) == 1 and said[0].startswith("servo-press: error:"), r.stderr
    assert _snapshot(out) == before  # the earlier plan, byte for byte
    assert sorted(p.name for p in tmp_path.iterdir()) == ["job.toml", "out"]  # no temporary folder left beside it
    return r


def test_a_grid_limit_no_plan_can_meet_exits_2_and_leaves_the_earlier_plan(tmp_path, door_panel_plan_run):
    r = _refused_into_an_earlier_plan(tmp_path, door_panel_plan_run, _job(tmp_path, "\n[planning.power]\ngrid_peak_limit_W = 1.0e5\n"))
    err = r.stderr
    assert "planning.power.grid_peak_limit_W = 100000 cannot be met" in err
    reached = float(err.split("draws ")[1].split(" MW")[0])
    assert reached > 0.1  # what the best stroke found draws, in MW, above the 0.1 MW asked for
    assert "no plan written" in err


def test_a_jerk_limit_the_optimiser_cannot_reach_exits_2_naming_it(tmp_path, door_panel_plan_run):
    r = _refused_into_an_earlier_plan(tmp_path, door_panel_plan_run, _job(tmp_path, ""))
    assert "planning.limits.crank_jerk_rad_s3 = 330 cannot be met" in r.stderr and "unbounded jerk" in r.stderr
