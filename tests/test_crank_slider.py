"""The crank-slider example press against its closed-form kinematics and frictionless drive torque.

The closed form is written here from scratch (it uses nothing of the package's physics): a centred
crank-slider with the crank pivot O at the origin, the crank pin A at radius r, a rod of length l and
the slide's wrist pin B on the line x = 0 below O. With the crank body angle t (from +x, counter-
clockwise) the slide point sits at

    y(t) = r sin t - sqrt(l^2 - (r cos t)^2)

and the drive torque follows from virtual work:

    tau = sum_i [ m_i (a_i + g y_hat) . dr_i/dt + J_i alpha_i dphi_i/dt ] - F_ext dy/dt.

The numbers of the press (r, l, masses, COM distances, inertias) are read from the TOML text itself,
so the test checks the model-building pipeline (reader, URDF, Pinocchio, loop closure, inverse
dynamics) and not a second copy of the same numbers.
"""
from __future__ import annotations

import math
import tomllib
from importlib import resources

import numpy as np
import pytest

from press_model import dynamics, forces, kinematics
from press_model.forces import BalanceForce, ProcessForce
from press_model.model import PressModel, Workspace
from press_model.press_data import load_press
from press_model.press_settings import PressSection

RAW = tomllib.loads(resources.files("press_model.data").joinpath("crank_slider.toml").read_text(encoding="utf-8"))
B = RAW["bodies"]
R = B["crank"]["points_m"]["A"][0]  # crank radius, m
L = B["rod"]["points_m"]["B"][0]  # rod length, m
D1 = B["crank"]["com"]["distance_m"]  # crank COM from O toward A, m
D2 = B["rod"]["com"]["distance_m"]  # rod COM from A toward B, m
M1, M2, M3 = B["crank"]["mass_kg"], B["rod"]["mass_kg"], B["slide"]["mass_kg"]
J1, J2 = B["crank"]["inertia_kg_m2"], B["rod"]["inertia_kg_m2"]
G = RAW["press"].get("gravity_m_s2", PressSection.gravity_m_s2)  # the file leaves standard gravity to its default
OFFSET = math.radians(RAW["drive"]["angle_offset_deg"])

# ~24 crank angles (not on the round TDC/BDC values) with a non-uniform, self-consistent crank speed:
# theta_dot = k (1 - e cos(theta_c - 0.7)), theta_ddot = theta_dot * d(theta_dot)/d(theta_c)
THETA_C = np.radians(3.7 + 15.0 * np.arange(24))
K_SPEED, E_SPEED = 2.3, 0.45
THETA_DOT = K_SPEED * (1.0 - E_SPEED * np.cos(THETA_C - 0.7))
THETA_DDOT = THETA_DOT * K_SPEED * E_SPEED * np.sin(THETA_C - 0.7)


def closed_form(t):
    """Closed-form geometry at crank body angle t (rad).

    Returns a dict of (value, d/dt, d2/dt2) triples: slide y, COM positions of crank/rod/slide
    (2-vectors), and the crank and rod body angles.
    """
    c, s = math.cos(t), math.sin(t)
    w = math.sqrt(L * L - (R * c) ** 2)  # vertical drop from A to B
    w1 = R * R * c * s / w
    w2 = R * R * (c * c - s * s) / w - (R * R * c * s) ** 2 / w**3
    y = (R * s - w, R * c - w1, -R * s - w2)
    # crank pin A and wrist pin B
    A = (np.array([R * c, R * s]), np.array([-R * s, R * c]), np.array([-R * c, -R * s]))
    Bp = tuple(np.array([0.0, yk]) for yk in y)
    # rod angle: cos phi2 = -r c / l, sin phi2 = -w / l; phi2' = r s / w
    phi2 = math.atan2(-w, -R * c)
    phi2_1 = R * s / w
    phi2_2 = R * c / w - R * s * w1 / w**2
    com1 = tuple(D1 / R * a for a in A)
    com2 = tuple(a + D2 / L * (b - a) for a, b in zip(A, Bp))
    return {
        "y": y,
        "com": (com1, com2, Bp),
        "phi": ((t, 1.0, 0.0), (phi2, phi2_1, phi2_2)),
    }


def closed_form_torque(t, t_dot, t_ddot, f_ext):
    """Frictionless drive torque (N m) at crank body angle t by virtual work; f_ext acts up on the slide."""
    cf = closed_form(t)
    tau = 0.0
    for m, (r0, r1, r2) in zip((M1, M2, M3), cf["com"]):
        acc = r2 * t_dot**2 + r1 * t_ddot
        tau += m * (acc + np.array([0.0, G])) @ r1
    for j, (p0, p1, p2) in zip((J1, J2), cf["phi"]):
        alpha = p2 * t_dot**2 + p1 * t_ddot
        tau += j * alpha * p1
    return tau - f_ext * cf["y"][1]


@pytest.fixture(scope="module")
def pm():
    return PressModel(load_press("crank-slider"))


def test_closed_form_derivatives_match_differences():
    """Self-check of the hand-derived derivatives against central differences of the positions."""
    h = 1e-4
    for t in np.radians([-170.0, -95.0, -30.0, 10.0, 85.0, 140.0]):
        lo, mid, hi = closed_form(t - h), closed_form(t), closed_form(t + h)
        pairs = [(lo["y"], mid["y"], hi["y"])]
        pairs += list(zip(lo["com"], mid["com"], hi["com"]))
        pairs += list(zip(lo["phi"], mid["phi"], hi["phi"]))
        for a, b, c in pairs:
            np.testing.assert_allclose((np.asarray(c[0]) - a[0]) / (2 * h), b[1], atol=1e-8)
            np.testing.assert_allclose((np.asarray(c[0]) - 2 * np.asarray(b[0]) + a[0]) / h**2, b[2], atol=1e-6)


def test_stroke_and_dead_centres(pm):
    asm = pm.assembly
    assert asm.stroke == pytest.approx(2 * R, abs=1e-9)
    assert asm.s_bdc == pytest.approx(-R - L, abs=1e-9)
    # theta_1 = offset + theta_c: BDC where the crank points down, TDC where it points up
    assert math.remainder(asm.theta_bdc - (-math.pi / 2 - OFFSET), 2 * math.pi) == pytest.approx(0.0, abs=1e-5)
    # TDC is a flat maximum (y - y_tdc ~ theta^2), so the optimiser locates it only to ~sqrt(eps)
    assert math.remainder(asm.theta_tdc - (math.pi / 2 - OFFSET), 2 * math.pi) == pytest.approx(0.0, abs=1e-4)


def test_kinematics_match_closed_form(pm):
    ws = Workspace(pm)
    y_bdc = -R - L
    err = {"H": 0.0, "H_dot": 0.0, "H_ddot": 0.0, "slide_y": 0.0}
    for th, td, tdd in zip(THETA_C, THETA_DOT, THETA_DDOT):
        st = kinematics.state_at(pm, ws, float(th), float(td), float(tdd))
        y, y1, y2 = closed_form(OFFSET + th)["y"]
        err["H"] = max(err["H"], abs(st.height - (y - y_bdc)))
        err["H_dot"] = max(err["H_dot"], abs(st.height_dot - y1 * td))
        err["H_ddot"] = max(err["H_ddot"], abs(st.height_ddot - (y2 * td**2 + y1 * tdd)))
        err["slide_y"] = max(err["slide_y"], abs(kinematics.slide_position(pm, ws.data, st.q) - y))
        assert 0.0 - 1e-12 <= st.height <= 2 * R + 1e-12
    assert err["H"] < 1e-9 and err["slide_y"] < 1e-9, err
    assert err["H_dot"] < 1e-9 and err["H_ddot"] < 1e-8, err


def _package_torques(pm, loads):
    ws = Workspace(pm)
    out = []
    for th, td, tdd in zip(THETA_C, THETA_DOT, THETA_DDOT):
        st = kinematics.state_at(pm, ws, float(th), float(td), float(tdd))
        out.append(dynamics.inverse_dynamics(pm, ws, st, loads, friction=False).crank_torque)
    return np.array(out)


def _closed_form_torques(balance: BalanceForce, process: ProcessForce):
    out = []
    for th, td, tdd in zip(THETA_C, THETA_DOT, THETA_DDOT):
        t = OFFSET + th
        y, y1, _ = closed_form(t)["y"]
        h, h_dot = y - (-R - L), y1 * td
        f_ext = float(balance(h)) + float(process(h, h_dot))
        out.append(closed_form_torque(t, td, tdd, f_ext))
    return np.array(out)


# a process force that acts on the way down below 0.2 m, rising linearly to 300 kN at BDC
PRESSING = ProcessForce(0.2, (0.2, 0.0), (0.0, 3.0e5))


@pytest.mark.parametrize("process", [forces.NO_PROCESS, PRESSING], ids=["load-none", "pressing"])
def test_frictionless_torque_matches_virtual_work(pm, process):
    # the balance force is evaluated at the closed-form height with the closed-form stroke 2 r
    balance = BalanceForce.from_press(pm.press, 2 * R)
    expected = _closed_form_torques(balance, process)
    got = _package_torques(pm, dynamics.slide_loads(pm, process))
    scale = np.max(np.abs(expected))
    assert scale > 1e3  # a torque worth comparing (N m)
    if process is PRESSING:  # the load must act at some of the samples, or this case tests nothing new
        h = np.array([closed_form(OFFSET + th)["y"][0] + R + L for th in THETA_C])
        h_dot = np.array([closed_form(OFFSET + th)["y"][1] for th in THETA_C]) * THETA_DOT
        assert np.count_nonzero(process(h, h_dot)) >= 3
    rel = np.max(np.abs(got - expected)) / scale
    assert rel < 1e-6, f"max relative torque error {rel:.3g} (scale {scale:.4g} N m)"


def test_balance_force_at_tdc_holds_psi_times_weight(pm):
    """Eq. 17 as documented in the press file: z P0 A_b = psi * (sum of moving masses) * g at TDC."""
    bal = BalanceForce.from_press(pm.press, 2 * R)
    psi = RAW["balance"]["coefficient"]
    assert float(bal(2 * R)) == pytest.approx(psi * (M1 + M2 + M3) * G, rel=1e-12)
    assert float(bal(0.0)) > float(bal(2 * R))  # the gas is compressed as the slide goes down


def test_comparison_detects_a_wrong_mass_or_com(pm):
    """The torque check must fail for a slightly wrong press: 1 % on the crank COM or rod mass."""
    balance = BalanceForce.from_press(pm.press, 2 * R)
    expected = _closed_form_torques(balance, forces.NO_PROCESS)
    scale = np.max(np.abs(expected))
    for override in ({"Ls1": D1 * 1.01}, {"m2": M2 * 1.01}):
        bad = PressModel(pm.press.with_overrides(override, "test"))
        got = _package_torques(bad, dynamics.slide_loads(bad, forces.NO_PROCESS))
        assert np.max(np.abs(got - expected)) / scale > 1e-4, override
