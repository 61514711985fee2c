"""Plans within the supply ([planning.power] grid_peak_limit_W; the jerk-limited stage's grid rows) and the front of
`plan --pareto`: one `plan --pareto --verify` run of the door panel with a grid limit at 60 % of its free plan's peak."""
from __future__ import annotations

import csv
import json
from importlib import resources

import numpy as np
import pytest

from servo_press.cli import main

FREE_PEAK_W = 4686768.15  # the door panel's grid peak without a limit (summary.json 'energy', reference press), W; 4687033.75 before the written torque between knots carried the friction's slope in the speed
LIMIT_W = 0.6 * FREE_PEAK_W  # the front's last limit too (pareto_lowest_fraction 0.6)


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    root = tmp_path_factory.mktemp("gridplan")
    text = resources.files("press_model.data").joinpath("door_panel.toml").read_text(encoding="utf-8")
    job = root / "job.toml"
    job.write_text(text + f"\n[planning.power]\ngrid_peak_limit_W = {LIMIT_W}\npareto_points = 3\n", encoding="utf-8")
    out = root / "plan"
    code = main(["plan", "--job", str(job), "--pareto", "--verify", "--out", str(out)])
    return code, out, json.loads((out / "summary.json").read_text())


def test_the_plan_holds_the_grid_limit_and_so_does_its_playback(run):
    code, out, s = run
    assert code == 0
    en, pb = s["energy"], s["playback"]
    assert en["within_grid_limit"] and en["grid_peak_W"] <= LIMIT_W
    assert en["grid_peak_W"] > 0.99 * LIMIT_W  # the limit binds: the time optimum runs up to it
    assert s["grid_limit"]["held"] and s["jerk_limit"]["optimiser"]["status"] != "fallback"
    assert pb["verdict"]["ok"], pb["verdict"]["line"]
    assert "grid peak" in pb["verdict"]["line"] and pb["energy"]["within_dc_link_window"]
    assert pb["energy"]["grid_peak_W"] <= LIMIT_W * 1.01  # the feedback's share on top of the planned peak
    with open(out / "power.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))
    assert max(float(r["grid_W"]) for r in rows) == pytest.approx(en["grid_peak_W"], rel=1e-9)


def test_the_grid_limit_costs_rate_against_the_free_plan(run):
    _, _, s = run
    spm = s["pareto"]["strokes_per_min"]
    assert s["strokes_per_min"] < spm[0]  # the free plan is the front's first row
    assert s["strokes_per_min"] > 0.97 * spm[0]


def test_pareto_front_is_written_and_monotone(run):
    _, out, s = run
    with open(out / "pareto.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))
    assert list(rows[0])[:4] == ["grid_peak_limit_W", "strokes_per_min", "grid_peak_W", "energy_per_stroke_J"]
    assert len(rows) == 3 and all(r["within_limit"] == "yes" for r in rows)
    limit = np.array([float(r["grid_peak_limit_W"]) for r in rows])
    spm = np.array([float(r["strokes_per_min"]) for r in rows])
    peak = np.array([float(r["grid_peak_W"]) for r in rows])
    assert limit[0] == pytest.approx(FREE_PEAK_W, rel=1e-3) and limit[-1] == pytest.approx(0.6 * limit[0], rel=1e-9)
    assert np.all(np.diff(limit) < 0) and np.all(np.diff(spm) < 0) and np.all(peak <= limit * (1 + 1e-9))
    assert (out / "pareto.png").stat().st_size > 5000


def test_the_limited_optimum_is_the_same_from_two_starts(run):
    """The job's plan under the limit (started from toppra's smoothed stroke) and the front's last plan at the same limit
    (started from the plan at the limit before) reach the same stroke: the grid rows leave no start-dependent optimum."""
    _, out, s = run
    with open(out / "pareto.csv", newline="") as fh:
        last = list(csv.DictReader(fh))[-1]
    assert float(last["grid_peak_limit_W"]) == pytest.approx(LIMIT_W, rel=1e-5)  # the free plan from another start: 1e-6 apart
    assert float(last["stroke_time_s"]) == pytest.approx(s["stroke_time_s"], rel=1e-5)
