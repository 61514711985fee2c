"""The balance force is set from the design masses (press_reference.md, "Balance system"), or, if the press
file says ``masses = "actual"``, from the current body masses. Checked against virtual work of the extra slide
mass on closed-form kinematics and Eq. 13 written out again here."""
from __future__ import annotations

import math

import numpy as np
import pytest
from closed_form import EightBar, derivatives

from press_model import dynamics as D
from press_model import kinematics as K
from press_io.errors import PressDataError
from press_model.forces import BalanceForce, balance_mass
from press_model.model import PressModel
from press_model.press_data import PressData, load_press, read_press

EXTRA_KG = 4000.0  # a heavier true slide (m8 + 4 t), within m8's sensitivity range


def _press_with(masses: str) -> PressData:
    press = load_press()
    raw = press.raw()
    raw["balance"]["masses"] = masses
    return read_press(raw, f"reference press, balance.masses = {masses}")


def _eq13_force(press: PressData, mass_kg: float, stroke: float, h: float) -> float:
    """Eq. 13 and 17 written out: z P0 A_b = psi M g; Q_b = z P0 A_b (1 + u1), P0 in MPa inside u1."""
    b = press.balance
    p0 = b.psi * mass_kg * press.gravity / (b.cylinders * b.piston_area)
    p0_mpa = p0 / 1e6
    u1 = (p0_mpa + b.pressure_offset_mpa) * ((1 + (stroke - h) * b.piston_area / b.tank_volume) ** b.polytropic_exponent - 1) / p0_mpa
    return b.cylinders * p0 * b.piston_area * (1 + u1)


def test_reference_press_reads_the_design_masses():
    press = load_press()
    assert press.balance.masses == "design"
    assert press.balance.design_mass == pytest.approx(sum(b.mass for b in press.bodies.values()))
    heavy = press.with_overrides({"m8": press.parameter_values()["m8"] + EXTRA_KG})
    # the pressure the controller was set to does not follow the true slide mass
    assert balance_mass(heavy) == balance_mass(press)
    assert heavy.fingerprint == press.fingerprint  # overrides keep the press's identity


def test_actual_reading_follows_the_body_masses():
    press = _press_with("actual")
    heavy = press.with_overrides({"m8": press.parameter_values()["m8"] + EXTRA_KG})
    assert balance_mass(heavy) == pytest.approx(balance_mass(press) + EXTRA_KG)


def test_the_reading_is_refused_unless_known():
    raw = load_press().raw()
    raw["balance"]["masses"] = "nominal"
    with pytest.raises(PressDataError, match="masses"):
        read_press(raw, "bad")


@pytest.mark.parametrize("masses", ["design", "actual"])
def test_extra_slide_mass_costs_its_virtual_work_and_only_the_reading_s_balance(cushion, masses):
    """Frictionless drive torque of (m8 + dm) minus that of m8, from Pinocchio, against virtual work on the
    closed-form kinematics: dm (ys' al + ys'' w^2 + g ys')  minus  d(balance force) ys', where the balance
    force changes only in the 'actual' reading (Eq. 13 with M + dm instead of M)."""
    job, motion = cushion
    press = _press_with(masses)
    heavy = press.with_overrides({"m8": press.parameter_values()["m8"] + EXTRA_KG})
    pm0, pm1 = PressModel(press), PressModel(heavy)
    ws0, ws1 = pm0.workspace(), pm1.workspace()
    loads0, loads1 = D.slide_loads(pm0, job.process), D.slide_loads(pm1, job.process)
    cf = EightBar(press)
    stroke, s_bdc = pm0.assembly.stroke, pm0.assembly.s_bdc
    m0 = sum(b.mass for b in press.bodies.values())
    diffs, refs = [], []
    for deg in np.arange(3.0, 360.0, 23.0):
        th = math.radians(deg)
        w, al = float(motion.theta_dot(th)), float(motion.theta_ddot(th))
        t0 = D.inverse_dynamics(pm0, ws0, K.state_at(pm0, ws0, th, w, al), loads0, friction=False).crank_torque
        t1 = D.inverse_dynamics(pm1, ws1, K.state_at(pm1, ws1, th, w, al), loads1, friction=False).crank_torque
        d1, d2 = derivatives(lambda x: np.array([cf.slide_y(x)]), th)
        ys1, ys2 = float(d1[0]), float(d2[0])
        h = cf.slide_y(th) - s_bdc
        ref = EXTRA_KG * (ys1 * ys1 * al + ys1 * ys2 * w * w + press.gravity * ys1)
        if masses == "actual":
            ref -= (_eq13_force(press, m0 + EXTRA_KG, stroke, h) - _eq13_force(press, m0, stroke, h)) * ys1
        diffs.append(t1 - t0)
        refs.append(ref)
    diffs, refs = np.array(diffs), np.array(refs)
    assert np.max(np.abs(diffs - refs)) < 1e-5 * np.max(np.abs(refs))


def test_design_reading_matches_eq13_at_the_reference_values(ref_model):
    """press_reference.md: psi = 1.15 gives P0 = 0.6098 MPa and Q_b = 487.8 kN at TDC, about 533 kN at BDC."""
    press = ref_model.press
    bf = BalanceForce.from_press(press, ref_model.assembly.stroke)
    assert bf.supply_pressure / 1e6 == pytest.approx(0.6098, abs=1e-4)
    assert float(bf(ref_model.assembly.stroke)) == pytest.approx(487.8e3, rel=1e-3)
    assert float(bf(0.0)) == pytest.approx(533e3, rel=2e-3)
    assert float(bf(0.7)) == pytest.approx(_eq13_force(press, press.balance.design_mass, ref_model.assembly.stroke, 0.7), rel=1e-12)
