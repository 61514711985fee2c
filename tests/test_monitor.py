"""servo-press monitor: a SYNTHETIC fleet with a known drift, calibrated on local processes, on a real Dask
LocalCluster (through --scheduler) and with a worker killed mid-run; the rules on numbers of their own. The local run
and the --scheduler runs share the module's one LocalCluster of two worker processes (local_run says how).

The fleet (made once for the module, with the cheap test job): three dated logs whose eta_gear truth moves
by 0.001 (log 1: far inside the combined 95 % uncertainty of two logs, about +/-0.016) and by 0.042 (log 2:
well outside it), plus a log dated between logs 1 and 2 that covers less than a crank turn and must fail
without stopping the others, and a copy of log 2 with a disturbance on the torque channel (a sensor fault)
that must be flagged as a poor fit.
"""
from __future__ import annotations

import contextlib
import csv
import json
import math
import os
import shutil
import signal
import threading
import time
from pathlib import Path

import psutil
import pytest

from calibration.fleet import cluster as fleet_cluster
from calibration.traces.drive_log import leading_comments, recorded_time
from calibration.fleet.cluster import Workers, find_logs, local_cluster, result_path, run_fleet
from calibration.fleet.monitor import Baseline, MonitorRules, assess, change_intervals, overlaps, poor_fit_rule
from servo_press.cli import main

ROOT = Path(__file__).resolve().parents[1]
JOB = str(ROOT / "tests" / "data" / "cushion_test_fast.toml")
ETA = [0.842, 0.841, 0.800]  # eta_gear truth of logs 0..2 (the job's [experiment.truth] is 0.842)
OUTPUTS = ("trend.csv", "alarms.json", "trend.png", "report.md")


@pytest.fixture(scope="module")
def fleet(tmp_path_factory) -> Path:
    d = tmp_path_factory.mktemp("fleet")
    drift = d.parent / "drift.toml"
    drift.write_text('[fleet]\nstart = "2025-01-06T08:00:00+00:00"\ninterval_days = 7.0\nseed_step = 1\n\n'
                     f"[drift]\neta_gear = {{ values = {ETA} }}\n", encoding="utf-8")
    assert main(["experiment", "--job", JOB, "--fleet", str(len(ETA)), "--drift", str(drift), "--seed", "3", "--out", str(d)]) == 0
    lines = (d / "log_001.csv").read_text(encoding="utf-8").splitlines()
    head = [ln for ln in lines if ln.startswith("#") and "recorded:" not in ln]
    data_at = len([ln for ln in lines if ln.startswith("#")])
    bad = ["# recorded: 2025-01-16T08:00:00+00:00", *head, *lines[data_at:data_at + 200]]  # 200 rows: a fraction of a turn
    (d / "broken.csv").write_text("\n".join(bad) + "\n", encoding="utf-8")
    # a sensor fault three days after log 2: a 7 Hz, 3 kN m disturbance on the torque channel, which no parameter explains
    lines = (d / "log_002.csv").read_text(encoding="utf-8").splitlines()
    head = ["# recorded: 2025-01-23T08:00:00+00:00"] + [ln for ln in lines if ln.startswith("#") and "recorded:" not in ln]
    rows = [ln.split(",") for ln in lines[len(head):]]
    body = [",".join(r[:3] + [f"{float(r[3]) + 3000.0 * math.sin(2 * math.pi * 7.0 * float(r[0])):.3f}"] + r[4:]) for r in rows[1:]]
    (d / "sensor_fault.csv").write_text("\n".join([*head, ",".join(rows[0]), *body]) + "\n", encoding="utf-8")
    return d


@pytest.fixture(scope="module")
def cluster():
    from multiprocessing import resource_tracker

    from dask.distributed import Client

    # multiprocessing's resource tracker, started with the first process spawned and kept while this one lives, is not
    # the cluster's: started before the snapshot (a local run started it before this fixture did)
    resource_tracker.ensure_running()
    before = {p.pid for p in psutil.Process().children(recursive=True)}
    # LocalCluster(n_workers=2, threads_per_worker=1, processes=True), bound to 127.0.0.1, no dashboard
    with local_cluster(2) as c, Client(c) as client:
        assert c.scheduler_address.startswith("tcp://127.0.0.1:")
        yield c, client
    deadline = time.monotonic() + 20
    while time.monotonic() < deadline:
        left = [p for p in psutil.Process().children(recursive=True) if p.pid not in before and p.is_running()
                and p.status() != psutil.STATUS_ZOMBIE]
        if not left:
            break
        time.sleep(0.2)
    assert not left, f"the Dask cluster left processes behind: {[p.pid for p in left]}"


@pytest.fixture(scope="module")
def local_run(fleet, cluster, tmp_path_factory) -> Path:
    """`monitor --workers 2`'s folder: the command's own path to local worker processes (run_tasks maps the logs on
    the cluster its local_cluster(2) gives, through a Client of its own, and closes that client), on the module's
    cluster, which the same local_cluster(2) made: one cluster of worker processes for the module, not two (a second
    one cost ~6.5 s of CPU, two interpreters importing Dask and the calibration stack, and the kernels loaded again).
    The scheduler and killed-worker tests then calibrate on the same, warm, worker processes."""
    c, _ = cluster

    @contextlib.contextmanager
    def the_modules_cluster(workers):
        assert workers == 2  # what --workers 2 asks for with five logs to calibrate
        yield c

    out = tmp_path_factory.mktemp("mon_local")
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(fleet_cluster, "local_cluster", the_modules_cluster)
        assert main(["monitor", "--logs", str(fleet), "--job", JOB, "--workers", "2", "--out", str(out)]) == 0
    return out


def _trend(out: Path) -> list[dict]:
    with open(out / "trend.csv", newline="", encoding="utf-8") as fh:
        return list(csv.DictReader(fh))


def _alarms(out: Path) -> dict:
    return json.loads((out / "alarms.json").read_text(encoding="utf-8"))


def test_local_parallel_run_finds_the_known_drift(local_run):
    rows = _trend(local_run)
    assert [r["log"] for r in rows] == ["log_000.csv", "log_001.csv", "broken.csv", "log_002.csv", "sensor_fault.csv"]  # by recorded date
    cols = list(rows[0])
    assert cols[:5] == ["log", "recorded", "eta_gear", "eta_gear_low", "eta_gear_high"]
    assert {"rmse_before_Nm", "rmse_after_Nm", "mu_r_low", "J_gear_high"} <= set(cols)
    ok = [r for r in rows if r["status"] == "ok"]
    assert len(ok) == 4
    # the calibrated eta_gear follows the truth's steps (model bias cancels in the differences)
    est = [float(r["eta_gear"]) for r in ok[:3]]
    steps_true = [b - a for a, b in zip(ETA, ETA[1:])]
    steps_est = [b - a for a, b in zip(est, est[1:])]
    assert abs(steps_est[1] - steps_true[1]) < 0.25 * abs(steps_true[1])
    assert abs(steps_est[0]) < 0.01

    rec = _alarms(local_run)
    assert rec["baseline"]["log"] == "log_000.csv"
    eta = [a for a in rec["alarms"] if a["parameter"] == "eta_gear"]
    assert [a["log"] for a in eta] == ["log_002.csv"]
    assert not [a for a in rec["alarms"] if a["log"] == "log_001.csv"]  # inside the combined uncertainty: silent
    for a in eta:  # each alarm is what the rule says: disjoint intervals
        assert a["interval"][1] < a["baseline_interval"][0]
        assert a["value"] < a["baseline"] and set(a) >= {"parameter", "log", "value", "baseline", "interval", "reason"}
    assert [f["log"] for f in rec["failed"]] == ["broken.csv"]
    poor = [a for a in rec["alarms"] if a["kind"] == "poor_fit"]
    assert [a["log"] for a in poor] == ["sensor_fault.csv"] and [r["poor_fit"] for r in ok] == ["no", "no", "no", "yes"]
    assert poor[0]["value"] > 3 * poor[0]["baseline"]  # far above the fleet's median RMSE
    assert not [a for a in rec["alarms"] if a["log"] == "sensor_fault.csv" and a["kind"] != "poor_fit"]
    assert "360" in rec["failed"][0]["error"] and "crank_angle_deg" in rec["failed"][0]["error"]
    assert rec["synthetic_logs"] == ["log_000.csv", "log_001.csv", "log_002.csv", "sensor_fault.csv"]
    assert rec["press_fingerprint"].startswith("sha256:")
    report = (local_run / "report.md").read_text(encoding="utf-8")
    assert "SYNTHETIC" in report and "broken.csv" in report and "eta_gear" in report
    assert (local_run / "trend.png").stat().st_size > 10_000


def test_rerun_reuses_results_and_is_byte_identical(fleet, local_run, capsys):
    before = {n: (local_run / n).read_bytes() for n in OUTPUTS}
    logs = {p.name: p.read_bytes() for p in (local_run / "logs").iterdir()}
    capsys.readouterr()
    assert main(["monitor", "--logs", str(fleet), "--job", JOB, "--workers", "2", "--out", str(local_run)]) == 0
    assert "(0 now, 5 reused)" in capsys.readouterr().out  # the broken log's refusal is reused too
    assert {n: (local_run / n).read_bytes() for n in OUTPUTS} == before
    assert {p.name: p.read_bytes() for p in (local_run / "logs").iterdir()} == logs


def test_interrupted_run_finishes_what_is_missing(fleet, local_run, tmp_path, capsys):
    out = tmp_path / "mon"
    shutil.copytree(local_run / "logs", out / "logs")
    result_path(out, "log_002.csv").unlink()  # as if the run had stopped before this log came back
    capsys.readouterr()
    assert main(["monitor", "--logs", str(fleet), "--job", JOB, "--workers", "1", "--out", str(out)]) == 0
    assert "(1 now, 4 reused)" in capsys.readouterr().out
    for n in ("trend.csv", "alarms.json", "report.md"):
        assert (out / n).read_bytes() == (local_run / n).read_bytes()


# the logs the cluster calibrates: in test_scheduler_run_on_a_local_cluster_gives_the_same_files and in
# test_killed_worker_task_is_rescheduled (each test starts with the other's logs' results from the local run)
SCHEDULER_RUN_LOGS = ("log_000.csv", "sensor_fault.csv")
KILLED_RUN_LOGS = ("log_001.csv", "broken.csv", "log_002.csv")


def test_scheduler_run_on_a_local_cluster_gives_the_same_files(fleet, local_run, cluster, tmp_path, capsys):
    """A run through --scheduler on the cluster's worker processes gives the local run's files. The results of the logs
    the killed-worker test calibrates on the same cluster are there already (copied, reused as after an interruption):
    this run calibrates the first log and the sensor-fault copy there, that one the other three, so between the two
    tests every log is calibrated on the cluster once and compared with the local run, for three fewer calibrations."""
    c, _ = cluster
    out = tmp_path / "mon"
    assert sorted(SCHEDULER_RUN_LOGS + KILLED_RUN_LOGS) == sorted(f.log for f in find_logs(str(fleet)))  # every log once
    shutil.copytree(local_run / "logs", out / "logs")
    for log in SCHEDULER_RUN_LOGS:
        result_path(out, log).unlink()
    capsys.readouterr()
    assert main(["monitor", "--logs", str(fleet), "--job", JOB, "--scheduler", c.scheduler_address, "--out", str(out)]) == 0
    assert "(2 now, 3 reused)" in capsys.readouterr().out
    for n in ("trend.csv", "alarms.json", "report.md"):
        assert (out / n).read_bytes() == (local_run / n).read_bytes(), n
    for p in (local_run / "logs").iterdir():
        assert (out / "logs" / p.name).read_bytes() == p.read_bytes(), p.name


def test_killed_worker_task_is_rescheduled(fleet, local_run, cluster, tmp_path):
    """A worker killed while it calibrates a log: its task runs again and every result is the undisturbed run's. The
    first and the last log's results are there already (copied, reused as after an interruption): the kill meets a busy
    cluster with tasks running and one waiting just the same with three logs left (two calibrations and the broken log's
    refusal) as with five, for two fewer calibrations."""
    c, client = cluster
    out = tmp_path / "mon"
    shutil.copytree(local_run / "logs", out / "logs")
    for log in KILLED_RUN_LOGS:
        result_path(out, log).unlink()
    pids = client.run(os.getpid)
    result = {}
    t = threading.Thread(target=lambda: result.update(run=run_fleet(str(fleet), None, JOB, out,
                                                                    workers=Workers(scheduler=c.scheduler_address),
                                                                    echo=lambda m: None)))
    t.start()
    killed = None
    deadline = time.monotonic() + 120
    while killed is None and time.monotonic() < deadline and t.is_alive():
        busy = [w for w, keys in client.processing().items() if keys and w in pids]
        if busy:
            time.sleep(1.0)  # let the task get going on that worker (imports, reading the log)
            killed = pids[busy[0]]
            os.kill(killed, signal.SIGKILL)
            break
        time.sleep(0.05)
    t.join(timeout=300)
    assert killed is not None, "no task was seen running on a worker"
    assert not t.is_alive()
    assert killed not in client.run(os.getpid).values()  # the nanny replaced the dead worker process
    # the replaced process too runs without the dashboard's profiler and with the slower housekeeping local_cluster sets
    # (its nanny keeps the config it was started with), as the scheduler does
    every = client.run(lambda dask_worker: {k: pc.callback_time for k, pc in dask_worker.periodic_callbacks.items()})
    assert len(every) == 2 and all("profile" not in pcs and pcs["tick"] >= 1000 and pcs["memory_monitor"] >= 1000
                                   for pcs in every.values()), every
    assert c.scheduler.periodic_callbacks["tick"].callback_time >= 1000
    entries = result["run"]["entries"]
    assert [e["status"] for e in entries] == ["ok", "ok", "failed", "ok", "ok"]
    for p in (local_run / "logs").iterdir():  # complete, and the same results as the undisturbed run
        assert (out / "logs" / p.name).read_bytes() == p.read_bytes(), p.name


def test_baseline_file_and_another_press_refused(fleet, local_run, tmp_path, capsys):
    base = result_path(local_run, "log_000.csv")  # a per-log result is a calibrated.json
    out = tmp_path / "mon"
    shutil.copytree(local_run / "logs", out / "logs")
    assert main(["monitor", "--logs", str(fleet), "--job", JOB, "--workers", "1", "--baseline", str(base), "--out", str(out)]) == 0
    rec = _alarms(out)
    assert rec["baseline"]["source"] == str(base) and rec["baseline"]["log"] is None
    # the same numbers as the first log, which is now judged too (and overlaps itself): the same alarms
    assert [(a["log"], a["parameter"]) for a in rec["alarms"]] == [(a["log"], a["parameter"]) for a in _alarms(local_run)["alarms"]]
    other = json.loads(base.read_text(encoding="utf-8"))
    other["press_fingerprint"] = "sha256:0123456789abcdef"
    (tmp_path / "other.json").write_text(json.dumps(other), encoding="utf-8")
    capsys.readouterr()
    assert main(["monitor", "--logs", str(fleet), "--job", JOB, "--baseline", str(tmp_path / "other.json"), "--out", str(tmp_path / "x")]) == 2
    err = capsys.readouterr().err
    assert err.startswith("servo-press: error:") and "press_fingerprint" in err and "another press" in err
    assert not (tmp_path / "x").exists()


# --- the rules and the ordering on numbers of their own ---------------------------------------------------
def _entry(log, value, lo, hi, rmse=100.0):
    return {"log": log, "recorded": None, "status": "ok",
            "record": {"parameters": {"p": value}, "intervals": {"p": [lo, hi]}, "metrics": {"rmse_after_Nm": rmse}}}


RULES = MonitorRules("test", mad_factor=5.0, relative_floor=0.5, min_logs=3)


def test_alarm_only_when_intervals_stop_overlapping():
    assert overlaps((0, 1), (1, 2)) and overlaps((0, 3), (1, 2)) and not overlaps((0, 1), (1.0001, 2))
    entries = [_entry("a", 1.0, 0.9, 1.1), _entry("b", 0.85, 0.75, 0.95), _entry("c", 0.79, 0.7, 0.8999), _entry("d", 1.25, 1.1001, 1.4)]
    v = assess(entries, RULES)
    assert v["baseline"].log == "a"
    assert [(a["log"], a["kind"]) for a in v["alarms"]] == [("c", "parameter_change"), ("d", "parameter_change")]
    assert "fell" in v["alarms"][0]["reason"] and "rose" in v["alarms"][1]["reason"]
    base = Baseline("file", None, {"p": 0.8}, {"p": (0.78, 0.82)}, {"p": (0.78, 0.82)})
    assert [a["log"] for a in assess(entries, RULES, base)["alarms"]] == ["a", "d"]


def _widened(log, value, own, shared_sd, q=1.959964):
    """An entry whose interval is its own half-width ``own`` widened in quadrature by a shared sd, as calibrated.json does."""
    h = math.hypot(own, q * shared_sd)
    e = _entry(log, value, value - h, value + h)
    e["record"]["interval_widening"] = {"process_force_sd": {"p": shared_sd}, "level_quantile": q}
    return e


def test_the_uncertainty_every_log_shares_cancels_in_a_change():
    # own half-width 0.01, the job force tolerance's share 0.02 (at q): whole intervals +/-0.0224 about the value
    base, near, far = _widened("a", 0.90, 0.01, 0.02 / 1.959964), _widened("b", 0.885, 0.01, 0.02 / 1.959964), \
        _widened("c", 0.87, 0.01, 0.02 / 1.959964)
    assert change_intervals(far["record"])["p"] == pytest.approx((0.86, 0.88), abs=1e-12)  # the widening undone exactly
    assert overlaps(tuple(far["record"]["intervals"]["p"]), tuple(base["record"]["intervals"]["p"]))  # whole intervals overlap
    v = assess([base, near, far], RULES)
    assert [a["log"] for a in v["alarms"]] == ["c"]  # 0.885 +/- 0.01 still meets 0.90 +/- 0.01; 0.87 does not
    a = v["alarms"][0]
    assert a["change_interval"] == pytest.approx([0.86, 0.88]) and a["baseline_change_interval"] == pytest.approx([0.89, 0.91])
    assert "force tolerance" in a["reason"]
    # an asymmetric interval keeps its asymmetry; a share larger than a side leaves that side at the value
    e = _entry("d", 1.0, 0.95, 1.02)
    e["record"]["interval_widening"] = {"process_force_sd": {"p": 0.03}, "level_quantile": 1.0}
    lo, hi = change_intervals(e["record"])["p"]
    assert lo == pytest.approx(1.0 - math.sqrt(0.05 ** 2 - 0.03 ** 2)) and hi == pytest.approx(1.0)
    # without a shared share (a log with the force column, or a record written before) the intervals are the primary ones
    assert change_intervals(_entry("e", 1.0, 0.9, 1.1)["record"]) == {"p": (0.9, 1.1)}


def test_poor_fit_rule_is_robust_and_needs_enough_logs():
    rmses = [100.0, 102.0, 98.0, 101.0, 99.0, 400.0]
    rule = poor_fit_rule(rmses, RULES)
    assert rule.median_Nm == pytest.approx(100.5) and rule.threshold_Nm == pytest.approx(150.75)  # the floor: 0.5 x median
    entries = [_entry(f"l{i}", 1.0, 0.9, 1.1, r) for i, r in enumerate(rmses)]
    v = assess(entries, RULES)
    assert [a["log"] for a in v["alarms"] if a["kind"] == "poor_fit"] == ["l5"]
    spread = poor_fit_rule([100.0, 140.0, 60.0, 120.0, 80.0], RULES)  # MAD 20 -> 5 x 1.4826 x 20 = 148.3 above the median
    assert spread.threshold_Nm == pytest.approx(100.0 + 5 * 1.4826 * 20.0)
    assert poor_fit_rule([100.0, 900.0], RULES).threshold_Nm == float("inf")
    # a poorly fitting first log is never the baseline
    bad_first = [_entry("x", 2.0, 1.9, 2.1, 900.0)] + entries[:5]
    assert assess(bad_first, RULES)["baseline"].log == "l0"


def test_logs_ordered_by_recorded_date_then_name(tmp_path):
    body = "time_s,crank_angle_deg,motor_speed_rpm,motor_torque_Nm\n"
    (tmp_path / "a.csv").write_text("# recorded: 2025-03-01T00:00:00+02:00\n" + body)
    (tmp_path / "b.csv").write_text("# recorded: 2025-02-28T23:00:00Z\n" + body)  # 1 h after a.csv in UTC (a.csv is 22:00Z)
    (tmp_path / "c.csv").write_text("# recorded: 2025-02-01\n" + body)
    (tmp_path / "d.csv").write_text(body)
    (tmp_path / "e.csv").write_text("# recorded: last tuesday\n" + body)
    logs = find_logs(str(tmp_path))
    assert [f.log for f in logs] == ["c.csv", "a.csv", "b.csv", "d.csv", "e.csv"]
    assert logs[-1].error is not None and "ISO-8601" in logs[-1].error
    assert recorded_time(leading_comments(tmp_path / "c.csv"), "c")[1].isoformat() == "2025-02-01T00:00:00+00:00"
    with pytest.raises(Exception, match="once"):
        recorded_time(["recorded: 2025-01-01", "recorded: 2025-01-02"], "x")


def test_bad_fleet_and_monitor_inputs_are_one_line_errors(tmp_path, capsys):
    # a drift that leaves eta_gear's range [0.7, 0.99] by log 37 is refused before any file is written
    assert main(["experiment", "--fleet", "60", "--out", str(tmp_path / "f")]) == 2
    err = capsys.readouterr().err
    assert err.startswith("servo-press: error:") and "log_036.csv" in err and "eta_gear" in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "f").exists()
    (tmp_path / "empty").mkdir()
    assert main(["monitor", "--logs", str(tmp_path / "empty"), "--out", str(tmp_path / "m")]) == 2
    err = capsys.readouterr().err
    assert "--logs" in err and "*.csv" in err and not (tmp_path / "m").exists()
