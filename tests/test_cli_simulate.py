"""servo-press simulate: columns, summary and figure, and parameter overrides."""
import csv
import json
import numpy as np
import pytest

from in_process import servo_press  # noqa: E402 (tests/ is on sys.path, conftest.py)

pytestmark = pytest.mark.usefixtures("pyplot_imported")  # fixtures_suitecal.py: the figure workers start with matplotlib

COLUMNS = ("time_s,crank_angle_deg,crank_speed_rad_s,crank_accel_rad_s2,slide_height_m,slide_velocity_m_s,motor_torque_Nm,"
           "motor_speed_rpm,reaction_O_N,reaction_A_N,reaction_B_N,reaction_C_N,reaction_D_N,reaction_E_N,reaction_F1_N,reaction_F2_N,"
           "reaction_G_N,guide_normal_N").split(",")


def run(*args):
    return servo_press(*args)  # in this process: the command's outputs are checked, not its process


def read(out):
    with open(out / "cycle.csv") as fh:
        rows = list(csv.reader(fh))
    return rows[0], np.array(rows[1:], dtype=float), json.loads((out / "summary.json").read_text())


def test_simulate_cushion_test(tmp_path):
    r = run("simulate", "--motion", "cushion-test", "--load", "cushion", "--out", str(tmp_path))
    assert r.returncode == 0, r.stderr
    header, data, summary = read(tmp_path)
    assert header == COLUMNS
    assert data.shape == (360, len(COLUMNS))
    assert np.allclose(data[:, 1], np.arange(360))
    assert data[-1, 0] < 60 / 11.4 and data[1, 0] > 0
    assert (tmp_path / "cycle.png").stat().st_size > 10_000
    t = data[:, 6]
    assert summary["peak_motor_torque_Nm"] == pytest.approx(np.max(np.abs(t)), rel=1e-8)
    assert 10_000 < summary["rms_motor_torque_Nm"] < 13_000  # press_reference.md: RMS about 10-13 kN m
    assert set(summary["parameters"]) >= {"J_gear", "eta_gear", "m8", "psi", "mu_r", "Ls41"}
    assert summary["versions"]["pin"].startswith("4.")
    # motor speed = crank speed x gear ratio, in rpm; the limits block against the press file's [motor] (per motor)
    assert np.allclose(data[:, 7], data[:, 2] * 32.0 * 60 / (2 * np.pi), rtol=1e-9)
    lim = summary["limits"]
    assert lim["peak_torque_ratio"] == pytest.approx(np.max(np.abs(t)) / 25_000, rel=1e-8)
    dt = np.radians(1.0) / data[:, 2]  # the time each grid angle stands for (Eq. 24 on the crank grid)
    assert lim["rms_torque_ratio"] == pytest.approx(np.sqrt(np.sum(t**2 * dt) / np.sum(dt)) / 13_500, rel=1e-6)
    assert lim["top_motor_speed_rpm"] == pytest.approx(np.max(data[:, 7]), rel=1e-9) and lim["max_speed_rpm"] == 1000
    assert lim["within_limits"] is True and lim["broken"] == [] and "WARNING" not in r.stderr


def test_params_override_changes_torque(tmp_path):
    base, heavy = tmp_path / "a", tmp_path / "b"
    assert run("simulate", "--motion", "constant", "--spm", "8", "--load", "none", "--out", str(base)).returncode == 0
    r = run("simulate", "--motion", "constant", "--spm", "8", "--load", "none", "--params", '{"eta_gear": 0.8}', "--out", str(heavy))
    assert r.returncode == 0, r.stderr
    _, a, sa = read(base)
    _, b, sb = read(heavy)
    assert sb["parameters"]["eta_gear"] == 0.8 and sb["overrides"] == {"eta_gear": 0.8}
    motoring = a[:, 6] > 0
    # while the motors drive, torque scales with 1/eta; kinematics do not change
    assert np.allclose(b[motoring, 6], a[motoring, 6] * 0.917 / 0.8, rtol=1e-6)
    assert np.allclose(a[:, 4], b[:, 4])


def test_bad_params_give_one_clear_error(tmp_path):
    r = run("simulate", "--params", '{"m8": -5}', "--out", str(tmp_path / "x"))
    assert r.returncode == 2
    assert "m8" in r.stderr and "-5" in r.stderr and "Traceback" not in r.stderr
    assert not (tmp_path / "x" / "cycle.csv").exists()


def test_playback_through_forward_dynamics(tmp_path):
    r = run("simulate", "--motion", "constant", "--spm", "11.4", "--load", "none", "--playback", "--out", str(tmp_path))
    assert r.returncode == 0, r.stderr
    pb = json.loads((tmp_path / "summary.json").read_text())["playback"]
    assert pb["max_loop_gap_m"] < 1e-6
    assert abs(pb["final_crank_angle_error_deg"]) < 0.2
    with open(tmp_path / "playback.csv") as fh:
        assert next(csv.reader(fh))[:2] == ["time_s", "crank_angle_deg"]
