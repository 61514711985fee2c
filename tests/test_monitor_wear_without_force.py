"""servo-press monitor on a SYNTHETIC six-month fleet whose logs carry no force column: gear wear is found.

Without a logged force every interval carries the job force tolerance's share (the cushion's stated 3 % accuracy).
That error is the same cushion's in every log of the press, so it moves every estimate alike and hides no change
between logs; the change test leaves it out. The fleet: one log a month, eta_gear worn from 0.900 to 0.853
(-5.2 %, -0.0094 a month) by the SYNTHETIC truth below, every other parameter at the test job's truth; noise seeds
11..16 (``--seed 11``, one seed a log).
"""
from __future__ import annotations

import csv
import json
from pathlib import Path

import pytest

from servo_press.cli import main

ROOT = Path(__file__).resolve().parents[1]
ETA = [0.900, 0.8906, 0.8812, 0.8718, 0.8624, 0.853]  # the SYNTHETIC truth of logs 0..5, one a month


@pytest.fixture(scope="module")
def monitored(tmp_path_factory) -> Path:
    d = tmp_path_factory.mktemp("wear")
    job = (ROOT / "tests" / "data" / "cushion_test_fast.toml").read_text(encoding="utf-8")
    job = job.replace("[experiment]\n", "[experiment]\nprocess_force_logged = false   # test: no force column in any log\n", 1)
    (d / "job.toml").write_text(job, encoding="utf-8")
    (d / "drift.toml").write_text('[fleet]\nstart = "2025-01-06T08:00:00+00:00"\ninterval_days = 30.0\nseed_step = 1\n\n'
                                  f"[drift]\neta_gear = {{ values = {ETA} }}\n", encoding="utf-8")
    logs, out = d / "logs", d / "monitor"
    assert main(["experiment", "--job", str(d / "job.toml"), "--fleet", str(len(ETA)), "--drift", str(d / "drift.toml"),
                 "--seed", "11", "--out", str(logs)]) == 0
    # in this process (--workers 1): what is checked is the trend and its alarms, which are the same bytes wherever the
    # logs are calibrated (test_monitor.py: a log calibrated in this process and on worker processes give one file); two
    # worker processes would each import Pinocchio, CasADi and numba again for six calibrations
    assert main(["monitor", "--logs", str(logs), "--job", str(d / "job.toml"), "--workers", "1", "--out", str(out)]) == 0
    return out


def test_wear_alarms_once_it_exceeds_the_logs_own_uncertainty_and_never_on_the_first_logs(monitored):
    with open(monitored / "trend.csv", newline="", encoding="utf-8") as fh:
        rows = list(csv.DictReader(fh))
    assert [r["status"] for r in rows] == ["ok"] * len(ETA)
    rec = json.loads((monitored / "alarms.json").read_text(encoding="utf-8"))
    assert rec["baseline"]["log"] == "log_000.csv"
    eta = {a["log"] for a in rec["alarms"] if a["parameter"] == "eta_gear"}
    logs = [f"log_{i:03d}.csv" for i in range(len(ETA))]
    assert "log_001.csv" not in eta  # the first month's 1 % of wear: inside one log's own uncertainty
    assert "log_005.csv" in eta  # 5.2 %: found
    first = min(logs.index(x) for x in eta)
    assert eta == set(logs[first:])  # once found, found on every later log
    # against the truth: where the true wear is well past the two logs' own half-widths (their intervals less the
    # shared share, as the rule reads them) it alarms
    base_half = 0.5 * (rec["baseline"]["change_intervals"]["eta_gear"][1] - rec["baseline"]["change_intervals"]["eta_gear"][0])
    own = {a["log"]: 0.5 * (a["change_interval"][1] - a["change_interval"][0]) for a in rec["alarms"] if a["parameter"] == "eta_gear"}
    for i, log in enumerate(logs[1:], start=1):
        wear = ETA[0] - ETA[i]
        if wear > 2.0 * (base_half + own.get(log, base_half)):
            assert log in eta, (log, wear)
    for a in rec["alarms"]:
        if a["parameter"] == "eta_gear":  # each alarm is what the rule says: disjoint intervals without the shared share
            assert a["change_interval"][1] < a["baseline_change_interval"][0] and a["value"] < a["baseline"]
    # the premise: the logs' whole intervals carry the force tolerance, and over them the 5.2 % would not be found
    last = next(a for a in rec["alarms"] if a["parameter"] == "eta_gear" and a["log"] == "log_005.csv")
    assert last["interval"][1] - last["interval"][0] > 1.5 * (last["change_interval"][1] - last["change_interval"][0])
    assert not (last["interval"][1] < last["baseline_interval"][0])
    # no other parameter moved: nothing else alarms
    assert {a["parameter"] for a in rec["alarms"] if a["kind"] == "parameter_change"} == {"eta_gear"}
