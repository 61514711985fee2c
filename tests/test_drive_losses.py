"""The drive losses Eq. 16 leaves out ([drive.losses] of the press file, press_model/motor.py): off they change no
number; on they take power (never give it), invert exactly, agree between the scalar and the batch path, and are
parameters like any other."""
import numpy as np
import pytest

from press_model import batch as BT
from press_model.cycle import simulate_cycle
from press_io.errors import PressDataError
from press_model.model import PressModel
from press_model.motor import crank_input_torque, eq16, motor_torque
from press_model.press_data import LOSS_SWITCH, read_press
from press_model.settings_fields import replaced

SEED = 20261123
LEVELS = 64  # torque limits drawn for the bracket interval's test (its 4,000 points share them)


def with_losses(press, enabled=True, **losses):
    """The press with [drive.losses] set (``losses``: load_loss_at_rated, viscous_Nms_per_rad)."""
    raw = press.raw()
    raw["drive"]["losses"].update(enabled=enabled, **losses)
    return read_press(raw, "test press")


def eq16_before_the_option(crank_torque, theta_dot, theta_ddot, gear_inertia, efficiency, gear_ratio, motors, motoring_at_zero):
    """press_model/motor.py's eq16 as it was before [drive.losses] existed (commit 1c41f8f), kept to pin byte identity."""
    u = gear_ratio
    bracket = np.asarray(crank_torque) + gear_inertia * (u * u) * np.asarray(theta_ddot)
    power = bracket * np.asarray(theta_dot)
    forward = power >= 0 if motoring_at_zero else power > 0
    nu = motors * u
    return bracket / np.where(forward, nu * np.asarray(efficiency), nu * (1.0 / np.asarray(efficiency)))


@pytest.fixture(scope="module")
def states():
    """Crank-side torques (N m), speeds (rad/s, some exactly 0) and accelerations (rad/s^2) of every sign."""
    rng = np.random.default_rng(SEED)
    n = 2000
    tau = rng.normal(0.0, 4e5, n)
    td = rng.normal(0.0, 1.0, n)
    td[::50] = 0.0
    tdd = rng.normal(0.0, 2.0, n)
    return tau, td, tdd


@pytest.fixture(scope="module")
def lossy(press):
    return with_losses(press, load_loss_at_rated=0.06, viscous_Nms_per_rad=4.0)


def test_losses_off_leave_eq16_byte_identical(press, states):
    tau, td, tdd = states
    d = press.drive
    old = eq16_before_the_option(tau, td, tdd, d.gear_inertia, d.efficiency, d.gear_ratio, d.motors, True)
    assert motor_torque(d, tau, td, tdd).tobytes() == old.tobytes()
    on_but_zero = with_losses(press).drive  # switched on at zero losses: still the paper's numbers
    assert motor_torque(on_but_zero, tau, td, tdd).tobytes() == old.tobytes()
    # the batch path's broadcast: (B, 1) columns of J_gear and eta against (n,) rows
    J, eta = np.array([[50.0], [60.0]]), np.array([[0.8], [0.95]])
    for at_zero in (True, False):
        new = eq16(tau[None], td[None], tdd[None], J, eta, d.gear_ratio, d.motors, at_zero, (np.zeros((2, 1)), np.zeros((2, 1)), 0.0))
        assert new.tobytes() == eq16_before_the_option(tau[None], td[None], tdd[None], J, eta, d.gear_ratio, d.motors, at_zero).tobytes()


def test_losses_take_power_and_never_give_it(press, lossy, states):
    """Motor power in = crank power + losses, losses >= those of the paper's Eq. 16 >= 0, driving or braking."""
    tau, td, tdd = states
    bracket = tau + lossy.drive.gear_inertia * lossy.drive.gear_ratio**2 * tdd  # what the gear delivers at the crank
    nu = lossy.drive.motors * lossy.drive.gear_ratio
    loss_paper = nu * motor_torque(press.drive, tau, td, tdd) * td - bracket * td
    loss_on = nu * motor_torque(lossy.drive, tau, td, tdd) * td - bracket * td
    scale = np.abs(bracket * td).max()
    assert loss_paper.min() >= -1e-12 * scale
    assert np.all(loss_on >= loss_paper - 1e-12 * scale)
    # the part the options add: k T_B^2 |theta_dot| n u (always against the motion) + n c omega_m^2
    tb = bracket / nu
    extra = nu * lossy.drive.load_loss_per_Nm * tb**2 * np.abs(td) + lossy.drive.motors * lossy.drive.viscous * (lossy.drive.gear_ratio * td) ** 2
    assert np.allclose(loss_on - loss_paper, extra, rtol=1e-9, atol=1e-9 * scale)


def test_efficiency_falls_with_load_as_the_press_file_says(press):
    """load_loss_at_rated = k: driving at the rated torque the efficiency is 1 / (1 / eta + k), at no load eta."""
    k = 0.057
    d = with_losses(press, load_loss_at_rated=k).drive
    nu, rated = d.motors * d.gear_ratio, press.motor.rated_torque
    for load, expected in ((rated, 1.0 / (1.0 / d.efficiency + k)), (1e-6 * rated, d.efficiency)):
        B = load * nu
        eff = B / (nu * float(motor_torque(d, B, 1.0, 0.0)))
        assert eff == pytest.approx(expected, rel=1e-6)
    assert 1.0 - (1.0 / (1.0 / d.efficiency + k)) / d.efficiency == pytest.approx(0.05, abs=2e-3)  # the file's "5 % at rated"


def test_crank_input_torque_inverts_eq16(press, lossy, states):
    tau, td, _ = states
    for p in (press, lossy, with_losses(press, load_loss_at_rated=0.15), with_losses(press, viscous_Nms_per_rad=10.0)):
        for standstill in ("motoring", "braking"):
            raw = p.raw()
            raw["drive"]["efficiency_at_standstill"] = standstill
            d = read_press(raw, "test press").drive
            tm = motor_torque(d, tau, td, 0.0)
            assert np.allclose(crank_input_torque(d, tm, td), tau, rtol=1e-12, atol=1e-9 * np.abs(tau).max())


def test_forward_dynamics_uses_the_same_inverse(lossy):
    from press_model.forward import ForwardModel

    fm = ForwardModel(PressModel(lossy))
    for tm, w in ((8000.0, 0.9), (-8000.0, 0.9), (3000.0, -0.5), (5000.0, 0.0)):
        assert fm.crank_input(tm, w) == pytest.approx(float(crank_input_torque(lossy.drive, tm, w)), rel=1e-14)


def test_batch_path_agrees_with_the_scalar_path_with_losses_on(lossy, cushion):
    """Random sets of all 30 parameters (k_load and c_drive among them) through the batch kernel and through
    PressModel + simulate_cycle on the overridden press."""
    job, motion = cushion
    pm = PressModel(lossy)
    bm = BT.build_batch_model(lossy, motion, job.process, step_deg=6.0, pm=pm)
    assert {"k_load", "c_drive"} <= set(bm.names)
    X = bm.low + (bm.high - bm.low) * np.random.default_rng(SEED).random((2, bm.n_params))
    T = BT.motor_torques(bm, X)
    for x, t in zip(X, T):
        cyc = simulate_cycle(PressModel(lossy.with_overrides(dict(zip(bm.names, map(float, x))))), motion, job.process, step_deg=6.0)
        assert np.max(np.abs(t - cyc.motor_torque)) < 1e-10 * np.max(np.abs(cyc.motor_torque))
    # the losses move the curve: k_load and c_drive at their nominal zero give the curve of the paper's model
    x0 = bm.nominal.copy()
    x_on = x0.copy()
    x_on[bm.names.index("k_load")], x_on[bm.names.index("c_drive")] = 0.1, 5.0
    T0, T1 = BT.motor_torques(bm, np.array([x0, x_on]))
    assert np.max(np.abs(T1 - T0)) > 100.0


def test_parameters_exist_only_when_the_switch_is_on(press):
    assert len(press.parameters) == 28 and "k_load" not in press.parameters
    on = with_losses(press)
    assert list(on.parameters)[:28] == list(press.parameters) and list(on.parameters)[28:] == ["k_load", "c_drive"]
    assert on.parameters["k_load"].target.field == "load_loss" and on.parameters["c_drive"].target.field == "viscous"
    moved = on.with_overrides({"k_load": 0.04, "c_drive": 2.0})
    assert moved.drive.load_loss_at_rated == 0.04 and moved.drive.viscous == 2.0
    with pytest.raises(PressDataError, match=f"k_load.*only when the press file sets {LOSS_SWITCH} = true"):
        press.with_overrides({"k_load": 0.04})


@pytest.mark.parametrize("edit, field, fix", [
    ({"enabled": True, "load_loss_at_rated": -0.01}, "drive.losses.load_loss_at_rated", ">= 0.0"),
    ({"enabled": True, "load_loss_at_rated": 1.5}, "drive.losses.load_loss_at_rated", "<= 1.0"),
    ({"enabled": True, "viscous_Nms_per_rad": -1.0}, "drive.losses.viscous_Nms_per_rad", ">= 0.0"),
    ({"enabled": True, "viscous_Nms_per_rad": 1e4}, "drive.losses.viscous_Nms_per_rad", "peak torque at their top speed"),
    ({"load_loss_at_rated": 0.05}, "drive.losses.load_loss_at_rated", f"set {LOSS_SWITCH} = true"),
    ({"enabled": "yes"}, "drive.losses.enabled", "true or false"),
    ({"enabeld": True}, "drive.losses.enabeld", "did you mean 'enabled'"),
])
def test_bad_losses_are_refused_naming_field_value_and_fix(press, edit, field, fix):
    raw = press.raw()
    raw["drive"]["losses"].update(edit)
    with pytest.raises(PressDataError) as exc:
        read_press(raw, "test press")
    msg = str(exc.value)
    assert "\n" not in msg and field in msg and fix in msg, msg


def test_bad_loss_parameter_ranges_are_refused(press):
    raw = press.raw()
    raw["drive"]["losses"]["enabled"] = True
    raw["parameters"]["k_load"]["range"] = [-0.1, 0.1]
    with pytest.raises(PressDataError, match=r"parameters\.k_load\.range.*must not go below 0"):
        read_press(raw, "test press")
    raw = press.raw()
    raw["parameters"]["k_load"]["requires"] = "drive.efficiency"
    with pytest.raises(PressDataError, match=r"parameters\.k_load\.requires.*must be 'drive.losses.enabled'"):
        read_press(raw, "test press")


@pytest.mark.parametrize("standstill", ["motoring", "braking"])
@pytest.mark.parametrize("load_loss, viscous", [(0.06, 4.0), (0.15, 0.0), (0.0, 10.0), (1.0, 10.0)])
def test_torque_bracket_interval_is_eq16s_set_with_the_losses(press, standstill, load_loss, viscous):
    """|eq16| <= L (losses on) exactly where the crank-side bracket B lies in torque_bracket_interval's [B_lo, B_hi],
    on random brackets, speeds and limits, the crank turning (B on the physical branch) or at rest (the press file's
    standstill exponent); beyond the branch (the gear passes less back, eq16 turns) B is outside the interval. The
    4,000 points share 64 limits, one call a limit over its points: the interval is elementwise for one limit (the
    planner's call, one level over all knots), so the relation checked per point does not depend on how they are grouped."""
    from press_model.motor import torque_bracket_interval

    raw = press.raw()
    raw["drive"]["efficiency_at_standstill"] = standstill
    raw["drive"]["losses"].update(enabled=True, load_loss_at_rated=load_loss, viscous_Nms_per_rad=viscous)
    raw["parameters"]["k_load"]["range"] = [0.0, 1.0]  # the largest loss the press file takes
    d = read_press(raw, "test press").drive
    rng = np.random.default_rng(SEED)
    n = 4000
    nu = d.motors * d.gear_ratio
    w = rng.uniform(0.0, press.motor.max_speed / d.gear_ratio, n)
    still = np.zeros(n, bool)
    still[::9] = True
    w[still] = 0.0
    # LEVELS limits, each point given one of them at random (see the docstring)
    levels = rng.uniform(0.3, 1.0, LEVELS) * press.motor.peak_torque
    pick = rng.integers(0, LEVELS, n)
    L = levels[pick]
    lo, hi = np.empty(n), np.empty(n)
    for j, level in enumerate(levels):
        at = pick == j
        lo[at], hi[at] = torque_bracket_interval(d, float(level), w[at], still[at])
    assert np.all(lo < hi)
    B = lo + (hi - lo) * rng.uniform(-0.6, 1.6, n)  # about half inside the interval, half beyond either end
    k = d.load_loss_per_Nm
    branch = np.full(n, -np.inf) if not k else np.where(still, -np.inf, -d.efficiency * nu / (2.0 * k))
    if k and standstill == "braking":  # at rest with the braking exponent eq16 turns on both sides
        branch = np.where(still, -d.efficiency * nu / (2.0 * k), branch)
    on = (B >= branch) & ((B <= -branch) | ~still | (standstill == "motoring"))
    inside = (B >= lo) & (B <= hi)
    holds = np.abs(motor_torque(d, B, w, 0.0)) <= L
    assert np.array_equal(inside[on], holds[on])
    assert not np.any(inside[~on])
    assert on.mean() > 0.5 and holds[on].mean() > 0.2 and (~holds[on]).mean() > 0.2  # both answers tried
    if k:  # beyond the branch, where eq16 would come back within the limit: outside the interval all the same
        beyond = branch[~still] * rng.uniform(1.0 + 1e-9, 4.0, (~still).sum())
        assert np.all(beyond < lo[~still])
    # the ends are on the limit: |eq16| = L there, or the branch's end
    for b in (lo, hi):
        t = np.abs(motor_torque(d, b, w, 0.0))
        at_branch = np.isclose(b, np.where(b < 0, branch, -branch), rtol=1e-12)
        assert np.allclose(t[~at_branch], L[~at_branch], rtol=1e-9)


def test_torque_bracket_interval_without_losses_is_the_linear_rows(press):
    """The losses off: the interval's ends are the linear rows' B = L / k_mot and -L / k_brk (torque_row_factors)."""
    from press_model.motor import torque_bracket_interval, torque_row_factors

    still = np.array([False, True, False])
    lo, hi = torque_bracket_interval(press.drive, 22250.0, np.array([1.0, 0.0, 0.3]), still)
    k_mot, k_brk = torque_row_factors(press.drive, still)
    assert np.allclose(hi, 22250.0 / k_mot, rtol=1e-14) and np.allclose(lo, -22250.0 / k_brk, rtol=1e-14)


def test_lossy_torque_rows_and_their_smooth_form_are_eq16(press, lossy, states):
    """The jerk-limited stage's rows with the losses (y = B / (n u eta)): the motoring form is eq16 where B >= 0, the
    braking form where B < 0, and (motoring <= L, |braking| <= L, branch >= 0) holds exactly where |eq16| <= L on
    the physical branch; the smooth form for the thermal row lies above eq16 by at most (1 - eta^2) eps / 2."""
    import casadi as ca

    from press_model.motor import loss_coefficients, lossy_torque_rows, smooth_lossy_motor_torque, torque_row_factors

    tau, td, _ = states
    d = lossy.drive
    w = np.abs(td) + 1e-3  # the crank turning forward
    B = 2.0 * tau  # motor torques up to about 2 T_max
    y = B * torque_row_factors(d, [False])[0][0]
    coef = loss_coefficients(d)
    mot, brk, branch = lossy_torque_rows(y, w, coef)
    T = motor_torque(d, B, w, 0.0)
    assert np.allclose(np.where(B >= 0, mot, brk), T, rtol=1e-12, atol=1e-9)
    on = branch >= 0
    assert on.all()  # these loads are far inside the branch (it ends at B = -eta n u / (2 k), -6.6e6 N m here)
    assert lossy_torque_rows(-d.efficiency * d.motors * d.gear_ratio / (2.0 * d.load_loss_per_Nm) * y.max() / B.max() * 1.001,
                             1.0, coef)[2] < 0.0
    for L in (5000.0, 12000.0, 22250.0):
        rows_hold = (mot <= L) & (np.abs(brk) <= L)
        assert np.array_equal(rows_hold[on], (np.abs(T) <= L)[on])
        assert 0.05 < rows_hold[on].mean() < 0.95
    eps = 50.0
    Y, W = ca.SX.sym("y"), ca.SX.sym("w")
    f = ca.Function("f", [Y, W], [smooth_lossy_motor_torque(Y, W, coef, eps)])
    smooth = np.asarray(f(y[None, :], w[None, :])).ravel()
    gap = smooth - T
    assert gap.min() >= -1e-9 and gap.max() <= (1.0 - d.efficiency**2) * eps / 2 * (1 + 1e-9)


def test_joint_calibration_with_losses_on_recovers_eta_gear_when_efficiency_falls_with_load(press, tmp_path):
    """SYNTHETIC: two logs of `experiment` (cushion_test.toml; cushion_validation.toml's motion with a 2,500 kN cushion)
    whose gear efficiency falls 5 % at rated torque (calibration/synthetic/effects.py, applied to the log, not through the
    model), a random truth of the six key parameters (seed 7001); calibrated jointly with the losses on and k_load,
    c_drive calibrated: eta_gear within 2 % (the paper's model alone misses it by ~12 %: scripts/bench_drive_losses.py)."""
    import dataclasses

    from calibration.synthetic.effects import LogEffects
    from calibration.synthetic.experiment import ExperimentSettings, write_experiment
    from calibration.identification.problem import CalibrationProblem
    from calibration.identification.run import calibrate
    from calibration.identification.settings import CalibrationSettings
    from press_model.jobs import load_job
    from importlib import resources

    seed = 7001
    job = load_job("cushion-test")
    text = resources.files("press_model.data").joinpath("cushion_validation.toml").read_text()
    assert "forces_N = [5.0e6, 5.0e6]" in text
    (tmp_path / "second.toml").write_text(text.replace("forces_N = [5.0e6, 5.0e6]", "forces_N = [2.5e6, 2.5e6]"))
    job2 = load_job(tmp_path / "second.toml")
    cs = CalibrationSettings.from_job(job)
    prob = CalibrationProblem.from_press(press, cs.parameters, cs.weight)
    truth_v = prob.low + (0.1 + 0.8 * np.random.default_rng(seed).random(len(prob.names))) * (prob.high - prob.low)
    truth = dict(zip(prob.names, map(float, truth_v)))
    logs = []
    for k, jb in enumerate((job, job2)):
        # a 0.5-degree model grid (the job's 0.25) halves the log's cost; its interpolation error stays far below the noise
        settings = dataclasses.replace(ExperimentSettings.from_job(jb), effects=LogEffects(efficiency_drop_at_rated=0.05),
                                       model_step=np.radians(0.5))
        logs.append(tmp_path / f"run{k}.csv")
        write_experiment(press, jb, truth, seed + k, logs[-1], settings=settings)
    names = prob.names + ("k_load", "c_drive")
    cal = calibrate(with_losses(press), job, logs[0], [cs.default_method], seed, settings=replaced(CalibrationSettings.from_job(job), {"bootstrap.refits": 0, "parameters": names}), progress=False, more_logs=[(logs[1], job2)])
    x = dict(zip(names, cal.best.x))
    assert abs(x["eta_gear"] / truth["eta_gear"] - 1.0) < 0.02, (x, truth)
    assert x["k_load"] > 0.03  # the fall was fitted by the loss term, not absorbed elsewhere


def test_a_loss_the_model_calibrates_is_no_suspect_of_the_adequacy_test():
    """With c_drive calibrated, the viscous-loss candidate is a column of the Jacobian: its score test has no direction
    left (it gave t ~ 1e10 on a log the model fits), so it is left out; the other candidates are still tested."""
    from calibration.identification.adequacy import candidate_columns, in_span

    rng = np.random.default_rng(SEED)
    theta = np.linspace(0.0, 2.0 * np.pi, 360, endpoint=False)
    td = 1.0 + 0.4 * np.cos(theta)
    torque = 5000.0 * np.sin(theta) + 800.0 * np.cos(3.0 * theta)
    cands = {c.name: c for c in candidate_columns(theta, td, torque, 32.0, 13500.0)}
    J = np.column_stack([rng.normal(size=360), 1e-4 * rng.normal(size=360), 2.5 * 32.0 * td])  # the last: d T / d c_drive
    assert in_span(J, cands["viscous_loss"].columns)
    assert not any(in_span(J, cands[n].columns) for n in ("channel_delay", "angle_offset", "load_dependent_efficiency"))


def test_a_switched_off_option_keeps_the_press_identity(press):
    """Results made on the reference press before [drive.losses] existed stay valid: its fingerprint is that of the
    file text without the option's lines (the file as shipped before its settings took defaults, every one written
    out); turning the option on makes it another press."""
    import tomllib
    from pathlib import Path

    from press_model.readers import data_fingerprint

    full = Path(__file__).parent / "data" / "history" / "reference_press" / "ea5bb72.toml"
    lines = full.read_text(encoding="utf-8").splitlines()
    start = lines.index("[drive.losses]")
    end = next(i for i in range(start + 1, len(lines)) if lines[i].startswith("["))
    kept = [s for s in lines[:start] + lines[end:] if "requires = " not in s]
    assert len(kept) < len(lines) - 3
    assert press.fingerprint == data_fingerprint(tomllib.loads("\n".join(kept)))
    assert with_losses(press).fingerprint != press.fingerprint
