"""Eq. 16 has one home, press_model/motor.py: its compiled batch twin gives eq16's bytes, the planner's linear rows and
the optimiser's smooth form are Eq. 16 (checked against eq16, not against themselves), and no other module of the
packages spells the efficiency switch out."""
import ast
from pathlib import Path

import numpy as np
import pytest

import source_trees

from press_model.motor import (CrankInput, braking_ratio, crank_input_torque, eq16, eq16_loops, motor_torque,
                               smooth_motor_torque, torque_row_factors)
from press_model.press_data import read_press

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("press_model", "planning", "calibration")
HOME = Path("press_model") / "motor.py"
SEED = 20261126


def _drive(press, standstill: str, efficiency: float | None = None):
    raw = press.raw()
    raw["drive"]["efficiency_at_standstill"] = standstill
    if efficiency is not None:
        raw["drive"]["efficiency"] = efficiency
    return read_press(raw, "test press").drive


def _batch_inputs(rng, B: int = 70, n: int = 360):
    """Crank torques (B, n), speeds and accelerations (n,), J_gear and eta (B,): both signs of the power, the crank
    at rest (theta_dot = 0 and -0), and the bracket B = tau + J u^2 theta_ddot exactly 0 (and -0) with and without
    an acceleration."""
    u = 12.5
    crank = rng.normal(0.0, 2e5, (B, n))
    td = rng.normal(1.0, 1.0, n)  # mostly forward, some backward: the power takes both signs from both factors
    tdd = rng.normal(0.0, 5.0, n)
    J, eta = 0.5 + rng.random(B), 0.6 + 0.4 * rng.random(B)
    eta[0] = 1.0
    td[:12] = 0.0
    td[12:15] = -0.0
    tdd[20:30] = 0.0
    crank[:, 20:25] = 0.0  # B = 0 with no acceleration
    crank[:, 25:27] = -0.0
    tdd[25:27] = -0.0  # B = -0 + -0 = -0
    crank[:, 30:40] = -((J * (u * u))[:, None] * tdd[None, 30:40])  # B = 0 exactly with an acceleration
    crank[:, 5:8], tdd[5:8] = 0.0, 0.0  # at rest and B = 0 together
    return crank, td, tdd, J, eta, u


@pytest.mark.parametrize("motoring_at_zero", [True, False])
def test_compiled_eq16_twin_gives_eq16s_bytes(motoring_at_zero):
    """eq16_loops compiled by numba (the batch evaluator's Eq. 16) equals eq16 to the bit on random inputs with the
    power positive (eta), negative (1 / eta) and zero (the press file's standstill choice), the crank at rest and
    the bracket exactly zero; the plain-Python loops give the same bytes too."""
    from press_model.jit import compiled

    rng = np.random.default_rng(SEED)
    crank, td, tdd, J, eta, u = _batch_inputs(rng)
    ref = eq16(crank, td[None], tdd[None], J[:, None], eta[:, None], u, 2, motoring_at_zero)
    bracket = crank + (J[:, None] * (u * u)) * tdd
    power = bracket * td
    assert np.any(power > 0) and np.any(power < 0)
    assert np.any((bracket == 0) & (td != 0)) and np.any((td == 0) & (bracket != 0)) and np.any((td == 0) & (bracket == 0))
    assert np.any(np.signbit(bracket[bracket == 0])) and np.any(~np.signbit(bracket[bracket == 0]))  # -0 and +0 met
    small = slice(0, 3), slice(0, 60)  # the plain-Python loops: a corner, they are slow
    py = np.empty((3, 60))
    eq16_loops(crank[small], td[:60], tdd[:60], J[:3], eta[:3], u, 2 * u, motoring_at_zero, py)
    assert np.array_equal(py, ref[small]) and py.tobytes() == ref[small].tobytes()
    loops = compiled(eq16_loops)
    if loops is None:
        pytest.skip("numba is not installed")
    out = np.empty_like(crank)
    loops(crank, td, tdd, J, eta, u, 2 * u, motoring_at_zero, out)
    assert np.array_equal(out, ref) and out.tobytes() == ref.tobytes()


@pytest.mark.parametrize("standstill", ["motoring", "braking"])
def test_linear_torque_rows_are_eq16(press, standstill):
    """The two rows B k_mot <= L and -B k_brk <= L: their larger value is |T_m| of eq16 at every crank torque while
    the crank turns forward, and at a knot where it rests, T_m of eq16 at theta_dot = 0 (standstill exponent)."""
    rng = np.random.default_rng(SEED + 1)
    d = _drive(press, standstill, efficiency=0.83)
    B = np.concatenate([rng.normal(0.0, 3e5, 400), [0.0]])
    still = np.zeros(len(B), bool)
    still[::7] = True
    k_mot, k_brk = torque_row_factors(d, still)
    rows = np.maximum(B * k_mot, -B * k_brk)
    turning = motor_torque(d, B, 1.0, 0.0)
    assert np.allclose(rows[~still], np.abs(turning[~still]), rtol=1e-14, atol=0.0)
    at_rest = motor_torque(d, B, 0.0, 0.0)
    assert np.allclose(B[still] * k_mot[still], at_rest[still], rtol=1e-14, atol=0.0)
    assert np.allclose(-B[still] * k_brk[still], -at_rest[still], rtol=1e-14, atol=0.0)


def test_smooth_eq16_is_eq16_within_its_smoothing(press):
    """The optimiser's differentiable Eq. 16 (CasADi) lies above eq16's T_m by at most (1 - eta^2) eps / 2 for
    both signs of the crank torque, with the largest gap at B = 0."""
    import casadi as ca

    d = _drive(press, "motoring", efficiency=0.8)
    eps = 50.0
    y, r = ca.SX.sym("y"), ca.SX.sym("r")
    f = ca.Function("t", [y, r], [smooth_motor_torque(y, r, eps)])
    B = np.concatenate([np.linspace(-4e5, 4e5, 801), [0.0]])
    exact = motor_torque(d, B, 1.0, 0.0)
    motoring = B / (d.motors * d.gear_ratio * d.efficiency)
    smooth = np.array([float(f(v, braking_ratio(d))) for v in motoring])
    gap = smooth - exact
    assert np.all(gap >= -1e-9 * np.abs(exact).max())
    assert np.max(gap) <= (1.0 - d.efficiency**2) * eps / 2.0 * (1 + 1e-12)
    assert gap[-1] == pytest.approx((1.0 - d.efficiency**2) * eps / 2.0, rel=1e-12)


@pytest.mark.parametrize("standstill", ["motoring", "braking"])
def test_scalar_crank_input_is_the_array_inverse(press, standstill):
    """CrankInput (the forward dynamics' per-step inverse) equals crank_input_torque, and both invert eq16."""
    rng = np.random.default_rng(SEED + 2)
    d = _drive(press, standstill)
    inv = CrankInput(d)
    for tau, w in zip(rng.normal(0.0, 3e5, 200), np.concatenate([rng.normal(1.0, 1.0, 190), np.zeros(10)])):
        tm = float(motor_torque(d, tau, w, 0.0))
        assert inv(tm, w) == pytest.approx(float(crank_input_torque(d, tm, w)), rel=1e-15, abs=0.0)
        assert inv(tm, w) == pytest.approx(tau, rel=1e-12, abs=1e-9)


# ---- the switch spelled outside its home ---------------------------------------------------------------------

def _is_efficiency(node) -> bool:
    """An expression that is the gear efficiency: a name or attribute eta / efficiency (eta_b, bm.efficiency, ...), an
    item of one, or one passed through a conversion (np.asarray(eta), bm.efficiency.take(X), -eta)."""
    if isinstance(node, ast.Name):
        return node.id.lower() in ("eta", "efficiency") or node.id.lower().startswith(("eta_", "efficiency_"))
    if isinstance(node, ast.Attribute):
        return node.attr.lower() in ("eta", "efficiency") or node.attr.lower().startswith(("eta_", "efficiency_"))
    if isinstance(node, ast.Subscript):
        return _is_efficiency(node.value)
    if isinstance(node, ast.UnaryOp):
        return _is_efficiency(node.operand)
    if isinstance(node, ast.Call):
        f = node.func
        conversion = isinstance(f, (ast.Name, ast.Attribute)) and (f.id if isinstance(f, ast.Name) else f.attr) in (
            "asarray", "array", "ascontiguousarray", "float", "take")
        return conversion and (any(_is_efficiency(a) for a in node.args) or (isinstance(f, ast.Attribute) and _is_efficiency(f.value)))
    return False


def switch_spellings(source: str, tree: ast.Module | None = None) -> list[str]:
    """Where ``source`` (Python; ``tree`` its parse if already made) spells Eq. 16's efficiency switch: arithmetic on
    the gear efficiency (n u eta, eta / (n u), eta**s, ...), a comparison with the standstill convention's words, or a
    branch on it."""
    found = []
    for node in ast.walk(tree or ast.parse(source)):
        if isinstance(node, ast.BinOp) and (_is_efficiency(node.left) or _is_efficiency(node.right)):
            found.append(f"line {node.lineno}: arithmetic on the efficiency: {ast.get_source_segment(source, node)}")
        elif isinstance(node, ast.Compare) and any(isinstance(c, ast.Constant) and c.value in ("motoring", "braking")
                                                   for c in [node.left, *node.comparators]):
            found.append(f"line {node.lineno}: the standstill convention: {ast.get_source_segment(source, node)}")
        elif isinstance(node, (ast.IfExp, ast.If)) and any(isinstance(n, ast.Name) and n.id == "motoring_at_zero" for n in ast.walk(node.test)):
            found.append(f"line {node.lineno}: a branch on the standstill convention: {ast.get_source_segment(source, node.test)}")
    return found


@pytest.mark.parametrize("spelling", [
    "k_mot = np.full(len(still), 1.0 / (n * u * eta))",
    "k_brk = np.full(len(still), eta / (n * u))",
    "k_mot[still] = 1.0 / (n * u * eta**s0)",
    "den_back = nu * (1.0 / eta[b])",
    "gain = {s: drive.motors * drive.gear_ratio * drive.efficiency**s for s in (-1.0, 1.0)}",
    "th = (self.drives[0].efficiency ** 2, 1.0 / rated)",
    "torque = bracket / np.where(forward, nu * np.asarray(efficiency), nu)",
    "at_zero = 1.0 if drive.standstill == 'motoring' else -1.0",
    "forward = power >= 0 if motoring_at_zero else power > 0",
])
def test_the_switch_scan_finds_the_spellings_eq16_had_outside_its_home(spelling):
    assert switch_spellings(spelling)


def test_the_switch_scan_passes_code_that_only_calls_the_home():
    assert not switch_spellings("k_mot, k_brk = torque_row_factors(drive, still)\n"
                                "tm = motor_torque(drive, crank, sd, u)\nth = braking_ratio(drive)\n"
                                "J, eta = bm.gear_inertia.take(X), bm.efficiency.take(X)\n"
                                "\"\"\"B / (n u eta) <= L while motoring\"\"\"\n")


def test_eq16_switch_is_spelled_only_in_its_home():
    """No module of press_model, planning or calibration but press_model/motor.py spells the efficiency switch."""
    found = []
    for pkg in PACKAGES:
        for path in sorted((ROOT / pkg).rglob("*.py")):
            rel = path.relative_to(ROOT)
            if rel != HOME:
                found += [f"{rel}: {hit}" for hit in switch_spellings(source_trees.source(path), source_trees.tree(path))]
    assert not found, "Eq. 16's switch outside press_model/motor.py (call its functions instead):\n" + "\n".join(found)
    assert switch_spellings((ROOT / HOME).read_text(encoding="utf-8"))  # the scan sees the home's own spelling
