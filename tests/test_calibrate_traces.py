"""`servo-press calibrate --log-format MAP.toml` and `monitor --log-format`: a SYNTHETIC drive log exported as the field
exports it (TwinCAT Scope CSV with torque in % for two motors and an extra channel; NI TDMS) calibrates, through
the CLI, to the same parameters as the plain drive-log CSV of the same samples.

The log: `servo-press experiment` on tests/data/cushion_test_fast.toml (SYNTHETIC, seed 0, truth in its sidecar).
The two motors' torques are the log's torque +- 300 sin(2 pi 2 t) N m (their mean is the log's); the cushion's force
(the log's process_force_N) is one more channel, mapped. Every separator
and decimal mark gives the same drive log as the CSV (tests/test_trace_formats.py), so the CLI runs here take one
Scope variant (tab, decimal comma: TwinCAT's default on a German PC) and TDMS. Without the bootstrap (refits = 0 in
a copy of the fast job) to keep the runs short: the parameters do not depend on it.
"""
from __future__ import annotations

import json
import math
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from calibration.traces.trace_formats import read_trace
from in_process import servo_press
from servo_press.cli import main
from press_model.press_data import load_press
from trace_writers import write_scope_csv, write_tdms

FAST_JOB = Path(__file__).parent / "data" / "cushion_test_fast.toml"
PRESS = load_press()


def _export(plain: Path, d: Path, stem: str) -> tuple[Path, Path]:
    """The log's TwinCAT Scope export and TDMS file (two motors' torques in %, the cushion's force, an extra current channel)."""
    ch = read_trace(plain).channels
    t, a, n, q = (ch[k].values for k in ("time_s", "crank_angle_deg", "motor_speed_rpm", "motor_torque_Nm"))
    e = 300.0 * np.sin(2.0 * math.pi * 2.0 * t)
    rated = PRESS.motor.rated_torque
    chans = [dict(name="fCrankAngle", time_ms=t * 1e3, values=a, unit="°"),
             dict(name="Drive1_ActVelo", time_ms=t * 1e3, values=n, unit="rpm"),
             dict(name="Drive1_ActTorque", time_ms=t * 1e3, values=(q + e) / rated * 100.0, unit="%"),
             dict(name="Drive2_ActTorque", time_ms=t * 1e3, values=(q - e) / rated * 100.0, unit="%"),
             dict(name="Drive1_Current", time_ms=t[::5] * 1e3, values=40.0 + 0.0 * t[::5], unit="A"),
             dict(name="Cushion_ActForce", time_ms=t * 1e3, values=ch["process_force_N"].values, unit="N")]
    scope = d / f"{stem}scope.csv"
    write_scope_csv(scope, "SYNTHETIC drive log (servo-press experiment, seed 0)", chans, "\t", ",")
    tdms = d / f"{stem}log.tdms"
    write_tdms(tdms, "Drive", [dict(name=c["name"], values=c["values"], unit=c["unit"],
                                    dt_s=float(np.median(np.diff(c["time_ms"]))) / 1e3) for c in chans],
               {"description": "SYNTHETIC drive log (servo-press experiment, seed 0)"})
    return scope, tdms


@pytest.fixture(scope="module")
def logs(tmp_path_factory):
    """The plain CSV log, its TwinCAT Scope export and its TDMS file, the channel map and a job without bootstrap;
    and a second recording (noise seed 1) as TDMS, to validate on."""
    d = tmp_path_factory.mktemp("traces")
    job = d / "job.toml"
    text = FAST_JOB.read_text(encoding="utf-8")
    assert "refits = 40 " in text
    job.write_text(text.replace("refits = 40 ", "refits = 0  "), encoding="utf-8")
    plain = d / "log.csv"
    assert main(["experiment", "--job", str(job), "--out", str(plain)]) == 0
    scope, tdms = _export(plain, d, "")
    second = d / "second.csv"
    assert main(["experiment", "--job", str(job), "--seed", "1", "--out", str(second)]) == 0
    _, second_tdms = _export(second, d, "second_")
    cmap = d / "press_map.toml"
    cmap.write_text(f'''press = "{PRESS.name}"
[channels]
crank_angle_deg = {{ name = "fCrankAngle", unit = "deg" }}
motor_speed_rpm = {{ name = "Drive1_ActVelo", unit = "rpm", side = "motor" }}
motor_torque_Nm = [{{ name = "Drive1_ActTorque", unit = "%" }}, {{ name = "Drive2_ActTorque", unit = "%" }}]
process_force_N = {{ name = "Cushion_ActForce", unit = "N" }}
''', encoding="utf-8")
    return {"dir": d, "job": job, "plain": plain, "scope": scope, "tdms": tdms, "map": cmap, "second": second,
            "second_tdms": second_tdms}


def _calibrate(logs, log, out, *extra):
    assert main(["calibrate", "--job", str(logs["job"]), "--log", str(log), *extra, "--out", str(out)]) == 0
    return json.loads((out / "calibrated.json").read_text())


@pytest.fixture(scope="module")
def plain_fit(logs):
    """The plain CSV log calibrated with ``--validate`` on a log half of whose samples are the fitted ones (the plain
    log's first half, then the second recording's second half: the same motion and time base, other noise), in this
    process: (its out folder, calibrated.json, the run's stdout, its stderr). The validation log is read before the fit
    and predicted after it, and changes nothing of the fit: its parameters are the plain log's for the formats'
    comparison too."""
    def rows(path):
        lines = path.read_text(encoding="utf-8").splitlines()
        head = sum(1 for ln in lines if not ln[:1].isdigit())
        return lines[:head], lines[head:]
    head, a = rows(logs["plain"])
    _, b = rows(logs["second"])
    assert len(a) == len(b)
    mixed = logs["dir"] / "half_fitted.csv"
    mixed.write_text("\n".join(head + a[:len(a) // 2] + b[len(a) // 2:]) + "\n", encoding="utf-8")
    out = logs["dir"] / "plain_cal"
    r = servo_press("calibrate", "--job", logs["job"], "--log", logs["plain"], "--validate", mixed, "--out", out)
    assert r.returncode == 0, r.stderr
    return out, json.loads((out / "calibrated.json").read_text()), r.stdout, r.stderr


def test_scope_export_and_tdms_calibrate_to_the_parameters_of_the_plain_csv(logs, plain_fit, tmp_path, capsys):
    ref = plain_fit[1]
    for kind in ("scope", "tdms"):
        validate = ["--validate", str(logs["second_tdms"])] if kind == "scope" else []  # read through the same map
        rec = _calibrate(logs, logs[kind], tmp_path / kind, "--log-format", str(logs["map"]), *validate)
        for name, x in ref["parameters"].items():
            assert rec["parameters"][name] == pytest.approx(x, rel=1e-7), (kind, name)
        assert rec["log"]["synthetic"] and rec["log"]["strokes"] == ref["log"]["strokes"]
        notes = " ".join(rec["log"]["warnings"])
        assert "Averaged 2 torque channels" in notes and "Drive1_Current" in notes  # reported, and the extra channel named
    assert rec is not None and "validation" not in rec
    val = json.loads((tmp_path / "scope" / "calibrated.json").read_text())["validation"]
    assert val["log"] == str(logs["second_tdms"]) and val["synthetic"] and "shared_samples_with_fit" not in val
    err = capsys.readouterr().err
    assert "warning: Ignored 1 channel the map does not name ('Drive1_Current')" in err


@pytest.mark.parametrize("edit, needle", [
    (('"Drive2_ActTorque"', '"Drive9_ActTorque"'), "channels.motor_torque_Nm.1.name = 'Drive9_ActTorque' is not valid: names no channel"),
    (('unit = "deg"', 'unit = "grad"'), "channels.crank_angle_deg.unit = 'grad' is not valid: is not a unit of crank_angle_deg "
                                       "(channel 'fCrankAngle')"),
    (("press = ", 'press = "press 7" #'), "press = 'press 7' is not valid: must be the name of the press calibrated"),
])
def test_bad_maps_are_refused_in_one_line_before_any_fit(logs, tmp_path, capsys, edit, needle):
    bad = tmp_path / "bad_map.toml"
    bad.write_text(logs["map"].read_text(encoding="utf-8").replace(*edit, 1), encoding="utf-8")
    assert main(["calibrate", "--job", str(logs["job"]), "--log", str(logs["scope"]), "--log-format", str(bad),
                 "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert err.startswith("servo-press: error: ") and needle in err and err.count("\n") == 1
    assert not (tmp_path / "o").exists()


def test_torque_unit_beside_a_map_is_refused(logs, tmp_path, capsys):
    assert main(["calibrate", "--job", str(logs["job"]), "--log", str(logs["scope"]), "--log-format", str(logs["map"]),
                 "--torque-unit", "kN*m", "--out", str(tmp_path / "o")]) == 2
    assert "--torque-unit = 'kN*m' is not valid: is for a plain drive-log CSV" in capsys.readouterr().err


def test_monitor_reads_a_folder_of_traces_through_the_map(logs, tmp_path, capsys):
    """A Scope export and a TDMS file in one folder: both found, dated by the trace's own start time, calibrated."""
    folder = tmp_path / "traces"
    folder.mkdir()
    for kind in ("scope", "tdms"):
        (folder / logs[kind].name).write_bytes(logs[kind].read_bytes())
    out = tmp_path / "mon"
    assert main(["monitor", "--job", str(logs["job"]), "--logs", str(folder), "--log-format", str(logs["map"]), "--workers", "1",
                 "--out", str(out)]) == 0
    capsys.readouterr()
    results = {p.name: json.loads(p.read_text()) for p in (out / "logs").glob("*.json") if p.name != "monitor_run.json"}
    assert sorted(results) == ["log.tdms.json", "scope.csv.json"]
    assert all(r["monitor"]["status"] == "ok" for r in results.values())
    assert results["scope.csv.json"]["monitor"]["recorded"] == "2025-03-03T08:00:00.000+00:00"  # the export's start time
    a, b = (results[k]["parameters"] for k in ("log.tdms.json", "scope.csv.json"))
    assert all(a[n] == pytest.approx(b[n], rel=1e-7) for n in a)


def _refused(capsys, out: Path, *argv) -> str:
    assert main(["calibrate", *map(str, argv), "--out", str(out)]) == 2
    err = capsys.readouterr().err
    line = err.strip().splitlines()[-1]
    assert line.startswith("servo-press: error: ") and "Traceback" not in err
    assert not out.exists()
    return line


def test_the_same_recording_given_twice_is_refused_whatever_its_name_or_format(logs, tmp_path, capsys):
    """Fitted twice, one recording would count as two (narrower intervals, nothing learnt): the log twice, a byte
    copy under another name, and its Scope export beside its TDMS file are each refused naming both."""
    copy = tmp_path / "copy_of_log.csv"
    copy.write_bytes(logs["plain"].read_bytes())
    job = logs["job"]
    for a, b, fmt in [(logs["plain"], logs["plain"], []), (logs["plain"], copy, []),
                      (logs["scope"], logs["tdms"], ["--log-format", logs["map"]])]:
        line = _refused(capsys, tmp_path / "o", "--job", job, "--log", a, "--log", b, *fmt)
        assert f"--log = '{b}' is not valid: is the recording of --log {a} (100 % of the samples" in line
        assert "give each recording once" in line


def test_validating_on_the_fitted_samples_in_another_format_or_less_one_row_is_refused(logs, tmp_path, capsys):
    line = _refused(capsys, tmp_path / "o", "--job", logs["job"], "--log", logs["scope"], "--log-format", logs["map"],
                    "--validate", logs["tdms"])
    assert f"--validate = '{logs['tdms']}' is not valid: holds the samples of the fitted log {logs['scope']} (100 % of its" in line
    lines = logs["plain"].read_text(encoding="utf-8").splitlines()
    less = tmp_path / "less_one_row.csv"
    less.write_text("\n".join(lines[:100] + lines[101:]) + "\n", encoding="utf-8")
    line = _refused(capsys, tmp_path / "o", "--job", logs["job"], "--log", logs["plain"], "--validate", less)
    assert f"--validate = '{less}' is not valid: holds the samples of the fitted log {logs['plain']} (100 % of its" in line


def test_a_torque_unit_the_model_check_refuses_is_named_in_the_map_not_as_torque_unit(logs, tmp_path, capsys):
    bad = tmp_path / "kNm_map.toml"
    bad.write_text(logs["map"].read_text(encoding="utf-8").replace('unit = "%"', 'unit = "kN*m"'), encoding="utf-8")
    line = _refused(capsys, tmp_path / "o", "--job", logs["job"], "--log", logs["scope"], "--log-format", bad)
    assert f"{bad}: channels.motor_torque_Nm.0.unit = 'kN*m' is not valid: does not fit {logs['scope']}" in line
    assert "unit = '%' on every torque channel (2) fits" in line and "--torque-unit" not in line


def test_a_validation_log_partly_fitted_says_how_much_beside_its_figures(plain_fit):
    """The validation log: the fitted log's first half, then the second recording's second half (the same motion and
    time base, other noise): half its samples are fitted ones, below the refusal; the share is stated in the
    warnings, the console line, calibrated.json and table4.md instead of 'not fitted' (the run: plain_fit)."""
    out, rec, stdout, stderr = plain_fit
    share = rec["validation"]["shared_samples_with_fit"]
    assert share == pytest.approx(0.5, abs=0.01)
    captured = SimpleNamespace(out=stdout, err=stderr)  # what capsys read when the test ran the command itself
    assert f"warning: the validation log shares {100 * share:.3g} % of its samples with the fitted logs" in captured.err
    assert f"({100 * share:.3g} % of its samples fitted)" in captured.out and "(not fitted)" not in captured.out
    assert "not wholly out of sample" in (out / "table4.md").read_text(encoding="utf-8")
