"""The minimum-energy plan at a stated rate ([planning.power] target_strokes_per_min; planning/energy.py): one
`plan --verify` of the door panel at 11 spm (its time optimum is 13.7 spm with its transfer window) on a 5-degree grid (the
coarsest a job may state, a fifth of the problem): the rate met, the energy at most the time optimum's and every limit in
playback hold on any knots."""
from __future__ import annotations

import csv
import json
from importlib import resources

import pytest

from servo_press.cli import main

TARGET_SPM = 11.0


@pytest.fixture(scope="module")
def run(coarse_min_energy_verified):
    """(exit code, output folder, summary) of the suite's `plan --verify` of that job (fixtures_min_energy.py), whose
    minimum-energy record test_min_energy_under_transfer_window reads too."""
    folder, code, _, err = coarse_min_energy_verified
    assert code == 0, err
    text = resources.files("press_model.data").joinpath("door_panel.toml").read_text(encoding="utf-8")
    text = text.replace("[planning]\n", "[planning]\ngrid_step_deg = 5.0\n", 1)
    assert (folder / "job.toml").read_text(encoding="utf-8") == text + f"\n[planning.power]\ntarget_strokes_per_min = {TARGET_SPM}\n"
    out = folder / "plan"
    return code, out, json.loads((out / "summary.json").read_text())


def test_min_energy_plan_draws_less_than_the_time_optimal_at_the_same_rate(run):
    code, out, s = run
    assert code == 0
    me = s["min_energy"]
    assert s["strokes_per_min"] == pytest.approx(TARGET_SPM, rel=1e-9)
    assert me["time_optimal_strokes_per_min"] > TARGET_SPM
    # the summary's own energy (profile.csv through the power flow) is the plan's, and below the time-optimal stroke's
    assert s["energy"]["net_J"] == pytest.approx(me["energy_per_stroke_J"], rel=1e-12)
    # at most the time-optimal stroke's, to the optimiser's tolerance (under the transfer window it draws about a quarter
    # less: tests/test_min_energy_under_transfer_window.py measures that on the shipped grid)
    assert me["energy_per_stroke_J"] <= me["time_optimal_energy_per_stroke_J"] * (1.0 + 1e-7)
    with open(out / "power.csv", newline="") as fh:
        t = [float(r["time_s"]) for r in csv.DictReader(fh)]
    assert t[-1] == pytest.approx(60.0 / TARGET_SPM, rel=1e-9)


def test_min_energy_plan_keeps_every_limit_in_playback(run):
    _, _, s = run
    pb = s["playback"]
    assert pb["verdict"]["ok"], pb["verdict"]["line"]
    assert s["peak_torque_ratio"] <= 0.9 and s["jerk_limit"]["kept"]
    assert pb["energy"]["within_dc_link_window"]


def test_a_target_above_the_time_optimal_rate_is_refused(tmp_path, capsys):
    """Refused once the time-optimal stroke is planned, on the coarsest knots a job may state (5 degrees): the door
    panel's time optimum (13.7 spm) is far below the 20 spm asked on any knots, and the test reads the refusal alone."""
    text = resources.files("press_model.data").joinpath("door_panel.toml").read_text(encoding="utf-8")
    text = text.replace("[planning]\n", "[planning]\ngrid_step_deg = 5.0\n", 1)
    job = tmp_path / "job.toml"
    job.write_text(text + "\n[planning.power]\ntarget_strokes_per_min = 20.0\n", encoding="utf-8")
    code = main(["plan", "--job", str(job), "--out", str(tmp_path / "plan")])
    assert code == 2
    err = capsys.readouterr().err
    assert "planning.power.target_strokes_per_min = 20" in err and "time-optimal" in err
    assert not (tmp_path / "plan").exists()
