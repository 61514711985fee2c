"""Drive traces in the formats of the field (TwinCAT Scope CSV export, NI TDMS, plain CSV with other names) read
through a channel map: real Scope exports (tests/data/twincat_scope, from the pytcs project, BSD-3) and our own
SYNTHETIC log written in each format, which must give the same drive log as the plain drive-log CSV of the same
samples (an independent path: the drive-log reader parses its own CSV by hand). Bad maps are refused in one line.

The SYNTHETIC log: torque f(theta) = 5000 + 3000 sin(theta) + 1000 cos(2 theta) N m per motor, crank speed
w0 (1 + 0.4 cos(w0 t)) at 11.4 strokes/min, 500 Hz, three turns, no noise (seed-free: nothing random); the two
motors' torques are f +- 200 sin(2 pi 3 t) N m, so their mean is f.
"""
from __future__ import annotations

import gzip
import math
from pathlib import Path

import numpy as np
import pytest

from calibration.traces.channel_map import load_channel_map
from calibration.traces.drive_log import read_drive_log, recorded_time, write_drive_log
from calibration.traces.trace_formats import read_trace
from calibration.traces.trace_log import read_trace_log
from press_io.errors import PressDataError
from press_model.press_data import load_press
from trace_writers import write_plain_csv, write_scope_csv, write_tdms

DATA = Path(__file__).parent / "data" / "twincat_scope"
PRESS = load_press()
G, RATED = PRESS.drive.gear_ratio, PRESS.motor.rated_torque
W0 = 2.0 * math.pi / (60.0 / 11.4)
LABEL = "SYNTHETIC drive log made by tests/test_trace_formats.py (truth: f(theta) in the test, no noise)"
SEPARATORS = ["\t", " ", ":", ";", ","]


def _columns(rate=500.0, turns=3.0):
    t = np.arange(0.0, turns * 2.0 * math.pi / W0, 1.0 / rate)
    th = math.radians(30.0) + W0 * t + 0.4 * np.sin(W0 * t)
    thd = W0 * (1.0 + 0.4 * np.cos(W0 * t))
    return t, np.degrees(th), thd * G * 60.0 / (2.0 * math.pi), 5000.0 + 3000.0 * np.sin(th) + 1000.0 * np.cos(2.0 * th)


@pytest.fixture(scope="module")
def plain(tmp_path_factory):
    """The plain drive-log CSV and the columns as written (rounded), which every other format repeats."""
    path = tmp_path_factory.mktemp("plain") / "log.csv"
    write_drive_log(path, *_columns(), [LABEL])
    ch = read_trace(path).channels
    cols = [ch[k].values for k in ("time_s", "crank_angle_deg", "motor_speed_rpm", "motor_torque_Nm")]
    return path, cols, read_drive_log(path, G, RATED)


def _scope_channels(cols):
    t, a, n, q = cols
    e = 200.0 * np.sin(2.0 * math.pi * 3.0 * t)
    tv = np.arange(0.0, t[-1] * 1000.0, 5.0)
    return [dict(name="fCrankAngle", time_ms=t * 1000.0, values=a, unit="°", comment="crank encoder"),
            dict(name="Drive1_ActVelo", time_ms=t * 1000.0, values=n, unit="rpm"),
            dict(name="Drive1_ActTorque", time_ms=t * 1000.0, values=(q + e) / RATED * 100.0, unit="%"),
            dict(name="Drive2_ActTorque", time_ms=t * 1000.0, values=(q - e) / RATED * 100.0, unit="%"),
            dict(name="DcBusVoltage", time_ms=tv, values=600.0 + 5.0 * np.sin(tv), unit="V")]  # another sample time


MAP = """press = "{press}"
[channels]
crank_angle_deg = {{ name = "fCrankAngle", unit = "deg" }}
motor_speed_rpm = {{ name = "Drive1_ActVelo", unit = "rpm", side = "motor" }}
motor_torque_Nm = [{{ name = "Drive1_ActTorque", unit = "%" }}, {{ name = "Drive2_ActTorque", unit = "%" }}]
"""


def _map(tmp_path, text=None, name="map.toml"):
    path = tmp_path / name
    path.write_text(text if text is not None else MAP.format(press=PRESS.name), encoding="utf-8")
    return path


def _same_log(a, b):
    assert a.strokes == b.strokes and a.synthetic and b.synthetic
    np.testing.assert_allclose(b.torque, a.torque, rtol=0, atol=1e-6)  # N m; % arithmetic rounds at ~1e-8
    np.testing.assert_allclose(b.crank_speed, a.crank_speed, rtol=1e-12)
    np.testing.assert_allclose(b.stroke_torque, a.stroke_torque, rtol=0, atol=1e-6)
    assert b.sample_rate_hz == pytest.approx(a.sample_rate_hz, rel=1e-9)


def _refusal(fn, *args) -> str:
    with pytest.raises(PressDataError) as err:
        fn(*args)
    msg = str(err.value)
    assert "\n" not in msg
    return msg


# --- real TwinCAT Scope exports --------------------------------------------------------------------------------------
def _real(tmp_path, option):
    path = tmp_path / f"tc3_scope_3_4_3145_3-{option}.csv"
    path.write_bytes(gzip.decompress((DATA / f"{path.name}.gz").read_bytes()))
    return path


def test_real_scope_exports_in_every_readable_separator_give_the_same_channels(tmp_path):
    """Colon- and comma-separated (which pytcs refuses) and tab-separated with decimal commas: one recording."""
    traces = {opt: read_trace(_real(tmp_path, opt)) for opt in ("Seperator_2", "Seperator_4", "DecimalMark_,")}
    assert [t.how.split(", ")[1:] for t in traces.values()] == [
        ["colon-separated", "decimal mark '.'"], ["comma-separated", "decimal mark '.'"], ["tab-separated", "decimal mark ','"]]
    first = traces["Seperator_2"]
    assert len(first.channels) == 21 and "test space" in first.channels and "test_special([{äöü!?ß$²}])" in first.channels
    os_ch, real = first.channels["func_OS"], first.channels["var_REAL64"]
    assert np.allclose(np.diff(os_ch.time_s), 0.2e-3) and np.allclose(np.diff(real.time_s), 1e-3)  # own sample times
    assert real.values[:4].tolist() == [0.0, 1.0, 2.0, 3.0] and real.time_s.size == 1000
    assert first.comments[1] == "recorded: 2022-05-02T13:56:24.376+00:00"  # FILETIME 132959733843760000, UTC
    for other in list(traces.values())[1:]:
        assert list(other.channels) == list(first.channels)
        for name, ch in first.channels.items():
            np.testing.assert_array_equal(other.channels[name].values, ch.values, err_msg=name)
            np.testing.assert_array_equal(other.channels[name].time_s, ch.time_s, err_msg=name)


def test_real_space_separated_export_with_spaces_in_channel_names_is_refused_in_one_line(tmp_path):
    msg = _refusal(read_trace, _real(tmp_path, "Seperator_1"))
    assert "line 7" in msg and "channel names hold the separator (space)" in msg and "tab or semicolon" in msg


# --- our SYNTHETIC log in each format ----------------------------------------------------------------------------------
# every separator with either decimal mark, except decimal commas in a comma-separated file (refused, below)
EXPORTS = [(s, d) for s in SEPARATORS for d in ".," if (s, d) != (",", ",")]


@pytest.mark.parametrize("sep, decimal", EXPORTS, ids=[f"{repr(s)[1:-1]}-{d}" for s, d in EXPORTS])
def test_scope_export_of_a_log_gives_the_same_drive_log_as_its_csv(tmp_path, plain, sep, decimal):
    path = tmp_path / "scope.csv"
    write_scope_csv(path, LABEL, _scope_channels(plain[1]), sep, decimal)
    log = read_trace_log(path, _map(tmp_path), PRESS)
    _same_log(plain[2], log)
    assert LABEL in log.label
    assert ("channel fCrankAngle: crank encoder" in log.comments) == (sep != " ")  # a space splits the comment: not read
    notes = " ".join(log.warnings)
    assert "Ignored 1 channel the map does not name ('DcBusVoltage')" in notes
    e = 200.0 * np.sin(2.0 * math.pi * 3.0 * plain[1][0])  # each motor's torque is the mean +- e
    assert "Averaged 2 torque channels ('Drive1_ActTorque', 'Drive2_ActTorque')" in notes
    assert f"differ from their mean by {math.sqrt(np.mean(e ** 2)):.4g} N m RMS" in notes
    assert recorded_time(log.comments, "x")[0] == "2025-03-03T08:00:00.000+00:00"


def test_tdms_of_a_log_gives_the_same_drive_log_as_its_csv(tmp_path, plain):
    chans = [dict(name=c["name"], values=c["values"], unit=c["unit"], dt_s=float(np.median(np.diff(c["time_ms"]))) / 1000.0)
             for c in _scope_channels(plain[1])]
    path = tmp_path / "log.tdms"
    write_tdms(path, "Drive", chans, {"description": LABEL})
    text = MAP.format(press=PRESS.name).replace('"Drive1_ActVelo"', '"Drive/Drive1_ActVelo"')  # either spelling works
    log = read_trace_log(path, _map(tmp_path, text), PRESS)
    _same_log(plain[2], log)
    assert "Ignored 1 channel the map does not name ('Drive/DcBusVoltage')" in " ".join(log.warnings)
    assert recorded_time(log.comments, "x")[0] == "2025-03-03T08:00:00.000+00:00"  # the waveform's start time (UTC)


def test_plain_csv_with_other_names_semicolons_decimal_commas_and_other_units(tmp_path, plain):
    """Time in ms, crank speed in rad/s at the crank, torque in kN m: the map converts each."""
    t, a, n, q = plain[1]
    path = tmp_path / "plc.csv"
    write_plain_csv(path, [LABEL], {"Zeit_ms": t * 1000.0, "Kurbelwinkel": np.radians(a), "Kurbel_rad_s": n / G * 2 * math.pi / 60,
                                    "Moment_kNm": q / 1000.0, "Strom_A": 0 * t}, sep=";", decimal=",")
    text = f'''press = "{PRESS.name}"
[channels]
time_s = {{ name = "Zeit_ms", unit = "ms" }}
crank_angle_deg = {{ name = "Kurbelwinkel", unit = "rad" }}
motor_speed_rpm = {{ name = "Kurbel_rad_s", unit = "rad/s", side = "crank" }}
motor_torque_Nm = {{ name = "Moment_kNm", unit = "kN*m" }}
'''
    log = read_trace_log(path, _map(tmp_path, text), PRESS)
    _same_log(plain[2], log)
    assert "CSV, semicolon-separated, decimal mark ','" in log.warnings[0] and "'Strom_A'" in log.warnings[-1]


def test_channels_with_other_sample_times_are_interpolated_onto_the_crank_angle_times(tmp_path, plain):
    """Torque logged every 1 ms and speed every 4 ms beside a 2 ms angle: linear in time onto the angle's samples.
    The torque curve on the grid then differs from the CSV's by interpolation error only (bounded by f'' h^2 / 8)."""
    t1, *_ = _columns(rate=1000.0)
    t, a, n, q = _columns(rate=500.0)
    _, _, n4, _ = _columns(rate=250.0)
    _, _, _, q1 = _columns(rate=1000.0)
    chans = [dict(name="fCrankAngle", time_ms=t * 1e3, values=a), dict(name="Drive1_ActVelo", time_ms=t[::2] * 1e3, values=n4),
             dict(name="Drive1_ActTorque", time_ms=t1 * 1e3, values=q1 / RATED * 100), dict(name="Drive2_ActTorque", time_ms=t1 * 1e3,
                                                                                             values=q1 / RATED * 100)]
    path = tmp_path / "scope.csv"
    write_scope_csv(path, LABEL, chans, ";", ",")
    log = read_trace_log(path, _map(tmp_path), PRESS)
    assert "Brought 'Drive1_ActVelo' (every 4 ms), 'Drive1_ActTorque' (every 1 ms), 'Drive2_ActTorque' (every 1 ms) onto the " \
           "time base of the crank angle channel 'fCrankAngle' (every 2 ms)" in " ".join(log.warnings)
    # at the 2 ms samples the 1 ms torque is hit exactly (every other sample): only the CSV's rounding to 1e-3 N m differs
    np.testing.assert_allclose(log.torque, plain[2].torque, rtol=0, atol=5e-4 + 1e-9)
    # the 4 ms speed, interpolated linearly in time: |n''| (4 ms)^2 / 8 bounds the error (crank rad/s)
    thdd = W0 * W0 * 0.4 * (W0 + 0.4 * W0)  # bound of |d2/dt2 theta_dot| for this motion, rad/s^3
    assert np.max(np.abs(log.crank_speed - plain[2].crank_speed)) <= thdd * 0.004 ** 2 / 8 + 1e-9


def test_comma_separated_scope_export_with_decimal_commas_is_refused_naming_the_line(tmp_path, plain):
    path = tmp_path / "scope.csv"
    write_scope_csv(path, LABEL, _scope_channels(plain[1]), ",", ",")
    msg = _refusal(read_trace_log, path, _map(tmp_path), PRESS)
    assert "line 25" in msg and "decimal comma in a comma-separated file" in msg


# --- bad maps ------------------------------------------------------------------------------------------------------
@pytest.fixture
def scope(tmp_path, plain):
    path = tmp_path / "scope.csv"
    write_scope_csv(path, LABEL, _scope_channels(plain[1]), "\t", ",")
    return path


def test_a_channel_the_trace_does_not_hold_is_refused_naming_it(tmp_path, scope):
    text = MAP.format(press=PRESS.name).replace('"Drive2_ActTorque"', '"Drive3_ActTorque"')
    msg = _refusal(read_trace_log, scope, _map(tmp_path, text), PRESS)
    assert msg.startswith(f"{tmp_path / 'map.toml'}: channels.motor_torque_Nm.1.name = 'Drive3_ActTorque' is not valid: names no "
                          f"channel of {scope}") and "'Drive2_ActTorque'" in msg


def test_an_unknown_unit_is_refused_naming_the_channel(tmp_path, scope):
    text = MAP.format(press=PRESS.name).replace('name = "Drive1_ActTorque", unit = "%"', 'name = "Drive1_ActTorque", unit = "Nm"')
    msg = _refusal(load_channel_map, _map(tmp_path, text))
    assert "channels.motor_torque_Nm.0.unit = 'Nm' is not valid: is not a unit of motor_torque_Nm (channel 'Drive1_ActTorque')" in msg
    assert "'N*m', 'kN*m', '%'" in msg


def test_a_speed_without_its_side_is_refused_naming_the_channel(tmp_path):
    msg = _refusal(load_channel_map, _map(tmp_path, MAP.format(press=PRESS.name).replace(', side = "motor"', "")))
    assert "channels.motor_speed_rpm.side" in msg and "'Drive1_ActVelo'" in msg and "'motor'" in msg


def test_a_map_for_another_press_is_refused(tmp_path, scope):
    msg = _refusal(read_trace_log, scope, _map(tmp_path, MAP.format(press="press 7, line 2")), PRESS)
    assert "press = 'press 7, line 2' is not valid: must be the name of the press calibrated" in msg
    one_motor = load_press("crank-slider")
    msg = _refusal(read_trace_log, scope, _map(tmp_path, MAP.format(press=one_motor.name)), one_motor)
    assert "channels.motor_torque_Nm.1.name = 'Drive2_ActTorque' is not valid: is torque channel 2 of a press with 1 motor" in msg


def test_a_misspelled_map_key_and_a_channel_in_two_roles_are_refused(tmp_path):
    msg = _refusal(load_channel_map, _map(tmp_path, MAP.format(press=PRESS.name).replace("crank_angle_deg", "crank_angel_deg")))
    assert "crank_angle_deg" in msg
    msg = _refusal(load_channel_map, _map(tmp_path, MAP.format(press=PRESS.name).replace('"Drive1_ActVelo"', '"fCrankAngle"')))
    assert "channels.motor_speed_rpm.name = 'fCrankAngle'" in msg and "each channel has one role" in msg


def test_a_csv_without_a_mapped_time_column_is_refused_naming_the_channel(tmp_path, plain):
    text = MAP.format(press=PRESS.name).replace("fCrankAngle", "crank_angle_deg").replace("Drive1_ActVelo", "motor_speed_rpm") \
        .replace('[{ name = "Drive1_ActTorque", unit = "%" }, { name = "Drive2_ActTorque", unit = "%" }]',
                 '{ name = "motor_torque_Nm", unit = "N*m" }')
    msg = _refusal(read_trace_log, plain[0], _map(tmp_path, text), PRESS)
    assert "channels.crank_angle_deg.name = 'crank_angle_deg'" in msg and "no time of its own" in msg and "time_s = " in msg
    log = read_trace_log(plain[0], _map(tmp_path, text + 'time_s = { name = "time_s", unit = "s" }\n'), PRESS)
    _same_log(plain[2], log)  # the plain drive-log CSV itself through a map


def test_a_cell_that_is_no_number_is_refused_naming_line_and_column(tmp_path, plain):
    path = tmp_path / "scope.csv"
    write_scope_csv(path, LABEL, _scope_channels(plain[1]), ";", ",")
    lines = path.read_text(encoding="utf-8").splitlines()
    cells = lines[29].split(";")
    cells[5] = "12,5kN"
    lines[29] = ";".join(cells)
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    msg = _refusal(read_trace, path)
    assert "line 30, column 6 = '12,5kN' is not valid: must be a number (decimal mark ',' detected from the file)" in msg


# --- hostile files: one line naming the file, the field, the value and the fix ----------------------------------------
@pytest.mark.parametrize("ticks", ["9999999999999999999", "2650467744000000000", "-5"])
def test_a_scope_start_time_beyond_the_year_9999_or_negative_is_refused_in_one_line(tmp_path, scope, ticks):
    lines = scope.read_text(encoding="utf-8").splitlines()
    assert lines[2].startswith("Starttime of export\t")
    cells = lines[2].split("\t")
    cells[1] = ticks
    lines[2] = "\t".join(cells)
    scope.write_text("\n".join(lines) + "\n", encoding="utf-8")
    msg = _refusal(read_trace, scope)
    assert msg.startswith(f"{scope}: line 3, Starttime of export = '{ticks}' is not valid: must be a Windows FILETIME")
    assert "the year 9999" in msg and "export again" in msg


def _tdms_channels(plain):
    return [dict(name=c["name"], values=c["values"], unit=c["unit"], dt_s=float(np.median(np.diff(c["time_ms"]))) / 1000.0)
            for c in _scope_channels(plain[1])]


def _tdms_with(path, chans, edit):
    """A TDMS file of ``chans`` in group 'Drive' whose channel objects ``edit(name, properties)`` changes."""
    from nptdms import ChannelObject, GroupObject, RootObject, TdmsWriter

    objs = [RootObject(properties={"description": LABEL}), GroupObject("Drive")]
    for c in chans:
        props = {"unit_string": c.get("unit", "")}
        if "dt_s" in c:
            props.update(wf_increment=float(c["dt_s"]), wf_start_time=np.datetime64("2025-03-03T08:00:00.000"))
        edit(c["name"], props)
        objs.append(ChannelObject("Drive", c["name"], np.asarray(c["values"]), properties=props))
    with TdmsWriter(str(path)) as w:
        w.write_segment(objs)
    return path


@pytest.mark.parametrize("prop, value", [("wf_increment", "0,002"), ("wf_start_time", "3. März 2025"), ("wf_increment", 0.0)])
def test_tdms_waveform_timing_that_is_text_is_refused_naming_the_channel_and_property(tmp_path, plain, prop, value):
    def edit(name, props):
        if name == "Drive1_ActVelo":
            props[prop] = value
    path = _tdms_with(tmp_path / "log.tdms", _tdms_channels(plain), edit)
    msg = _refusal(read_trace_log, path, _map(tmp_path), PRESS)
    assert msg.startswith(f"{path}: Drive/Drive1_ActVelo: {prop} = {value!r} is not valid: must be a ")
    other = _tdms_with(tmp_path / "other.tdms", _tdms_channels(plain),
                       lambda n, p: p.__setitem__(prop, value) if n == "DcBusVoltage" else None)
    assert read_trace_log(other, _map(tmp_path), PRESS).strokes == plain[2].strokes  # an unmapped channel's timing is not read


def test_tdms_channels_of_text_in_several_groups_or_of_time_stamps_are_named_as_such(tmp_path, plain):
    from nptdms import ChannelObject, GroupObject, RootObject, TdmsWriter

    path = tmp_path / "log.tdms"
    objs = [RootObject(), GroupObject("Drive"), GroupObject("Spare")]
    for c in _tdms_channels(plain):
        objs.append(ChannelObject("Drive", c["name"], np.asarray(c["values"]), properties={"wf_increment": c["dt_s"]}))
    objs += [ChannelObject("Drive", "Status", np.array(["run"] * 10)),
             ChannelObject("Drive", "Stamp", np.array(["2025-03-03T08:00"] * 10, dtype="datetime64[us]")),
             ChannelObject("Spare", "Drive2_ActTorque", np.zeros(10))]
    with TdmsWriter(str(path)) as w:
        w.write_segment(objs)
    base = MAP.format(press=PRESS.name)
    msg = _refusal(read_trace_log, path, _map(tmp_path, base), PRESS)
    assert "channels.motor_torque_Nm.1.name = 'Drive2_ActTorque' is not valid: is ambiguous" in msg
    assert "'Drive/Drive2_ActTorque', 'Spare/Drive2_ActTorque'" in msg and "'group/channel'" in msg
    fixed = base.replace('"Drive2_ActTorque"', '"Drive/Drive2_ActTorque"')
    msg = _refusal(read_trace_log, path, _map(tmp_path, fixed.replace('"Drive1_ActVelo"', '"Status"')), PRESS)
    assert "channels.motor_speed_rpm.name = 'Status' is not valid: names the channel 'Drive/Status'" in msg and "holds text" in msg
    msg = _refusal(read_trace_log, path, _map(tmp_path, fixed.replace('"Drive1_ActVelo"', '"Stamp"')), PRESS)
    assert "names the channel 'Drive/Stamp'" in msg and "holds time stamps" in msg


def test_a_tdms_file_cut_off_says_so_in_one_warning_and_npTDMS_prints_nothing(tmp_path, plain, capfd):
    """A recording cut inside its last segment: npTDMS logs '[nptdms.reader WARNING] ...' to the terminal itself; the
    reader keeps those lines as one note of the log, and a channel the cut left short is refused naming it."""
    full = tmp_path / "full.tdms"
    write_tdms(full, "Drive", _tdms_channels(plain), {"description": LABEL})
    data = full.read_bytes()
    cut = tmp_path / "cut.tdms"
    cut.write_bytes(data[:int(0.9 * len(data))])
    trace = read_trace(cut)
    assert len(trace.notes) == 1 and "npTDMS reported" in trace.notes[0] and "less data than expected" in trace.notes[0]
    msg = _refusal(read_trace_log, cut, _map(tmp_path), PRESS)
    assert "is short in" in msg and "npTDMS reported" in msg
    out, err = capfd.readouterr()
    assert "nptdms" not in (out + err).lower()


def test_a_short_torque_channel_is_named_with_its_length_against_the_crank_angles(tmp_path, plain):
    chans = _scope_channels(plain[1])
    chans[3] = dict(chans[3], time_ms=chans[3]["time_ms"][:2000], values=chans[3]["values"][:2000])
    path = tmp_path / "scope.csv"
    write_scope_csv(path, LABEL, chans, "\t", ",")
    msg = _refusal(read_trace_log, path, _map(tmp_path), PRESS)
    n = plain[1][0].size
    assert msg.startswith(f"{tmp_path / 'map.toml'}: channels.motor_torque_Nm.1.name = 'Drive2_ActTorque' is not valid: is short")
    assert "holds 2000 samples over 0-3.998 s" in msg and f"'fCrankAngle' {n} over" in msg


def test_two_motors_torques_that_cancel_are_named_as_cancelling_with_the_signs_in_the_map(tmp_path, scope):
    text = MAP.format(press=PRESS.name).replace('{ name = "Drive2_ActTorque", unit = "%" }',
                                                '{ name = "Drive2_ActTorque", unit = "%", sign = -1 }')
    msg = _refusal(read_trace_log, scope, _map(tmp_path, text), PRESS)
    assert msg.startswith(f"{tmp_path / 'map.toml'}: channels.motor_torque_Nm = ['Drive1_ActTorque', 'Drive2_ActTorque'] is not "
                          "valid: cancel in") and "check each motor's sign in the map" in msg and "'Drive2_ActTorque' -1" in msg
    both = text.replace('{ name = "Drive1_ActTorque", unit = "%" }', '{ name = "Drive1_ActTorque", unit = "%", sign = -1 }')
    log = read_trace_log(scope, _map(tmp_path, both), PRESS)  # both turned: no cancelling (the model check names the sign)
    assert np.allclose(log.torque, -read_trace_log(scope, _map(tmp_path), PRESS).torque)


@pytest.mark.parametrize("edit, field, now, fits", [
    (('unit = "%" }', 'unit = "N*m" }'), "channels.motor_torque_Nm.0.unit", "'N*m'", "unit = '%' on every torque channel (2) fits"),
    (('side = "motor"', 'side = "crank"'), "channels.motor_speed_rpm.side", "'crank'", "channels.motor_speed_rpm.side = 'motor' fits"),
    (('unit = "rpm"', 'unit = "rad/s"'), "channels.motor_speed_rpm.unit", "'rad/s'", "channels.motor_speed_rpm.unit = 'rpm' fits"),
    (('unit = "deg"', 'unit = "rad"'), "channels.crank_angle_deg.unit", "'rad'", "channels.crank_angle_deg.unit = 'deg' fits"),
    (('side = "motor"', 'side = "motor", sign = -1'), "channels.motor_speed_rpm.sign", "-1", "channels.motor_speed_rpm.sign = 1 fits"),
])
def test_a_wrong_unit_side_or_sign_in_the_map_is_named_in_the_map_not_blamed_on_the_log(tmp_path, scope, edit, field, now, fits):
    msg = _refusal(read_trace_log, scope, _map(tmp_path, MAP.format(press=PRESS.name).replace(*edit)), PRESS)
    assert msg.startswith(f"{tmp_path / 'map.toml'}: {field} = {now} is not valid: does not fit {scope}")
    assert fits in msg and "--torque-unit" not in msg and "torque_unit" not in msg


def test_a_wrong_time_unit_in_the_map_is_named_in_the_map(tmp_path, plain):
    t, a, n, q = plain[1]
    path = tmp_path / "plc.csv"
    write_plain_csv(path, [LABEL], {"Zeit_ms": t * 1000.0, "W": a, "N": n, "M": q}, sep=";", decimal=",")
    text = (f'press = "{PRESS.name}"\n[channels]\ntime_s = {{ name = "Zeit_ms", unit = "s" }}\n'
            'crank_angle_deg = { name = "W", unit = "deg" }\nmotor_speed_rpm = { name = "N", unit = "rpm", side = "motor" }\n'
            'motor_torque_Nm = { name = "M", unit = "N*m" }\n')
    msg = _refusal(read_trace_log, path, _map(tmp_path, text), PRESS)
    assert msg.startswith(f"{tmp_path / 'map.toml'}: channels.time_s.unit = 's' is not valid: does not fit {path}")
    assert "channels.time_s.unit = 'ms' fits" in msg
    _same_log(plain[2], read_trace_log(path, _map(tmp_path, text.replace('unit = "s"', 'unit = "ms"')), PRESS))


def test_an_empty_map_is_answered_with_the_channel_map_format(tmp_path):
    msg = _refusal(load_channel_map, _map(tmp_path, "\n# nothing yet\n"))
    assert "a channel map names the press" in msg and "'Drive traces' in calibration/README.md" in msg
    assert "press file" not in msg.replace("the press file's name", "") and "reference_press.toml" not in msg


def test_the_model_check_of_a_mapped_log_names_the_maps_sign_or_unit(tmp_path, scope):
    """check_against_model on a log read through a map: measured = -1 x predicted names the map's torque sign, 1000 x
    the map's torque unit (never --torque-unit, refused beside a map). The log's own torque stands in for the model's."""
    from calibration.traces.drive_log import check_against_model

    log = read_trace_log(scope, _map(tmp_path), PRESS)
    assert check_against_model(log, log.torque) == pytest.approx(1.0)
    msg = _refusal(check_against_model, log, -log.torque)
    assert msg.startswith(f"{tmp_path / 'map.toml'}: channels.motor_torque_Nm.0.sign = 1 is not valid: does not fit {scope}")
    assert "sign = -1 on every torque channel (2) fits" in msg
    msg = _refusal(check_against_model, log, log.torque / 135.0)  # as if the % were N m: 100 / rated torque 13500 N m
    assert "channels.motor_torque_Nm.0.unit = '%' is not valid" in msg and "unit = 'N*m' on every torque channel (2) fits" in msg
    assert "--torque-unit" not in msg
