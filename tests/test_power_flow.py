"""The drive's electrical side ([drive.electrical], press_model/electrical.py) and the power flows of a cycle
(press_model/power_flow.py): the press file's values, the losses' closed forms, the stroke's energy balance, the
supplies and the storage, and the motor-side energy against the mechanical side through the linkage."""
import copy
import dataclasses
import math

import numpy as np
import pytest

from press_model.cycle import simulate_cycle
from press_model.electrical import Electrical, Storage, Supply
from press_io.errors import PressDataError
from press_model.power_flow import motor_losses, power_flow, trapezoid_weights
from press_model.press_data import load_press, read_press

JOB = "cushion-test"


@pytest.fixture(scope="module")
def cycle(job):
    from press_model.jobs import make_motion
    from press_model.model import PressModel

    pm = PressModel(load_press())
    return pm, simulate_cycle(pm, make_motion(job.motion, job.source), job.process, step_deg=2.0)


def _flow(el, pm, cyc):
    d = pm.press.drive
    return power_flow(el, d.motors, cyc.motor_torque, cyc.theta_dot * d.gear_ratio, cyc.dt_weights)


def test_reference_press_reads_its_electrical_section(press):
    el = press.electrical
    assert el is not None
    assert el.motor.torque_constant_Nm_per_A == 10.0 and el.motor.winding_resistance_ohm == 0.009
    assert el.supply.kind == "regenerative" and el.storage.enabled is False
    assert el.max_speed == pytest.approx(1000.0 * 2 * math.pi / 60)


def test_every_electrical_default_carries_unit_and_reason():
    from press_model.electrical import SUBTABLES

    for cls in SUBTABLES.values():
        for f in dataclasses.fields(cls):
            assert f.metadata.get("unit") and f.metadata.get("reason"), f"{cls.__name__}.{f.name}"


def test_electrical_side_is_off_where_absent_or_disabled(press):
    assert load_press("crank-slider").electrical is None
    raw = press.raw()
    raw["drive"]["electrical"]["enabled"] = False
    raw["drive"]["electrical"]["motor"]["winding_resistance_ohm"] = -1.0  # not read while off
    assert read_press(raw, "test").electrical is None


def test_electrical_section_keeps_the_press_identity(press):
    raw = press.raw()
    del raw["drive"]["electrical"]
    assert read_press(raw, "test").fingerprint == press.fingerprint


@pytest.mark.parametrize("path, value, expected", [
    (("inverter", "efficiency"), 1.5, "must be > 0.0 and <= 1.0"),
    (("supply", "kind"), "thyristor", "must be one of 'regenerative', 'diode'"),
    (("dc_link", "nominal_voltage_V"), 1300.0, "must lie strictly between"),
    (("brake_resistor", "chopper_voltage_V"), 1000.0, "must lie above"),
    (("storage", "energy_Joule"), 1.0, "is not a known key"),
])
def test_bad_electrical_values_are_refused_naming_the_field(press, path, value, expected):
    raw = copy.deepcopy(press.raw())
    raw["drive"]["electrical"][path[0]][path[1]] = value
    with pytest.raises(PressDataError) as exc:
        read_press(raw, "test")
    assert "drive.electrical." + ".".join(path) in str(exc.value) and expected in str(exc.value)


def test_motor_losses_are_three_I_squared_R_and_the_iron_law():
    el = Electrical(max_speed=100.0)
    copper, iron = motor_losses(el, np.array([-13500.0, 0.0, 25000.0]), np.array([50.0, -100.0, 0.0]))
    assert copper == pytest.approx([3 * 1350.0**2 * 0.009, 0.0, 3 * 2500.0**2 * 0.009], rel=1e-12)
    assert iron == pytest.approx([15000.0 * (0.5 * 0.5 + 0.5 * 0.25), 15000.0, 0.0], rel=1e-12)


SUPPLIES = {
    "regenerative": {},
    "diode": {"supply": Supply(kind="diode")},
    "storage": {"storage": Storage(enabled=True)},
    "diode+storage": {"supply": Supply(kind="diode"), "storage": Storage(enabled=True)},
    "small storage": {"storage": Storage(enabled=True, energy_J=2.0e4, power_limit_W=5.0e5)},
}


@pytest.mark.parametrize("case", SUPPLIES)
def test_energy_balance_of_a_stroke_closes(press, cycle, case):
    """Grid energy = shaft work + every loss + change of the stored energies, to 1e-6 of the energy drawn."""
    pm, cyc = cycle
    el = dataclasses.replace(press.electrical, **SUPPLIES[case])
    en = _flow(el, pm, cyc).energy(el)
    parts = (en["shaft_motoring_J"] - en["shaft_braking_J"] + sum(en["lost_J"].values())
             + sum(en["stored_change_J"].values()))
    assert abs(en["drawn_J"] - en["returned_J"] - parts) <= 1e-6 * en["drawn_J"]
    assert abs(en["balance_residual_J"]) <= 1e-6 * en["drawn_J"]
    assert all(v >= 0.0 for v in en["lost_J"].values())
    assert en["periodic"]


def test_energies_are_the_power_curves_integrated_in_time(press):
    """The summary's energies against the trapezoid rule on the written curves (numpy's, not the module's weights)."""
    el = press.electrical
    t = np.linspace(0.0, 4.0, 2001)
    speed = 90.0 * np.sin(math.pi * t / 4.0)
    torque = 18000.0 * np.cos(math.pi * t / 4.0) + 2000.0
    flow = power_flow(el, 2, torque, speed, trapezoid_weights(t))
    en = flow.energy(el)
    cols = flow.columns(t)
    assert en["drawn_J"] == pytest.approx(np.trapezoid(np.maximum(cols["grid_W"], 0.0), t), rel=1e-9)
    assert en["lost_J"]["copper_J"] == pytest.approx(2 * np.trapezoid(3 * (torque / 10.0) ** 2 * 0.009, t), rel=1e-9)
    assert en["shaft_motoring_J"] - en["shaft_braking_J"] == pytest.approx(np.trapezoid(2 * torque * speed, t), rel=1e-9)


def test_a_diode_rectifier_returns_nothing_and_burns_the_braking_energy(press, cycle):
    pm, cyc = cycle
    regen = dataclasses.replace(press.electrical)
    diode = dataclasses.replace(press.electrical, supply=Supply(kind="diode"))
    a, b = (_flow(e, pm, cyc).energy(e) for e in (regen, diode))
    assert a["returned_J"] > 0.0 and a["lost_J"]["brake_resistor_J"] == 0.0
    assert b["returned_J"] == 0.0 and b["lost_J"]["brake_resistor_J"] > 0.5 * b["regenerated_J"]
    assert b["dc_link_voltage_V"]["max"] == pytest.approx(press.electrical.brake_resistor.chopper_voltage_V, rel=1e-9)
    assert b["within_dc_link_window"]


def test_a_capacitor_bank_lowers_the_grid_peak_and_repeats_each_cycle(press, cycle):
    pm, cyc = cycle
    plain = press.electrical
    bank = dataclasses.replace(plain, storage=Storage(enabled=True))
    a = _flow(plain, pm, cyc).energy(plain)
    fb = _flow(bank, pm, cyc)
    b = fb.energy(bank)
    assert b["grid_peak_W"] < 0.7 * a["grid_peak_W"]
    assert abs(b["stored_change_J"]["storage"]) <= 1e-6 * b["drawn_J"]
    assert 0.0 <= b["storage"]["energy_min_J"] and b["storage"]["energy_max_J"] <= bank.storage.energy_J
    assert b["regenerated_to"]["storage_J"] > 0.9 * b["regenerated_J"]


def test_supply_short_of_the_demand_sags_the_dc_link_out_of_its_window(press, cycle):
    pm, cyc = cycle
    weak = dataclasses.replace(press.electrical, supply=Supply(motoring_limit_W=1.0e6))
    en = _flow(weak, pm, cyc).energy(weak)
    assert en["grid_peak_W"] == pytest.approx(1.0e6, rel=1e-9)
    assert not en["within_dc_link_window"] and en["dc_link_voltage_V"]["min"] < weak.dc_link.min_voltage_V


def test_motor_side_energy_matches_the_mechanical_side_through_the_linkage(press, cycle):
    """Oracle: the shaft work of both motors over the stroke (the power flow's, from Eq. 16's torque and the speed)
    against the mechanical side: the work the crank takes (its kinetic, potential and balance energy return to their
    start over the periodic turn, so that is friction + process work), plus the gear's loss computed here from the
    crank-side power and the efficiency by its sign. Agree to 1e-6."""
    pm, cyc = cycle
    d = press.drive
    en = _flow(press.electrical, pm, cyc).energy(press.electrical)
    shaft = en["shaft_motoring_J"] - en["shaft_braking_J"]
    p_crank = (cyc.crank_torque + d.gear_inertia * d.gear_ratio**2 * cyc.theta_ddot) * cyc.theta_dot
    gear = np.where(p_crank >= 0.0, p_crank * (1.0 / d.efficiency - 1.0), -p_crank * (1.0 - d.efficiency))
    mechanical = cyc.friction_work() + cyc.process_work() + float(np.sum(gear * cyc.dt_weights))
    assert abs(shaft - mechanical) <= 1e-6 * en["shaft_motoring_J"]


def test_a_bad_electrical_value_is_a_one_line_error_of_the_command(tmp_path, capsys):
    from importlib import resources

    from servo_press.cli import main

    text = resources.files("press_model.data").joinpath("reference_press.toml").read_text(encoding="utf-8")
    bad = tmp_path / "press.toml"
    bad.write_text(text.replace("capacitance_F = 0.03 ", "capacitance_F = -0.03 "), encoding="utf-8")
    assert main(["simulate", "--press", str(bad), "--step-deg", "10", "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"servo-press: error: {bad}: drive.electrical.dc_link.capacitance_F = -0.03 is not valid: must be > 0.0")
    assert "Traceback" not in err and not (tmp_path / "out").exists()
