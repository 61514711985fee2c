"""Bad drive logs (``servo-press calibrate --log``): the reader :func:`calibration.traces.drive_log.read_drive_log`.

The logs of the command-line cases are lines of one SYNTHETIC log written by ``servo-press experiment`` (seed 0),
edited. The cases that the reader repairs (NaN rows, rows out of order, torque in kN m with ``--torque-unit kN*m``)
run a calibration with the fastest method and must say what they repaired: what the reader decides before any fit, so
the calibration is the cheapest that still runs through (fixtures_suitecal.py's eta_gear_only_job: eta_gear alone and
none held back, no bootstrap, no recording estimate, one start; settings the reader does not read); logs that disagree with the model
(sign, unit, a crank that does not turn) are refused before fitting. Property-based fuzzing of a small valid log
(rows deleted, duplicated or swapped, cells made NaN, empty or garbage, torque scaled, time jittered): the reader
returns a log whose grid torque lies within the range of its samples, or raises a PressDataError.
"""
from __future__ import annotations

import math
import re

import numpy as np
import pytest
from hypothesis import event, given, settings, strategies as st

from calibration.traces.drive_log import COLUMNS, read_drive_log
from press_io.errors import PressDataError
from press_model.press_data import load_press
from test_drive_log import G, RATED, make_log
from bad_input_helpers import FIXED, cli, servo_press, refused, write_log, with_cell, calibrated, flipped


def test_log_not_found(capsys, work):
    refused(cli(capsys, "calibrate", "--log", work.root / "nolog.csv", "--out", work.out),
            "nolog.csv", "must be an existing drive-log CSV file")
    work.unchanged()


def test_log_empty(capsys, work):
    path = write_log(work, [])
    refused(cli(capsys, "calibrate", "--log", path, "--out", work.out),
            "<file> = 'empty'", "must hold the header line 'time_s, crank_angle_deg, motor_speed_rpm, motor_torque_Nm'")
    work.unchanged()


def test_log_wrong_header_subprocess(work, log_lines):
    lines, h = log_lines
    path = write_log(work, lines[:h] + ["time, angle, speed, torque"] + lines[h + 1:])
    refused(servo_press("calibrate", "--log", path, "--out", work.out),
            f"header (line {h + 1}) = 'time, angle, speed, torque'", "missing time_s, crank_angle_deg",
            "unknown 'time', 'angle'", "torque per motor in N m")
    work.unchanged()


def test_log_nan_rows_are_dropped_with_a_warning(capsys, work, log_lines, eta_gear_only_job):
    lines, h = log_lines
    edited = list(lines)
    bad = [h + 101, h + 102, h + 2001, h + 3001]  # 0-based indices of data lines
    for i in bad[:3]:
        edited[i] = with_cell(edited[i], 3, "nan")
    edited[bad[3]] = with_cell(edited[bad[3]], 2, "")
    path = write_log(work, edited)
    result = cli(capsys, "calibrate", "--log", path, "--job", eta_gear_only_job, "--method", "least-squares", "--out", work.out)
    rec = calibrated(result, work.out)
    warning = (f"warning: Dropped 4 rows with an empty, NaN or infinite cell (line {', '.join(str(i + 1) for i in bad)}); "
               "the crank angles they held are treated as gaps.")
    assert warning in result[2]
    assert warning.removeprefix("warning: ") in rec["log"]["warnings"]


def test_log_torque_in_kilonewton_metres_is_refused(capsys, work, log_lines):
    lines, h = log_lines
    path = write_log(work, lines[:h + 1] + [with_cell(s, 3, f"{float(s.split(',')[3]) / 1e3:.6f}") for s in lines[h + 1:]])
    refused(cli(capsys, "calibrate", "--log", path, "--out", work.out),
            "motor_torque_Nm = 'max |torque|", "looks like kN m", "--torque-unit kN*m")
    work.unchanged()


def test_log_torque_in_kilonewton_metres_is_read_with_the_unit_given(capsys, work, log_lines, eta_gear_only_job):
    lines, h = log_lines
    path = write_log(work, lines[:h + 1] + [with_cell(s, 3, f"{float(s.split(',')[3]) / 1e3:.6f}") for s in lines[h + 1:]])
    original = write_log(work, lines, "original.csv")
    press = load_press()
    a = read_drive_log(original, press.drive.gear_ratio, press.motor.rated_torque)
    b = read_drive_log(path, press.drive.gear_ratio, press.motor.rated_torque, torque_unit="kN*m")
    np.testing.assert_allclose(b.torque, a.torque, rtol=1e-12, atol=1e-9)  # N m: the same log, in the other unit
    calibrated(cli(capsys, "calibrate", "--log", path, "--job", eta_gear_only_job, "--torque-unit", "kN*m", "--method", "least-squares", "--out", work.out), work.out)


def test_log_single_partial_stroke(capsys, work, log_lines):
    lines, h = log_lines
    path = write_log(work, lines[:h + 1 + 1500])  # 3 s of a 5.3 s stroke
    refused(cli(capsys, "calibrate", "--log", path, "--out", work.out),
            "crank_angle_deg = '", "the log covers only", "calibration needs at least one full turn (360 deg)")
    work.unchanged()


def test_log_duplicated_time_with_different_values(capsys, work, log_lines):
    lines, h = log_lines
    edited = list(lines)
    i = h + 1001
    edited[i + 1] = with_cell(edited[i + 1], 0, edited[i].split(",")[0])
    path = write_log(work, edited)
    refused(cli(capsys, "calibrate", "--log", path, "--out", work.out),
            f"lines {i + 1} and {i + 2} = 'time_s = {float(edited[i].split(',')[0])!r} twice'",
            "two rows with the same time must be identical", "remove the wrong row")
    work.unchanged()


def test_log_rows_out_of_time_order_are_sorted_with_a_warning(capsys, work, log_lines, eta_gear_only_job):
    lines, h = log_lines
    edited = list(lines)
    for i in (h + 1001, h + 5001):
        edited[i], edited[i + 1] = edited[i + 1], edited[i]
    path = write_log(work, edited)
    result = cli(capsys, "calibrate", "--log", path, "--job", eta_gear_only_job, "--method", "least-squares", "--out", work.out)
    rec = calibrated(result, work.out)
    warning = "Sorted the rows by time_s (2 were out of order); sorted, the crank angle turns forward."
    assert f"warning: {warning}" in result[2] and warning in rec["log"]["warnings"]


def test_log_gap_leaving_crank_angles_without_data(capsys, work, log_lines):
    lines, h = log_lines
    kept = [s for s in lines[h + 1:] if not 100.0 <= float(s.split(",")[1]) <= 110.0]  # the same gap in every stroke
    path = write_log(work, lines[:h + 1] + kept)
    refused(cli(capsys, "calibrate", "--log", path, "--out", work.out),
            "crank_angle_deg = 'no data at 100-110 deg'", "fall inside gaps in time in every turn")
    work.unchanged()


def test_log_speed_column_in_crank_rpm(capsys, work, log_lines):
    lines, h = log_lines
    path = write_log(work, lines[:h + 1] + [with_cell(s, 2, f"{float(s.split(',')[2]) / 32.0:.4f}") for s in lines[h + 1:]])
    refused(cli(capsys, "calibrate", "--log", path, "--out", work.out),
            "motor_speed_rpm = 'crank angle rate / (speed / gear_ratio) = 32", "holds crank rpm instead of motor rpm")
    work.unchanged()


def test_log_cell_that_is_not_a_number(capsys, work, log_lines):
    lines, h = log_lines
    edited = list(lines)
    edited[h + 11] = with_cell(edited[h + 11], 3, "1,234.5")
    path = write_log(work, edited)
    refused(cli(capsys, "calibrate", "--log", path, "--out", work.out),
            f"line {h + 12} = ", f"must hold {len(lines[h].split(','))} comma-separated cells", "use '.' as the decimal point")
    work.unchanged()


def test_log_torque_sign_flipped(capsys, work, log_lines):
    lines, h = log_lines
    path = write_log(work, flipped(lines, h, -1.0))
    refused(cli(capsys, "calibrate", "--log", path, "--out", work.out), "motor_torque_Nm = 'measured / predicted torque = -",
            "opposite sign to the model's", "multiply the torque column by -1")
    work.unchanged()


def test_log_in_newton_metres_read_as_kilonewton_metres(capsys, work, log_lines):
    path = write_log(work, log_lines[0])
    refused(cli(capsys, "calibrate", "--log", path, "--torque-unit", "kN*m", "--out", work.out),
            "measured / predicted torque = 9", "must lie in [0.33, 3]", "drop --torque-unit kN*m")
    work.unchanged()


def test_log_torque_zero_in_every_row(capsys, work, log_lines):
    lines, h = log_lines
    path = write_log(work, flipped(lines, h, 0.0))
    line = refused(cli(capsys, "calibrate", "--log", path, "--out", work.out), "motor_torque_Nm = 0.0", "is 0 in every row")
    assert "kN" not in line
    work.unchanged()


def test_log_crank_that_does_not_turn(capsys, work, log_lines):
    lines, h = log_lines
    still = lines[:h + 1] + [with_cell(with_cell(s, 1, "12.5"), 2, "0.0") for s in lines[h + 1:]]
    path = write_log(work, still)
    refused(cli(capsys, "calibrate", "--log", path, "--out", work.out), "motor_speed_rpm = 0.0", "turning crank")
    work.unchanged()


@pytest.mark.parametrize("sep, name", [(";", "semicolon"), ("\t", "tab")])
def test_log_with_another_separator(capsys, work, log_lines, sep, name):
    lines, h = log_lines
    comma = sep == ";"  # the European export: ';' between cells and ',' in numbers
    body = [s.replace(",", sep).replace(".", "," if comma else ".") for s in lines[h:]]
    path = write_log(work, lines[:h] + body)
    refused(cli(capsys, "calibrate", "--log", path, "--out", work.out),
            f"is {name}-separated{' with decimal commas' if comma else ';'}", "export it as CSV with ','")
    work.unchanged()


def test_log_with_extra_columns_is_read_with_a_warning(capsys, work, log_lines, eta_gear_only_job):
    lines, h = log_lines
    extra = [lines[h] + ",motor_current_A,bus_voltage_V"] + [s + ",412.5,620.0" for s in lines[h + 1:]]
    path = write_log(work, lines[:h] + extra)
    result = cli(capsys, "calibrate", "--log", path, "--job", eta_gear_only_job, "--method", "least-squares", "--out", work.out)
    rec = calibrated(result, work.out)
    warning = "Ignored 2 extra columns ('motor_current_A', 'bus_voltage_V'); calibration reads time_s, crank_angle_deg"
    assert f"warning: {warning}" in result[2] and any(w.startswith(warning) for w in rec["log"]["warnings"])
    assert "\r" not in result[2]  # stderr is not a terminal here: no progress bar redraws, one line per phase
    assert re.search(r"peak error [+-]\d+ -> [+-]\d+ N m", result[1]) and "-0 N m" not in result[1]
    assert rec["press_fingerprint"] == load_press().fingerprint


_LOG = make_log(turns=2.3, rate=100.0)  # N m per motor, ~1,200 rows over 2.3 turns
_LOG_ROWS = np.column_stack([_LOG[c] for c in COLUMNS])
_N = len(_LOG_ROWS)
_CELLS = tuple(tuple(repr(float(x)) for x in row) for row in _LOG_ROWS)  # the unmutated cells' text, made once for all examples
_GARBAGE = st.sampled_from(["nan", "", "inf", "-inf", "NaN", "1e400", "x", "1,5", "0x10", " ", "1e-400", "--1"])


_LOG_EDITS = st.one_of(
    st.tuples(st.just("delete"), st.integers(0, _N - 1), st.integers(1, 400)),
    st.tuples(st.just("duplicate"), st.integers(0, _N - 1), st.integers(1, 5)),
    st.tuples(st.just("swap"), st.integers(0, _N - 1), st.integers(0, _N - 1)),
    st.tuples(st.just("cell"), st.integers(0, _N - 1), st.integers(0, 3), _GARBAGE),
    st.tuples(st.just("scale"), st.integers(0, 3), st.sampled_from([1e-3, -1.0, 0.0, 1e3, 32.0, 1.0 / 32.0, 1e300])),
    st.tuples(st.just("jitter"), st.integers(0, 2**32 - 1), st.sampled_from([1e-6, 1e-4, 3e-3, 0.02])),
    st.tuples(st.just("shift"), st.integers(0, _N - 1), st.floats(-10.0, 10.0)),
)


def _cell_value(text: str) -> tuple[float, bool]:
    """(the float a cell's text reads as, True), or (NaN, False) where it reads as none."""
    try:
        return float(text), True
    except ValueError:
        return math.nan, False


def mutate_log(edits) -> tuple[str, np.ndarray]:
    """The text of the mutated log, and the finite torque values (N m) it holds.

    The cells' texts (rows, 4) are kept beside the floats they read as and whether they read as one, so that an edit of
    a whole column (scale, jitter, shift) is one array operation on the cells that read as floats, each then written as
    its repr, as a loop over the rows would (a generator's draws in one call are its draws one by one); the torque the
    log holds is that of the rows whose four cells read as finite floats."""
    cells = np.array(_CELLS, dtype=object)
    values, reads = _LOG_ROWS.astype(float), np.ones(_LOG_ROWS.shape, bool)
    for op, i, *arg in edits:
        if len(cells) == 0:
            break
        if op in ("scale", "jitter", "shift"):
            col = i if op == "scale" else 0  # scale: column i; jitter and shift act on time_s
            rows = np.flatnonzero(reads[:, col])
            x = values[rows, col]
            with np.errstate(all="ignore"):  # a scale of 1e300 overflows to inf, as Python's float arithmetic does
                if op == "scale":
                    x = x * arg[0]
                elif op == "jitter":
                    x = x + np.random.default_rng(i).normal(0.0, arg[0], rows.size)
                else:
                    x = np.where(rows >= i % len(cells), x + arg[0], x)  # a step of the clock from row i on
            values[rows, col] = x
            cells[rows, col] = [repr(v) for v in x.tolist()]
            continue
        i %= len(cells)
        if op == "delete":
            order = np.r_[0:i, i + arg[0]:len(cells)]
        elif op == "duplicate":
            order = np.r_[0:i, np.full(arg[0], i), i:len(cells)]
        elif op == "swap":
            order = np.arange(len(cells))
            order[[i, arg[0] % len(cells)]] = order[[arg[0] % len(cells), i]]
        else:  # cell
            cells[i, arg[0]] = arg[1]
            values[i, arg[0]], reads[i, arg[0]] = _cell_value(arg[1])
            continue
        cells, values, reads = cells[order], values[order], reads[order]
    label = "# synthetic drive log fuzzed by tests/test_drive_log_errors.py (truth: smooth_torque of test_drive_log.py, no noise)"
    text = label + "\n" + ",".join(COLUMNS) + "\n"
    text += "".join(",".join(r) + "\n" for r in cells.tolist())
    return text, values[np.all(reads & np.isfinite(values), axis=1), 3]


@settings(max_examples=600, **FIXED)
@given(st.lists(_LOG_EDITS, min_size=1, max_size=5))
def test_a_mutated_drive_log_reads_or_raises_a_press_data_error(tmp_path, edits):
    text, torque = mutate_log(edits)
    path = tmp_path / "fuzz_log.csv"
    path.write_text(text, encoding="utf-8")
    try:
        log = read_drive_log(path, G, RATED)
    except PressDataError as exc:
        event("refused")
        assert str(exc).startswith(str(path)) and "\n" not in str(exc)
        return
    event("read" + (" with repairs" if log.warnings else ""))
    # documented: theta on the 1-degree grid; torque and crank speed finite at every grid point (every point
    # has data from some turn, or the reader refuses); the spread NaN only where one turn covers the point
    assert log.theta.shape == log.torque.shape == log.crank_speed.shape == (360,)
    assert np.all(np.isfinite(log.torque)) and np.all(np.isfinite(log.crank_speed))
    assert np.all(np.isfinite(log.torque_spread) | np.isnan(log.torque_spread))
    assert log.stroke_torque.shape[1] == 360 and 0 <= log.strokes <= log.stroke_torque.shape[0]
    # interpolation and averaging never leave the range of the samples (the reader's only arithmetic on torque)
    slack = 1e-9 * max(1.0, float(np.max(np.abs(torque))))
    assert torque.min() - slack <= log.torque.min() and log.torque.max() <= torque.max() + slack
    assert all(isinstance(w, str) and w for w in log.warnings)


def test_log_one_absurd_speed_sample_is_named_by_its_line(capsys, work, log_lines):
    """One motor_speed_rpm cell of 1e300 once set the top speed every other row was compared with, and the check
    blamed the whole column's unit (crank rpm, rad/s); now the rows around it are named."""
    lines, h = log_lines
    path = write_log(work, lines[:h + 500] + [with_cell(lines[h + 500], 2, "1e300")] + lines[h + 501:])
    line = refused(cli(capsys, "calibrate", "--log", path, "--out", work.out), "log.csv", f"lines {h + 500}-{h + 501}, crank_angle_deg",
                   "wrong motor_speed_rpm in these rows")
    assert "crank rpm instead of motor rpm" not in line
    work.unchanged()


@pytest.mark.parametrize("value", ["1e300", "-4e7"])
def test_log_one_absurd_crank_angle_is_refused_by_its_line(capsys, work, log_lines, value):
    """A crank_angle_deg cell of 1e300 was refused as 'falls 180 deg below the angle reached before': its line and
    value are named as a corrupt cell, with the bound of drive_log.toml."""
    lines, h = log_lines
    path = write_log(work, lines[:h + 500] + [with_cell(lines[h + 500], 1, value)] + lines[h + 501:])
    line = refused(cli(capsys, "calibrate", "--log", path, "--out", work.out), f"line {h + 501}, crank_angle_deg = {float(value)!r}",
                   "max_crank_angle_deg", "remove or fix the row")
    assert "falls" not in line
    work.unchanged()
