"""Each input of a command is read from disk once and passed on as an object: `calibrate` reads the press file, the
job, each drive log and the channel map once (the recording correction grids the rows already read, it does not read
the log again), `plan --robust` and `compare` read the press file, the job and calibrated.json once.

The count is of the opens for reading of each file, the lowest level every reader goes through (``Path.read_text``,
``Path.read_bytes`` and ``Path.open`` all open the file with ``Path.open``; ``open()`` is counted as well). The logs
are SYNTHETIC, from `servo-press experiment` on tests/data/cushion_test_fast.toml (least squares, one start), in a copy
of the job without the bootstrap (refits = 0) to keep the run short; the recording estimate stays on, since its
corrected states are where a log was read again.
"""
from __future__ import annotations

import builtins
import collections
import json
import pathlib
from pathlib import Path

import pytest

import planning.compare
import planning.report
from servo_press.cli import main
from press_model.data import __file__ as _data_init
from press_model.press_data import load_press

FAST_JOB = Path(__file__).parent / "data" / "cushion_test_fast.toml"
DATA = Path(_data_init).parent


class _Stop(Exception):
    """Raised in place of the planning once the inputs are read: the reads of the inputs are what is counted."""


def _stop(*args, **kwargs):
    raise _Stop


@pytest.fixture
def reads(monkeypatch):
    """Counter of opens for reading by resolved path, while the test runs."""
    counts: collections.Counter = collections.Counter()
    path_open, builtin_open = pathlib.Path.open, builtins.open

    def reading(mode) -> bool:
        return not any(c in mode for c in "wax+")

    def counted_path_open(self, mode="r", *args, **kwargs):
        if reading(mode):
            counts[self.resolve()] += 1
        return path_open(self, mode, *args, **kwargs)

    def counted_open(file, mode="r", *args, **kwargs):
        if isinstance(file, (str, Path)) and reading(mode):
            counts[Path(file).resolve()] += 1
        return builtin_open(file, mode, *args, **kwargs)

    monkeypatch.setattr(pathlib.Path, "open", counted_path_open)
    monkeypatch.setattr(builtins, "open", counted_open)
    return counts


@pytest.fixture(scope="module")
def inputs(tmp_path_factory):
    """A press file (a copy of the reference press), the lean job, two SYNTHETIC logs and a channel map for the plain CSV."""
    d = tmp_path_factory.mktemp("read_once")
    press = d / "press.toml"
    press.write_text((DATA / "reference_press.toml").read_text(encoding="utf-8"), encoding="utf-8")
    job = d / "job.toml"
    text = FAST_JOB.read_text(encoding="utf-8")
    assert "refits = 40 " in text
    job.write_text(text.replace("refits = 40 ", "refits = 0  "), encoding="utf-8")
    logs = []
    for seed in (0, 1):
        logs.append(d / f"log{seed}.csv")
        assert main(["experiment", "--press", str(press), "--job", str(job), "--seed", str(seed), "--out", str(logs[-1])]) == 0
    cmap = d / "map.toml"
    cmap.write_text(f'press = "{load_press(str(press)).name}"\n[channels]\n'
                    'crank_angle_deg = { name = "crank_angle_deg", unit = "deg" }\n'
                    'motor_speed_rpm = { name = "motor_speed_rpm", unit = "rpm", side = "motor" }\n'
                    'motor_torque_Nm = { name = "motor_torque_Nm", unit = "N*m" }\n'
                    'time_s = { name = "time_s", unit = "s" }\n', encoding="utf-8")
    return {"dir": d, "press": press, "job": job, "log": logs[0], "validate": logs[1], "map": cmap}


def _once(counts, *paths):
    return {p.name: counts[p.resolve()] for p in paths}


def test_calibrate_reads_press_job_and_each_log_once(inputs, reads, tmp_path):
    i = inputs
    out = tmp_path / "cal"
    assert main(["calibrate", "--press", str(i["press"]), "--job", str(i["job"]), "--log", str(i["log"]),
                 "--validate", str(i["validate"]), "--out", str(out)]) == 0
    rec = json.loads((out / "calibrated.json").read_text())
    assert "channel_delay_s" in rec["nuisance"]  # the recording's corrected states were built (where the log was read again)
    assert _once(reads, i["press"], i["job"], i["log"], i["validate"]) == {"press.toml": 1, "job.toml": 1, "log0.csv": 1, "log1.csv": 1}


def test_calibrate_through_a_channel_map_reads_the_map_and_the_log_once(inputs, reads, tmp_path):
    i = inputs
    assert main(["calibrate", "--press", str(i["press"]), "--job", str(i["job"]), "--log", str(i["log"]),
                 "--log-format", str(i["map"]), "--out", str(tmp_path / "cal")]) == 0
    assert _once(reads, i["press"], i["job"], i["log"], i["map"]) == {"press.toml": 1, "job.toml": 1, "log0.csv": 1, "map.toml": 1}


@pytest.fixture(scope="module")
def calibrated(inputs):
    """A calibration result for the planning commands' --params / --calibrated: the theoretical values of the paper's
    six key parameters with a box of +-1 % of each range around them, on this press."""
    press = load_press(str(inputs["press"]))
    values = press.parameter_values()
    names = ("eta_gear", "psi", "mu_r", "m8", "J_gear", "mu_s")
    box = {n: [values[n] - 0.01 * (press.parameters[n].high - press.parameters[n].low),
               values[n] + 0.01 * (press.parameters[n].high - press.parameters[n].low)] for n in names}
    path = inputs["dir"] / "calibrated.json"
    path.write_text(json.dumps({"parameters": {n: values[n] for n in names}, "intervals": box, "joint_region": {"box": box},
                                **press.identity()}), encoding="utf-8")
    return path


def test_plan_reads_press_job_and_calibration_once(inputs, calibrated, reads, monkeypatch, tmp_path):
    job = tmp_path / "door.toml"
    job.write_text((DATA / "door_panel.toml").read_text(encoding="utf-8"), encoding="utf-8")
    monkeypatch.setattr(planning.report, "run_plan", _stop)
    reads.clear()
    with pytest.raises(_Stop):
        main(["plan", "--press", str(inputs["press"]), "--job", str(job), "--params", str(calibrated), "--robust",
              "--out", str(tmp_path / "plan")])
    assert _once(reads, inputs["press"], job, calibrated) == {"press.toml": 1, "door.toml": 1, "calibrated.json": 1}


def test_compare_reads_press_job_and_calibration_once(inputs, calibrated, reads, monkeypatch, tmp_path):
    job = tmp_path / "door.toml"
    job.write_text((DATA / "door_panel.toml").read_text(encoding="utf-8"), encoding="utf-8")
    monkeypatch.setattr(planning.compare, "run_compare", _stop)
    reads.clear()
    with pytest.raises(_Stop):
        main(["compare", "--press", str(inputs["press"]), "--job", str(job), "--calibrated", str(calibrated),
              "--out", str(tmp_path / "compare")])
    assert _once(reads, inputs["press"], job, calibrated) == {"press.toml": 1, "door.toml": 1, "calibrated.json": 1}
