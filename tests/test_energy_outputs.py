"""What `simulate`, `plan` and the playback report of a stroke's energy (summary.json 'energy', power.csv,
playback_power.csv) and the playback's check of the DC-link window, on the reference press's [drive.electrical]."""
from __future__ import annotations

import csv
import dataclasses
import json

import numpy as np
import pytest

from planning.playback import play_back, verdict
from planning.settings import read_planning
from servo_press.cli import main
from press_model.electrical import Supply
from press_model.jobs import load_job
from press_model.model import PressModel

JOB = "door-panel"  # the shipped job the `job` fixture (conftest.py) reads


def _csv(path):
    with open(path, newline="") as fh:
        rows = list(csv.reader(fh))
    return {k: np.array([float(r[i]) for r in rows[1:]]) for i, k in enumerate(rows[0])}


def _closes(en: dict) -> float:
    """drawn - returned less every part the balance names, relative to the energy drawn."""
    parts = sum(en["lost_J"].values()) + sum(en["stored_change_J"].values()) + en.get("mechanical_residual_J", 0.0)
    return abs(en["drawn_J"] - en["returned_J"] - parts) / en["drawn_J"]


@pytest.fixture(scope="module")
def written(job, door_panel_plan, door_panel_written):
    out, info = door_panel_written  # the shipped plan's outputs (conftest.py: planned and written once a session)
    return read_planning(job), door_panel_plan, out, info


def test_plan_reports_the_energy_of_its_stroke(written):
    _, _, out, info = written
    en = json.loads((out / "summary.json").read_text())["energy"]
    assert en == json.loads(json.dumps(info["energy"]))
    prof = _csv(out / "profile.csv")
    shaft = 2 * prof["motor_torque_Nm"] * prof["motor_speed_rpm"] * np.pi / 30.0
    assert en["shaft_peak_W"] == pytest.approx(np.max(shaft), rel=1e-9)
    assert en["shaft_peak_braking_W"] == pytest.approx(-np.min(shaft), rel=1e-9)
    assert en["grid_peak_W"] > en["shaft_peak_W"] and en["regenerated_J"] > 0.0 and en["returned_J"] > 0.0
    assert set(en["lost_J"]) >= {"copper_J", "inverter_J", "brake_resistor_J", "friction_J", "process_work_J", "gear_J"}
    assert _closes(en) <= 1e-6 and abs(en["balance_residual_J"]) <= 1e-6 * en["drawn_J"]
    assert en["within_dc_link_window"]


def test_plan_process_work_is_the_jobs_force_over_the_stroke(written, job):
    """The process work of the plan's energy against the integral of the job's F(H) from die contact to BDC (closed
    form of the piecewise-linear table)."""
    _, _, _, info = written
    h, f = np.asarray(job.process.heights), np.asarray(job.process.forces)
    order = np.argsort(h)
    closed = float(np.sum(np.diff(h[order]) * 0.5 * (f[order][1:] + f[order][:-1])))
    assert info["energy"]["lost_J"]["process_work_J"] == pytest.approx(closed, rel=1e-3)


def test_power_csv_integrates_to_the_summary(written):
    _, _, out, info = written
    p = _csv(out / "power.csv")
    en = info["energy"]
    assert np.trapezoid(p["grid_W"], p["time_s"]) == pytest.approx(en["drawn_J"] - en["returned_J"], rel=1e-6)
    assert np.trapezoid(p["shaft_W"], p["time_s"]) == pytest.approx(en["shaft_motoring_J"] - en["shaft_braking_J"], rel=1e-6)


def test_playback_recomputes_the_power_flow_and_refuses_a_sagging_dc_link(ref_model, job, written):
    spec, plan, out, _ = written
    _, played = play_back(ref_model, job, spec, plan, t_end=0.4)  # past the first grid peak (0.17 s); no whole cycle (its RMS fails)
    assert not [f for f in played["verdict"]["failures"] if f["limit"].startswith("DC-link")]
    assert played["energy"]["dc_link_voltage_V"]["min"] == pytest.approx(1050.0, rel=1e-12)
    prof = _csv(out / "profile.csv")
    early = prof["time_s"] <= 0.4
    planned = np.max(2 * prof["motor_torque_Nm"][early] * prof["motor_speed_rpm"][early] * np.pi / 30.0)
    assert played["energy"]["shaft_peak_W"] == pytest.approx(planned, rel=0.01)  # the feedback's share is small
    press = ref_model.press
    weak = dataclasses.replace(press, electrical=dataclasses.replace(press.electrical, supply=Supply(motoring_limit_W=2.0e6)))
    cols, weak_played = play_back(PressModel(weak), job, spec, plan, t_end=0.4)
    (sag,) = [f for f in weak_played["verdict"]["failures"] if f["limit"].startswith("DC-link")]
    assert sag["line"].startswith("VERIFY FAILED: DC-link undervoltage at crank angle") and sag["value"] < 900.0, sag
    assert weak_played["energy"]["grid_peak_W"] == pytest.approx(2.0e6, rel=1e-9)


def test_verdict_names_an_overvoltage():
    from planning.settings import read_planning

    spec = read_planning(load_job("door-panel"))
    cols = {"crank_angle_deg": np.array([0.0, 10.0, 20.0]), "motor_torque_Nm": np.zeros(3), "tracking_error_deg": np.zeros(3),
            "loop_gap_m": np.zeros(3)}
    v = verdict(spec, 25000.0, cols, np.zeros(3), None, (np.array([1050.0, 1250.0, 1100.0]), 900.0, 1200.0))
    assert not v["ok"] and v["line"] == "VERIFY FAILED: DC-link overvoltage at crank angle 10.00 deg: 1,250 V (1,200 V)"


def test_simulate_writes_power_curves_and_energy(tmp_path, capsys):
    out = tmp_path / "sim"
    assert main(["simulate", "--motion", "cushion-test", "--load", "cushion", "--step-deg", "2", "--out", str(out)]) == 0
    assert "energy per stroke:" in capsys.readouterr().out
    en = json.loads((out / "summary.json").read_text())["energy"]
    assert _closes(en) <= 1e-6
    assert abs(en["mechanical_residual_J"]) <= 1e-6 * en["shaft_motoring_J"]  # the turn is periodic
    p = _csv(out / "power.csv")
    assert list(p)[:3] == ["time_s", "shaft_W", "motor_electrical_W_per_motor"]
    assert en["shaft_peak_W"] == pytest.approx(np.max(p["shaft_W"]), rel=1e-9)


def test_a_press_without_electrical_side_reports_shaft_figures_only(tmp_path, capsys):
    out = tmp_path / "sim"
    assert main(["simulate", "--press", "crank-slider", "--step-deg", "10", "--out", str(out)]) == 0
    en = json.loads((out / "summary.json").read_text())["energy"]
    assert en["electrical_model"].startswith("off") and "drawn_J" not in en and en["shaft_peak_W"] > 0.0
    assert not (out / "power.csv").exists()
