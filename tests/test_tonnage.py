"""The virtual tonnage against the force a SYNTHETIC cushion test logged, the per-stroke store read back through DuckDB,
and the drift chart's false-alarm rate and delay on SYNTHETIC production.

The calibration is made on the experiment's seed-0 log; the tonnage is estimated on seed-1 and seed-2 logs of the same
press and job (data the calibration did not see), from the torque alone: the logged force (the truth plus the cushion
channel's own noise) is read only to judge it.
"""
from __future__ import annotations

import json
import math
from datetime import timezone
from pathlib import Path

import numpy as np
import pytest

from calibration.traces.drive_log import read_drive_log, read_log_rows
from press_model.jobs import load_job
from press_model.model import PressModel
from press_model.press_data import load_press
from in_process import servo_press

from monitoring.drift import Cusum, decision_limit, siegmund_arl
from monitoring.production import eta_curves, production_ratios
from monitoring.rules import load_rules
from monitoring.store import QUERIES, query, write_records
from monitoring.strokes import COLUMNS, SCHEMA_VERSION, job_force, log_records, log_tonnage, motoring_points
from monitoring.tonnage import running_median


@pytest.fixture(scope="module")
def calibration_file(synthetic_log_calibrated):
    """calibrated.json of `calibrate --log` on the seed-0 log, every default (conftest.py, shared with other modules)."""
    return synthetic_log_calibrated[0] / "calibrated.json"


@pytest.fixture(scope="module")
def calibrated(calibration_file):
    return json.loads(calibration_file.read_text(encoding="utf-8"))


@pytest.fixture(scope="module")
def unseen_logs(tmp_path_factory):
    """A folder of the seed-1 and seed-2 SYNTHETIC logs (each with its truth beside it)."""
    folder = tmp_path_factory.mktemp("unseen")
    for seed in (1, 2):
        assert servo_press("experiment", "--seed", seed, "--out", folder / f"log{seed}.csv").returncode == 0
    return folder


@pytest.fixture(scope="module")
def unseen(calibrated, unseen_logs):
    """(press, job, rules, pm, [(log, LogTonnage)]) of the seed-1 and seed-2 SYNTHETIC logs."""
    press, job, rules = load_press(None), load_job("cushion-test"), load_rules()
    pm = PressModel(press)
    box = {k: tuple(v) for k, v in calibrated["joint_region"]["box"].items()}
    out = []
    for seed in (1, 2):
        path = unseen_logs / f"log{seed}.csv"
        log = read_drive_log(path, press.drive.gear_ratio, press.motor.rated_torque)
        out.append((log, log_tonnage(press, job, calibrated["parameters"], box, log, rules, pm=pm)))
    return press, job, rules, pm, out


def _logged(log, lt):
    """(S, n) N: the logged force's bin means of the strokes the tonnage kept, and the channel's noise per bin (N)."""
    forces = np.asarray(log.stroke_force_binned, float)[lt.rows]
    noise = math.sqrt(np.nanmean(np.nanvar(forces, axis=0, ddof=1)))
    return forces, noise


def test_virtual_tonnage_holds_the_logged_force_within_its_interval(unseen):
    for log, lt in unseen[-1]:
        logged, noise = _logged(log, lt)
        est = lt.est
        ok = est.observable[None, :] & np.isfinite(logged)
        # the logged force is itself noisy: the difference is judged against both uncertainties together
        within = np.abs(est.force - logged) <= np.hypot(est.half_width, 1.959963984540054 * noise)
        assert ok.sum() > 0.8 * ok.size
        assert within[ok].mean() >= 0.95, (log.source, within[ok].mean())


def test_virtual_tonnage_peak_within_two_percent_of_the_logged_peak(unseen):
    rules = unseen[2]
    for log, lt in unseen[-1]:
        logged, _ = _logged(log, lt)
        k = rules.tonnage.peak_median_points
        obs = lt.est.observable
        peak = np.nanmax(np.where(obs, running_median(lt.est.force, k), np.nan), axis=1)
        truth = np.nanmax(np.where(obs, running_median(logged, k), np.nan), axis=1)
        assert np.all(np.abs(peak / truth - 1.0) <= 0.02), (log.source, peak / truth - 1.0)


def test_force_not_observable_at_the_dead_centre_and_in_the_contact_transient(unseen):
    press, job, rules, pm, logs = unseen
    lt = logs[0][1]
    bdc = int(np.argmin(np.abs(lt.fmap.theta - pm.assembly.theta_bdc)))
    assert not lt.est.observable[bdc]  # the force barely moves the torque there
    assert np.all(lt.est.half_width[:, bdc] > rules.tonnage.observable_half_width_of_job_force * job_force(job))
    touch = int(np.argmax(lt.fmap.height <= job.process.contact_height))  # the die contact on the way down
    assert not lt.est.observable[touch]  # the ringing after contact is the calibration's peak window: not observable


def test_stroke_records_read_back_through_duckdb(unseen, tmp_path):
    press, job, rules, pm, logs = unseen
    written = []
    for j, (log, lt) in enumerate(logs):
        recs = log_records(lt, pm, log, rules, f"P{j}", None, job=job)
        assert all(set(r) == set(COLUMNS) for r in recs)  # every record holds the declared columns and no other
        assert all(r["peak_observable"] for r in recs)  # the cushion's 300 mm plateau lies where the force is observable
        assert all(r["heaviest_motor"] == 0 and not r["eccentric_load"] for r in recs)  # one torque column: no motor named
        assert write_records(recs, tmp_path, f"log{j}") == len(recs)
        written += recs
    rows = query(tmp_path, "SELECT press, stroke_index, peak_force_N, schema_version FROM read_parquet('{store}/**/*.parquet', "
                           "hive_partitioning = true) ORDER BY press, stroke_index")
    assert [(r[0], r[1]) for r in rows] == sorted((r["press"], r["stroke_index"]) for r in written)
    assert np.allclose([r[2] for r in rows], [r["peak_force_N"] for r in sorted(written, key=lambda r: (r["press"], r["stroke_index"]))])
    assert {r[3] for r in rows} == {SCHEMA_VERSION}
    # the README's queries run as written: no stroke of the cushion test is over 110 %
    assert query(tmp_path, QUERIES["strokes over 110 %"]) == []
    shifts = query(tmp_path, QUERIES["peak force per shift"])
    assert sum(r[2] for r in shifts) == len(written)
    # writing a log again replaces its own file: no stroke twice
    write_records(log_records(logs[0][1], pm, logs[0][0], rules, "P0", None), tmp_path, "log0")
    assert len(query(tmp_path, "SELECT * FROM read_parquet('{store}/**/*.parquet', hive_partitioning = true)")) == len(written)


def test_siegmund_limit_against_its_own_formula():
    h = decision_limit(1000.0, 0.5)
    assert siegmund_arl(h, 0.5, 0.0) == pytest.approx(2000.0, rel=1e-9)
    assert siegmund_arl(h, 0.5, 1.0) < siegmund_arl(h, 0.5, 0.5) < siegmund_arl(h, 0.5, 0.0)


@pytest.fixture(scope="module")
def production(unseen, calibrated):
    """SYNTHETIC production of the seed-1 log's press, motion and job: the efficiency ratio's clean curves at a
    fan of eta_gear values, the motoring mask and the log's channel noise."""
    from press_model.batch import build_batch_model
    from calibration.identification.settings import CalibrationSettings
    from calibration.identification.speed_fit import crank_motion

    press, job, rules, pm, logs = unseen
    log, lt = logs[0]
    truth = json.loads(open(str(log.source).replace(".csv", ".truth.json"), encoding="utf-8").read())["all_parameters_true"]
    bm = build_batch_model(press, crank_motion(log, CalibrationSettings.from_job(job)), job.process, pm=pm)
    eta0 = truth["eta_gear"]
    etas = np.array([0.95, 0.97, 0.985, 1.0]) * eta0
    model, motoring = motoring_points(lt)
    return etas, eta_curves(bm, truth, etas), model, motoring, lt.est.noise_Nm


def test_cusum_false_alarm_rate_on_clean_synthetic_production(production):
    etas, curves, model, motoring, noise = production
    stated = 1000.0  # strokes between false alarms; the shipped 100,000 is measured by scripts/bench_tonnage.py
    r = production_ratios(curves, etas, np.full(302_000, etas[-1]), model, motoring, noise, seed=11)
    chart = Cusum.from_baseline(r[:2000], stated, 0.5)
    alarms = chart.run(r[2000:])
    rate = len(alarms) / 300_000 * stated
    assert 0.5 <= rate <= 2.0, rate


def test_cusum_flags_a_three_percent_step_in_eta_gear_within_the_stated_delay(production):
    etas, curves, model, motoring, noise = production
    base = production_ratios(curves, etas, np.full(2000, etas[-1]), model, motoring, noise, seed=12)
    chart = Cusum.from_baseline(base, 100_000.0, 0.5)
    worn = production_ratios(curves, etas, np.full(2000, etas[1]), model, motoring, noise, seed=13)
    shift = (np.mean(worn) - chart.mean) / chart.sd
    stated = chart.detection_delay(shift)
    delays = []
    for rep in range(200):  # the step at stroke 0 of a fresh chart, again and again
        alarms = chart.run(worn[rep * 10:rep * 10 + 200])
        delays.append(alarms[0] + 1 if alarms.size else 200)
    assert shift > 0.0  # a less efficient gear needs more motoring torque
    assert np.mean(delays) <= stated * 1.5 + 1.0, (np.mean(delays), stated)


def test_strokes_command_fills_a_store_and_replaces_a_log_it_reads_again(calibration_file, unseen_logs, tmp_path):
    store = tmp_path / "store"
    args = ("strokes", "--logs", unseen_logs, "--params", calibration_file, "--press-id", "P7", "--workers", 1, "--out", store)
    first = servo_press(*args)
    assert first.returncode == 0, first.stderr
    count = "SELECT count(*) FROM read_parquet('{store}/**/*.parquet', hive_partitioning = true)"
    n = query(store, count)[0][0]
    assert n >= 4 and "strokes of 2 logs" in first.stdout
    assert servo_press(*args).returncode == 0
    assert query(store, count)[0][0] == n  # each log replaced its own records
    drift = json.loads((store / "_reports" / "P7" / "drift.json").read_text(encoding="utf-8"))
    assert drift["strokes"] == n and "baseline" in drift["note"]  # too few strokes for a chart: said, not charted
    assert (store / "_reports" / "P7" / "trend.png").stat().st_size > 0


def test_strokes_command_refuses_a_folder_it_did_not_make_and_a_bad_press_name(calibration_file, unseen_logs, tmp_path):
    mine = tmp_path / "mine"
    mine.mkdir()
    (mine / "notes.txt").write_text("keep", encoding="utf-8")
    res = servo_press("strokes", "--logs", unseen_logs, "--params", calibration_file, "--press-id", "P7", "--out", mine)
    assert res.returncode == 2 and "--out" in res.stderr and "store.json" in res.stderr
    assert sorted(p.name for p in mine.iterdir()) == ["notes.txt"]
    res = servo_press("strokes", "--logs", unseen_logs, "--params", calibration_file, "--press-id", "a/b", "--out", tmp_path / "s")
    assert res.returncode == 2 and "--press-id" in res.stderr


def test_drift_report_alarms_after_a_shift_in_the_store_and_not_before(tmp_path):
    # SYNTHETIC records (seed 3): 3,000 in-control strokes, then the efficiency ratio 3 sd up (a worn gear)
    from monitoring.run import drift_report

    rules = load_rules()
    rng = np.random.default_rng(3)
    n, shift_at = 4000, 3000
    ratio = rng.normal(1.0, 0.01, n)
    ratio[shift_at:] += 0.03
    t0 = np.datetime64("2026-03-01T06:00:00")
    recs = []
    for i in range(n):
        r = {c: (math.nan if kind == "float" else 0 if kind == "int" else False if kind == "bool" else None if kind == "floats"
                 else "x") for c, kind in COLUMNS.items()}
        when = (t0 + np.timedelta64(int(4.4 * i), "s")).astype(object).replace(tzinfo=timezone.utc)
        r.update(schema_version=SCHEMA_VERSION, press="P9", day=when.date().isoformat(), stroke_index=i, tdc_time=when, source="synthetic",
                 efficiency_ratio=float(ratio[i]), residual_rms_Nm=float(abs(rng.normal(60.0, 5.0))), peak_force_N=5.0e6)
        recs.append(r)
    write_records(recs, tmp_path, "synthetic")
    rep = drift_report(tmp_path, "P9", rules)
    eff = [a["stroke"] for a in rep["alarms"] if a["statistic"] == "efficiency_ratio"]
    assert eff and min(eff) >= shift_at and min(eff) <= shift_at + 20
    assert rep["charts"]["efficiency_ratio"]["alarms"] == len(eff)


def test_eccentric_load_from_each_motors_torque(calibration_file, tmp_path):
    # a SYNTHETIC twin-drive log (seed 4) whose motor 1 carries 60 % of the torque: every stroke names motor 1 at 0.60 and
    # raises EccentricLoad (the reference press states an even load, tolerance 0.03); the plain log raises none
    log = tmp_path / "logs" / "twin.csv"
    assert servo_press("experiment", "--seed", 4, "--effect", "motor1_share=0.6", "--out", log).returncode == 0
    store = tmp_path / "store"
    res = servo_press("strokes", "--logs", log.parent, "--params", calibration_file, "--press-id", "T", "--workers", 1, "--out", store)
    assert res.returncode == 0, res.stderr
    rows = query(store, "SELECT heaviest_motor, heaviest_share, eccentric_load FROM read_parquet('{store}/**/*.parquet', "
                        "hive_partitioning = true)")
    assert rows and all(r[0] == 1 and abs(r[1] - 0.6) < 0.01 and r[2] for r in rows)


SHARES = (0.53, 0.47)  # the twin-drive log's motor shares (twin_drive_log, fixtures_suiteident.py)


def _twin_rows(store):
    return query(store, "SELECT heaviest_motor, heaviest_share, eccentric_load, motor_share, motor_peak_torque_Nm, "
                        "peak_motor_torque_Nm FROM read_parquet('{store}/**/*.parquet', hive_partitioning = true)")


@pytest.mark.parametrize("stated", [None, SHARES])
def test_twin_drive_strokes_record_each_motors_peak_and_share_against_the_press_files_shares(calibration_file, calibrated,
                                                                                               twin_drive_log, stated, tmp_path):
    # the reference press file (an even load, tolerance 0.03): 6 points apart, EccentricLoad on every stroke, through the
    # command; the press with [motor] load_shares = [0.53, 0.47] (a press whose motors are known to share so): none. The
    # stated shares are a new press fingerprint, which the calibration of the reference press is refused on: that case
    # runs in this process on the reference press with only its stated shares replaced
    import dataclasses

    from calibration.traces.drive_log import grid_rows
    from monitoring.store import write_records
    from monitoring.strokes import motor_turns

    store = tmp_path / "store"
    if stated is None:
        res = servo_press("strokes", "--logs", twin_drive_log.parent, "--params", calibration_file, "--press-id", "T",
                          "--workers", 1, "--out", store)
        assert res.returncode == 0, res.stderr
    else:
        ref = load_press(None)
        press = dataclasses.replace(ref, motor=dataclasses.replace(ref.motor, load_shares=stated))
        rows, rules, job = read_log_rows(twin_drive_log), load_rules(), load_job("cushion-test")
        log = grid_rows(rows, press.drive.gear_ratio, press.motor.rated_torque)
        box = {k: tuple(v) for k, v in calibrated["joint_region"]["box"].items()}
        pm = PressModel(press)
        lt = log_tonnage(press, job, calibrated["parameters"], box, log, rules, pm=pm)
        write_records(log_records(lt, pm, log, rules, "T", None, motor_turns(rows, lt.turns), job), store, "twin")
    raw = np.abs(read_log_rows(twin_drive_log).motor_torques)
    rows = _twin_rows(store)
    assert len(rows) == 3
    for heaviest, share, eccentric, shares, peaks, peak in rows:
        assert heaviest == 1 and share == pytest.approx(SHARES[0], abs=0.005) and shares[0] == share
        assert np.allclose(shares, SHARES, atol=0.005) and sum(shares) == pytest.approx(1.0)
        assert eccentric == (stated is None)
        # each motor's peak is that motor's own largest |torque| of the stroke, under the log's largest of either motor
        assert len(peaks) == 2 and peaks[0] > peaks[1] and max(peaks) == peak <= raw.max()


def _edited_log(log: Path, folder: Path, edit) -> Path:
    """A copy of ``log`` in a folder of its own, its header line and data rows passed through ``edit(rows) -> rows``."""
    lines = log.read_text(encoding="utf-8").splitlines()
    at = next(i for i, s in enumerate(lines) if s.startswith("time_s"))
    out = folder / "log.csv"
    folder.mkdir()
    out.write_text("\n".join(lines[:at] + [",".join(r) for r in edit([s.split(",") for s in lines[at:]])]) + "\n", encoding="utf-8")
    return out


@pytest.mark.parametrize("case, field, fix", [
    ("no angle column", "missing crank_angle_deg", "must name the four columns"),
    ("header only", "rows = 0", "at least"),
    ("three motors", "torque columns", "[drive] motors = 2"),
])
def test_strokes_refuses_a_log_it_cannot_cut_in_one_line_naming_the_field(calibration_file, twin_drive_log, tmp_path, case, field, fix):
    edits = {"no angle column": lambda rows: [r[:1] + r[2:] for r in rows],
             "header only": lambda rows: rows[:1],
             "three motors": lambda rows: [r[:5] + (["motor_torque_Nm_3"] if i == 0 else r[4:5]) + r[5:] for i, r in enumerate(rows)]}
    log = _edited_log(twin_drive_log, tmp_path / "logs", edits[case])
    store = tmp_path / "store"
    res = servo_press("strokes", "--logs", log.parent, "--params", calibration_file, "--press-id", "E", "--out", store)
    assert res.returncode == 2 and res.stdout == "", (res.stdout, res.stderr)
    assert len(res.stderr.strip().splitlines()) == 1 and "Traceback" not in res.stderr
    assert field in res.stderr and fix in res.stderr and str(log) in res.stderr
    assert not store.exists()  # the store this run began, with no stroke in it, is not left behind


TWO_SPEED = (0.6, 2.0, 30.0, 200.0, 30.0)  # rad/s slow from 30 to 200 deg, fast elsewhere, 30-degree ramps (SYNTHETIC)


def test_tonnage_and_records_of_a_continuous_two_speed_motion(calibrated, monkeypatch, tmp_path):
    # a SYNTHETIC cushion-test log (seed 31) whose crank runs continuously at two speeds (calibration/synthetic/motions.py),
    # a motion no shipped job has: the estimate holds the logged force, and each record's TDC and BDC times are the
    # motion's own crossings of the press's dead centres
    import calibration.synthetic.experiment as experiment
    from calibration.synthetic.experiment import experiment_truth, write_experiment
    from calibration.synthetic.motions import TwoSpeedMotion
    from monitoring.strokes import peak_seen, peak_zone
    from monitoring.tonnage import Z95

    press, job, rules = load_press(None), load_job("cushion-test"), load_rules()
    motion = TwoSpeedMotion(*TWO_SPEED)
    monkeypatch.setattr(experiment, "make_motion", lambda spec, source: motion)
    path = tmp_path / "two_speed.csv"
    write_experiment(press, job, experiment_truth(press, job, None), 31, path)
    log = read_drive_log(path, press.drive.gear_ratio, press.motor.rated_torque)
    pm = PressModel(press)
    box = {k: tuple(v) for k, v in calibrated["joint_region"]["box"].items()}
    lt = log_tonnage(press, job, calibrated["parameters"], box, log, rules, pm=pm)
    logged, noise = _logged(log, lt)
    est = lt.est
    ok = est.observable[None, :] & np.isfinite(logged)
    assert ok.sum() > 0.8 * ok.size
    assert (np.abs(est.force - logged) <= np.hypot(est.half_width, Z95 * noise))[ok].mean() >= 0.95
    assert peak_seen(peak_zone(lt.fmap, job, rules), est.observable, rules)
    recs = log_records(lt, pm, log, rules, "P", None, job=job)
    assert len(recs) == 3
    for r in recs:
        turn = 2.0 * math.pi * r["stroke_index"]
        assert r["tdc_time_s"] == pytest.approx(motion.time(turn + pm.assembly.theta_tdc), abs=2e-3)
        assert r["bdc_time_s"] == pytest.approx(motion.time(turn + pm.assembly.theta_bdc), abs=2e-3)
        assert r["peak_force_N"] == pytest.approx(job_force(job), rel=0.02) and not r["overload"] and not r["process_low"]


class _Swing:
    """SYNTHETIC pendulum motion theta(t) = c - a cos(w t) between the turning points c -+ a (rad) as a motion of the
    angle: ``sign`` +1 the working swing, -1 the return (speed and acceleration as press_model.motion's motions give)."""

    def __init__(self, c: float, a: float, w: float, sign: int):
        self.c, self.a, self.w, self.sign, self.period = c, a, w, sign, math.pi / w

    def theta_dot(self, theta):
        return self.sign * self.w * np.sqrt(np.clip(self.a ** 2 - (np.asarray(theta) - self.c) ** 2, 0.0, None))

    def theta_ddot(self, theta):
        x = np.asarray(theta) - self.c
        return np.where(np.abs(x) <= self.a, -self.w ** 2 * x, 0.0)


PENDULUM = (50.0, 236.0, 5.0)  # deg, deg, s: turning points A and B (0.41 m above BDC, over the cushion's 0.30 m), cycle


def _pendulum_log(path: Path, press, job, seed: int) -> tuple[float, float, float]:
    """Write a SYNTHETIC twin-drive pendulum log of the cushion test (4.3 cycles at 500 Hz from mid working swing: 4
    complete working swings; the cushion's force on each working swing, none on the returns; the true parameters the
    job's [experiment.truth]; motor 1 carrying SHARES[0] of the torque; white noise of 150 N m on each motor's torque and
    25 kN on the force, seeded); returns (c, a, w)."""
    from calibration.synthetic.experiment import experiment_truth
    from press_model.batch import build_batch_model, motor_torques
    from press_model.forces import NO_PROCESS

    pm = PressModel(press)
    a_deg, b_deg, cycle = PENDULUM
    c, a, w = math.radians(0.5 * (a_deg + b_deg)), math.radians(0.5 * (b_deg - a_deg)), 2.0 * math.pi / cycle
    truth = press.parameter_values() | experiment_truth(press, job, None)
    curves = {}
    for sign, process in ((1, job.process), (-1, NO_PROCESS)):
        bm = build_batch_model(press, _Swing(c, a, w, sign), process, pm=pm)
        curves[sign] = (np.asarray(bm.theta), motor_torques(bm, [truth])[0],
                        np.asarray(process(np.asarray(bm.height), np.asarray(bm.height_dot))))
    rng = np.random.default_rng(seed)
    t = np.arange(0.3 * cycle, 4.6 * cycle, 0.002)
    theta = c - a * np.cos(w * t)
    forward = np.sin(w * t) > 0.0
    grid = curves[1][0]
    torque = np.where(forward, np.interp(theta, grid, curves[1][1]), np.interp(theta, grid, curves[-1][1]))
    force = np.where(forward, np.interp(theta, grid, curves[1][2]), 0.0)
    speed_rpm = a * w * np.sin(w * t) * press.drive.gear_ratio * 60.0 / (2.0 * math.pi)
    lines = ["# SYNTHETIC pendulum drive log (tests/test_tonnage.py), not measured data",
             "time_s,crank_angle_deg,motor_speed_rpm,motor_torque_Nm_1,motor_torque_Nm_2,process_force_N"]
    each = [2.0 * s * torque + rng.normal(0.0, 150.0, t.size) for s in SHARES]  # their mean is the torque per motor
    lines += [f"{x:.4f},{d:.5f},{v:.4f},{q1:.3f},{q2:.3f},{f:.1f}" for x, d, v, q1, q2, f in
              zip(t - t[0], np.degrees(theta), speed_rpm, *each, force + rng.normal(0.0, 2.5e4, t.size))]
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return c, a, w


def test_a_pendulum_log_is_cut_at_its_turning_points_into_working_swings(calibration_file, tmp_path):
    # SYNTHETIC twin-drive pendulum log (seed 41): each complete working swing one record; no TDC (the crank turns back
    # before it), BDC at the swing's own crossing; the force estimated from the torque alone holds the cushion's 5,000 kN;
    # each motor's share of the swing and EccentricLoad against the reference press's even load
    press, job = load_press(None), load_job("cushion-test")
    log = tmp_path / "logs" / "pendulum.csv"
    log.parent.mkdir()
    c, a, w = _pendulum_log(log, press, job, 41)
    store = tmp_path / "store"
    res = servo_press("strokes", "--logs", log.parent, "--params", calibration_file, "--press-id", "S", "--workers", 1, "--out", store)
    assert res.returncode == 0, res.stderr
    rows = query(store, "SELECT stroke_index, tdc_time_s, tdc_angle_deg, tdc_height_m, bdc_time_s, touch_height_m, peak_force_N, "
                        "peak_observable, overload, process_low, observable_points, motor_share, eccentric_load FROM "
                        "read_parquet('{store}/**/*.parquet', "
                        "hive_partitioning = true) ORDER BY stroke_index")
    assert [r[0] for r in rows] == [0, 1, 2, 3]
    pm = PressModel(press)
    start = 0.3 * 2.0 * math.pi / w
    for k, (_, t_tdc, tdc_deg, tdc_h, t_bdc, touch_h, peak, seen, overload, low, observable, shares, eccentric) in enumerate(rows):
        assert t_tdc is None and tdc_deg is None and tdc_h is None  # absent (the store's NULL): said so, not made up
        bdc = (math.acos((c - pm.assembly.theta_bdc) / a) + 2.0 * math.pi * (k + 1)) / w - start  # theta(t) = c - a cos(w t)
        assert t_bdc == pytest.approx(bdc, abs=0.01)
        assert touch_h <= job.process.contact_height + 1e-3 and observable > 100
        assert seen and peak == pytest.approx(job_force(job), rel=0.02) and not overload and not low
        assert np.allclose(shares, SHARES, atol=0.005) and eccentric


def test_the_readme_shows_the_queries_the_store_runs():
    from pathlib import Path

    readme = " ".join((Path(__file__).resolve().parents[1] / "monitoring" / "README.md").read_text(encoding="utf-8").split())
    for name, sql in QUERIES.items():
        assert " ".join(sql.format(store="STORE").split()) in readme, name
