"""Sensitivity on any load case: --job (the no-load cycle), --profile (a planned profile's turn), any press."""
import csv
import json
import math
import tempfile

import numpy as np
import pytest

from calibration.sensitivity import sobol as S
from calibration.sensitivity.report import load_case
from press_model import batch as BT
from press_io.errors import PressDataError
from press_model.profile_motion import COLUMNS, read_profile_motion

from in_process import servo_press  # noqa: E402 (tests/ is on sys.path, conftest.py)

CLI = ["sensitivity"]  # run in this process (tests/in_process.py): the command's outputs are checked, not its process
N = 64  # small: these tests check the plumbing and a large effect, not converged indices
pytestmark = pytest.mark.usefixtures("pyplot_imported")  # fixtures_suitecal.py: the figure workers start with matplotlib


def _st(folder, response, parameter):
    with open(folder / "sobol.csv") as fh:
        return next(float(r["ST"]) for r in csv.DictReader(fh) if r["response"] == response and r["parameter"] == parameter)


def _profile_rows(motion, dt=0.002, dwell_s=0.0, start_deg=0.0):
    """A profile.csv of one turn of ``motion`` from ``start_deg``, sampled every dt s (time from the motion's own t(theta))."""
    th0 = math.radians(start_deg)
    t_end = float(motion.time(np.array(th0 + 2 * math.pi)) - motion.time(np.array(th0)))
    fine = np.linspace(th0, th0 + 2 * math.pi, 200001)
    t_fine = motion.time(fine) - motion.time(np.array(th0))
    t = np.append(np.arange(0.0, t_end, dt), t_end)
    th = np.interp(t, t_fine, fine)
    th[-1] = th0 + 2 * math.pi
    rows = [[ti, math.degrees(x), float(motion.theta_dot(np.array(x))), float(motion.theta_ddot(np.array(x)))] for ti, x in zip(t, th)]
    if dwell_s:
        rows += [[t_end + k * dt, rows[-1][1], 0.0, 0.0] for k in range(1, int(dwell_s / dt))]
    return rows


def _write(path, rows, header=COLUMNS):
    with open(path, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(list(header) + ["motor_torque_Nm"])
        for r in rows:
            w.writerow([repr(float(v)) for v in r] + ["0"])
    return path


@pytest.fixture(scope="module")
def two_cases(reference_sensitivity, tmp_path_factory):
    """The same seed and N under the cushion test and under the no-load cycle: {case: its folder}, the cushion test's
    the suite's `sensitivity --n 64 --seed 5` (conftest.py, read only)."""
    cushion = reference_sensitivity[0]
    provenance = json.loads((cushion / "key_parameters.json").read_text())["provenance"]
    assert (provenance["n"], provenance["seed"]) == (N, 5)
    no_load = tmp_path_factory.mktemp("cases") / "no_load"
    r = servo_press(*CLI, "--job", "no-load", "--n", str(N), "--seed", "5", "--out", str(no_load))
    assert r.returncode == 0, r.stderr
    return {"cushion": cushion, "no_load": no_load}


def test_no_load_job_is_a_valid_load_case(two_cases):
    rec = json.loads((two_cases["no_load"] / "run.json").read_text())
    assert rec["load_case"]["peak_process_force_N"] == 0.0 and rec["load_case"]["motion"] == "[motion] of the job"
    assert "no-load" in rec["job"]
    cushion = json.loads((two_cases["cushion"] / "run.json").read_text())
    assert cushion["load_case"]["peak_process_force_N"] == 5.0e6
    # the same motion: only the load differs
    assert rec["load_case"]["period_s"] == cushion["load_case"]["period_s"]
    md = (two_cases["no_load"] / "paper_comparison.md").read_text()
    assert "does not state the load case" in md and "no-load" in md


def test_balance_weighs_more_without_process_force(two_cases):
    """Without the 5 MN cushion the balance force (psi) is a large part of the slide load: its S_T on Y_RMSE
    must rise well above its cushion-test value, and it must be a key parameter there and not under the cushion."""
    st_no, st_cu = _st(two_cases["no_load"], "Y_RMSE", "psi"), _st(two_cases["cushion"], "Y_RMSE", "psi")
    assert st_no > 0.2 and st_no > 5 * st_cu
    keys_no = json.loads((two_cases["no_load"] / "key_parameters.json").read_text())["key_parameters"]
    assert "psi" in keys_no


def test_profile_motion_reproduces_the_motion_it_was_sampled_from(cushion):
    """A profile sampled (2 ms) from the cushion test's analytic motion gives back its speed and acceleration."""
    _, motion = cushion
    with tempfile.TemporaryDirectory() as tmp:
        tab = read_profile_motion(_write(f"{tmp}/p.csv", _profile_rows(motion, dwell_s=0.5, start_deg=37.0)))
    th = np.radians(np.arange(0.0, 360.0, 1.0))
    assert np.max(np.abs(tab.theta_dot(th) - motion.theta_dot(th))) < 1e-5 * np.max(motion.theta_dot(th))
    # theta_ddot is held constant over each 2 ms sample interval: error ~ jerk * dt
    assert np.max(np.abs(tab.theta_ddot(th) - motion.theta_ddot(th))) < 2e-2 * np.max(np.abs(motion.theta_ddot(th)))
    assert tab.period == pytest.approx(motion.period, rel=1e-9)  # the dwell rows are left out
    assert float(tab.time(np.array(2 * math.pi))) == pytest.approx(motion.period, rel=1e-9)


def test_profile_gives_the_same_torque_as_the_job_motion(ref_model, cushion, tmp_path):
    job, motion = cushion
    tab = read_profile_motion(_write(tmp_path / "p.csv", _profile_rows(motion, dwell_s=0.2)))
    a = BT.motor_torques(BT.build_batch_model(ref_model.press, motion, job.process, pm=ref_model), [{}])[0]
    b = BT.motor_torques(BT.build_batch_model(ref_model.press, tab, job.process, pm=ref_model), [{}])[0]
    assert np.max(np.abs(a - b)) < 1e-3 * np.max(np.abs(a))


def test_cli_profile_run(cushion, tmp_path):
    """A stop-at-top style profile (rest at both ends, a dwell after) runs with the door panel's process force."""
    _, motion = cushion
    rows = _profile_rows(motion, start_deg=308.5)
    rows[0][2] = rows[-1][2] = 0.0  # at rest at both ends of the turn
    rows += [[rows[-1][0] + 0.002 * k, rows[-1][1], 0.0, 0.0] for k in range(1, 500)]  # 1 s dwell at TDC
    path = _write(tmp_path / "profile.csv", rows)
    out = tmp_path / "sens"
    r = servo_press(*CLI, "--job", "door-panel", "--profile", str(path), "--n", str(N), "--out", str(out))
    assert r.returncode == 0, r.stderr
    rec = json.loads((out / "run.json").read_text())
    assert rec["load_case"]["motion"] == str(path) and rec["load_case"]["peak_process_force_N"] == 6.0e6
    assert rec["load_case"]["period_s"] == pytest.approx(motion.period, rel=1e-6)


@pytest.mark.parametrize("edit, field, words", [
    (lambda rows: rows[: len(rows) // 2], "crank_angle_deg", "full crank turn"),
    (lambda rows: rows[:100] + [[rows[99][0] + 0.002 * k, rows[99][1], 0.0, 0.0] for k in range(1, 5)] +
     [[r[0] + 0.008, *r[1:]] for r in rows[100:]], "crank_speed_rad_s", "stands still"),
    (lambda rows: rows[:50] + [[rows[50][0], rows[49][1] - 1.0, *rows[50][2:]]] + rows[51:], "crank_angle_deg", "forward"),
    (lambda rows: [[*r[:2], r[2] * (1 + 0.2 * i / len(rows)), r[3]] for i, r in enumerate(rows)], "crank_speed_rad_s", "periodic"),
    (lambda rows: rows + [[rows[-1][0] + 0.002, rows[-1][1] + 1.0, 1.0, 0.0]], "row", "only the dwell"),
    (lambda rows: [rows[0], rows[0]] + rows[1:], "time_s", "rise"),
])
def test_bad_profiles_are_refused(cushion, tmp_path, edit, field, words):
    _, motion = cushion
    path = _write(tmp_path / "bad.csv", edit(_profile_rows(motion, dt=0.01)))
    with pytest.raises(PressDataError, match=words) as exc:
        read_profile_motion(path)
    assert field in exc.value.field


def test_profile_without_columns_and_cli_error(tmp_path):
    bad = tmp_path / "p.csv"
    bad.write_text("time_s,crank_angle_deg\n0,0\n1,360\n2,720\n")
    with pytest.raises(PressDataError, match="crank_speed_rad_s"):
        read_profile_motion(bad)
    r = servo_press(*CLI, "--profile", str(bad), "--n", "8", "--out", str(tmp_path / "o"))
    assert r.returncode == 2 and "servo-press: error:" in r.stderr and "Traceback" not in r.stderr
    assert not (tmp_path / "o").exists()


def test_job_without_motion_needs_a_profile():
    with pytest.raises(PressDataError, match="--profile"):
        load_case("door-panel")


def test_crank_slider_runs_and_compares_only_matching_names(crank_slider_sensitivity):
    """The suite's `sensitivity --press crank-slider --n 64` (conftest.py: it exited 0; read only)."""
    out = crank_slider_sensitivity[0]
    for f in ("sobol.csv", "key_parameters.json", "sobol_indices.png", "paper_comparison.csv", "paper_comparison.md", "run.json"):
        assert (out / f).is_file(), f
    md = (out / "paper_comparison.md").read_text()
    names = set(S.problem(__import__("press_model.press_data", fromlist=["load_press"]).load_press("crank-slider"))["names"])
    missing = [n for n in ("eta_gear", "psi", "mu_r", "m8", "J_gear", "mu_s") if n not in names]
    assert missing and "no parameter named" in md and all(n in md.split("no parameter named")[1] for n in missing)
    assert "of the paper's own press" in md.splitlines()[0]  # the paper's values labelled as another press's
    with open(out / "paper_comparison.csv") as fh:
        assert {r["parameter"] for r in csv.DictReader(fh)} <= names
