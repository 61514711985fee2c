"""The job's supply limit ([planning.power] grid_peak_limit_W, planning/power.py): read and refused like the other
settings, its grid-power row against the power flow, and the playback's check of it."""
from __future__ import annotations

import math

import numpy as np
import pytest

from planning.playback import verdict
from planning.power import grid_bound_coefficients, read_power
from press_io.errors import PressDataError
from press_model.jobs import Job, load_job
from press_model.power_flow import power_flow, trapezoid_weights


def _job(power: dict) -> Job:
    job = load_job("door-panel")
    raw = {**job.raw, "planning": {**job.raw["planning"], "power": power}}
    return Job(job.name, "job.toml", job.process, job.motion, raw)


def test_no_grid_limit_by_default(press):
    assert not read_power(load_job("door-panel"), press.electrical).limited
    assert read_power(_job({"grid_peak_limit_W": 3.0e6}), press.electrical).grid_peak_limit_W == 3.0e6


@pytest.mark.parametrize("power, expected", [
    ({"grid_peak_limit_W": -1.0}, "must be > 0.0"),
    ({"grid_peak_limit_W": "3 MW"}, "must be a finite number"),
    ({"grid_peak_limt_W": 3.0e6}, "did you mean 'grid_peak_limit_W'"),
])
def test_bad_grid_limits_are_refused_naming_the_field(press, power, expected):
    with pytest.raises(PressDataError) as exc:
        read_power(_job(power), press.electrical)
    assert "planning.power.grid_peak_lim" in str(exc.value) and expected in str(exc.value)


def test_a_grid_limit_needs_the_press_files_electrical_side():
    with pytest.raises(PressDataError, match=r"needs a press file with \[drive.electrical\]"):
        read_power(_job({"grid_peak_limit_W": 3.0e6}), None)


def test_the_grid_row_is_the_power_flows_grid_power(press):
    """k (T w + a T^2 + b |w| + c w^2) equals the power flow's grid power where the drives draw, bounds it where they
    regenerate (an independent path: press_model/power_flow.py steps the supply)."""
    el = press.electrical
    rng = np.random.default_rng(1)
    torque = rng.uniform(-25000.0, 25000.0, 400)
    speed = rng.uniform(0.0, el.max_speed, 400)
    t = np.arange(400) * 1e-3
    flow = power_flow(el, 2, torque, speed, trapezoid_weights(t))
    a, b, c, k = grid_bound_coefficients(el, 2)
    row = k * (torque * speed + a * torque**2 + b * speed + c * speed**2)
    draw = row > 0.0
    assert draw.sum() > 100 and (~draw).sum() > 100
    assert np.allclose(flow.grid_W[draw], row[draw], rtol=1e-12, atol=1e-6)
    assert np.all(flow.grid_W[~draw] >= row[~draw]) and np.all(flow.grid_W[~draw] <= 0.0)


def test_the_playback_verdict_names_a_broken_grid_limit():
    from planning.settings import read_planning

    spec = read_planning(load_job("door-panel"))
    cols = {"crank_angle_deg": np.array([0.0, 10.0, 20.0]), "motor_torque_Nm": np.zeros(3), "tracking_error_deg": np.zeros(3),
            "loop_gap_m": np.zeros(3)}
    ok = verdict(spec, 25000.0, cols, np.zeros(3), None, None, (np.array([1.0e6, 2.9e6, -1.0e6]), 3.0e6))
    assert ok["ok"] and ok["line"].endswith("grid peak 2.900 MW (limit 3.000)")
    bad = verdict(spec, 25000.0, cols, np.zeros(3), None, None, (np.array([1.0e6, 3.1e6, -1.0e6]), 3.0e6))
    assert bad["line"] == "VERIFY FAILED: grid peak power at crank angle 10.00 deg: 3.100 MW (3.000 MW)"
    assert math.isclose(bad["failures"][0]["value"], 3.1e6)
